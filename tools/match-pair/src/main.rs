//! `linetrack-match-pair`: see the library documentation or `--help`.

use clap::Parser;

fn main() -> anyhow::Result<()> {
    let args = linetrack_match_pair::Args::parse();
    let summary = linetrack_match_pair::run(&args)?;
    println!("{summary}");
    Ok(())
}
