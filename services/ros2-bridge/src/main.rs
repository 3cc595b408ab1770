//! The `linetrack-ros2` process: the pipeline's poses as ROS 2 messages, started by the
//! supervisor when `[ros2] enabled = true`.

use anyhow::Context;
use clap::Parser;
use linetrack_ipc::{Bus, Scope, Shutdown};
use linetrack_pipeline_config::PipelineConfig;
use linetrack_ros2_bridge::PoseSink;
use linetrack_ros2_bridge::dds::DdsSink;
use std::path::PathBuf;
use std::process::ExitCode;

/// What the supervisor passes.
#[derive(Debug, Parser)]
#[command(
    about = "Publishes a linetrack run's poses to ROS 2; started by the supervisor (`linetrack run`)."
)]
struct Args {
    /// The run's pipeline config.
    #[arg(long)]
    config: PathBuf,
    /// The run's id: it names the shared-memory services.
    #[arg(long)]
    run_id: String,
    /// The supervisor's pid: the bridge ends when that process does.
    #[arg(long)]
    supervisor_pid: Option<u32>,
}

fn main() -> ExitCode {
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("ros2: {e:#}");
            eprintln!("linetrack-ros2: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: Args) -> anyhow::Result<()> {
    let config = PipelineConfig::from_file(&args.config)?;
    let _logs = linetrack_telemetry::init("ros2", "warn", None)?;
    let shutdown = Shutdown::on_signals()?;
    linetrack_stage_runtime::end_with_parent(&shutdown, args.supervisor_pid)?;
    let bus = Bus::shared_memory(
        &Scope::new(&args.run_id).with_configured_root(config.ipc.root.as_deref()),
        &format!("ros2-{}", std::process::id()),
    )?;
    let ros2 = config.ros2.clone();
    let tally =
        linetrack_ros2_bridge::run(&config.ros2, &config.budget, &bus, &shutdown, move || {
            Ok(Box::new(DdsSink::new(&ros2)?) as Box<dyn PoseSink>)
        })
        .context("ROS 2 output")?;
    tracing::info!("ROS 2 output: {tally:?}");
    Ok(())
}
