//! The `linetrack-link` process: the ground-station link's onboard side, started by the
//! supervisor when `[link] enabled` (with the arguments every stage gets). It forwards the
//! allowed topics to zenoh until the run ends, and writes its counters to `link.json` in
//! the run folder. It starts as every node of the pipeline does and runs as a sink of the
//! stage runtime.

use linetrack_msgs::StageKind;
use std::process::ExitCode;

fn main() -> ExitCode {
    linetrack_stage_runtime::node_main(StageKind::Link, "info,zenoh=warn", forward)
}

#[cfg(feature = "zenoh")]
fn forward(
    ctx: &linetrack_stage_runtime::StageContext,
    bus: &linetrack_ipc::Bus,
    shutdown: &linetrack_ipc::Shutdown,
) -> anyhow::Result<()> {
    use anyhow::Context;
    let path = ctx.args.run_dir.join("link.json");
    let config = &ctx.config.link;
    linetrack_stage_runtime::run_sink(ctx, bus, shutdown, |bus| {
        linetrack_link::onboard::Onboard::open(config, bus, &path)
            .with_context(|| format!("link.listen = {:?}", config.listen))
    })
}

#[cfg(not(feature = "zenoh"))]
fn forward(
    _: &linetrack_stage_runtime::StageContext,
    _: &linetrack_ipc::Bus,
    _: &linetrack_ipc::Shutdown,
) -> anyhow::Result<()> {
    anyhow::bail!(
        "this linetrack-link was built without zenoh: build with `--features linetrack/link` (docs/link.md, \"Ground-station link\")"
    )
}
