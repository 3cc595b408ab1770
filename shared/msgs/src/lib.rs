//! The messages the pipeline's stages exchange, and the names of the services that carry
//! them.
//!
//! Every message is a slice of fixed-layout records (`#[repr(C)]`, no pointers) under a
//! user header, so a subscriber in another process reads it in place from shared memory.
//! A frame's messages are headed by its [`FrameHeader`] (what every frame has) and the
//! results of the stages upstream, each in its own record: images by a [`FrameHeader`],
//! segments by a [`SegmentsHeader`] (with the [`Detection`]), tracks and poses by a
//! [`TracksHeader`] (with the [`Detection`] and the [`Matching`]); status reports and
//! commands have no header. The topology is static: [`Topic::consumers`] says which stages
//! read a topic, and so which stages a publisher wakes.
//!
//! Codes (a stage, a status, a mode) travel as [`Code`]s: a `u32` that another, possibly
//! older or crashed, process wrote, read back only through a checked conversion, so no
//! value in shared memory is ever taken for an enum it is not.
//!
//! The records the ground-station link forwards (headers, segments, tracks, poses, status
//! reports) are also serde types.

use iceoryx2::prelude::ZeroCopySend;
use num_enum::{IntoPrimitive, TryFromPrimitive};
use std::fmt;
use std::marker::PhantomData;

/// An enum that travels as a `u32` code ([`Code`]).
pub trait WireEnum: Copy + fmt::Debug + Into<u32> + TryFrom<u32> + 'static {
    /// What the code names, for errors ("frame status").
    const WHAT: &'static str;
}

/// A code read from the wire that names no variant: written by another build, or garbage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("unknown {what} code {code}")]
pub struct UnknownCode {
    /// What the code should have named ([`WireEnum::WHAT`]).
    pub what: &'static str,
    /// The code.
    pub code: u32,
}

/// An `E` on the wire: its `u32` code. Whatever another process wrote, reading a `Code` is
/// sound (any `u32` is a valid `Code`, where a `#[repr(u32)]` enum read from shared memory
/// with an unknown discriminant would be undefined behaviour); the only way to the enum is
/// the checked [`Code::get`], and the only way in is an `E`.
#[repr(transparent)]
pub struct Code<E> {
    raw: u32,
    kind: PhantomData<E>,
}

impl<E: WireEnum> Code<E> {
    /// The code of `value`.
    pub fn new(value: E) -> Self {
        Self {
            raw: value.into(),
            kind: PhantomData,
        }
    }

    /// The value, or an error naming the code when it names no `E`.
    pub fn get(self) -> Result<E, UnknownCode> {
        E::try_from(self.raw).map_err(|_| UnknownCode {
            what: E::WHAT,
            code: self.raw,
        })
    }

    /// Whether this is the code of `value`.
    pub fn is(self, value: E) -> bool {
        self.raw == value.into()
    }

    /// The bare code, for records and messages that show it as it was read.
    pub fn raw(self) -> u32 {
        self.raw
    }
}

impl<E: WireEnum> From<E> for Code<E> {
    fn from(value: E) -> Self {
        Self::new(value)
    }
}

impl<E> Clone for Code<E> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<E> Copy for Code<E> {}

impl<E> PartialEq for Code<E> {
    fn eq(&self, other: &Self) -> bool {
        self.raw == other.raw
    }
}

impl<E> Eq for Code<E> {}

impl<E: WireEnum + Default> Default for Code<E> {
    fn default() -> Self {
        Self::new(E::default())
    }
}

impl<E: WireEnum> fmt::Debug for Code<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.get() {
            Ok(value) => write!(f, "{value:?}"),
            Err(unknown) => write!(f, "<{unknown}>"),
        }
    }
}

// SAFETY: a `Code` is one `u32` (`repr(transparent)`; the `PhantomData` takes no room): no
// pointer, no handle, the same layout in every process, and every bit pattern is valid.
#[allow(unsafe_code)]
unsafe impl<E: WireEnum> ZeroCopySend for Code<E> {}

impl<E: WireEnum> serde::Serialize for Code<E> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_u32(self.raw)
    }
}

