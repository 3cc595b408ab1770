//! `linetrack-synth`: see the library documentation or `--help`.

use clap::Parser;

fn main() -> anyhow::Result<()> {
    let args = linetrack_synth::Args::parse();
    let summary = linetrack_synth::run(&args)?;
    println!("{summary}");
    Ok(())
}
