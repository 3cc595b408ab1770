//! What the supervisor knows of a run: every frame's outcome, the events, the matcher mode,
//! and whether the run is complete. Shared by the multi-process and the single-process
//! modes.
//!
//! Records are appended to the run folder as they happen ([`RecordWriter`]) and the report
//! is built up as they go ([`Tally`]), so the supervisor's memory does not grow with the
//! length of the run, and a run that ends any way at all leaves its records.

use crate::stamps::{detected, end_ns, stage_ms};
use linetrack_msgs::{
    CameraFailure, FrameHeader, FrameStatus, MatcherMode, PoseRecord, StageKind, StatusKind,
    StatusReport, TracksHeader,
};
use linetrack_pipeline_config::{CameraConfig, PipelineConfig};
use linetrack_run_record::{
    EventRecord, FrameRecord, Percentiles, RecordError, RecordWriter, Report, RunEnd, Summary,
    Tally,
};
use linetrack_stage_runtime::detector_kind;
use linetrack_trajectory::tum::StampedPose;
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Frames the live status line's percentiles are over.
const STATUS_WINDOW: usize = 100;

/// Which frames have an outcome, in memory bounded by how far out of order they arrive:
/// every frame below `below` has one, and so has each frame in `above`.
#[derive(Debug, Clone)]
struct Accounted {
    below: u64,
    above: BTreeSet<u64>,
    count: usize,
    highest: Option<u64>,
}

impl Accounted {
    fn new(first_frame: u64) -> Self {
        Self {
            below: first_frame,
            above: BTreeSet::new(),
            count: 0,
            highest: None,
        }
    }

    fn contains(&self, frame_id: u64) -> bool {
        frame_id < self.below || self.above.contains(&frame_id)
    }

    /// Marks `frame_id`; false when it already had an outcome.
    fn insert(&mut self, frame_id: u64) -> bool {
        if self.contains(frame_id) {
            return false;
        }
        self.above.insert(frame_id);
        while self.above.remove(&self.below) {
            self.below += 1;
        }
        self.count += 1;
        self.highest = Some(self.highest.map_or(frame_id, |h| h.max(frame_id)));
        true
    }

    /// Whether every frame up to `last` has an outcome.
    fn all_up_to(&self, last: u64) -> bool {
        self.below > last
    }

    /// Frames whose outcome is remembered one by one (the out-of-order window).
    fn window(&self) -> usize {
        self.above.len()
    }
}

/// The run's bookkeeping.
pub struct Monitor {
    config: PipelineConfig,
    started: Instant,
    run_dir: PathBuf,
    writer: RecordWriter,
    /// The first record that could not be written (the run goes on; the run then fails).
    write_error: Option<RecordError>,
    accounted: Accounted,
    tally: Tally,
    recent_end_to_end_ms: VecDeque<f64>,
    duplicates: usize,
    /// Frames a stage saw skipped in its full queue, by the stage: dropped unless they
    /// still turn up (an earlier frame arriving late is no loss).
    presumed_lost: BTreeMap<u64, String>,
    /// The pose estimator died: frames from this one up to the first its successor
    /// publishes died with it (the last stage: no stage after it sees them skipped), and
    /// how it died.
    lost_with_pose_estimator: Option<(u64, String)>,
    last_pose: Option<(u64, PoseRecord)>,
    /// The pose before `last_pose` (a restarted pose estimator predicts from the two).
    previous_pose: Option<(u64, PoseRecord)>,
    first_frame: u64,
    source_last: Option<u64>,
    /// The source finished without publishing any frame (a camera that never opened).
    source_empty: bool,
    published: Option<u64>,
    /// The sequence's ground truth (empty without): the summary scores `poses.tum` with it.
    ground_truth: Vec<StampedPose>,
}

/// Milliseconds between the stage before `stage` publishing the frame (its capture, for
/// the source) and `stage` taking it; NaN when either stamp is missing.
fn wait_ms(header: &FrameHeader, stage: StageKind) -> f64 {
    let Some(slot) = stage.stamp_slot() else {
        return f64::NAN;
    };
    let ready = match slot.before() {
        None => header.capture_ns,
        Some(before) => header.stamps[before].end_ns,
    };
    let taken = header.stamp(stage).map_or(0, |s| s.start_ns);
    if ready == 0 || taken == 0 || taken < ready {
        f64::NAN
    } else {
        (taken - ready) as f64 * 1e-6
    }
}