/// Decoded as it was sent, like a code read from shared memory: one that names no `E` (a
/// newer build's) is an error only when [`Code::get`] reads it, so the rest of its message
/// still arrives.
impl<'de, E: WireEnum> serde::Deserialize<'de> for Code<E> {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        Ok(Self {
            raw: u32::deserialize(deserializer)?,
            kind: PhantomData,
        })
    }
}

/// Declares an enum that travels as a [`Code`]: `#[repr(u32)]` with an explicit code per
/// variant, its [`WireEnum::WHAT`], and `ALL`, every variant in the order declared (so a
/// test over `ALL` covers a variant added later).
macro_rules! wire_enum {
    (
        $(#[$meta:meta])*
        $vis:vis enum $name:ident: $what:literal {
            $( $(#[$variant_meta:meta])* $variant:ident = $code:literal, )+
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, TryFromPrimitive, IntoPrimitive)]
        #[repr(u32)]
        $vis enum $name {
            $( $(#[$variant_meta])* $variant = $code, )+
        }

        impl WireEnum for $name {
            const WHAT: &'static str = $what;
        }

        impl $name {
            /// Every variant, in the order declared.
            pub const ALL: &'static [$name] = &[$($name::$variant),+];
        }
    };
}

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
    }
}

impl StageKind {
    /// The four processing stages, upstream first.
    pub const PROCESSING: [StageKind; 4] = [
        StageKind::FrameSource,
        StageKind::LineDetector,
        StageKind::Matcher,
        StageKind::PoseEstimator,
    ];

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
        }
    }

    /// Index into [`FrameHeader::stamps`]; the supervisor has none.
    pub fn stamp_index(self) -> Option<usize> {
        Self::PROCESSING.iter().position(|&k| k == self)
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

    /// The stages that subscribe, and so are woken when a message is published, in the
    /// order they are woken.
    ///
    /// A frame wakes the pose estimator first, then the detector: they start on it at once,
    /// and the pose estimator's corners are the longer path. The matcher, which needs a
    /// frame's images only with its segments, is woken last. Woken before the pose
    /// estimator, it took the idle core for nothing at that moment, and the kernel queued
    /// the pose estimator behind the busy one: in `perf sched timehist` of `linetrack run`
    /// on the EuRoC excerpt, the pose estimator then waited 4 ms (one timer tick) to start
    /// on 30–38 of 95 frames; in this order, on 4–11.
    pub fn consumers(self) -> &'static [StageKind] {
        use StageKind::*;
        // The recorder reads every topic but control's commands to others; it is woken like
        // a stage (a notification costs the publisher no wait) and sleeps otherwise.
        match self {
            Topic::Frames => &[PoseEstimator, LineDetector, Matcher, Recorder],
            Topic::Segments => &[Matcher, Recorder],
            Topic::Tracks => &[PoseEstimator, Recorder],
            Topic::Poses => &[Supervisor, Recorder],
            Topic::Rig => &[PoseEstimator, Recorder],
            Topic::Status => &[Supervisor, Recorder],
            Topic::Control => &[
                FrameSource,
                LineDetector,
                Matcher,
                PoseEstimator,
                Supervisor,
                Recorder,
            ],
        }
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

/// No frame: the value of [`Matching::previous_frame_id`] when there is none.
pub const NO_FRAME: u64 = u64::MAX;

wire_enum! {
    /// What happened to a frame.
    pub enum FrameStatus: "frame status" {
        /// Processed.
        #[default]
        Ok = 0,
        /// The source could not read or decode it.
        Corrupt = 1,
        /// A stage dropped it because it was already over the latency budget.
        DroppedLate = 2,
        /// A stage failed on it (the header says which, in [`FrameHeader::status_by`]).
        StageError = 3,
        /// A stage dropped it because its queue was behind (a newer frame was waiting).
        DroppedBehind = 4,
        /// The camera delivered it but the source could not take it (a gap in the driver's
        /// timestamps, or the source's hand-over queue was full): no pixels.
        CaptureDropped = 5,
        /// The camera's frame waited in a buffer longer than `camera.late_ms`: dropped by the
        /// source (with `budget.drop_late`).
        CaptureLate = 6,
    }
}

impl FrameStatus {
    /// Short name used in run records.
    pub fn name(self) -> &'static str {
        match self {
            FrameStatus::Ok => "ok",
            FrameStatus::Corrupt => "corrupt",
            FrameStatus::DroppedLate => "dropped-late",
            FrameStatus::StageError => "stage-error",
            FrameStatus::DroppedBehind => "dropped-behind",
            FrameStatus::CaptureDropped => "capture-dropped",
            FrameStatus::CaptureLate => "capture-late",
        }
    }
}

wire_enum! {
    /// How the matcher matched a frame ([`Matching::mode`]).
    pub enum MatcherMode: "matcher mode" {
        /// LBD descriptors.
        #[default]
        Lbd = 0,
        /// The geometric ℓ1 matcher.
        L1 = 1,
    }
}

impl MatcherMode {
    /// `lbd` or `l1`.
    pub fn name(self) -> &'static str {
        match self {
            MatcherMode::Lbd => "lbd",
            MatcherMode::L1 => "l1",
        }
    }
}

