//! The `linetrack-link` process: the ground-station link's onboard side, started by the
//! supervisor when `[link] enabled` (with the arguments every stage gets). It forwards the
//! allowed topics to zenoh until the run ends, and writes its counters to `link.json` in
//! the run folder.

use clap::Parser;
use linetrack_ipc::{Bus, Scope, Shutdown};
use linetrack_pipeline_config::PipelineConfig;
use linetrack_stage_runtime::{StageArgs, end_with_parent};
use std::process::ExitCode;

fn main() -> ExitCode {
    let args = StageArgs::parse();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("link: {e:#}");
            eprintln!("linetrack-link: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &StageArgs) -> anyhow::Result<()> {
    let config = PipelineConfig::from_file(&args.config)?;
    let _log = linetrack_telemetry::init("link", "info,zenoh=warn", None)?;
    let shutdown = Shutdown::on_signals()?;
    end_with_parent(&shutdown, args.supervisor_pid)?;
    let pid = std::process::id();
    let bus = Bus::shared_memory(
        &Scope::new(&args.run_id).with_configured_root(config.ipc.root.as_deref()),
        &format!("link-{pid}"),
    )?;
    forward(&config, &bus, &shutdown, args)
}

#[cfg(feature = "zenoh")]
fn forward(
    config: &PipelineConfig,
    bus: &Bus,
    shutdown: &Shutdown,
    args: &StageArgs,
) -> anyhow::Result<()> {
    use anyhow::Context;
    let path = args.run_dir.join("link.json");
    let counts = linetrack_link::onboard::run(&config.link, bus, shutdown, &path)
        .with_context(|| format!("link.listen = {:?}", config.link.listen))?;
    tracing::info!(
        "link: {} frames; per topic (sent, bytes, dropped, unheard): {}",
        counts.frames,
        counts
            .topics
            .iter()
            .map(|(t, c)| format!("{t} {} {} {} {}", c.sent, c.bytes, c.dropped, c.unheard))
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}

#[cfg(not(feature = "zenoh"))]
fn forward(_: &PipelineConfig, _: &Bus, _: &Shutdown, _: &StageArgs) -> anyhow::Result<()> {
    anyhow::bail!(
        "this linetrack-link was built without zenoh: build with `--features linetrack/link` (docs/link.md, \"Ground-station link\")"
    )
}
