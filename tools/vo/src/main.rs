//! `linetrack-vo`: see the library documentation or `--help`.

use clap::Parser;

fn main() -> anyhow::Result<()> {
    let args = linetrack_vo::Args::parse();
    let summary = linetrack_vo::run(&args)?;
    println!("{summary}");
    Ok(())
}
