//! The `linetrack-frame-source` process: one stage of the pipeline, started by the supervisor.

use linetrack_msgs::StageKind;
use std::process::ExitCode;

fn main() -> ExitCode {
    linetrack_stage_runtime::stage_main(StageKind::FrameSource, linetrack_frame_source::run_process)
}