impl Monitor {
    /// A monitor for a run of `config` starting at frame `first_frame`, recording into
    /// `run_dir` (its record files are created, empty, now).
    pub fn new(
        config: &PipelineConfig,
        first_frame: u64,
        run_dir: &Path,
    ) -> Result<Self, RecordError> {
        Ok(Self {
            config: config.clone(),
            started: Instant::now(),
            run_dir: run_dir.to_path_buf(),
            writer: RecordWriter::create(run_dir)?,
            write_error: None,
            accounted: Accounted::new(first_frame),
            tally: Tally::default(),
            recent_end_to_end_ms: VecDeque::with_capacity(STATUS_WINDOW),
            duplicates: 0,
            presumed_lost: BTreeMap::new(),
            lost_with_pose_estimator: None,
            last_pose: None,
            previous_pose: None,
            first_frame,
            source_last: None,
            source_empty: false,
            published: None,
            ground_truth: Vec::new(),
        })
    }

    /// Scores the run's trajectory against `truth` (stamped with the sequence times the
    /// poses carry) in `summary.json`.
    pub fn with_ground_truth(mut self, truth: Vec<StampedPose>) -> Self {
        self.ground_truth = truth;
        self
    }

    /// Keeps the first write error and logs it, naming the file and the OS error (the
    /// record writer stops at it: every record file ends at its last whole row).
    fn note(&mut self, result: Result<(), RecordError>) {
        if let Err(e) = result
            && self.write_error.is_none()
        {
            tracing::error!(
                "run records: {}: the records end here (output.on_record_error = \"{}\")",
                linetrack_run_record::full_message(&e),
                self.config.output.on_record_error.name()
            );
            self.write_error = Some(e);
        }
    }

    /// A file of the run folder other than the records (`status.json`) could not be
    /// written: the records have failed too.
    pub fn file_failed(&mut self, e: RecordError) {
        self.writer.stop();
        self.note(Err(e));
    }

    /// The first record that could not be written (the file and the OS error), if any.
    /// A row the writer's thread failed to write counts as soon as it failed, before the
    /// loop takes the error with its next row.
    pub fn records_failed(&self) -> Option<String> {
        self.write_error
            .as_ref()
            .map(|e| linetrack_run_record::full_message(e))
            .or_else(|| self.writer.failure())
    }

    /// Appends a frame's record and counts it.
    fn record_frame(&mut self, record: &FrameRecord) {
        let written = self.writer.frame(record);
        self.note(written);
        self.tally.add_frame(record);
        if record.has_pose() {
            if self.recent_end_to_end_ms.len() == STATUS_WINDOW {
                self.recent_end_to_end_ms.pop_front();
            }
            self.recent_end_to_end_ms.push_back(record.end_to_end_ms);
        }
    }

    /// Records an event and logs it.
    pub fn event(&mut self, kind: &str, stage: &str, frame_id: Option<u64>, detail: String) {
        let at = frame_id
            .map(|f| format!(" at frame {f}"))
            .unwrap_or_default();
        tracing::info!("{kind} [{stage}]{at}: {detail}");
        let event = EventRecord {
            time_s: self.started.elapsed().as_secs_f64(),
            kind: kind.to_string(),
            stage: stage.to_string(),
            frame_id,
            detail,
        };
        let written = self.writer.event(&event);
        self.note(written);
        self.tally.add_event(&event);
    }

