//! The `linetrack-frame-source` process: one stage of the pipeline, started by the supervisor.

use linetrack_msgs::StageKind;
use std::process::ExitCode;

fn main() -> ExitCode {
    linetrack_stage_runtime::stage_main(StageKind::FrameSource, |ctx, bus, shutdown| {
        // A process of its own: OpenCV's work (rectifying the frames read ahead) stays on
        // the reading thread, at its lower priority (`source.reader_nice`).
        if let Err(e) = linetrack_datasets::opencv_on_calling_threads() {
            tracing::warn!("{e}");
        }
        linetrack_frame_source::run(ctx, bus, shutdown)
    })
}
