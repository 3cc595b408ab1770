//! The pipeline declared once: [`PIPELINE`], one [`NodeDecl`] per node — its role, binary,
//! the topics it is woken by, reads and publishes (each a [`TopicOf`] carrying its payload and
//! header types), the stamp slot it fills, its budget key, how it is started and restarted,
//! and whether a standby can take over from it while the run goes on.
//!
//! What the rest of the system knows about the graph is derived from it: which nodes a
//! publish wakes and in which order ([`Topic::consumers`]), the named stamp slots of a
//! frame ([`StampSlot`], [`StageKind::stamp_slot`]), the supervisor's spawn table, restarts
//! and hot swap (`linetrack_supervisor`), each stage's `[budget]` key and the nodes that
//! take `[stages.<name>]` (`linetrack_pipeline_config`), whether an output is restarted.
//! Adding a node is one entry here plus its `Stage` impl, its wire code ([`StageKind`]) and
//! its thread code (`linetrack_supervisor::Pipeline`); an observer added by a test or an
//! experiment needs neither (`StageKind::Observer`, `Pipeline::with_node`). How:
//! docs/pipeline.md, "Adding a node".

use crate::{
    Control, FrameHeader, PoseRecord, RigRecord, SegmentRecord, SegmentsHeader, StageKind,
    StatusReport, Topic, TrackedLine, TracksHeader,
};
use std::marker::PhantomData;
use std::ops::{Index, IndexMut};

/// A topic with the types it carries: messages of `P` records under an `H` header. Ports
/// are opened from these, so a stage reading a topic as the wrong type does not compile.
pub struct TopicOf<P, H> {
    topic: Topic,
    types: PhantomData<fn() -> (P, H)>,
}

impl<P, H> TopicOf<P, H> {
    const fn new(topic: Topic) -> Self {
        Self {
            topic,
            types: PhantomData,
        }
    }

    /// The topic.
    pub const fn topic(self) -> Topic {
        self.topic
    }
}

impl<P, H> Clone for TopicOf<P, H> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<P, H> Copy for TopicOf<P, H> {}

impl<P, H> std::fmt::Debug for TopicOf<P, H> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "TopicOf({})", self.topic.name())
    }
}

/// The pipeline's topics with their types.
pub mod topics {
    use super::*;

    /// Stereo images: the left image's bytes then the right image's, under the frame's header.
    pub const FRAMES: TopicOf<u8, FrameHeader> = TopicOf::new(Topic::Frames);
    /// Both images' segments under the detection.
    pub const SEGMENTS: TopicOf<SegmentRecord, SegmentsHeader> = TopicOf::new(Topic::Segments);
    /// One track per left segment under the matching.
    pub const TRACKS: TopicOf<TrackedLine, TracksHeader> = TopicOf::new(Topic::Tracks);
    /// One pose under the frame's tracks header.
    pub const POSES: TopicOf<PoseRecord, TracksHeader> = TopicOf::new(Topic::Poses);
    /// Heartbeats and stage events.
    pub const STATUS: TopicOf<StatusReport, ()> = TopicOf::new(Topic::Status);
    /// Commands.
    pub const CONTROL: TopicOf<Control, ()> = TopicOf::new(Topic::Control);
    /// The stereo rig.
    pub const RIG: TopicOf<RigRecord, ()> = TopicOf::new(Topic::Rig);
}

/// A slot of [`FrameHeader::stamps`]: the stage that times its work on a frame there.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StampSlot {
    /// The frame source's reading.
    FrameSource = 0,
    /// The line detector's detection.
    LineDetector = 1,
    /// The matcher's matching.
    Matcher = 2,
    /// The pose estimator's estimate.
    PoseEstimator = 3,
}

impl StampSlot {
    /// How many slots a frame has.
    pub const COUNT: usize = 4;

    /// Every slot, upstream first (the order of the slots in a header, and of the
    /// per-stage columns of the run records).
    pub const ALL: [StampSlot; StampSlot::COUNT] = [
        StampSlot::FrameSource,
        StampSlot::LineDetector,
        StampSlot::Matcher,
        StampSlot::PoseEstimator,
    ];