    /// Records one pose message; returns whether it was the frame's first outcome (a frame
    /// that reaches the end twice keeps its first).
    pub fn on_pose(&mut self, message: &TracksHeader, pose: &PoseRecord) -> bool {
        let TracksHeader {
            frame: header,
            detection,
            matching,
        } = message;
        if let Some((first, cause)) = self
            .lost_with_pose_estimator
            .take_if(|(first, _)| header.frame_id >= *first)
            && header.frame_id > first
        {
            self.presume_lost_as(
                first,
                header.frame_id - first,
                "pose-estimator",
                format!(
                    "frames {first}..{} died with the pose estimator ({cause}): its successor's first frame is {}",
                    header.frame_id, header.frame_id
                ),
            );
        }
        let status = header.status.get().unwrap_or_else(|unknown| {
            tracing::warn!("frame {}: {unknown}: recorded as failed", header.frame_id);
            FrameStatus::StageError
        });
        let outcome = match status {
            FrameStatus::Ok if pose.lost == 1 => "lost",
            FrameStatus::Ok => "pose",
            other => other.name(),
        };
        let stage = StageKind::PROCESSING.map(|s| stage_ms(header, s));
        let wait = StageKind::PROCESSING.map(|s| wait_ms(header, s));
        let pose_end = end_ns(header, StageKind::PoseEstimator);
        let end_to_end_ms = if pose_end >= header.capture_ns && header.capture_ns > 0 {
            header.age_ms(pose_end)
        } else {
            f64::NAN
        };
        let budget = &self.config.budget;
        let over_stage = StageKind::PROCESSING
            .into_iter()
            .zip(stage)
            .any(|(kind, ms)| budget.stage_ms(kind).is_some_and(|b| ms > b));
        let record = FrameRecord {
            frame_id: header.frame_id,
            outcome: outcome.to_string(),
            dropped_by: if status == FrameStatus::Ok {
                String::new()
            } else {
                header
                    .status_by
                    .get()
                    .map_or_else(|unknown| unknown.to_string(), |s| s.name().to_string())
            },
            stage_ms: stage,
            wait_ms: wait,
            end_to_end_ms,
            matcher: if status == FrameStatus::Ok {
                matching
                    .mode
                    .get()
                    .map(|m| m.name().to_string())
                    .unwrap_or_default()
            } else {
                String::new()
            },
            // Only a frame the detector detected names it: one it dropped carries no
            // detection (its code would read as the first detector's).
            detector: if end_ns(header, StageKind::LineDetector) > 0
                && detected(header, StageKind::LineDetector)
            {
                detection
                    .detector
                    .get()
                    .map(|d| detector_kind(d).name().to_string())
                    .unwrap_or_default()
            } else {
                String::new()
            },
            stereo_matches: matching.stereo_matches,
            tracked_matches: matching.tracked_matches,
            deadline_miss: over_stage
                || end_to_end_ms > budget.end_to_end_ms
                || status == FrameStatus::DroppedLate,
            lost_reason: if outcome == "lost" {
                pose.lost_reason_name().to_string()
            } else {
                String::new()
            },
            disparity_offset_px: if outcome == "pose" || outcome == "lost" {
                pose.disparity_offset_px
            } else {
                f64::NAN
            },
        };
        if !self.accounted.insert(header.frame_id) {
            self.duplicates += 1;
            tracing::warn!("frame {} reached the end twice", header.frame_id);
            return false;
        }
        self.presumed_lost.remove(&header.frame_id);
        self.record_frame(&record);
        if status != FrameStatus::Ok {
            return true;
        }
        if pose.rescued == 1 {
            self.event(
                "l1-rescue",
                "pose-estimator",
                Some(header.frame_id),
                "LBD's segment matches would have lost the frame: tracked with l1 at the predicted positions".into(),
            );
        }
        if self
            .last_pose
            .is_none_or(|(frame, _)| header.frame_id > frame)
        {
            self.previous_pose = self.last_pose;
            self.last_pose = Some((header.frame_id, *pose));
        }
        let written = self
            .writer
            .pose(header.sequence_ns, pose.translation, pose.rotation_xyzw);
        self.note(written);
        true
    }

    /// Takes what a stage's status report says about the run (the frames the source
    /// published, its end, skipped frames, camera and hold events); reports about the stage
    /// processes themselves (ready, hand-over) are the supervisor's. `camera` names the
    /// camera in the events.
    pub fn on_report(&mut self, report: &StatusReport, stage: StageKind, camera: &CameraConfig) {
        match report.kind.get().ok() {
            Some(StatusKind::SourceFinished) => {
                if report.value == 0 && report.frame_id == 0 && !self.any_published() {
                    // A camera that never delivered: no frame to wait for.
                    self.source_finished_empty();
                } else {
                    self.published(report.frame_id);
                    self.source_finished(report.frame_id);
                }
            }
            Some(StatusKind::CameraLost) => {
                // An unknown failure (another build's) is described as the catch-all.
                let failure = linetrack_msgs::decode(report.detail).unwrap_or(CameraFailure::Other);
                self.event(
                    "camera-lost",
                    stage.name(),
                    Some(report.frame_id),
                    format!(
                        "{} {}; reopening (attempt {}, backoff from {} ms)",
                        crate::camera_check::describe(camera),
                        failure.describe(),
                        report.value,
                        camera.retry_ms
                    ),
                );
            }
            Some(StatusKind::CameraBack) => self.event(
                "camera-back",
                stage.name(),
                Some(report.frame_id),
                format!(
                    "{} delivers again after {} failed attempts",
                    crate::camera_check::describe(camera),
                    report.value
                ),
            ),
            Some(StatusKind::Overflow) => self.event(
                "overflow",
                stage.name(),
                Some(report.frame_id),
                format!(
                    "{} held frames released before their other input arrived (hold of {})",
                    report.value,
                    linetrack_stage_runtime::HELD_FRAMES
                ),
            ),
            Some(StatusKind::QueueGap) => {
                self.presume_lost(report.frame_id, report.value, stage.name());
            }
            Some(StatusKind::Heartbeat) if stage == StageKind::FrameSource && report.value > 0 => {
                self.published(report.frame_id)
            }
            _ => {}
        }
    }

