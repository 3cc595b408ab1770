//! The `linetrack-ros2-source` process: the frame source fed by two ROS 2 image topics
//! (`[camera.ros2_images]`), started by the supervisor in place of `linetrack-frame-source`.
//! It starts as every node of the pipeline does (`linetrack_stage_runtime::stage_main`).

use linetrack_ipc::{Bus, Shutdown};
use linetrack_msgs::StageKind;
use linetrack_ros2_bridge::image_source::RosImageSource;
use linetrack_stage_runtime::{RigOutlet, StageContext, run_source};
use std::process::ExitCode;

fn main() -> ExitCode {
    linetrack_stage_runtime::stage_main(StageKind::FrameSource, run)
}

fn run(ctx: &StageContext, bus: &Bus, shutdown: &Shutdown) -> anyhow::Result<()> {
    let rig = RigOutlet::open(bus)?;
    run_source(ctx, bus, RosImageSource::new(ctx, rig)?, shutdown)
}
