//! The `linetrack-line-detector` process: one stage of the pipeline, started by the supervisor.

use linetrack_msgs::StageKind;
use std::process::ExitCode;

fn main() -> ExitCode {
    linetrack_stage_runtime::stage_main(StageKind::LineDetector, linetrack_line_detector::run)
}
