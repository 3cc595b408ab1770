//! The `linetrack-line-detector` process: one stage of the pipeline, started by the supervisor.

use linetrack_msgs::StageKind;
use std::process::ExitCode;

fn main() -> ExitCode {
    linetrack_stage_runtime::stage_main(StageKind::LineDetector, |ctx, bus, shutdown| {
        let ports = linetrack_line_detector::Ports::open(bus, ctx)?;
        linetrack_line_detector::run(ctx, ports, shutdown)
    })
}
