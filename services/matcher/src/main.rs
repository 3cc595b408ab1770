//! The `linetrack-matcher` process: one stage of the pipeline, started by the supervisor.

use linetrack_msgs::StageKind;
use std::process::ExitCode;

fn main() -> ExitCode {
    linetrack_stage_runtime::stage_main(StageKind::Matcher, |ctx, bus, shutdown| {
        let ports = linetrack_matcher::Ports::open(bus, ctx)?;
        linetrack_matcher::run(ctx, ports, shutdown)
    })
}
