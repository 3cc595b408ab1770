//! The pipeline's stages and the topics between them: who publishes what, who reads it,
//! and the names of the services that carry them.

use crate::WireEnum;
use crate::pipeline::{self, NodeDecl, PIPELINE, StampSlot};
use num_enum::{IntoPrimitive, TryFromPrimitive};
use std::fmt;

wire_enum! {
    /// A stage of the pipeline.
    pub enum StageKind: "stage" {
        /// Reads (or renders) stereo frames and publishes them.
        #[default]
        FrameSource = 0,
        /// Detects segments in both images.
        LineDetector = 1,
        /// Stereo and frame-to-frame segment matching.
        Matcher = 2,
        /// Visual odometry.
        PoseEstimator = 3,
        /// Starts, watches and steers the others.
        Supervisor = 4,
        /// Records the run into an MCAP file (`[record] mcap = true`); no processing stage.
        Recorder = 5,
        /// Publishes the poses to ROS 2 (`[ros2]`); no processing stage.
        Ros2Bridge = 6,
        /// Forwards the run to a ground station over zenoh (`[link]`); no processing stage.
        Link = 7,
        /// A node added to the pipeline's declaration besides [`PIPELINE`]'s (a test's or an
        /// experiment's observer, `linetrack_supervisor::Pipeline::with_node`): its identity
        /// on the wire, so that adding one needs no new variant. [`PIPELINE`] declares none.
        Observer = 8,
    }
}

impl StageKind {
    /// The processing stages, upstream first: the nodes [`PIPELINE`] declares to fill the
    /// stamp slots, in slot order.
    pub const PROCESSING: [StageKind; StampSlot::COUNT] = pipeline::slot_stages(PIPELINE);

    /// The stage's name: also its binary's suffix (`linetrack-<name>`) and its config key.
    pub fn name(self) -> &'static str {
        match self {
            StageKind::FrameSource => "frame-source",
            StageKind::LineDetector => "line-detector",
            StageKind::Matcher => "matcher",
            StageKind::PoseEstimator => "pose-estimator",
            StageKind::Supervisor => "supervisor",
            StageKind::Recorder => "recorder",
            StageKind::Ros2Bridge => "ros2-bridge",
            StageKind::Link => "link",
            StageKind::Observer => "observer",
        }
    }

    /// The slot of [`crate::FrameHeader::stamps`] it fills, as [`PIPELINE`] declares
    /// (none for a node that times no frame: the supervisor, the outputs).
    pub fn stamp_slot(self) -> Option<StampSlot> {
        pipeline::stamp_slot(self)
    }

    /// Its declaration in [`PIPELINE`].
    pub fn decl(self) -> Option<&'static NodeDecl> {
        pipeline::node(self)
    }

    /// The stage named `name` (see [`StageKind::name`]).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.iter().copied().find(|k| k.name() == name)
    }
}

impl fmt::Display for StageKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The pipeline's topics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Topic {
    /// Stereo images: payload `[u8]`, left image then right image, row-major.
    Frames,
    /// Detected segments: payload [`SegmentRecord`]s, left image's then right image's.
    Segments,
    /// Matched segments: payload [`TrackedLine`]s, one per left segment.
    Tracks,
    /// Poses: payload one [`PoseRecord`].
    Poses,
    /// Heartbeats and stage events: payload one [`StatusReport`].
    Status,
    /// Commands: payload one [`Control`].
    Control,
    /// The stereo rig the frames are rectified to: payload one [`RigRecord`], published by
    /// the frame source before its first frame and whenever the rig changes; kept as history,
    /// so a stage that starts later (a restart) gets it too.
    Rig,
}

impl Topic {
    /// Every topic.
    pub const ALL: [Topic; 7] = [
        Topic::Frames,
        Topic::Segments,
        Topic::Tracks,
        Topic::Poses,
        Topic::Status,
        Topic::Control,
        Topic::Rig,
    ];

    /// Short name.
    pub fn name(self) -> &'static str {
        match self {
            Topic::Frames => "frames",
            Topic::Segments => "segments",
            Topic::Tracks => "tracks",
            Topic::Poses => "poses",
            Topic::Status => "status",
            Topic::Control => "control",
            Topic::Rig => "rig",
        }
    }

    /// The nodes that subscribe, and so are woken when a message is published, in the
    /// order they are woken: derived from [`PIPELINE`] (each node's `wakes_on`, by its
    /// `wake_rank`).
    pub fn consumers(self) -> &'static [StageKind] {
        pipeline::consumers(self)
    }

    /// How many messages a subscriber queues before the oldest is overwritten. Images are
    /// large and stages drop late frames rather than queue them; the small topics get room
    /// for bursts.
    ///
    /// The one number behind a subscriber's buffer, its borrow limit (the same) and the
    /// frames a stage may hold (`linetrack_stage_runtime::HELD_FRAMES`, one less).
    pub const fn queue_depth(self) -> usize {
        match self {
            Topic::Frames => 12,
            Topic::Segments | Topic::Tracks => 16,
            Topic::Poses | Topic::Status | Topic::Control => 64,
            Topic::Rig => 4,
        }
    }

    /// Messages a subscriber that connects later still receives: the last rig.
    pub const fn history(self) -> usize {
        match self {
            Topic::Rig => 1,
            _ => 0,
        }
    }

    /// Most publishers at once: two line detectors during a hot swap; every stage reports
    /// status; the supervisor and `linetrack ctl` send control.
    pub fn max_publishers(self) -> usize {
        match self {
            Topic::Frames | Topic::Tracks | Topic::Poses | Topic::Rig => 2,
            Topic::Segments => 3,
            Topic::Status | Topic::Control => 12,
        }
    }

    /// The iceoryx2 service name of this topic in run `run_id`.
    pub fn service_name(self, run_id: &str) -> String {
        format!("linetrack/{run_id}/{}", self.name())
    }
}

/// The iceoryx2 event service that wakes `stage` in run `run_id`.
pub fn wake_service_name(run_id: &str, stage: StageKind) -> String {
    format!("linetrack/{run_id}/wake/{}", stage.name())
}