/// When a stage took a frame and when it published its result: UNIX-epoch nanoseconds, so
/// processes on one machine share the clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
#[derive(serde::Serialize, serde::Deserialize)]
pub struct StageStamp {
    /// Taken from the input queue (for the source: started reading).
    pub start_ns: u64,
    /// Published.
    pub end_ns: u64,
}

wire_enum! {
    /// The line detector that found a frame's segments, as the wire names it (the mirror of
    /// `linetrack_vision::DetectorKind`, which this crate cannot see: the algorithm crates do
    /// not depend on the transport; `linetrack_stage_runtime` converts, exhaustively).
    pub enum Detector: "detector" {
        /// Line Segment Detector.
        #[default]
        Lsd = 0,
        /// Fast Line Detector.
        Fld = 1,
        /// The edge-drawing detector.
        EdgeLines = 2,
    }
}

/// What every frame has, on every topic that carries frames: the user header of the images
/// and the first part of every later stage's header.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("linetrack::FrameHeader")]
#[derive(serde::Serialize, serde::Deserialize)]
pub struct FrameHeader {
    /// Frame number in the sequence, from 0.
    pub frame_id: u64,
    /// The dataset's timestamp of the frame, nanoseconds.
    pub sequence_ns: u64,
    /// When the frame source started reading it (UNIX ns): the start of end-to-end latency.
    pub capture_ns: u64,
    /// Per stage, in [`StageKind::PROCESSING`] order.
    pub stamps: [StageStamp; 4],
    /// What happened to the frame.
    pub status: Code<FrameStatus>,
    /// The stage that set [`FrameHeader::status`]: the one that dropped or failed the frame
    /// (the frame source while it is Ok).
    pub status_by: Code<StageKind>,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

impl FrameHeader {
    /// A header for a new frame.
    pub fn new(frame_id: u64, sequence_ns: u64, capture_ns: u64) -> Self {
        Self {
            frame_id,
            sequence_ns,
            capture_ns,
            ..Self::default()
        }
    }

    /// Whether the frame is still to be processed (an unknown status is not Ok).
    pub fn is_ok(&self) -> bool {
        self.status.is(FrameStatus::Ok)
    }

    /// Marks the frame dropped or failed by `stage`.
    pub fn mark(&mut self, status: FrameStatus, stage: StageKind) {
        self.status = status.into();
        self.status_by = stage.into();
    }

    /// The stamp of `stage`.
    pub fn stamp_mut(&mut self, stage: StageKind) -> Option<&mut StageStamp> {
        stage.stamp_index().map(|i| &mut self.stamps[i])
    }

