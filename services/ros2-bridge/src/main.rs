//! The `linetrack-ros2` process: the pipeline's poses as ROS 2 messages, started by the
//! supervisor when `[ros2] enabled = true`. It starts as every node of the pipeline does
//! (`linetrack_stage_runtime::node_main`: the arguments, the config, logging, signals, the
//! run's shared memory).

use anyhow::Context;
use linetrack_ipc::{Bus, Shutdown};
use linetrack_msgs::StageKind;
use linetrack_pipeline_config::StampSource;
use linetrack_ros2_bridge::PoseSink;
use linetrack_ros2_bridge::dds::DdsSink;
use linetrack_stage_runtime::StageContext;
use std::process::ExitCode;

fn main() -> ExitCode {
    linetrack_stage_runtime::node_main(StageKind::Ros2Bridge, "warn", run)
}

fn run(ctx: &StageContext, bus: &Bus, shutdown: &Shutdown) -> anyhow::Result<()> {
    let mut ros2 = ctx.config.ros2.clone();
    if ctx.config.camera.ros2_images.enabled() {
        // Frames from ROS 2 images: the messages carry the images' header stamps.
        ros2.stamp = StampSource::Sequence;
    }
    let config = ros2.clone();
    let tally = linetrack_ros2_bridge::run(&config, &ctx.config.budget, bus, shutdown, move || {
        Ok(Box::new(DdsSink::new(&ros2)?) as Box<dyn PoseSink>)
    })
    .context("ROS 2 output")?;
    tracing::info!("ROS 2 output: {tally:?}");
    Ok(())
}