    /// `stage` saw `count` frames from `first` skipped on its input (overwritten in its full
    /// queue, or lost with an upstream stage that died): they are recorded as `skipped` by
    /// that stage unless they still arrive, and the run does not wait for them.
    pub fn presume_lost(&mut self, first: u64, count: u64, stage: &str) {
        let detail = format!(
            "frames {first}..{} never arrived here: overwritten in its full queue, or lost with a stage that died",
            first.saturating_add(count)
        );
        self.presume_lost_as(first, count, stage, detail);
    }

    /// [`Monitor::presume_lost`] with the event's words.
    fn presume_lost_as(&mut self, first: u64, count: u64, stage: &str, detail: String) {
        let ids = first..first.saturating_add(count);
        self.event("skipped", stage, Some(first), detail);
        for id in ids.filter(|&id| !self.accounted.contains(id)) {
            self.presumed_lost.insert(id, stage.to_string());
        }
    }

    /// The pose estimator died, after every pose it published was taken: the frames it had
    /// taken and not published died with it. Its successor's first pose says which (those
    /// from the first frame without an outcome up to it): they are recorded as `skipped`
    /// unless they still arrive, and the run does not wait for them; when the run ends
    /// before the successor publishes any, at the end. Either way a `skipped` event names
    /// the range and `cause` (how it died: the pid, crash or hang, the exit status).
    pub fn pose_estimator_died(&mut self, cause: String) {
        let first = match &self.lost_with_pose_estimator {
            // Died again before its successor published: the range starts where it did.
            Some((first, _)) => *first,
            None => self.accounted.below,
        };
        self.lost_with_pose_estimator = Some((first, cause));
    }

    /// The source published everything up to `last_frame`.
    pub fn source_finished(&mut self, last_frame: u64) {
        self.source_last = Some(last_frame);
    }

    /// The source finished without publishing a single frame.
    pub fn source_finished_empty(&mut self) {
        self.source_empty = true;
    }

    /// Whether the source has finished.
    pub fn source_done(&self) -> bool {
        self.source_last.is_some() || self.source_empty
    }

    /// Whether the source has published any frame.
    pub fn any_published(&self) -> bool {
        self.published.is_some()
    }

    /// The source published frame `frame_id`.
    pub fn published(&mut self, frame_id: u64) {
        self.published = Some(self.published.map_or(frame_id, |p| p.max(frame_id)));
    }

    /// The frame a restarted source starts from.
    pub fn next_source_frame(&self) -> u64 {
        self.published
            .map_or(self.first_frame, |p| p + 1)
            .max(self.accounted.highest.map_or(0, |k| k + 1))
    }

    /// The last pose and the one before it, as `--resume-pose` text
    /// (`frame,tx,ty,tz,qx,qy,qz,qw[;frame,tx,…]`).
    pub fn resume_pose(&self) -> Option<String> {
        let text = |(frame, p): (u64, PoseRecord)| {
            let [tx, ty, tz] = p.translation;
            let [qx, qy, qz, qw] = p.rotation_xyzw;
            format!("{frame},{tx},{ty},{tz},{qx},{qy},{qz},{qw}")
        };
        let last = text(self.last_pose?);
        Some(match self.previous_pose {
            Some(previous) => format!("{last};{}", text(previous)),
            None => last,
        })
    }

    /// Whether every frame the source published has an outcome.
    pub fn complete(&self) -> bool {
        if self.source_empty && self.source_last.is_none() && self.published.is_none() {
            return true;
        }
        self.source_last.is_some_and(|last| {
            self.accounted.all_up_to(last)
                || (self.accounted.below..=last)
                    .all(|f| self.accounted.contains(f) || self.presumed_lost.contains_key(&f))
        })
    }

    /// Frames with an outcome.
    pub fn accounted(&self) -> usize {
        self.accounted.count
    }

    /// Frames with a tracked pose (not predicted, not dropped).
    pub fn tracked(&self) -> usize {
        self.tally.tracked()
    }

    /// Frame ids the monitor remembers one by one: those with an outcome ahead of a frame
    /// still on its way. Bounded by the pipeline's depth, not by the run's length.
    pub fn remembered_frames(&self) -> usize {
        self.accounted.window()
    }

    /// Waits until the writer's thread has written every record added so far (tests that
    /// read the files back while the run goes on).
    #[cfg(test)]
    pub(crate) fn flush_records(&self) {
        self.writer.flush();
    }