    /// Milliseconds from capture to `end_ns`.
    pub fn age_ms(&self, end_ns: u64) -> f64 {
        end_ns.saturating_sub(self.capture_ns) as f64 * 1e-6
    }
}

/// The line detector's result for a frame.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("linetrack::Detection")]
#[derive(serde::Serialize, serde::Deserialize)]
pub struct Detection {
    /// The detector that found the segments.
    pub detector: Code<Detector>,
    /// Process id of the detector (two run at once during a hot swap).
    pub detector_pid: u32,
    /// Segments in the left image: the message's first ones (the right image's follow).
    pub left_count: u32,
    /// Segments in the right image.
    pub right_count: u32,
}

/// The matcher's result for a frame.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("linetrack::Matching")]
#[derive(serde::Serialize, serde::Deserialize)]
pub struct Matching {
    /// The frame the tracks are matched against, or [`NO_FRAME`].
    pub previous_frame_id: u64,
    /// How the frame was matched.
    pub mode: Code<MatcherMode>,
    /// Stereo segment matches.
    pub stereo_matches: u32,
    /// Frame-to-frame segment matches.
    pub tracked_matches: u32,
    /// While in ℓ1 mode: stereo matches an LBD probe found on this frame, or
    /// [`Matching::NO_PROBE`].
    pub lbd_probe_matches: i32,
}

impl Matching {
    /// [`Matching::lbd_probe_matches`] of a frame without an LBD probe.
    pub const NO_PROBE: i32 = -1;
}

impl Default for Matching {
    fn default() -> Self {
        Self {
            previous_frame_id: NO_FRAME,
            mode: Code::default(),
            stereo_matches: 0,
            tracked_matches: 0,
            lbd_probe_matches: Self::NO_PROBE,
        }
    }
}

/// The user header of the segments: the frame and the detector's result.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("linetrack::SegmentsHeader")]
#[derive(serde::Serialize, serde::Deserialize)]
pub struct SegmentsHeader {
    /// The frame.
    pub frame: FrameHeader,
    /// What the detector found.
    pub detection: Detection,
}

/// The user header of the tracks and of the poses: the frame and the results of the
/// detector and the matcher they derive from.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("linetrack::TracksHeader")]
#[derive(serde::Serialize, serde::Deserialize)]
pub struct TracksHeader {
    /// The frame.
    pub frame: FrameHeader,
    /// What the detector found.
    pub detection: Detection,
    /// What the matcher found.
    pub matching: Matching,
}

/// A user header that heads a frame's message: every such header starts with the frame's
/// [`FrameHeader`], and a stage's output header is made from its input's
/// ([`From`]: the results upstream carried on, its own still to fill).
pub trait FrameMessage: Copy {
    /// The frame.
    fn frame(&self) -> &FrameHeader;
    /// The frame, to stamp or mark.
    fn frame_mut(&mut self) -> &mut FrameHeader;
}

impl FrameMessage for FrameHeader {
    fn frame(&self) -> &FrameHeader {
        self
    }
    fn frame_mut(&mut self) -> &mut FrameHeader {
        self
    }
}

impl FrameMessage for SegmentsHeader {
    fn frame(&self) -> &FrameHeader {
        &self.frame
    }
    fn frame_mut(&mut self) -> &mut FrameHeader {
        &mut self.frame
    }
}

impl FrameMessage for TracksHeader {
    fn frame(&self) -> &FrameHeader {
        &self.frame
    }
    fn frame_mut(&mut self) -> &mut FrameHeader {
        &mut self.frame
    }
}

impl From<FrameHeader> for SegmentsHeader {
    fn from(frame: FrameHeader) -> Self {
        Self {
            frame,
            detection: Detection::default(),
        }
    }
}

impl From<FrameHeader> for TracksHeader {
    fn from(frame: FrameHeader) -> Self {
        SegmentsHeader::from(frame).into()
    }
}

impl From<SegmentsHeader> for TracksHeader {
    fn from(segments: SegmentsHeader) -> Self {
        Self {
            frame: segments.frame,
            detection: segments.detection,
            matching: Matching::default(),
        }
    }
}

/// One segment, pixels.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[derive(serde::Serialize, serde::Deserialize)]
pub struct SegmentRecord {
    /// x1, y1, x2, y2.
    pub endpoints: [f32; 4],
}

/// A left segment with its stereo match and its frame-to-frame match.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[derive(serde::Serialize, serde::Deserialize)]
pub struct TrackedLine {
    /// The segment in the left image.
    pub left: [f32; 4],
    /// Its match in the right image (meaningful when `has_stereo` is 1).
    pub right: [f32; 4],
    /// 1 when the segment has a stereo match.
    pub has_stereo: u32,
    /// Index of the matching left segment of the previous frame, or -1.
    pub previous: i32,
}

/// The pose of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[derive(serde::Serialize, serde::Deserialize)]
pub struct PoseRecord {
    /// Position of the left camera in the first frame's world, metres.
    pub translation: [f64; 3],
    /// Orientation, quaternion x, y, z, w.
    pub rotation_xyzw: [f64; 4],
    /// 1 when tracking was lost in this frame (the pose is a prediction).
    pub lost: u32,
    /// Inliers after the motion estimate: points, lines.
    pub inliers: [u32; 2],
    /// Frame-to-frame observations used: points, lines.
    pub observations: [u32; 2],
    /// RMS residual of the inliers, pixels.
    pub rms_px: f64,
}

wire_enum! {
    /// What a [`StatusReport`] says.
    pub enum StatusKind: "status kind" {
        /// Alive; `value` = frames processed.
        #[default]
        Heartbeat = 0,
        /// Started and warmed up; for a standby detector, `frame_id` = the first frame it holds.
        Ready = 1,
        /// A detector handing over: it published every frame below `frame_id` and stops.
        HandedOver = 2,
        /// The frame source reached the end: `value` = frames published.
        SourceFinished = 3,
        /// A stage exits on its own (`value`: 0 done, 1 error).
        Exiting = 4,
        /// A stage's hold overflowed: `value` frames from `frame_id` on were released before
        /// their other input arrived (they go on without it).
        Overflow = 5,
        /// Frames never arrived on a stage's input: `value` frames from `frame_id` on were
        /// skipped (overwritten in its full queue while it was stopped or slow).
        QueueGap = 6,
        /// The frame source's camera failed and is being reopened: `frame_id` = the next
        /// frame's id, `value` = the attempt (1, 2, …), `detail` = a [`CameraFailure`] code.
        CameraLost = 7,
        /// The frame source's camera delivers again: `frame_id` = the next frame's id,
        /// `value` = the attempts it took.
        CameraBack = 8,
    }
}

wire_enum! {
    /// Why a camera failed ([`StatusKind::CameraLost`]'s `detail`).
    pub enum CameraFailure: "camera failure" {
        /// It could not be opened (no such device, busy, a pipeline that does not start).
        Open = 0,
        /// A read failed: the device is gone or the stream ended.
        Read = 1,
        /// Its frames are not the size the calibration is for.
        Size = 2,
        /// Anything else (a frame that cannot be split, rectified or converted).
        #[default]
        Other = 3,
    }
}

impl CameraFailure {
    /// What happened, for the event's text.
    pub fn describe(self) -> &'static str {
        match self {
            CameraFailure::Open => "cannot be opened",
            CameraFailure::Read => "read failed (device gone or stream ended)",
            CameraFailure::Size => "delivers frames of another size than the calibration's",
            CameraFailure::Other => "delivered a frame that could not be used",
        }
    }
}

