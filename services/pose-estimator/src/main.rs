//! The `linetrack-pose-estimator` process: one stage of the pipeline, started by the supervisor.

use linetrack_msgs::StageKind;
use std::process::ExitCode;

fn main() -> ExitCode {
    linetrack_stage_runtime::stage_main(StageKind::PoseEstimator, |ctx, bus, shutdown| {
        let ports = linetrack_pose_estimator::Ports::open(bus, ctx)?;
        linetrack_pose_estimator::run(ctx, ports, shutdown)
    })
}