    /// Its position in [`FrameHeader::stamps`].
    pub const fn index(self) -> usize {
        self as usize
    }

    /// The node declared to fill it.
    pub const fn stage(self) -> StageKind {
        StageKind::PROCESSING[self.index()]
    }

    /// The slot before this one (none for the first).
    pub fn before(self) -> Option<StampSlot> {
        self.index().checked_sub(1).map(|i| StampSlot::ALL[i])
    }
}

impl<T> Index<StampSlot> for [T; StampSlot::COUNT] {
    type Output = T;
    fn index(&self, slot: StampSlot) -> &T {
        &self[slot.index()]
    }
}

impl<T> IndexMut<StampSlot> for [T; StampSlot::COUNT] {
    fn index_mut(&mut self, slot: StampSlot) -> &mut T {
        &mut self[slot.index()]
    }
}

/// What a node does in the pipeline.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Publishes frames (a data set, a replay, a camera, ROS 2 images).
    Source,
    /// Takes a frame's message, publishes the next one.
    Stage,
    /// Reads the run and writes it elsewhere (a file, ROS 2, a ground station).
    Sink,
    /// Reads the run and acts on it without publishing frames.
    Observer,
    /// Starts, watches and steers the others.
    Supervisor,
}

/// When the supervisor starts a node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Start {
    /// At the start of the run, before the source.
    WithStages,
    /// Once every [`Start::WithStages`] node is ready and the outputs settled.
    AfterStages,
    /// When the config turns it on (`[record]`, `[ros2]`, `[link]`), before the stages.
    WhenConfigured,
    /// Not started by the supervisor (it is the supervisor).
    Never,
}

/// How a node that dies is brought back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Restart {
    /// Restarted after a doubling backoff, up to `supervisor.max_restarts`; past it the run
    /// fails.
    Backoff,
    /// An output: restarted after the same doubling backoff, up to the same limit; past
    /// it the run goes on without it.
    Output,
    /// Not restarted (an output that dies is recorded and left: the run goes on without
    /// it).
    Never,
}

/// One node of the pipeline.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NodeDecl {
    /// Its kind: its name, its config key and its code on the wire.
    pub stage: StageKind,
    /// What it does.
    pub role: Role,
    /// Its binary (started from the supervisor's folder).
    pub binary: &'static str,
    /// The topics whose publishes wake it (it subscribes to each).
    pub wakes_on: &'static [Topic],
    /// Topics it reads without being woken by them (side inputs).
    pub reads: &'static [Topic],
    /// The topics it publishes (all but the supervisor report on [`Topic::Status`]).
    pub publishes: &'static [Topic],
    /// Among the nodes a topic wakes, lower ranks are woken first.
    pub wake_rank: u8,
    /// The slot of a frame's header it times its work in.
    pub stamp: Option<StampSlot>,
    /// Its per-frame budget, the key under `[budget]`.
    pub budget: Option<&'static str>,
    /// Whether `[stages.<name>]` sets its CPUs and scheduling policy.
    pub scheduled: bool,
    /// When the supervisor starts it.
    pub start: Start,
    /// How it is brought back when it dies.
    pub restart: Restart,
    /// Whether a standby instance can take over from it while the run goes on
    /// (`linetrack ctl swap-*`).
    pub hot_swap: bool,
}

impl NodeDecl {
    /// A node with nothing declared but its kind and binary, for building entries with
    /// `..NodeDecl::new(..)`.
    pub const fn new(stage: StageKind, role: Role, binary: &'static str) -> Self {
        Self {
            stage,
            role,
            binary,
            wakes_on: &[],
            reads: &[],
            publishes: &[Topic::Status],
            wake_rank: u8::MAX,
            stamp: None,
            budget: None,
            scheduled: false,
            start: Start::Never,
            restart: Restart::Never,
            hot_swap: false,
        }
    }

