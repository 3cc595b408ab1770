//! The records of a run (a frame's outcome and latencies, an event) and their CSV rows.

use serde::{Deserialize, Serialize};

/// What became of one frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameRecord {
    /// Frame number.
    pub frame_id: u64,
    /// `pose`, `lost` (pose predicted), or a drop: `corrupt`, `dropped-late`,
    /// `dropped-behind`, `stage-error`, `skipped` (never reached a stage: overwritten in
    /// its full queue while it was stopped or slow, or lost with a stage that died), `missing` (never reached the end: a stage was down).
    pub outcome: String,
    /// The stage that dropped it, or empty.
    pub dropped_by: String,
    /// Per stage in [`StageKind::PROCESSING`] order: milliseconds from taking the frame to publishing
    /// (NaN when the stage did not handle it).
    pub stage_ms: [f64; 4],
    /// Per stage in [`StageKind::PROCESSING`] order: milliseconds from the stage before it publishing the
    /// frame (the frame's capture, for the source) to this stage taking it — transport and
    /// the time the frame queued while the stage was busy (NaN when not handled).
    pub wait_ms: [f64; 4],
    /// Capture to pose published, milliseconds (NaN for a missing frame).
    pub end_to_end_ms: f64,
    /// Matcher mode used: `lbd`, `l1` or empty.
    pub matcher: String,
    /// Detector used: `lsd`, `fld` or empty.
    pub detector: String,
    /// Stereo segment matches.
    pub stereo_matches: u32,
    /// Frame-to-frame segment matches.
    pub tracked_matches: u32,
    /// Whether any budget (a stage's or end to end) was exceeded.
    pub deadline_miss: bool,
    /// Why a `lost` frame was lost (`too-few-inliers`, `degenerate`, `departed`,
    /// `restart-gap`), else empty.
    pub lost_reason: String,
    /// The disparity offset the pose estimator subtracted for this frame, pixels
    /// (`[odometry.disparity_offset]`); NaN for a frame without a pose.
    pub disparity_offset_px: f64,
}

impl FrameRecord {
    /// A frame that never reached the end.
    pub fn missing(frame_id: u64) -> Self {
        Self {
            frame_id,
            outcome: "missing".to_string(),
            dropped_by: String::new(),
            stage_ms: [f64::NAN; 4],
            wait_ms: [f64::NAN; 4],
            end_to_end_ms: f64::NAN,
            matcher: String::new(),
            detector: String::new(),
            stereo_matches: 0,
            tracked_matches: 0,
            deadline_miss: false,
            lost_reason: String::new(),
            disparity_offset_px: f64::NAN,
        }
    }

    /// Whether the frame got a pose (tracked or predicted).
    pub fn has_pose(&self) -> bool {
        self.outcome == "pose" || self.outcome == "lost"
    }
}

/// A notable event of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EventRecord {
    /// Seconds since the run started.
    pub time_s: f64,
    /// `fallback`, `recover`, `crash`, `hang`, `restart`, `swap`, `stale-cleanup`, ...
    pub kind: String,
    /// The stage concerned.
    pub stage: String,
    /// The frame it happened at, when known.
    pub frame_id: Option<u64>,
    /// Why, in words.
    pub detail: String,
}

pub(crate) const FRAME_HEADER: &str = "frame_id,outcome,dropped_by,frame_source_ms,line_detector_ms,matcher_ms,pose_estimator_ms,end_to_end_ms,matcher,detector,stereo_matches,tracked_matches,deadline_miss,frame_source_wait_ms,line_detector_wait_ms,matcher_wait_ms,pose_estimator_wait_ms,lost_reason,disparity_offset_px";
/// The header of runs recorded before `disparity_offset_px` (read as no offset known).
pub(crate) const FRAME_HEADER_WITHOUT_OFFSET: &str = "frame_id,outcome,dropped_by,frame_source_ms,line_detector_ms,matcher_ms,pose_estimator_ms,end_to_end_ms,matcher,detector,stereo_matches,tracked_matches,deadline_miss,frame_source_wait_ms,line_detector_wait_ms,matcher_wait_ms,pose_estimator_wait_ms,lost_reason";
/// The header of runs recorded before `lost_reason` (read as empty reasons).
pub(crate) const FRAME_HEADER_WITHOUT_REASON: &str = "frame_id,outcome,dropped_by,frame_source_ms,line_detector_ms,matcher_ms,pose_estimator_ms,end_to_end_ms,matcher,detector,stereo_matches,tracked_matches,deadline_miss,frame_source_wait_ms,line_detector_wait_ms,matcher_wait_ms,pose_estimator_wait_ms";
pub(crate) const EVENT_HEADER: &str = "time_s,kind,stage,frame_id,detail";

