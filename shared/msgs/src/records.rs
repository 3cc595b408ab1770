//! The fixed-layout records the stages exchange: frame headers with their stage stamps,
//! detection and matching results, segments, tracks, poses, the rig, status reports and
//! commands.

use crate::{Code, StageKind, StampSlot, WireEnum};
use iceoryx2::prelude::ZeroCopySend;
use num_enum::{IntoPrimitive, TryFromPrimitive};

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
    /// Per stage, indexed by its [`StampSlot`] (`stamps[StampSlot::Matcher]`).
    pub stamps: [StageStamp; StampSlot::COUNT],
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

    /// The stamp of `stage` (none for a stage that stamps no frame).
    pub fn stamp(&self, stage: StageKind) -> Option<&StageStamp> {
        stage.stamp_slot().map(|slot| &self.stamps[slot])
    }

    /// The stamp of `stage`.
    pub fn stamp_mut(&mut self, stage: StageKind) -> Option<&mut StageStamp> {
        stage.stamp_slot().map(|slot| &mut self.stamps[slot])
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

/// The pose of a frame, with its uncertainty. The covariances are symmetric 6×6 matrices
/// sent as their upper triangle row by row (21 values: (0,0), (0,1), …, (0,5), (1,1), …,
/// (5,5)); all zeros means none. The type name carries the layout's version: a process of
/// another build refuses to connect instead of misreading the record.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("linetrack::PoseRecord/4")]
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
    /// 1 when the matcher stage matched the frame with LBD, those matches would have lost
    /// it, and the pose estimator tracked it with ℓ1 matches at the predicted positions
    /// instead (`[matcher.fallback] rescue_lost_frames`).
    pub rescued: u32,
    /// Why the frame was lost (0 when it was not): [`PoseRecord::LOST_REASONS`] names
    /// each code (1 too few inliers, 2 degenerate geometry, 3 the estimate departed from
    /// the prediction, 4 predicted across a restarted pose estimator's gap).
    pub lost_reason: u32,
    /// The disparity offset subtracted before this frame's features were triangulated,
    /// pixels (`[odometry.disparity_offset]`: given, or self-calibrated over the frames).
    pub disparity_offset_px: f64,
    /// RMS residual of the inliers, pixels.
    pub rms_px: f64,
    /// Conditioning of the motion estimate's normal matrix: its smallest eigenvalue over
    /// its largest (0 when lost).
    pub conditioning: f64,
    /// Covariance of the pose: position (x, y, z, metres) then orientation (rotation
    /// vector about x, y, z, radians; `R_true = exp(θ)·R`), both in the world's axes (the
    /// first frame's camera), chained over the frames since the first.
    pub covariance: [f64; 21],
    /// Covariance of this frame's motion `p_curr = motion · p_prev` (left-multiplied error,
    /// translation metres then rotation radians, in the current camera frame; to first order
    /// the pose's error in its own body frame); zeros when the frame was lost or is the
    /// first one tracked.
    pub step_covariance: [f64; 21],
}

impl PoseRecord {
    /// The names of [`PoseRecord::lost_reason`]'s codes, code 1 first.
    pub const LOST_REASONS: [&'static str; 4] =
        ["too-few-inliers", "degenerate", "departed", "restart-gap"];

    /// The `lost_reason` code of `name` (one of [`PoseRecord::LOST_REASONS`]); 0 for any
    /// other name.
    pub fn lost_reason_code(name: &str) -> u32 {
        Self::LOST_REASONS
            .iter()
            .position(|known| *known == name)
            .map_or(0, |k| k as u32 + 1)
    }

    /// The name of its `lost_reason`: empty for 0, `unknown` for a code no build of
    /// this one knows.
    pub fn lost_reason_name(&self) -> &'static str {
        match self.lost_reason {
            0 => "",
            code => (code as usize)
                .checked_sub(1)
                .and_then(|k| Self::LOST_REASONS.get(k))
                .copied()
                .unwrap_or("unknown"),
        }
    }

    /// The symmetric 6×6 matrix of a covariance sent as its upper triangle
    /// ([`PoseRecord::covariance`], [`PoseRecord::step_covariance`]).
    pub fn unpack_covariance(values: &[f64; 21]) -> [[f64; 6]; 6] {
        std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                let (row, column) = (i.min(j), i.max(j));
                // Rows 0..row hold 6, 5, … values: 6·row − row·(row − 1)/2 in all.
                values[6 * row - row * row.saturating_sub(1) / 2 + (column - row)]
            })
        })
    }

    /// The upper triangle of a symmetric 6×6 matrix, row by row (the lower is not read).
    pub fn pack_covariance(m: &[[f64; 6]; 6]) -> [f64; 21] {
        let mut out = [0.0; 21];
        let mut k = 0;
        for (i, row) in m.iter().enumerate() {
            for value in &row[i..] {
                out[k] = *value;
                k += 1;
            }
        }
        out
    }
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
        /// To the instance `target_pid` of a hot-swappable stage: hand over to the standby,
        /// which holds frames from `frame_id` on.
        HandOver = 1,
        /// To the standby `target_pid`: the old instance published every frame below
        /// `frame_id`; take over from there.
        TakeOver = 2,
        /// To the supervisor: swap the detector for [`Detector`] `value`.
        SwapDetector = 3,
        /// To everyone: finish and exit.
        Shutdown = 4,
        /// To the supervisor: a fresh instance of the stage [`StageKind`] `value` takes over
        /// from the running one (a hot swap).
        SwapStage = 5,
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