/// A `u32` argument read from the wire as an `E` (a report's `detail`, a command's
/// `value`: arguments whose meaning depends on the message's kind), checked.
pub fn decode<E: WireEnum>(raw: u32) -> Result<E, UnknownCode> {
    E::try_from(raw).map_err(|_| UnknownCode {
        what: E::WHAT,
        code: raw,
    })
}

/// A rectified pinhole stereo rig on the wire (`linetrack_geometry::StereoRig`).
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
pub struct RigRecord {
    /// Focal length, pixels (square pixels).
    pub focal_px: f64,
    /// Principal point x, pixels.
    pub cx_px: f64,
    /// Principal point y, pixels.
    pub cy_px: f64,
    /// Baseline, metres.
    pub baseline_m: f64,
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
}

/// A stage's heartbeat or event.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[derive(serde::Serialize, serde::Deserialize)]
pub struct StatusReport {
    /// The sender.
    pub stage: Code<StageKind>,
    /// Its process id.
    pub pid: u32,
    /// What the report says.
    pub kind: Code<StatusKind>,
    /// The sender's [`Detector`] for detector reports, the [`CameraFailure`] of a
    /// [`StatusKind::CameraLost`] (read with [`decode`]).
    pub detail: u32,
    /// A frame id the report is about.
    pub frame_id: u64,
    /// A count the report is about.
    pub value: u64,
}

wire_enum! {
    /// Commands.
    pub enum Command: "command" {
        /// To the matcher: use [`MatcherMode`] `value` from the next frame.
        #[default]
        SetMatcherMode = 0,
        /// To the detector with pid `target_pid`: hand over to the standby detector, which holds
        /// frames from `frame_id` on.
        HandOver = 1,
        /// To the standby detector `target_pid`: the old detector published every frame below
        /// `frame_id`; take over from there.
        TakeOver = 2,
        /// To the supervisor: swap the detector for [`Detector`] `value`.
        SwapDetector = 3,
        /// To everyone: finish and exit.
        Shutdown = 4,
    }
}