    /// The one-line live status; `auto_mode`: the mode the matcher's policy chose
    /// (`matcher.mode = "auto"`).
    pub fn status_line(&self, auto_mode: Option<MatcherMode>) -> String {
        let elapsed = self.started.elapsed().as_secs_f64();
        let e2e = Percentiles::of(self.recent_end_to_end_ms.iter().copied());
        let frames = self.tally.frames();
        let rate = frames as f64 / elapsed.max(1e-3);
        let drops = frames - self.tally.with_pose();
        let misses = self.tally.deadline_misses();
        let mode = auto_mode.map_or_else(
            || self.config.matcher.mode_name().to_string(),
            |mode| format!("auto:{}", mode.name()),
        );
        let mut line = format!("[{elapsed:6.1} s] frames {frames:>5}  {rate:5.1} fps  ");
        match e2e {
            Some(p) => {
                let _ = write!(
                    line,
                    "e2e p50 {:.1} p90 {:.1} p99 {:.1} ms  ",
                    p.p50, p.p90, p.p99
                );
            }
            None => line.push_str("e2e -  "),
        }
        let restarts = self.tally.events_of("restart");
        let _ = write!(line, "matcher {mode}  drops {drops}");
        // Frames the source was already too late with (a realtime source starved of CPU,
        // a camera's stale buffer): the pipeline never saw them.
        let late_at_source = self.tally.dropped_as(FrameStatus::CaptureLate.name());
        if late_at_source > 0 {
            let _ = write!(line, " ({late_at_source} late at the source)");
        }
        let _ = write!(line, "  misses {misses}  restarts {restarts}");
        line
    }

