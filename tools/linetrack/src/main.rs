//! `linetrack`: run the pipeline, steer a running one, report on a run.

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = linetrack::Cli::parse();
    match linetrack::main(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("linetrack: {e:#}");
            ExitCode::FAILURE
        }
    }
}