    /// Whether the supervisor starts it with the run and restarts it with backoff (a node
    /// of the pipeline proper, as opposed to an output the config turns on).
    pub fn supervised(&self) -> bool {
        matches!(self.start, Start::WithStages | Start::AfterStages)
    }
}

use Topic::{Control as CONTROL, Frames, Poses, Rig, Segments, Status, Tracks};

/// The pipeline, upstream first.
///
/// Wake ranks: a frame wakes the pose estimator first, then the detector: they start on it
/// at once, and the pose estimator's corners are the longer path. The matcher, which needs a
/// frame's images only with its segments, is woken last. Woken before the pose estimator, it
/// took the idle core for nothing at that moment, and the kernel queued the pose estimator
/// behind the busy one: in `perf sched timehist` of `linetrack run` on the EuRoC excerpt,
/// the pose estimator then waited 4 ms (one timer tick) to start on 30–38 of 95 frames; in
/// this order, on 4–11.
pub const PIPELINE: &[NodeDecl] = &[
    NodeDecl {
        // Waits for poses with `pacing = "fastest"` and `drop_late = false`
        // (linetrack_stage_runtime's source role).
        wakes_on: &[CONTROL, Poses],
        reads: &[Status],
        publishes: &[Frames, Rig, Status],
        wake_rank: 6,
        stamp: Some(StampSlot::FrameSource),
        budget: Some("frame_source_ms"),
        scheduled: true,
        start: Start::AfterStages,
        restart: Restart::Backoff,
        ..NodeDecl::new(
            StageKind::FrameSource,
            Role::Source,
            "linetrack-frame-source",
        )
    },
    NodeDecl {
        wakes_on: &[Frames, CONTROL],
        publishes: &[Segments, Status],
        wake_rank: 1,
        stamp: Some(StampSlot::LineDetector),
        budget: Some("line_detector_ms"),
        scheduled: true,
        start: Start::WithStages,
        restart: Restart::Backoff,
        hot_swap: true,
        ..NodeDecl::new(
            StageKind::LineDetector,
            Role::Stage,
            "linetrack-line-detector",
        )
    },
    NodeDecl {
        wakes_on: &[Segments, Frames, CONTROL],
        publishes: &[Tracks, Status],
        wake_rank: 2,
        stamp: Some(StampSlot::Matcher),
        budget: Some("matcher_ms"),
        scheduled: true,
        start: Start::WithStages,
        restart: Restart::Backoff,
        hot_swap: true,
        ..NodeDecl::new(StageKind::Matcher, Role::Stage, "linetrack-matcher")
    },
    NodeDecl {
        wakes_on: &[Tracks, Frames, Rig, CONTROL],
        publishes: &[Poses, Status],
        wake_rank: 0,
        stamp: Some(StampSlot::PoseEstimator),
        budget: Some("pose_estimator_ms"),
        scheduled: true,
        start: Start::WithStages,
        restart: Restart::Backoff,
        ..NodeDecl::new(
            StageKind::PoseEstimator,
            Role::Stage,
            "linetrack-pose-estimator",
        )
    },
    NodeDecl {
        wakes_on: &[Poses, Status, CONTROL],
        publishes: &[CONTROL],
        wake_rank: 3,
        ..NodeDecl::new(
            StageKind::Supervisor,
            Role::Supervisor,
            "linetrack-supervisor",
        )
    },
    NodeDecl {
        // Reads every topic but control's commands to others; woken like a stage (a
        // notification costs the publisher no wait) and sleeps otherwise.
        wakes_on: &[Frames, Segments, Tracks, Poses, Rig, Status, CONTROL],
        wake_rank: 4,
        start: Start::WhenConfigured,
        ..NodeDecl::new(StageKind::Recorder, Role::Sink, "linetrack-recorder")
    },
    NodeDecl {
        reads: &[Poses],
        start: Start::WhenConfigured,
        ..NodeDecl::new(StageKind::Ros2Bridge, Role::Sink, "linetrack-ros2")
    },
    NodeDecl {
        // Woken with the supervisor (its wake-up), it reads what `[link]` forwards.
        reads: &[Frames, Segments, Tracks, Poses, Status],
        start: Start::WhenConfigured,
        restart: Restart::Output,
        ..NodeDecl::new(StageKind::Link, Role::Sink, "linetrack-link")
    },
];

