//! The pipeline a run starts: the nodes of the declaration ([`PIPELINE`]) with, for each,
//! its binary (processes) and its code (threads), or that declaration with nodes added
//! ([`Pipeline::with_node`]) — how a test or an experiment adds an observer without a new
//! binary of the supervisor's or a new stage kind.

use anyhow::{bail, ensure};
use linetrack_ipc::{Bus, Shutdown};
use linetrack_msgs::pipeline::{NodeDecl, Role, node_in};
use linetrack_msgs::{PIPELINE, StageKind, Topic};
use linetrack_pipeline_config::PipelineConfig;
use linetrack_stage_runtime::StageContext;

/// A node's code, as a thread runs it (the same function its process's `main` hands to
/// `linetrack_stage_runtime::stage_main`).
pub type NodeRun = fn(&StageContext, &Bus, &Shutdown) -> anyhow::Result<()>;

/// The frame source fed by ROS 2 image topics (`[camera.ros2_images]`), built with this
/// cargo feature.
pub const ROS2_SOURCE: (&str, &str) = ("linetrack-ros2-source", "linetrack-ros2-bridge/ros2");

/// The nodes a run starts and the code of each for single-process mode.
#[derive(Debug, Clone)]
pub struct Pipeline {
    nodes: &'static [NodeDecl],
    /// The code of the nodes added to [`PIPELINE`].
    added: Vec<(StageKind, NodeRun)>,
}

impl Default for Pipeline {
    /// [`PIPELINE`] as declared.
    fn default() -> Self {
        Self {
            nodes: PIPELINE,
            added: Vec::new(),
        }
    }
}

impl Pipeline {
    /// This pipeline and `node`, whose code is `code` (run on a thread with
    /// `--single-process`; as a process, the supervisor starts `node.binary` from the folder
    /// of the stage binaries, which hands the same function to `stage_main`).
    ///
    /// Only an observer or a sink that publishes nothing but its status can be added this
    /// way: the shipped binaries learnt whom to wake and which stamp slots a frame has
    /// from [`PIPELINE`] when they were built, so an added node declares what it takes as
    /// `reads` (it is woken by no publisher: it polls, `linetrack_stage_runtime::Sink::
    /// max_sleep`), stamps no frame, has no `[budget]` key and no `[stages.<name>]`. A node
    /// that is to be woken, stamp frames or publish is an entry of [`PIPELINE`] itself.
    /// The node's kind must not be declared already.
    pub fn with_node(mut self, node: NodeDecl, code: NodeRun) -> anyhow::Result<Self> {
        let stage = node.stage;
        if node_in(self.nodes, stage).is_some() {
            bail!("{stage} is declared already: an added node needs a kind of its own");
        }
        ensure!(
            matches!(node.role, Role::Observer | Role::Sink),
            "{stage}: only an observer or a sink can be added to the declaration, not a {:?}",
            node.role
        );
        ensure!(
            node.wakes_on.is_empty(),
            "{stage}: an added node is woken by no publisher (their wake lists come from PIPELINE): declare its inputs as `reads`"
        );
        ensure!(
            node.publishes.iter().all(|&t| t == Topic::Status),
            "{stage}: an added node publishes nothing but its status"
        );
        ensure!(
            node.stamp.is_none() && node.budget.is_none() && !node.scheduled,
            "{stage}: an added node stamps no frame and has no [budget] key or [stages.{stage}]"
        );
        let mut nodes = self.nodes.to_vec();
        nodes.push(node);
        // Once per pipeline built (a run, a test): the declaration lives as long as the
        // program, as PIPELINE does.
        self.nodes = Vec::leak(nodes);
        self.added.push((stage, code));
        Ok(self)
    }

