//! How a stage instance runs: a child process, or (single-process mode) a thread of the
//! supervisor's process running the same code its process's `main` runs.

use linetrack_ipc::{Bus, Shutdown};
use linetrack_msgs::StageKind;
use linetrack_pipeline_config::PipelineConfig;
use linetrack_stage_runtime::StageContext;
use std::process::Child;

/// Ids of thread stages start here (above any Linux pid), so that commands and status
/// reports name each instance as they name processes.
pub const THREAD_IDS: u32 = 1 << 30;

/// How a stage instance runs: a child process, or a thread of this process.
pub(crate) enum Launch {
    Process(Child),
    Thread {
        handle: Option<std::thread::JoinHandle<anyhow::Result<()>>>,
        stop: Shutdown,
    },
}

impl Launch {
    /// How it ended, if it has: a description and whether it succeeded.
    pub(crate) fn try_wait(&mut self) -> Result<Option<(String, bool)>, std::io::Error> {
        match self {
            Launch::Process(child) => Ok(child
                .try_wait()?
                .map(|status| (status.to_string(), status.success()))),
            Launch::Thread { handle, .. } => {
                if !handle.as_ref().is_some_and(|h| h.is_finished()) {
                    return Ok(handle.is_none().then(|| ("left behind".to_string(), false)));
                }
                Ok(handle.take().map(|h| match h.join() {
                    Ok(Ok(())) => ("exit status: 0".to_string(), true),
                    Ok(Err(e)) => (format!("failed: {e:#}"), false),
                    Err(_) => ("panicked".to_string(), false),
                }))
            }
        }
    }

    /// Ends it: a process is killed; a thread is asked to stop (it cannot be killed).
    pub(crate) fn kill(&mut self) {
        match self {
            Launch::Process(child) => {
                let _ = child.kill();
            }
            Launch::Thread { stop, .. } => stop.request(),
        }
    }

    /// Reaps a process; a thread that has not ended is left behind.
    pub(crate) fn reap(&mut self) {
        match self {
            Launch::Process(child) => {
                let _ = child.wait();
            }
            Launch::Thread { handle, .. } => {
                if handle.as_ref().is_some_and(|h| h.is_finished())
                    && let Some(h) = handle.take()
                {
                    let _ = h.join();
                }
                *handle = None;
            }
        }
    }
}

/// A stage's code, as a thread runs it.
pub(crate) type StageRun = fn(&StageContext, &Bus, &Shutdown) -> anyhow::Result<()>;

/// The code of `stage` (the same function its process's `main` runs).
pub(crate) fn stage_code(stage: StageKind) -> Option<StageRun> {
    match stage {
        StageKind::FrameSource => Some(linetrack_frame_source::run),
        StageKind::LineDetector => Some(linetrack_line_detector::run),
        StageKind::Matcher => Some(linetrack_matcher::run),
        StageKind::PoseEstimator => Some(linetrack_pose_estimator::run),
        StageKind::Supervisor | StageKind::Recorder | StageKind::Ros2Bridge | StageKind::Link => {
            None
        }
    }
}

/// The frame source fed by ROS 2 image topics (`[camera.ros2_images]`), built with this
/// cargo feature.
pub const ROS2_SOURCE: (&str, &str) = ("linetrack-ros2-source", "linetrack-ros2-bridge/ros2");

/// The binary of `stage` in a run of `config`: the one the pipeline's declaration names,
/// but for the frame source fed by ROS 2 image topics when `[camera.ros2_images]` names
/// them.
pub(crate) fn stage_binary(config: &PipelineConfig, stage: StageKind) -> String {
    if stage == StageKind::FrameSource && config.camera.ros2_images.enabled() {
        ROS2_SOURCE.0.to_string()
    } else {
        stage.decl().map_or_else(
            || format!("linetrack-{}", stage.name()),
            |node| node.binary.to_string(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_msgs::PIPELINE;

    /// Every node the supervisor starts has its code for single-process mode and a binary
    /// for processes, both as declared.
    #[test]
    fn every_supervised_node_has_its_code_and_its_declared_binary() {
        let config = PipelineConfig::default();
        for node in PIPELINE.iter().filter(|n| n.supervised()) {
            assert!(stage_code(node.stage).is_some(), "{}", node.stage);
            assert_eq!(stage_binary(&config, node.stage), node.binary);
            assert_eq!(node.binary, format!("linetrack-{}", node.stage.name()));
        }
    }
}
