//! `linetrack-eval`: see the library documentation or `--help`.

use clap::Parser;

fn main() -> anyhow::Result<()> {
    let args = linetrack_eval::Args::parse();
    let summary = linetrack_eval::run(&args)?;
    println!("{summary}");
    Ok(())
}
