//! The messages the pipeline's stages exchange, and the names of the services that carry
//! them.
//!
//! Every message is a slice of fixed-layout records (`#[repr(C)]`, no pointers) under one
//! user header, [`FrameHeader`], so a subscriber in another process reads it in place from
//! shared memory. The topology is static: [`Topic::consumers`] says which stages read a
//! topic, and so which stages a publisher wakes.
//!
//! The records the ground-station link forwards (headers, segments, tracks, poses, status
//! reports) are also serde types.

use iceoryx2::prelude::ZeroCopySend;
use num_enum::{IntoPrimitive, TryFromPrimitive};
use std::fmt;

/// A stage of the pipeline.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, TryFromPrimitive, IntoPrimitive)]
#[repr(u32)]
pub enum StageKind {
    /// Reads (or renders) stereo frames and publishes them.
    FrameSource,
    /// Detects segments in both images.
    LineDetector,
    /// Stereo and frame-to-frame segment matching.
    Matcher,
    /// Visual odometry.
    PoseEstimator,
    /// Starts, watches and steers the others.
    Supervisor,
    /// Records the run into an MCAP file (`[record] mcap = true`); no processing stage.
    Recorder,
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
        }
    }

    /// Index into [`FrameHeader::stamps`]; the supervisor has none.
    pub fn stamp_index(self) -> Option<usize> {
        Self::PROCESSING.iter().position(|&k| k == self)
    }

    /// The stage with this wire code.
    pub fn from_code(code: u32) -> Option<Self> {
        Self::try_from(code).ok()
    }

    /// The wire code.
    pub fn code(self) -> u32 {
        u32::from(self)
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

    /// The stages that subscribe, and so are woken when a message is published.
    pub fn consumers(self) -> &'static [StageKind] {
        use StageKind::*;
        // The recorder reads every topic but control's commands to others; it is woken like
        // a stage (a notification costs the publisher no wait) and sleeps otherwise.
        match self {
            Topic::Frames => &[LineDetector, Matcher, PoseEstimator, Recorder],
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

/// No frame: the value of [`FrameHeader::previous_frame_id`] when there is none.
pub const NO_FRAME: u64 = u64::MAX;

/// What happened to a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, TryFromPrimitive, IntoPrimitive)]
#[repr(u32)]
pub enum FrameStatus {
    /// Processed.
    Ok = 0,
    /// The source could not read or decode it.
    Corrupt = 1,
    /// A stage dropped it because it was already over the latency budget.
    DroppedLate = 2,
    /// A stage failed on it (the message says which stage in `dropped_by`).
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

impl FrameStatus {
    /// The status with this wire code.
    pub fn from_code(code: u32) -> Option<Self> {
        Self::try_from(code).ok()
    }

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

/// Matcher mode codes in [`FrameHeader::matcher_mode`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, TryFromPrimitive, IntoPrimitive)]
#[repr(u32)]
pub enum MatcherMode {
    /// LBD descriptors.
    Lbd = 0,
    /// The geometric ℓ1 matcher.
    L1 = 1,
}

impl MatcherMode {
    /// The mode with this wire code.
    pub fn from_code(code: u32) -> Option<Self> {
        Self::try_from(code).ok()
    }

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

/// The per-frame metadata every message carries.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
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
    /// [`FrameStatus`] code.
    pub status: u32,
    /// The stage that dropped or failed the frame ([`StageKind::code`]), when not Ok.
    pub dropped_by: u32,
    /// Image width and height, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Segments: left count (the right image's follow).
    pub left_count: u32,
    /// Segments in the right image.
    pub right_count: u32,
    /// Detector that found the segments: 0 LSD, 1 FLD.
    pub detector: u32,
    /// [`MatcherMode`] the matcher used.
    pub matcher_mode: u32,
    /// Stereo segment matches.
    pub stereo_matches: u32,
    /// Frame-to-frame segment matches.
    pub tracked_matches: u32,
    /// While in ℓ1 mode: stereo matches an LBD probe found on this frame, or -1 (no probe).
    pub lbd_probe_matches: i32,
    /// Process id of the detector that produced the segments.
    pub detector_pid: u32,
    /// The frame the tracks are matched against, or [`NO_FRAME`].
    pub previous_frame_id: u64,
}

impl FrameHeader {
    /// A header for a new frame.
    pub fn new(frame_id: u64, sequence_ns: u64, capture_ns: u64) -> Self {
        Self {
            frame_id,
            sequence_ns,
            capture_ns,
            previous_frame_id: NO_FRAME,
            lbd_probe_matches: -1,
            ..Self::default()
        }
    }

    /// The decoded status (unknown codes read as a stage error).
    pub fn frame_status(&self) -> FrameStatus {
        FrameStatus::from_code(self.status).unwrap_or(FrameStatus::StageError)
    }

    /// Marks the frame dropped or failed by `stage`.
    pub fn mark(&mut self, status: FrameStatus, stage: StageKind) {
        self.status = status as u32;
        self.dropped_by = stage.code();
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

/// What a [`StatusReport`] says.
#[derive(Debug, Clone, Copy, PartialEq, Eq, TryFromPrimitive, IntoPrimitive)]
#[repr(u32)]
pub enum StatusKind {
    /// Alive; `value` = frames processed.
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

/// Why a camera failed ([`StatusKind::CameraLost`]'s `detail`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, TryFromPrimitive, IntoPrimitive)]
#[repr(u32)]
pub enum CameraFailure {
    /// It could not be opened (no such device, busy, a pipeline that does not start).
    Open = 0,
    /// A read failed: the device is gone or the stream ended.
    Read = 1,
    /// Its frames are not the size the calibration is for.
    Size = 2,
    /// Anything else (a frame that cannot be split, rectified or converted).
    Other = 3,
}

impl CameraFailure {
    /// The failure with this code (unknown codes read as `Other`).
    pub fn from_code(code: u32) -> Self {
        Self::try_from(code).unwrap_or(Self::Other)
    }

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

impl StatusKind {
    /// The kind with this wire code.
    pub fn from_code(code: u32) -> Option<Self> {
        Self::try_from(code).ok()
    }
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
    /// [`StageKind::code`] of the sender.
    pub stage: u32,
    /// Its process id.
    pub pid: u32,
    /// [`StatusKind`] code.
    pub kind: u32,
    /// Detector kind for detector reports (0 LSD, 1 FLD).
    pub detail: u32,
    /// A frame id the report is about.
    pub frame_id: u64,
    /// A count the report is about.
    pub value: u64,
}

impl StatusReport {
    /// What the report says (`None` for a code this build does not know).
    pub fn kind(&self) -> Option<StatusKind> {
        StatusKind::from_code(self.kind)
    }

    /// The stage that sent it.
    pub fn stage(&self) -> Option<StageKind> {
        StageKind::from_code(self.stage)
    }
}

/// Commands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, TryFromPrimitive, IntoPrimitive)]
#[repr(u32)]
pub enum Command {
    /// To the matcher: use [`MatcherMode`] `value` from the next frame.
    SetMatcherMode = 0,
    /// To the detector with pid `target_pid`: hand over to the standby detector, which holds
    /// frames from `frame_id` on.
    HandOver = 1,
    /// To the standby detector `target_pid`: the old detector published every frame below
    /// `frame_id`; take over from there.
    TakeOver = 2,
    /// To the supervisor: swap the detector for kind `value` (0 LSD, 1 FLD).
    SwapDetector = 3,
    /// To everyone: finish and exit.
    Shutdown = 4,
}

impl Command {
    /// The command with this wire code.
    pub fn from_code(code: u32) -> Option<Self> {
        Self::try_from(code).ok()
    }
}

/// A command.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
pub struct Control {
    /// [`Command`] code.
    pub command: u32,
    /// The process the command is for; 0 = every process of `target_stage`.
    pub target_pid: u32,
    /// [`StageKind::code`] of the stage the command is for.
    pub target_stage: u32,
    /// Command argument.
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

    /// The command (`None` for a code this build does not know).
    pub fn command(&self) -> Option<Command> {
        Command::from_code(self.command)
    }

    /// Whether this command is for the process `pid` of stage `stage`.
    pub fn is_for(&self, stage: StageKind, pid: u32) -> bool {
        self.target_stage == stage.code() && (self.target_pid == 0 || self.target_pid == pid)
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

    #[test]
    fn codes_round_trip() {
        for stage in [
            StageKind::FrameSource,
            StageKind::LineDetector,
            StageKind::Matcher,
            StageKind::PoseEstimator,
            StageKind::Supervisor,
            StageKind::Recorder,
        ] {
            assert_eq!(StageKind::from_code(stage.code()), Some(stage));
        }
        assert_eq!(StageKind::from_code(99), None);
        for status in [
            FrameStatus::Ok,
            FrameStatus::Corrupt,
            FrameStatus::DroppedLate,
            FrameStatus::StageError,
            FrameStatus::DroppedBehind,
        ] {
            assert_eq!(FrameStatus::from_code(status as u32), Some(status));
        }
        assert_eq!(
            Command::from_code(Command::Shutdown as u32),
            Some(Command::Shutdown)
        );
        assert_eq!(
            StatusKind::from_code(StatusKind::Exiting as u32),
            Some(StatusKind::Exiting)
        );
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

    #[test]
    fn control_addressing() {
        let c = Control {
            command: Command::HandOver as u32,
            target_pid: 42,
            target_stage: StageKind::LineDetector.code(),
            value: 0,
            frame_id: 0,
        };
        assert!(c.is_for(StageKind::LineDetector, 42));
        assert!(!c.is_for(StageKind::LineDetector, 43));
        assert!(!c.is_for(StageKind::Matcher, 42));
        let all = Control { target_pid: 0, ..c };
        assert!(all.is_for(StageKind::LineDetector, 7));
    }
}