    /// The declaration.
    pub fn nodes(&self) -> &'static [NodeDecl] {
        self.nodes
    }

    /// The code of `stage` for a thread (the same function its process's `main` runs).
    pub(crate) fn code(&self, stage: StageKind) -> Option<NodeRun> {
        if let Some(&(_, code)) = self.added.iter().find(|(s, _)| *s == stage) {
            return Some(code);
        }
        match stage {
            StageKind::FrameSource => Some(linetrack_frame_source::run),
            StageKind::LineDetector => Some(linetrack_line_detector::run),
            StageKind::Matcher => Some(linetrack_matcher::run),
            StageKind::PoseEstimator => Some(linetrack_pose_estimator::run),
            StageKind::Supervisor
            | StageKind::Recorder
            | StageKind::Ros2Bridge
            | StageKind::Link
            | StageKind::Observer => None,
        }
    }

    /// The binary of `stage` in a run of `config`: the one the declaration names, but for
    /// the frame source fed by ROS 2 image topics when `[camera.ros2_images]` names them.
    pub(crate) fn binary(&self, config: &PipelineConfig, stage: StageKind) -> String {
        if stage == StageKind::FrameSource && config.camera.ros2_images.enabled() {
            ROS2_SOURCE.0.to_string()
        } else {
            node_in(self.nodes, stage).map_or_else(
                || format!("linetrack-{}", stage.name()),
                |node| node.binary.to_string(),
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_msgs::pipeline::{Restart, Start};

    fn nothing(_: &StageContext, _: &Bus, _: &Shutdown) -> anyhow::Result<()> {
        Ok(())
    }

    const OBSERVER: NodeDecl = NodeDecl {
        reads: &[Topic::Poses],
        start: Start::WithStages,
        restart: Restart::Backoff,
        ..NodeDecl::new(StageKind::Observer, Role::Observer, "linetrack-counter")
    };

    /// Every node the supervisor starts has its code for single-process mode and a binary
    /// for processes, both as declared.
    #[test]
    fn every_supervised_node_has_its_code_and_its_declared_binary() {
        let config = PipelineConfig::default();
        let pipeline = Pipeline::default();
        for node in PIPELINE.iter().filter(|n| n.supervised()) {
            assert!(pipeline.code(node.stage).is_some(), "{}", node.stage);
            assert_eq!(pipeline.binary(&config, node.stage), node.binary);
            assert_eq!(node.binary, format!("linetrack-{}", node.stage.name()));
        }
    }

    /// An added node is declared after the others, with its binary and its code.
    #[test]
    fn an_added_observer_has_its_binary_and_its_code() -> anyhow::Result<()> {
        let config = PipelineConfig::default();
        let pipeline = Pipeline::default().with_node(OBSERVER, nothing)?;
        assert_eq!(pipeline.nodes().len(), PIPELINE.len() + 1);
        assert_eq!(pipeline.nodes().last(), Some(&OBSERVER));
        assert_eq!(
            pipeline.binary(&config, StageKind::Observer),
            "linetrack-counter"
        );
        assert!(pipeline.code(StageKind::Observer).is_some());
        assert!(Pipeline::default().code(StageKind::Observer).is_none());
        Ok(())
    }

    /// What the shipped binaries cannot honour for a node they were not built with is
    /// refused, naming the node.
    #[test]
    fn an_added_node_the_binaries_cannot_serve_is_refused() {
        let cases = [
            (
                NodeDecl {
                    stage: StageKind::Matcher,
                    ..OBSERVER
                },
                "matcher is declared already",
            ),
            (
                NodeDecl {
                    wakes_on: &[Topic::Poses],
                    ..OBSERVER
                },
                "observer: an added node is woken by no publisher",
            ),
            (
                NodeDecl {
                    publishes: &[Topic::Tracks, Topic::Status],
                    ..OBSERVER
                },
                "publishes nothing but its status",
            ),
            (
                NodeDecl {
                    role: Role::Stage,
                    ..OBSERVER
                },
                "only an observer or a sink",
            ),
            (
                NodeDecl {
                    budget: Some("matcher_ms"),
                    ..OBSERVER
                },
                "no [budget] key",
            ),
        ];
        for (node, expected) in cases {
            let refused = Pipeline::default()
                .with_node(node, nothing)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(refused.contains(expected), "{refused:?}: {expected}");
        }
    }
}