/// The declaration of `stage` in `nodes`.
pub fn node_in(nodes: &[NodeDecl], stage: StageKind) -> Option<&NodeDecl> {
    nodes.iter().find(|n| n.stage == stage)
}

/// The declaration of `stage` in [`PIPELINE`], when the crate using it is built (a stage
/// [`PIPELINE`] does not declare does not build).
pub const fn declared(stage: StageKind) -> &'static NodeDecl {
    let mut i = 0;
    while i < PIPELINE.len() {
        if PIPELINE[i].stage as u32 == stage as u32 {
            return &PIPELINE[i];
        }
        i += 1;
    }
    panic!("a node PIPELINE does not declare")
}

/// The declaration of `stage` in [`PIPELINE`].
pub fn node(stage: StageKind) -> Option<&'static NodeDecl> {
    node_in(PIPELINE, stage)
}

/// Most nodes a topic wakes.
const MAX_CONSUMERS: usize = 16;

/// The nodes a topic wakes, in wake order.
struct Consumers {
    stages: [StageKind; MAX_CONSUMERS],
    len: usize,
}

const fn declares(list: &[Topic], topic: Topic) -> bool {
    let mut i = 0;
    while i < list.len() {
        if list[i] as usize == topic as usize {
            return true;
        }
        i += 1;
    }
    false
}

/// The nodes of `nodes` woken by `topic`, by wake rank (declaration order among equals).
const fn consumers_in(nodes: &[NodeDecl], topic: Topic) -> Consumers {
    let mut out = Consumers {
        stages: [StageKind::FrameSource; MAX_CONSUMERS],
        len: 0,
    };
    let mut rank: u16 = 0;
    while rank <= u8::MAX as u16 {
        let mut i = 0;
        while i < nodes.len() {
            if nodes[i].wake_rank as u16 == rank && declares(nodes[i].wakes_on, topic) {
                assert!(out.len < MAX_CONSUMERS, "a topic wakes too many nodes");
                out.stages[out.len] = nodes[i].stage;
                out.len += 1;
            }
            i += 1;
        }
        rank += 1;
    }
    out
}

const fn all_consumers(nodes: &[NodeDecl]) -> [Consumers; Topic::ALL.len()] {
    [
        consumers_in(nodes, Topic::ALL[0]),
        consumers_in(nodes, Topic::ALL[1]),
        consumers_in(nodes, Topic::ALL[2]),
        consumers_in(nodes, Topic::ALL[3]),
        consumers_in(nodes, Topic::ALL[4]),
        consumers_in(nodes, Topic::ALL[5]),
        consumers_in(nodes, Topic::ALL[6]),
    ]
}

/// Every topic's consumers, derived from [`PIPELINE`] when the crate is built.
static CONSUMERS: [Consumers; Topic::ALL.len()] = all_consumers(PIPELINE);

/// The nodes [`PIPELINE`] declares woken by `topic`, in wake order.
pub(crate) fn consumers(topic: Topic) -> &'static [StageKind] {
    let position = Topic::ALL.iter().position(|&t| t == topic).unwrap_or(0);
    let c = &CONSUMERS[position];
    &c.stages[..c.len]
}

/// The nodes of `nodes` that fill the stamp slots, in slot order; every slot must be
/// filled (else the crate does not build).
pub(crate) const fn slot_stages(nodes: &[NodeDecl]) -> [StageKind; StampSlot::COUNT] {
    let mut out = [StageKind::Supervisor; StampSlot::COUNT];
    let mut filled = [false; StampSlot::COUNT];
    let mut i = 0;
    while i < nodes.len() {
        if let Some(slot) = nodes[i].stamp {
            assert!(!filled[slot.index()], "two nodes fill one stamp slot");
            out[slot.index()] = nodes[i].stage;
            filled[slot.index()] = true;
        }
        i += 1;
    }
    let mut slot = 0;
    while slot < StampSlot::COUNT {
        assert!(filled[slot], "a stamp slot no node fills");
        slot += 1;
    }
    out
}

