//! The `linetrack-recorder` process: records a run into an MCAP file; started by the
//! supervisor when the config says `[record] mcap = true`.

use linetrack_msgs::StageKind;
use std::process::ExitCode;

fn main() -> ExitCode {
    linetrack_stage_runtime::stage_main(StageKind::Recorder, linetrack_recorder::run)
}
