//! `linetrack-supervisor`: runs the pipeline from a config (the same as `linetrack run`).

use clap::Parser;
use linetrack_ipc::Shutdown;
use linetrack_pipeline_config::PipelineConfig;
use linetrack_supervisor::{Mode, RunOptions};
use std::path::PathBuf;
use std::process::ExitCode;

/// Runs the linetrack pipeline: one process per stage over shared memory.
#[derive(Parser)]
struct Args {
    /// Pipeline config.
    #[arg(
        long,
        env = "LINETRACK_CONFIG",
        default_value = "configs/pipeline.toml"
    )]
    config: PathBuf,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let run = || -> anyhow::Result<()> {
        let _logs = linetrack_telemetry::init("supervisor", "info", None)?;
        let config = PipelineConfig::from_file(&args.config)?;
        let outcome = linetrack_supervisor::run(
            &config,
            &RunOptions {
                mode: Mode::Processes,
                bin_dir: None,
                live_status: true,
            },
            &Shutdown::on_signals()?,
        )?;
        print!("{}", outcome.report.to_text());
        Ok(())
    };
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("linetrack-supervisor: {e:#}");
            ExitCode::FAILURE
        }
    }
}