/// The slot `stage` fills in [`PIPELINE`].
pub(crate) fn stamp_slot(stage: StageKind) -> Option<StampSlot> {
    node(stage).and_then(|n| n.stamp)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_node_is_declared_once_and_every_stamp_slot_filled_once() {
        for &stage in StageKind::ALL {
            let declared = PIPELINE.iter().filter(|n| n.stage == stage).count();
            // The observer is for nodes added besides the shipped ones.
            let expected = usize::from(stage != StageKind::Observer);
            assert_eq!(declared, expected, "{stage} declared {declared} times");
        }
        for slot in StampSlot::ALL {
            let filled: Vec<_> = PIPELINE.iter().filter(|n| n.stamp == Some(slot)).collect();
            assert_eq!(filled.len(), 1, "{slot:?}");
            assert_eq!(slot.stage().stamp_slot(), Some(slot));
            assert_eq!(StampSlot::ALL[slot.index()], slot);
        }
        assert_eq!(
            StageKind::PROCESSING,
            [
                StageKind::FrameSource,
                StageKind::LineDetector,
                StageKind::Matcher,
                StageKind::PoseEstimator
            ]
        );
        assert_eq!(StampSlot::Matcher.before(), Some(StampSlot::LineDetector));
        assert_eq!(StampSlot::FrameSource.before(), None);
    }

    /// The wake order as it was written out by hand before the declaration, but for
    /// control's (which no measurement chose): now by wake rank too.
    #[test]
    fn the_derived_wake_order_is_the_measured_one() {
        use StageKind::*;
        assert_eq!(
            Topic::Frames.consumers(),
            [PoseEstimator, LineDetector, Matcher, Recorder]
        );
        assert_eq!(Topic::Segments.consumers(), [Matcher, Recorder]);
        assert_eq!(Topic::Tracks.consumers(), [PoseEstimator, Recorder]);
        assert_eq!(
            Topic::Poses.consumers(),
            [Supervisor, Recorder, FrameSource]
        );
        assert_eq!(Topic::Rig.consumers(), [PoseEstimator, Recorder]);
        assert_eq!(Topic::Status.consumers(), [Supervisor, Recorder]);
        assert_eq!(
            Topic::Control.consumers(),
            [
                PoseEstimator,
                LineDetector,
                Matcher,
                Supervisor,
                Recorder,
                FrameSource
            ]
        );
    }

    /// A node added to a declaration is woken by what it declares, after the nodes ranked
    /// before it, and stamps nothing.
    #[test]
    fn a_declared_observer_is_woken_by_its_topics_in_rank_order() {
        let observer = NodeDecl {
            wakes_on: &[Topic::Poses, Topic::Tracks],
            wake_rank: 5,
            start: Start::WithStages,
            restart: Restart::Backoff,
            ..NodeDecl::new(StageKind::Observer, Role::Observer, "linetrack-observer")
        };
        let mut nodes = PIPELINE.to_vec();
        nodes.push(observer);
        let poses = consumers_in(&nodes, Topic::Poses);
        assert_eq!(
            &poses.stages[..poses.len],
            [
                StageKind::Supervisor,
                StageKind::Recorder,
                StageKind::Observer,
                StageKind::FrameSource
            ]
        );
        let frames = consumers_in(&nodes, Topic::Frames);
        assert!(!frames.stages[..frames.len].contains(&StageKind::Observer));
        assert!(node_in(&nodes, StageKind::Observer).is_some_and(NodeDecl::supervised));
    }

    #[test]
    fn a_slot_indexes_any_per_stage_array() {
        let mut ms = [0.0; StampSlot::COUNT];
        ms[StampSlot::Matcher] = 2.5;
        assert_eq!(ms[2], 2.5);
        assert_eq!(ms[StampSlot::Matcher], 2.5);
    }
}
