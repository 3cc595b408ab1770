//! `linetrack-match-demo`: see the library documentation or `--help`.

use clap::Parser;

fn main() -> anyhow::Result<()> {
    let args = linetrack_match_demo::Args::parse();
    let report = linetrack_match_demo::run(&args)?;
    print!("{report}");
    Ok(())
}