/// Milliseconds and seconds are written to the microsecond / millisecond: 3 decimals.
pub(crate) fn three_decimals(v: f64) -> f64 {
    (v * 1e3).round() / 1e3
}

/// A latency as written: 3 decimals, empty when the stage did not handle the frame.
pub(crate) fn ms(v: f64) -> Option<f64> {
    v.is_finite().then(|| three_decimals(v))
}

/// One row of `frames.csv`, in [`FRAME_HEADER`] order: a [`FrameRecord`] with its stage
/// latencies in columns of their own.
#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct FrameRow {
    frame_id: u64,
    outcome: String,
    dropped_by: String,
    frame_source_ms: Option<f64>,
    line_detector_ms: Option<f64>,
    matcher_ms: Option<f64>,
    pose_estimator_ms: Option<f64>,
    end_to_end_ms: Option<f64>,
    matcher: String,
    detector: String,
    stereo_matches: u32,
    tracked_matches: u32,
    /// 0 or 1.
    deadline_miss: u8,
    frame_source_wait_ms: Option<f64>,
    line_detector_wait_ms: Option<f64>,
    matcher_wait_ms: Option<f64>,
    pose_estimator_wait_ms: Option<f64>,
    #[serde(default)]
    lost_reason: String,
    #[serde(default)]
    disparity_offset_px: Option<f64>,
}

impl From<&FrameRecord> for FrameRow {
    fn from(f: &FrameRecord) -> Self {
        Self {
            frame_id: f.frame_id,
            outcome: f.outcome.clone(),
            dropped_by: f.dropped_by.clone(),
            frame_source_ms: ms(f.stage_ms[0]),
            line_detector_ms: ms(f.stage_ms[1]),
            matcher_ms: ms(f.stage_ms[2]),
            pose_estimator_ms: ms(f.stage_ms[3]),
            end_to_end_ms: ms(f.end_to_end_ms),
            matcher: f.matcher.clone(),
            detector: f.detector.clone(),
            stereo_matches: f.stereo_matches,
            tracked_matches: f.tracked_matches,
            deadline_miss: u8::from(f.deadline_miss),
            frame_source_wait_ms: ms(f.wait_ms[0]),
            line_detector_wait_ms: ms(f.wait_ms[1]),
            matcher_wait_ms: ms(f.wait_ms[2]),
            pose_estimator_wait_ms: ms(f.wait_ms[3]),
            lost_reason: f.lost_reason.clone(),
            disparity_offset_px: f
                .disparity_offset_px
                .is_finite()
                .then(|| (f.disparity_offset_px * 1e4).round() / 1e4),
        }
    }
}

impl FrameRow {
    /// The record, or what is wrong with the row (the column and why).
    pub(crate) fn into_record(self) -> Result<FrameRecord, String> {
        let latency = |v: Option<f64>, column: &str| match v {
            None => Ok(f64::NAN),
            Some(v) if v.is_finite() => Ok(v),
            Some(v) => Err(format!("{column}: {v} is not a finite number")),
        };
        Ok(FrameRecord {
            frame_id: self.frame_id,
            outcome: self.outcome,
            dropped_by: self.dropped_by,
            stage_ms: [
                latency(self.frame_source_ms, "frame_source_ms")?,
                latency(self.line_detector_ms, "line_detector_ms")?,
                latency(self.matcher_ms, "matcher_ms")?,
                latency(self.pose_estimator_ms, "pose_estimator_ms")?,
            ],
            wait_ms: [
                latency(self.frame_source_wait_ms, "frame_source_wait_ms")?,
                latency(self.line_detector_wait_ms, "line_detector_wait_ms")?,
                latency(self.matcher_wait_ms, "matcher_wait_ms")?,
                latency(self.pose_estimator_wait_ms, "pose_estimator_wait_ms")?,
            ],
            end_to_end_ms: latency(self.end_to_end_ms, "end_to_end_ms")?,
            matcher: self.matcher,
            detector: self.detector,
            stereo_matches: self.stereo_matches,
            tracked_matches: self.tracked_matches,
            deadline_miss: match self.deadline_miss {
                0 => false,
                1 => true,
                v => return Err(format!("deadline_miss: {v} is neither 0 nor 1")),
            },
            lost_reason: self.lost_reason,
            disparity_offset_px: latency(self.disparity_offset_px, "disparity_offset_px")?,
        })
    }
}

/// `row` as one CSV line (fields quoted where they need it).
pub(crate) fn csv_line(row: &impl Serialize) -> Result<Vec<u8>, csv::Error> {
    let mut csv = csv::WriterBuilder::new()
        .has_headers(false)
        .from_writer(Vec::with_capacity(256));
    csv.serialize(row)?;
    csv.into_inner().map_err(|e| e.into_error().into())
}