    /// Records the frames that never arrived as `missing`, writes `summary.json` saying
    /// how the run ended (`reason`: why it failed) and returns the report. Called on every
    /// way a run ends.
    pub fn finish(mut self, end: RunEnd, reason: Option<String>) -> Result<Report, RecordError> {
        let last = self
            .source_last
            .or(self.published)
            .or(self.accounted.highest);
        if let (Some(last), Some((first, cause))) = (last, self.lost_with_pose_estimator.take())
            && let Some(count) = (first..=last)
                .rev()
                .find(|&f| !self.accounted.contains(f))
                .map(|newest| newest + 1 - first)
        {
            self.presume_lost_as(
                first,
                count,
                "pose-estimator",
                format!(
                    "frames {first}..{} died with the pose estimator ({cause}): the run ended before its successor published a frame after them",
                    first + count
                ),
            );
        }
        if let Some(last) = last {
            for f in self.first_frame..=last {
                if self.accounted.insert(f) {
                    let mut record = FrameRecord::missing(f);
                    if let Some(stage) = self.presumed_lost.remove(&f) {
                        record.outcome = "skipped".to_string();
                        record.dropped_by = stage;
                    }
                    self.record_frame(&record);
                }
            }
        }
        if self.duplicates > 0 {
            let n = self.duplicates;
            self.event(
                "duplicate",
                "supervisor",
                None,
                format!("{n} frames reached the end twice (first outcome kept)"),
            );
        }
        match end {
            RunEnd::Interrupted => self.event(
                "interrupted",
                "supervisor",
                None,
                "stopped before the sequence ended".to_string(),
            ),
            RunEnd::Failed => self.event(
                "failed",
                "supervisor",
                None,
                reason.clone().unwrap_or_default(),
            ),
            RunEnd::Running | RunEnd::Completed | RunEnd::RecordsFailed => {}
        }
        let closed = self.writer.close();
        self.note(closed);
        let report = self.tally.report();
        let metrics = linetrack_run_record::trajectory_metrics(
            &self.run_dir.join("poses.tum"),
            &self.ground_truth,
        );
        let metrics = metrics.unwrap_or_else(|e| {
            self.note(Err(e));
            None
        });
        Summary {
            end,
            reason,
            report: report.clone(),
            metrics,
        }
        .write(&self.run_dir.join("summary.json"))?;
        match self.write_error {
            Some(e) => Err(e),
            None => Ok(report),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use linetrack_msgs::StampSlot;
    use linetrack_run_record::files::SpaceReserve;
    use linetrack_run_record::{read_events, read_frames};
    use linetrack_test_data::Scratch;

    #[test]
    fn each_stage_waits_from_the_stage_before_publishing_to_taking_the_frame() {
        let ms = |v: f64| (v * 1e6) as u64;
        let mut header = FrameHeader::new(7, 0, ms(1.0));
        for (stamp, [start, end]) in
            header
                .stamps
                .iter_mut()
                .zip([[1.0, 2.0], [3.0, 10.0], [10.5, 12.0], [15.0, 20.0]])
        {
            stamp.start_ns = ms(start);
            stamp.end_ns = ms(end);
        }
        let waits = StageKind::PROCESSING.map(|s| wait_ms(&header, s));
        let expected = [0.0, 1.0, 0.5, 3.0];
        assert!(
            waits
                .iter()
                .zip(expected)
                .all(|(w, e)| (w - e).abs() < 1e-9),
            "{waits:?}"
        );
        // A stage that never took the frame, or stamps out of order: no wait.
        header.stamps[StampSlot::Matcher].start_ns = 0;
        assert!(wait_ms(&header, StageKind::Matcher).is_nan());
        header.stamps[StampSlot::PoseEstimator].start_ns = ms(11.0);
        assert!(wait_ms(&header, StageKind::PoseEstimator).is_nan());
    }

    fn pose_of(monitor: &mut Monitor, frame_id: u64) {
        let mut header = TracksHeader::from(FrameHeader::new(frame_id, frame_id * 50_000_000, 1));
        header.frame.stamps[StampSlot::PoseEstimator].end_ns = 2_000_001;
        header.matching.stereo_matches = 40;
        header.matching.mode = MatcherMode::Lbd.into();
        monitor.on_pose(&header, &PoseRecord::default());
    }

    #[test]
    fn records_are_on_disk_as_frames_complete_and_memory_stays_bounded() {
        let dir = Scratch::new("supervisor", "monitor-stream");
        let config = PipelineConfig::default();
        let mut monitor = Monitor::new(&config, 0, &dir).unwrap_or_else(|e| panic!("{e}"));
        // 20 000 frames arriving up to 3 out of order (a restarted stage, a hot swap).
        const FRAMES: u64 = 20_000;
        let mut most_remembered = 0;
        for base in (0..FRAMES).step_by(4) {
            for f in [base + 3, base + 1, base + 2, base] {
                pose_of(&mut monitor, f);
                most_remembered = most_remembered.max(monitor.remembered_frames());
            }
        }
        monitor.event("restart", "matcher", Some(7), "restart 1 of 5".to_string());
        assert!(
            most_remembered <= 3,
            "{most_remembered} frame ids held one by one"
        );
        // Everything so far is in the files before the run ends, once the writer's thread
        // has written what the loop handed it (it never waited for the disk).
        monitor.flush_records();
        let frames = read_frames(&dir.join("frames.csv")).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(frames.len(), FRAMES as usize);
        assert_eq!(frames.last().map(|f| f.frame_id), Some(FRAMES - 1));
        assert_eq!(
            read_events(&dir.join("events.csv"))
                .unwrap_or_else(|e| panic!("{e}"))
                .len(),
            1
        );
        let poses = std::fs::read_to_string(dir.join("poses.tum")).unwrap_or_default();
        assert_eq!(poses.lines().count(), FRAMES as usize + 1);
        // A frame arriving twice is counted once.
        pose_of(&mut monitor, 5);
        monitor.source_finished(FRAMES + 1);
        assert!(
            !monitor.complete(),
            "frames {FRAMES} and {} missing",
            FRAMES + 1
        );
        let report = monitor
            .finish(RunEnd::Failed, Some("matcher died".to_string()))
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            (report.frames, report.poses, report.restarts),
            (FRAMES as usize + 2, FRAMES as usize, 1)
        );
        assert_eq!(report.drops, [("missing".to_string(), 2)]);
        let summary = Summary::read(&dir.join("summary.json")).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(summary.end, RunEnd::Failed);
        assert_eq!(summary.reason.as_deref(), Some("matcher died"));
        assert_eq!(summary.report, report);
        let events = read_events(&dir.join("events.csv")).unwrap_or_else(|e| panic!("{e}"));
        assert!(
            events.iter().any(|e| e.kind == "duplicate")
                && events
                    .iter()
                    .any(|e| e.kind == "failed" && e.detail == "matcher died"),
            "{events:?}"
        );
    }

    #[test]
    fn a_file_that_cannot_be_written_ends_the_records_at_a_whole_row_and_the_run_says_so() {
        let dir = Scratch::new("supervisor", "monitor-records-failed");
        let mut monitor =
            Monitor::new(&PipelineConfig::default(), 0, &dir).unwrap_or_else(|e| panic!("{e}"));
        assert!(dir.join(SpaceReserve::FILE).is_file(), "no space held");
        for f in 0..3 {
            pose_of(&mut monitor, f);
        }
        assert!(monitor.records_failed().is_none());
        monitor.file_failed(RecordError::Io {
            path: dir.join("status.json"),
            source: std::io::Error::from_raw_os_error(28),
        });
        let failed = monitor.records_failed().unwrap_or_default();
        assert!(
            failed.contains("status.json") && failed.contains("No space left on device"),
            "{failed}"
        );
        monitor.flush_records();
        assert!(
            !dir.join(SpaceReserve::FILE).exists(),
            "the reserve is given up"
        );
        // Later frames are counted, not recorded.
        for f in 3..5 {
            pose_of(&mut monitor, f);
        }
        monitor.source_finished(4);
        let finished = monitor.finish(RunEnd::RecordsFailed, Some(failed.clone()));
        assert!(finished.is_err(), "the run's records failed");
        let summary = Summary::read(&dir.join("summary.json")).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            (summary.end, summary.report.frames),
            (RunEnd::RecordsFailed, 5)
        );
        let frames = read_frames(&dir.join("frames.csv")).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            frames.iter().map(|f| f.frame_id).collect::<Vec<_>>(),
            [0, 1, 2]
        );
        let poses = std::fs::read_to_string(dir.join("poses.tum")).unwrap_or_default();
        assert_eq!(poses.lines().count(), 4, "the header and 3 poses");
    }

    #[test]
    fn only_a_detected_frame_names_its_detector() {
        let dir = Scratch::new("supervisor", "monitor-detector-label");
        let mut monitor =
            Monitor::new(&PipelineConfig::default(), 0, &dir).unwrap_or_else(|e| panic!("{e}"));
        let stamped = |id: u64| {
            let mut h = TracksHeader::from(FrameHeader::new(id, id * 50_000_000, 1));
            h.frame.stamps[StampSlot::LineDetector].start_ns = 1_000_000;
            h.frame.stamps[StampSlot::LineDetector].end_ns = 2_000_000;
            h.detection.detector =
                linetrack_stage_runtime::detector_on_wire(linetrack_vision::DetectorKind::Fld)
                    .into();
            h
        };
        // Dropped by the detector itself: it detected nothing, whatever its code says.
        let mut behind = stamped(0);
        behind.detection = Default::default();
        behind
            .frame
            .mark(FrameStatus::DroppedBehind, StageKind::LineDetector);
        monitor.on_pose(&behind, &PoseRecord::default());
        // Detected by FLD, dropped by the matcher.
        let mut late = stamped(1);
        late.frame
            .mark(FrameStatus::DroppedLate, StageKind::Matcher);
        monitor.on_pose(&late, &PoseRecord::default());
        let _ = monitor.finish(RunEnd::Completed, None);
        let frames = read_frames(&dir.join("frames.csv")).unwrap_or_else(|e| panic!("{e}"));
        let labels: Vec<&str> = frames.iter().map(|f| f.detector.as_str()).collect();
        assert_eq!(labels, ["", "fld"]);
    }

    /// A frame the source was over the budget with (a starved realtime source) is a drop
    /// of its own: `capture-late` by the frame source in `frames.csv`, the report and the
    /// live line; the frames it kept carry the source's delay in its stage's time.
    #[test]
    fn frames_late_at_the_source_are_their_own_drop_in_the_records_and_the_live_line() {
        let dir = Scratch::new("supervisor", "monitor-late-at-source");
        let mut monitor =
            Monitor::new(&PipelineConfig::default(), 0, &dir).unwrap_or_else(|e| panic!("{e}"));
        let mut late = TracksHeader::from(FrameHeader::new(0, 0, 1_000_000));
        late.frame.stamps[StampSlot::FrameSource].start_ns = 1_000_000;
        late.frame.stamps[StampSlot::FrameSource].end_ns = 151_000_000;
        late.frame
            .mark(FrameStatus::CaptureLate, StageKind::FrameSource);
        monitor.on_pose(&late, &PoseRecord::default());
        assert!(
            monitor
                .status_line(None)
                .contains("drops 1 (1 late at the source)"),
            "{}",
            monitor.status_line(None)
        );
        pose_of(&mut monitor, 1);
        monitor.source_finished(1);
        let report = monitor
            .finish(RunEnd::Completed, None)
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(
            report.to_text().contains("dropped capture-late: 1"),
            "{}",
            report.to_text()
        );
        let frames = read_frames(&dir.join("frames.csv")).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            (frames[0].outcome.as_str(), frames[0].dropped_by.as_str()),
            ("capture-late", "frame-source")
        );
    }

    #[test]
    fn frames_skipped_on_a_stage_input_are_drops_unless_they_still_arrive() {
        let dir = Scratch::new("supervisor", "monitor-skipped");
        let mut monitor =
            Monitor::new(&PipelineConfig::default(), 0, &dir).unwrap_or_else(|e| panic!("{e}"));
        for f in [0, 1, 5, 6] {
            pose_of(&mut monitor, f);
        }
        monitor.source_finished(6);
        assert!(!monitor.complete());
        monitor.presume_lost(2, 3, "pose-estimator");
        assert!(monitor.complete(), "no wait for frames known to be lost");
        // Frame 3 was late, not lost (frames from two publishers during a hot swap).
        pose_of(&mut monitor, 3);
        let report = monitor
            .finish(RunEnd::Completed, None)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(report.drops, [("skipped".to_string(), 2)]);
        let frames = read_frames(&dir.join("frames.csv")).unwrap_or_else(|e| panic!("{e}"));
        let skipped: Vec<(u64, &str)> = frames
            .iter()
            .filter(|f| f.outcome == "skipped")
            .map(|f| (f.frame_id, f.dropped_by.as_str()))
            .collect();
        assert_eq!(skipped, [(2, "pose-estimator"), (4, "pose-estimator")]);
    }

    #[test]
    fn frames_that_died_with_the_pose_estimator_are_drops_once_its_successor_publishes() {
        let dir = Scratch::new("supervisor", "monitor-pose-estimator-died");
        let mut monitor =
            Monitor::new(&PipelineConfig::default(), 0, &dir).unwrap_or_else(|e| panic!("{e}"));
        for f in [0, 1] {
            pose_of(&mut monitor, f);
        }
        // Frames 2 and 3 were in the pose estimator when it died; its successor's first
        // frame is 4.
        monitor.pose_estimator_died("pid 7 crash: signal: 9 (SIGKILL)".to_string());
        monitor.source_finished(5);
        assert!(!monitor.complete());
        pose_of(&mut monitor, 4);
        assert!(!monitor.complete(), "frame 5 is still on its way");
        pose_of(&mut monitor, 5);
        assert!(
            monitor.complete(),
            "no wait for the frames that died with it"
        );
        let report = monitor
            .finish(RunEnd::Completed, None)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(report.drops, [("skipped".to_string(), 2)]);
        let frames = read_frames(&dir.join("frames.csv")).unwrap_or_else(|e| panic!("{e}"));
        let outcomes: Vec<(u64, &str)> = frames
            .iter()
            .map(|f| (f.frame_id, f.outcome.as_str()))
            .collect();
        assert_eq!(
            outcomes,
            [
                (0, "pose"),
                (1, "pose"),
                (2, "skipped"),
                (3, "skipped"),
                (4, "pose"),
                (5, "pose")
            ]
        );
        let events = read_events(&dir.join("events.csv")).unwrap_or_else(|e| panic!("{e}"));
        let skipped: Vec<(&str, Option<u64>, &str)> = events
            .iter()
            .filter(|e| e.kind == "skipped")
            .map(|e| (e.stage.as_str(), e.frame_id, e.detail.as_str()))
            .collect();
        assert_eq!(
            skipped,
            [(
                "pose-estimator",
                Some(2),
                "frames 2..4 died with the pose estimator (pid 7 crash: signal: 9 (SIGKILL)): its successor's first frame is 4"
            )]
        );
    }

    #[test]
    fn frames_that_died_with_a_pose_estimator_whose_successor_never_published_carry_an_event() {
        let dir = Scratch::new("supervisor", "monitor-pose-estimator-died-last");
        let mut monitor =
            Monitor::new(&PipelineConfig::default(), 0, &dir).unwrap_or_else(|e| panic!("{e}"));
        for f in [0, 1] {
            pose_of(&mut monitor, f);
        }
        // Hung, killed, and its successor died too before publishing: one range, the last
        // cause.
        monitor.pose_estimator_died("pid 7 hang: signal: 9 (SIGKILL)".to_string());
        monitor.pose_estimator_died("pid 8 crash: exit status: 1".to_string());
        monitor.source_finished(4);
        let report = monitor
            .finish(RunEnd::Completed, None)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(report.drops, [("skipped".to_string(), 3)]);
        let events = read_events(&dir.join("events.csv")).unwrap_or_else(|e| panic!("{e}"));
        let skipped: Vec<&str> = events
            .iter()
            .filter(|e| e.kind == "skipped" && e.stage == "pose-estimator")
            .map(|e| e.detail.as_str())
            .collect();
        assert_eq!(
            skipped,
            [
                "frames 2..5 died with the pose estimator (pid 8 crash: exit status: 1): the run ended before its successor published a frame after them"
            ]
        );
        let frames = read_frames(&dir.join("frames.csv")).unwrap_or_else(|e| panic!("{e}"));
        assert!(
            frames[2..]
                .iter()
                .all(|f| f.outcome == "skipped" && f.dropped_by == "pose-estimator"),
            "{frames:?}"
        );
    }
}