/// A command.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
pub struct Control {
    /// The command.
    pub command: Code<Command>,
    /// The process the command is for; 0 = every process of `target_stage`.
    pub target_pid: u32,
    /// The stage the command is for.
    pub target_stage: Code<StageKind>,
    /// Command argument (a [`MatcherMode`], a [`Detector`]: read with [`decode`]).
    pub value: u32,
    /// Command argument: a frame id.
    pub frame_id: u64,
}

impl Control {
    /// A command for process `pid` of `stage` (0: every process of it).
    pub fn new(command: Command, stage: StageKind, pid: u32, value: u32, frame_id: u64) -> Self {
        Self {
            command: command.into(),
            target_pid: pid,
            target_stage: stage.into(),
            value,
            frame_id,
        }
    }

    /// Whether this command is for the process `pid` of stage `stage`.
    pub fn is_for(&self, stage: StageKind, pid: u32) -> bool {
        self.target_stage.is(stage) && (self.target_pid == 0 || self.target_pid == pid)
    }
}

/// The time the pipeline's policies read (frame ages, budgets, heartbeats, hang detection):
/// the system's wall clock, or in tests a clock that moves only when told, so that a test of
/// a policy does not depend on how loaded the machine is.
#[derive(Debug, Clone, Default)]
pub enum Clock {
    /// UNIX-epoch nanoseconds from the system.
    #[default]
    System,
    /// A clock that stands still until [`Clock::advance`].
    Manual(std::sync::Arc<std::sync::atomic::AtomicU64>),
}

impl Clock {
    /// A manual clock reading `start_ns`.
    pub fn manual(start_ns: u64) -> Self {
        Clock::Manual(std::sync::Arc::new(std::sync::atomic::AtomicU64::new(
            start_ns,
        )))
    }

    /// Now, UNIX-epoch nanoseconds.
    pub fn now_ns(&self) -> u64 {
        match self {
            Clock::System => now_ns(),
            Clock::Manual(t) => t.load(std::sync::atomic::Ordering::SeqCst),
        }
    }

    /// Moves a manual clock on (the system clock moves by itself).
    pub fn advance(&self, by: std::time::Duration) {
        if let Clock::Manual(t) = self {
            let ns = u64::try_from(by.as_nanos()).unwrap_or(u64::MAX);
            t.fetch_add(ns, std::sync::atomic::Ordering::SeqCst);
        }
    }

    /// Time since `earlier_ns` (zero if that is in the future).
    pub fn since(&self, earlier_ns: u64) -> std::time::Duration {
        std::time::Duration::from_nanos(self.now_ns().saturating_sub(earlier_ns))
    }
}

