//! `linetrack-detector-bench`: see the library documentation or `--help`.

use clap::Parser;

fn main() -> anyhow::Result<()> {
    let args = linetrack_detector_bench::Args::parse();
    let report = linetrack_detector_bench::run(&args)?;
    print!("{report}");
    Ok(())
}