/// Wall-clock time as UNIX-epoch nanoseconds (0 if the clock is before 1970).
pub fn now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every variant of `E` goes onto the wire and comes back; the codes are distinct; a
    /// code past the last one is an error naming what it should have been.
    fn round_trips<E: WireEnum + PartialEq>(all: &[E]) {
        for &value in all {
            let code = Code::new(value);
            assert_eq!(code.get(), Ok(value), "{value:?}");
            assert!(code.is(value));
            assert_eq!(decode::<E>(code.raw()), Ok(value));
        }
        let mut raws: Vec<u32> = all.iter().map(|&v| v.into()).collect();
        raws.sort_unstable();
        raws.dedup();
        assert_eq!(
            raws.len(),
            all.len(),
            "two {} variants share a code",
            E::WHAT
        );
        let unknown = raws.last().map_or(0, |&r| r + 1);
        assert!(
            E::try_from(unknown).is_err(),
            "{} has more variants",
            E::WHAT
        );
        assert_eq!(
            decode::<E>(unknown),
            Err(UnknownCode {
                what: E::WHAT,
                code: unknown
            })
        );
    }

    #[test]
    fn every_code_round_trips_and_an_unknown_one_is_refused() {
        round_trips(StageKind::ALL);
        round_trips(FrameStatus::ALL);
        round_trips(MatcherMode::ALL);
        round_trips(Detector::ALL);
        round_trips(StatusKind::ALL);
        round_trips(CameraFailure::ALL);
        round_trips(Command::ALL);
    }

    /// What another process left in shared memory: a header whose codes name nothing.
    fn garbled(frame_id: u64, status: u32, stage: u32) -> FrameHeader {
        FrameHeader {
            status: Code {
                raw: status,
                kind: PhantomData,
            },
            status_by: Code {
                raw: stage,
                kind: PhantomData,
            },
            ..FrameHeader::new(frame_id, 0, 0)
        }
    }

    #[test]
    fn an_unknown_code_read_back_is_an_error_naming_it() {
        let header = garbled(3, 77, 9);
        let err = header.status.get().err().map(|e| e.to_string());
        assert_eq!(err.as_deref(), Some("unknown frame status code 77"));
        let err = header.status_by.get().err().map(|e| e.to_string());
        assert_eq!(err.as_deref(), Some("unknown stage code 9"));
        assert!(!header.is_ok(), "an unknown status is not Ok");
        assert!(format!("{header:?}").contains("unknown frame status code 77"));
        // Known codes read back as themselves.
        let mut ok = header;
        ok.mark(FrameStatus::DroppedLate, StageKind::Matcher);
        assert_eq!(ok.status.get(), Ok(FrameStatus::DroppedLate));
        assert_eq!(ok.status_by.get(), Ok(StageKind::Matcher));
    }

    #[test]
    fn a_code_is_a_bare_u32_on_the_wire() {
        assert_eq!(std::mem::size_of::<Code<FrameStatus>>(), 4);
        assert_eq!(std::mem::align_of::<Code<Command>>(), 4);
        assert_eq!(Code::new(FrameStatus::StageError).raw(), 3);
        assert_eq!(
            Code::<StageKind>::default().get(),
            Ok(StageKind::FrameSource)
        );
    }

    #[test]
    fn stage_results_start_empty_and_carry_downstream() {
        let frame = FrameHeader::new(5, 1, 2);
        assert!(frame.is_ok());
        let mut segments = SegmentsHeader::from(frame);
        assert_eq!(segments.detection, Detection::default());
        segments.detection.left_count = 4;
        let tracks = TracksHeader::from(segments);
        assert_eq!(tracks.frame, frame);
        assert_eq!(tracks.detection.left_count, 4);
        assert_eq!(tracks.matching.previous_frame_id, NO_FRAME);
        assert_eq!(tracks.matching.lbd_probe_matches, Matching::NO_PROBE);
    }

    #[test]
    fn stage_names_come_back_to_their_stage() {
        for &stage in StageKind::ALL {
            assert_eq!(StageKind::from_name(stage.name()), Some(stage));
        }
        assert_eq!(StageKind::from_name("camera"), None);
    }

    #[test]
    fn every_consumer_is_woken_by_name_in_its_run() {
        assert_eq!(Topic::Frames.service_name("r1"), "linetrack/r1/frames");
        assert_eq!(
            wake_service_name("r1", StageKind::Matcher),
            "linetrack/r1/wake/matcher"
        );
        // Every processing stage after the source consumes something.
        for stage in &StageKind::PROCESSING[1..] {
            assert!(
                Topic::ALL.iter().any(|t| t.consumers().contains(stage)),
                "{stage} consumes nothing"
            );
        }
    }

    /// The pose estimator is woken by a frame before the detector, and the matcher after
    /// both (see [`Topic::consumers`]: the order was measured).
    #[test]
    fn a_frame_wakes_the_longest_path_first_and_the_matcher_last() {
        let order = Topic::Frames.consumers();
        let at = |stage| order.iter().position(|&s| s == stage);
        let (pose, detector, matcher) = (
            at(StageKind::PoseEstimator),
            at(StageKind::LineDetector),
            at(StageKind::Matcher),
        );
        assert!(pose.is_some() && detector.is_some() && matcher.is_some());
        assert!(pose < detector && detector < matcher, "{order:?}");
    }

    #[test]
    fn control_addressing() {
        let c = Control::new(Command::HandOver, StageKind::LineDetector, 42, 0, 0);
        assert!(c.is_for(StageKind::LineDetector, 42));
        assert!(!c.is_for(StageKind::LineDetector, 43));
        assert!(!c.is_for(StageKind::Matcher, 42));
        let all = Control { target_pid: 0, ..c };
        assert!(all.is_for(StageKind::LineDetector, 7));
    }
}
