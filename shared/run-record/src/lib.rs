//! A pipeline run's records and the latency report computed from them.
//!
//! The supervisor writes one [`FrameRecord`] per frame of the sequence to `frames.csv`
//! (what became of it, per-stage and end-to-end latency, matcher mode) and one
//! [`EventRecord`] per notable event to `events.csv` (fallbacks, restarts, hot swaps).
//! [`Report`] turns them into percentiles, deadline misses, drops and counts. With ground
//! truth, [`trajectory_metrics`] scores the run's `poses.tum` with the metrics (and names)
//! `linetrack-vo` writes, for [`Summary::metrics`].
//!
//! The files are written so that a crash or a full disk leaves them valid ([`files`]: a
//! whole row per write, cut back when the disk refuses part of it; small files whole or not
//! at all), and read back up to a cut last row ([`read_frames_to_cut`]), with the frames a
//! cut run did not record ([`unrecorded`]).

use hdrhistogram::Histogram;
use linetrack_msgs::StageKind;
use linetrack_trajectory::metrics;
use linetrack_trajectory::tum::{self, StampedPose};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

pub mod files;

use files::{RowFile, SpaceReserve};

/// Record errors.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// A file could not be read or written.
    #[error("{}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A line does not parse.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// `poses.tum` cannot be read back.
    #[error(transparent)]
    Trajectory(#[from] linetrack_trajectory::TrajectoryError),
}

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

const FRAME_HEADER: &str = "frame_id,outcome,dropped_by,frame_source_ms,line_detector_ms,matcher_ms,pose_estimator_ms,end_to_end_ms,matcher,detector,stereo_matches,tracked_matches,deadline_miss,frame_source_wait_ms,line_detector_wait_ms,matcher_wait_ms,pose_estimator_wait_ms";
const EVENT_HEADER: &str = "time_s,kind,stage,frame_id,detail";

/// Milliseconds and seconds are written to the microsecond / millisecond: 3 decimals.
fn three_decimals(v: f64) -> f64 {
    (v * 1e3).round() / 1e3
}

/// A latency as written: 3 decimals, empty when the stage did not handle the frame.
fn ms(v: f64) -> Option<f64> {
    v.is_finite().then(|| three_decimals(v))
}

/// One row of `frames.csv`, in [`FRAME_HEADER`] order: a [`FrameRecord`] with its stage
/// latencies in columns of their own.
#[derive(Debug, Serialize, Deserialize)]
struct FrameRow {
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
        }
    }
}

impl FrameRow {
    /// The record, or what is wrong with the row (the column and why).
    fn into_record(self) -> Result<FrameRecord, String> {
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
        })
    }
}

/// `row` as one CSV line (fields quoted where they need it).
fn csv_line(row: &impl Serialize) -> Result<Vec<u8>, csv::Error> {
    let mut csv = csv::WriterBuilder::new()
        .has_headers(false)
        .from_writer(Vec::with_capacity(256));
    csv.serialize(row)?;
    csv.into_inner().map_err(|e| e.into_error().into())
}

const POSES_HEADER: &str =
    "# timestamp tx ty tz qx qy qz qw (left camera in the first frame's world)";

/// Appends a run's records as they happen: `frames.csv` (a row per frame as its outcome
/// is known, so not necessarily in frame order), `events.csv` and `poses.tum`. Every row
/// goes to the kernel whole when it is added ([`files`]), so the records of a run whose
/// supervisor is killed are complete up to that moment.
///
/// The first row that cannot be written (a full disk, ...) is an error naming the file and
/// the OS error; the writer then stops (every file ends at its last whole row, later rows
/// are not attempted) and gives up its [`SpaceReserve`], so that `summary.json` and
/// `status.json` can still say how the run ended.
pub struct RecordWriter {
    frames: RowFile,
    events: RowFile,
    poses: RowFile,
    reserve: SpaceReserve,
    stopped: bool,
}

impl RecordWriter {
    /// Holds [`SpaceReserve::BYTES`] in `run_dir`, then creates the three files there
    /// (emptying earlier ones) with their headers.
    pub fn create(run_dir: &Path) -> Result<Self, RecordError> {
        let reserve = SpaceReserve::hold(run_dir, SpaceReserve::BYTES)?;
        let line = |text: &str| format!("{text}\n").into_bytes();
        Ok(Self {
            frames: RowFile::create(run_dir.join("frames.csv"), &line(FRAME_HEADER))?,
            events: RowFile::create(run_dir.join("events.csv"), &line(EVENT_HEADER))?,
            poses: RowFile::create(run_dir.join("poses.tum"), &line(POSES_HEADER))?,
            reserve,
            stopped: false,
        })
    }

    /// Whether a row could not be written (no more are).
    pub fn stopped(&self) -> bool {
        self.stopped
    }

    /// Stops the writer as a failed row would (another file of the run folder could not be
    /// written): no more rows, the reserve given up.
    pub fn stop(&mut self) {
        self.stopped = true;
        self.reserve.release();
    }

    /// Appends `row` to one of the files unless the writer has stopped; the first failure
    /// stops it and gives up the reserve.
    fn append(
        file: &mut RowFile,
        reserve: &mut SpaceReserve,
        stopped: &mut bool,
        row: Result<Vec<u8>, csv::Error>,
    ) -> Result<(), RecordError> {
        if *stopped {
            return Ok(());
        }
        let written = match row {
            Ok(row) => file.append(&row),
            // Serialising a record into memory cannot fail; were it to, it is no disk error.
            Err(e) => Err(RecordError::Parse {
                path: file.path().to_path_buf(),
                line: 0,
                message: format!("a row could not be formed: {e}"),
            }),
        };
        if written.is_err() {
            *stopped = true;
            reserve.release();
        }
        written
    }

    /// Appends a frame's row to `frames.csv`.
    pub fn frame(&mut self, frame: &FrameRecord) -> Result<(), RecordError> {
        let row = csv_line(&FrameRow::from(frame));
        Self::append(&mut self.frames, &mut self.reserve, &mut self.stopped, row)
    }

    /// Appends an event's row to `events.csv`.
    pub fn event(&mut self, event: &EventRecord) -> Result<(), RecordError> {
        let row = csv_line(&EventRecord {
            time_s: three_decimals(event.time_s),
            ..event.clone()
        });
        Self::append(&mut self.events, &mut self.reserve, &mut self.stopped, row)
    }

    /// Appends a pose (TUM: seconds, position, quaternion x y z w) to `poses.tum`.
    pub fn pose(
        &mut self,
        sequence_ns: u64,
        translation: [f64; 3],
        rotation_xyzw: [f64; 4],
    ) -> Result<(), RecordError> {
        let [tx, ty, tz] = translation;
        let [qx, qy, qz, qw] = rotation_xyzw;
        let line = format!(
            "{:.9} {tx:.6} {ty:.6} {tz:.6} {qx:.6} {qy:.6} {qz:.6} {qw:.6}\n",
            sequence_ns as f64 * 1e-9
        );
        Self::append(
            &mut self.poses,
            &mut self.reserve,
            &mut self.stopped,
            Ok(line.into_bytes()),
        )
    }

    /// The end of the run: syncs the files to the disk and gives up the reserve (the
    /// summary is written next).
    pub fn close(&mut self) -> Result<(), RecordError> {
        self.reserve.release();
        for file in [&self.frames, &self.events, &self.poses] {
            file.sync()?;
        }
        Ok(())
    }
}

/// The last row of a record file, cut (by a crash, a full disk, a power cut) and left out.
#[derive(Debug, Clone, PartialEq)]
pub struct CutRow {
    /// The file.
    pub path: PathBuf,
    /// The row's 1-based line.
    pub line: usize,
    /// What is wrong with it.
    pub message: String,
}

impl std::fmt::Display for CutRow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}:{}: the last row is cut ({}); read up to the row before it",
            self.path.display(),
            self.line,
            self.message
        )
    }
}

/// The whole rows of a record file, and its cut last row if it has one.
pub type ReadToCut<T> = (Vec<T>, Option<CutRow>);

/// How the readers take a file's last row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum LastRow {
    /// Like every other: a bad one is an error.
    Strict,
    /// A last row without its end of line, or one that does not parse, is a cut row: left
    /// out and reported ([`CutRow`]); a bad row before it is still an error.
    MayBeCut,
}

/// The rows of the CSV record file `path` whose header must be `header`, in file order
/// with their lines; errors name the file, the line and the column.
fn read_rows<T: serde::de::DeserializeOwned>(
    path: &Path,
    header: &str,
    last: LastRow,
) -> Result<ReadToCut<(usize, T)>, RecordError> {
    let bytes = std::fs::read(path).map_err(|source| RecordError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let parse = |line: u64, message: String| RecordError::Parse {
        path: path.to_path_buf(),
        line: usize::try_from(line).unwrap_or(usize::MAX),
        message,
    };
    let line_of = |at: usize| bytes[..at].iter().filter(|&&b| b == b'\n').count() + 1;
    // A whole row ends with its end of line: bytes after the last one are a cut row.
    let mut cut = None;
    let mut body = &bytes[..];
    if !bytes.is_empty() && !bytes.ends_with(b"\n") {
        let whole = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
        let message = format!("{} bytes without an end of line", bytes.len() - whole);
        if last == LastRow::Strict {
            return Err(parse(line_of(whole) as u64, message));
        }
        body = &bytes[..whole];
        cut = Some(CutRow {
            path: path.to_path_buf(),
            line: line_of(whole),
            message,
        });
    }
    let mut reader = csv::ReaderBuilder::new().from_reader(body);
    let columns = match reader.headers() {
        Ok(found) if found.iter().eq(header.split(',')) => found.clone(),
        _ => return Err(parse(1, format!("expected the header {header:?}"))),
    };
    let mut rows = Vec::new();
    let mut record = csv::StringRecord::new();
    loop {
        let (line, row) = match reader.read_record(&mut record) {
            Ok(false) => break,
            Ok(true) => {
                let line = record.position().map_or(0, csv::Position::line);
                let row = record.deserialize::<T>(Some(&columns)).map_err(|e| {
                    let message = match e.kind() {
                        csv::ErrorKind::Deserialize { err, .. } => {
                            let column = err
                                .field()
                                .and_then(|k| columns.get(usize::try_from(k).ok()?))
                                .unwrap_or("?");
                            format!("{column}: {}", err.kind())
                        }
                        _ => e.to_string(),
                    };
                    (line, message)
                });
                (line, row)
            }
            Err(e) => {
                let line = e.position().map_or(0, csv::Position::line);
                (line, Err((line, e.to_string())))
            }
        };
        match row {
            Ok(row) => rows.push((usize::try_from(line).unwrap_or(usize::MAX), row)),
            Err((line, message)) => {
                // Only the last row may be cut: nothing whole may follow it.
                let more = !matches!(reader.read_record(&mut record), Ok(false));
                if last == LastRow::Strict || more || cut.is_some() {
                    return Err(parse(line, message));
                }
                cut = Some(CutRow {
                    path: path.to_path_buf(),
                    line: usize::try_from(line).unwrap_or(usize::MAX),
                    message,
                });
                break;
            }
        }
    }
    Ok((rows, cut))
}

/// The rows of `frames.csv` as records, in frame order.
fn frames_of(path: &Path, last: LastRow) -> Result<ReadToCut<FrameRecord>, RecordError> {
    let (rows, mut cut) = read_rows::<FrameRow>(path, FRAME_HEADER, last)?;
    let count = rows.len();
    let mut frames = Vec::with_capacity(count);
    for (k, (line, row)) in rows.into_iter().enumerate() {
        match row.into_record() {
            Ok(frame) => frames.push(frame),
            Err(message) if last == LastRow::MayBeCut && cut.is_none() && k + 1 == count => {
                cut = Some(CutRow {
                    path: path.to_path_buf(),
                    line,
                    message,
                });
            }
            Err(message) => {
                return Err(RecordError::Parse {
                    path: path.to_path_buf(),
                    line,
                    message,
                });
            }
        }
    }
    // Rows are appended as frames complete: a frame lost to a stage crash comes last.
    frames.sort_by_key(|f| f.frame_id);
    Ok((frames, cut))
}

/// Reads `frames.csv`, in frame order; any bad row is an error.
pub fn read_frames(path: &Path) -> Result<Vec<FrameRecord>, RecordError> {
    Ok(frames_of(path, LastRow::Strict)?.0)
}

/// Reads `frames.csv` of a run that may have been cut short (a crash, a full disk), in
/// frame order: a cut last row is left out and returned, a bad row before it is an error.
pub fn read_frames_to_cut(path: &Path) -> Result<ReadToCut<FrameRecord>, RecordError> {
    frames_of(path, LastRow::MayBeCut)
}

/// Reads `events.csv`; any bad row is an error.
pub fn read_events(path: &Path) -> Result<Vec<EventRecord>, RecordError> {
    Ok(read_events_to_cut_as(path, LastRow::Strict)?.0)
}

/// Reads `events.csv` of a run that may have been cut short (as [`read_frames_to_cut`]).
pub fn read_events_to_cut(path: &Path) -> Result<ReadToCut<EventRecord>, RecordError> {
    read_events_to_cut_as(path, LastRow::MayBeCut)
}

fn read_events_to_cut_as(
    path: &Path,
    last: LastRow,
) -> Result<ReadToCut<EventRecord>, RecordError> {
    let (rows, cut) = read_rows::<EventRecord>(path, EVENT_HEADER, last)?;
    Ok((rows.into_iter().map(|(_, event)| event).collect(), cut))
}

/// The frame ids from 0 below `expected` that `frames` (in frame order) has no row for,
/// as ranges: what a cut run did not record.
pub fn unrecorded(frames: &[FrameRecord], expected: u64) -> Vec<std::ops::Range<u64>> {
    let mut gaps = Vec::new();
    let mut next = 0u64;
    for id in frames
        .iter()
        .map(|f| f.frame_id)
        .filter(|&id| id < expected)
    {
        if id > next {
            gaps.push(next..id);
        }
        next = next.max(id + 1);
    }
    if next < expected {
        gaps.push(next..expected);
    }
    gaps
}

/// `e` and the errors under it, joined by ": " (the OS error of a [`RecordError::Io`]).
pub fn full_message(e: &(dyn std::error::Error + 'static)) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(inner) = source {
        text.push_str(": ");
        text.push_str(&inner.to_string());
        source = inner.source();
    }
    text
}

/// Percentiles of a latency, milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Percentiles {
    /// Samples.
    pub count: usize,
    /// Median.
    pub p50: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
}

impl Percentiles {
    /// Nearest-rank percentiles of the finite values; `None` when there are none.
    pub fn of(values: impl IntoIterator<Item = f64>) -> Option<Self> {
        let mut v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let rank =
            |p: f64| v[(((p / 100.0) * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1];
        Some(Self {
            count: v.len(),
            p50: rank(50.0),
            p90: rank(90.0),
            p99: rank(99.0),
            max: v[v.len() - 1],
        })
    }
}

/// A latency distribution kept in bounded memory however many samples it takes: an
/// HDR histogram of microseconds to 3 significant digits (percentiles within 0.1 %), up to
/// an hour; the largest sample is kept exactly.
#[derive(Debug, Clone)]
pub struct LatencyHistogram {
    micros: Histogram<u64>,
    max_ms: f64,
}

/// Microseconds per millisecond: the histogram's unit.
const MICROS_PER_MS: f64 = 1000.0;
/// The largest latency the histogram tells apart (larger ones count as this), microseconds.
const HIGHEST_MICROS: u64 = 3_600_000_000;
/// Significant decimal digits the histogram keeps.
const SIGNIFICANT_DIGITS: u8 = 3;

impl Default for LatencyHistogram {
    fn default() -> Self {
        Self {
            // Constant bounds, valid (the tests build one): this cannot fail.
            micros: Histogram::new_with_max(HIGHEST_MICROS, SIGNIFICANT_DIGITS)
                .unwrap_or_else(|e| unreachable!("constant histogram bounds: {e}")),
            max_ms: f64::NAN,
        }
    }
}

impl LatencyHistogram {
    /// Adds a sample; NaN (the stage did not handle the frame) and negative values are
    /// left out.
    pub fn record(&mut self, ms: f64) {
        if !(ms >= 0.0) || !ms.is_finite() {
            return;
        }
        self.micros
            .saturating_record((ms * MICROS_PER_MS).round().min(HIGHEST_MICROS as f64) as u64);
        self.max_ms = if self.max_ms.is_nan() {
            ms
        } else {
            self.max_ms.max(ms)
        };
    }

    /// The percentiles of the samples so far; `None` when there are none.
    pub fn percentiles(&self) -> Option<Percentiles> {
        if self.micros.is_empty() {
            return None;
        }
        let at =
            |q: f64| (self.micros.value_at_quantile(q) as f64 / MICROS_PER_MS).min(self.max_ms);
        Some(Percentiles {
            count: self.micros.len() as usize,
            p50: at(0.50),
            p90: at(0.90),
            p99: at(0.99),
            max: self.max_ms,
        })
    }
}

/// A run's report built up one frame and one event at a time, in memory that does not
/// grow with the run's length.
#[derive(Debug, Clone, Default)]
pub struct Tally {
    frames: usize,
    poses: usize,
    lost: usize,
    drops: BTreeMap<String, usize>,
    stage: [LatencyHistogram; 4],
    end_to_end: LatencyHistogram,
    deadline_misses: usize,
    l1_frames: usize,
    events: BTreeMap<String, usize>,
}

impl Tally {
    /// Counts a frame.
    pub fn add_frame(&mut self, f: &FrameRecord) {
        self.frames += 1;
        match f.outcome.as_str() {
            "pose" => self.poses += 1,
            "lost" => self.lost += 1,
            other => *self.drops.entry(other.to_string()).or_default() += 1,
        }
        // Latency over the frames every stage worked on: a dropped frame's near-zero
        // times would flatter the stages.
        if f.has_pose() {
            for (h, ms) in self.stage.iter_mut().zip(f.stage_ms) {
                h.record(ms);
            }
            self.end_to_end.record(f.end_to_end_ms);
        }
        self.deadline_misses += usize::from(f.deadline_miss);
        self.l1_frames += usize::from(f.matcher == "l1");
    }

    /// Counts an event.
    pub fn add_event(&mut self, e: &EventRecord) {
        *self.events.entry(e.kind.clone()).or_default() += 1;
    }

    /// Events of `kind` so far.
    pub fn events_of(&self, kind: &str) -> usize {
        self.events.get(kind).copied().unwrap_or(0)
    }

    /// Frames counted so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Frames with a tracked pose.
    pub fn tracked(&self) -> usize {
        self.poses
    }

    /// Frames that got a pose (tracked or predicted).
    pub fn with_pose(&self) -> usize {
        self.poses + self.lost
    }

    /// Frames over some budget.
    pub fn deadline_misses(&self) -> usize {
        self.deadline_misses
    }

    /// The report so far.
    pub fn report(&self) -> Report {
        Report {
            frames: self.frames,
            poses: self.poses,
            lost: self.lost,
            drops: self.drops.iter().map(|(k, n)| (k.clone(), *n)).collect(),
            stage_latency: StageKind::PROCESSING
                .iter()
                .zip(&self.stage)
                .map(|(s, h)| (s.name().to_string(), h.percentiles()))
                .collect(),
            end_to_end: self.end_to_end.percentiles(),
            deadline_misses: self.deadline_misses,
            l1_frames: self.l1_frames,
            fallbacks: self.events_of("fallback"),
            recoveries: self.events_of("recover"),
            restarts: self.events_of("restart"),
            swaps: self.events_of("swap"),
            camera_losses: self.events_of("camera-lost"),
        }
    }
}

/// What a run's records add up to.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// Frames accounted for.
    pub frames: usize,
    /// Frames with a tracked pose.
    pub poses: usize,
    /// Frames whose pose is a prediction (tracking lost).
    pub lost: usize,
    /// Dropped frames by outcome (corrupt, dropped-late, ...), sorted by name.
    pub drops: Vec<(String, usize)>,
    /// Per stage in [`StageKind::PROCESSING`] order, over the frames that got a pose.
    pub stage_latency: Vec<(String, Option<Percentiles>)>,
    /// End to end.
    pub end_to_end: Option<Percentiles>,
    /// Frames over some budget.
    pub deadline_misses: usize,
    /// Frames the matcher handled in ℓ1 mode.
    pub l1_frames: usize,
    /// Switches to ℓ1.
    pub fallbacks: usize,
    /// Switches back to LBD.
    pub recoveries: usize,
    /// Stage restarts.
    pub restarts: usize,
    /// Detector hot swaps.
    pub swaps: usize,
    /// Times the live camera failed and was reopened (`camera-lost` events).
    #[serde(default)]
    pub camera_losses: usize,
}

impl Report {
    /// The report of `frames` and `events` (percentiles as [`LatencyHistogram`] gives them).
    pub fn new(frames: &[FrameRecord], events: &[EventRecord]) -> Self {
        let mut tally = Tally::default();
        frames.iter().for_each(|f| tally.add_frame(f));
        events.iter().for_each(|e| tally.add_event(e));
        tally.report()
    }

    /// Frames dropped, all reasons.
    pub fn dropped(&self) -> usize {
        self.drops.iter().map(|(_, n)| n).sum()
    }

    /// The report as a text table.
    pub fn to_text(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "frames {}: {} tracked, {} predicted (tracking lost), {} dropped",
            self.frames,
            self.poses,
            self.lost,
            self.dropped()
        );
        for (why, n) in &self.drops {
            let _ = writeln!(out, "  dropped {why}: {n}");
        }
        let _ = writeln!(
            out,
            "{:<16} {:>6} {:>9} {:>9} {:>9} {:>9}",
            "latency (ms)", "n", "p50", "p90", "p99", "max"
        );
        let row = |out: &mut String, name: &str, p: &Option<Percentiles>| {
            let _ = match p {
                Some(p) => writeln!(
                    out,
                    "{name:<16} {:>6} {:>9.2} {:>9.2} {:>9.2} {:>9.2}",
                    p.count, p.p50, p.p90, p.p99, p.max
                ),
                None => writeln!(out, "{name:<16} {:>6}", 0),
            };
        };
        for (name, p) in &self.stage_latency {
            row(&mut out, name, p);
        }
        row(&mut out, "end-to-end", &self.end_to_end);
        let _ = writeln!(
            out,
            "deadline misses {}   l1 frames {}   fallbacks {}   recoveries {}   restarts {}   detector swaps {}",
            self.deadline_misses,
            self.l1_frames,
            self.fallbacks,
            self.recoveries,
            self.restarts,
            self.swaps
        );
        if self.camera_losses > 0 {
            let _ = writeln!(
                out,
                "camera lost {} times (reopened with backoff; events.csv names the device)",
                self.camera_losses
            );
        }
        out
    }
}

/// How a run ended (`summary.json`, and `status.json` while it runs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RunEnd {
    /// Not over yet.
    Running,
    /// Every frame has an outcome (or the drain timed out).
    Completed,
    /// Stopped by a signal before the sequence ended.
    Interrupted,
    /// Abandoned: a stage would not start, died past the restart limit, ... (see `reason`).
    Failed,
    /// A record could not be written (a full disk, ...): the records end at their last
    /// whole row; `reason` names the file and the OS error (`output.on_record_error` says
    /// whether the pipeline stopped there or ran on).
    RecordsFailed,
}

/// `summary.json`: how the run ended and its report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// How it ended.
    pub end: RunEnd,
    /// Why it failed (or other words on its end).
    pub reason: Option<String>,
    /// What the records add up to.
    #[serde(flatten)]
    pub report: Report,
    /// The trajectory (`poses.tum`) against the sequence's ground truth, when it has some:
    /// the names and definitions of `linetrack-vo`'s `metrics.json`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metrics: Option<metrics::Summary>,
}

/// The metrics of the run's trajectory (`poses`, a `poses.tum` as [`RecordWriter`] writes it)
/// against `truth` (the sequence's ground truth, stamped with the same sequence times), each
/// pose compared with the true pose of its frame ([`metrics::Summary::of_stamped`]).
/// `None` without ground truth or when no pose has one.
pub fn trajectory_metrics(
    poses: &Path,
    truth: &[StampedPose],
) -> Result<Option<metrics::Summary>, RecordError> {
    if truth.is_empty() {
        return Ok(None);
    }
    Ok(metrics::Summary::of_stamped(&tum::read(poses)?, truth))
}

impl Summary {
    /// Writes `path` whole or not at all ([`files::write_whole`], synced to the disk).
    pub fn write(&self, path: &Path) -> Result<(), RecordError> {
        let text = serde_json::to_string_pretty(self).map_err(|e| RecordError::Io {
            path: path.to_path_buf(),
            source: e.into(),
        })?;
        files::write_whole(path, text.as_bytes(), true)
    }

    /// Reads `summary.json`.
    pub fn read(path: &Path) -> Result<Self, RecordError> {
        let text = std::fs::read_to_string(path).map_err(|source| RecordError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        serde_json::from_str(&text).map_err(|e| RecordError::Parse {
            path: path.to_path_buf(),
            line: e.line(),
            message: e.to_string(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(id: u64, outcome: &str, e2e: f64) -> FrameRecord {
        FrameRecord {
            outcome: outcome.to_string(),
            end_to_end_ms: e2e,
            stage_ms: [1.0, 2.0, 3.0, 4.0],
            wait_ms: [0.0, 0.5, 0.25, 0.125],
            matcher: "lbd".into(),
            detector: "lsd".into(),
            ..FrameRecord::missing(id)
        }
    }

    #[test]
    fn nearest_rank_percentiles() {
        let p = Percentiles::of((1..=100).map(f64::from)).unwrap_or_else(|| panic!("no samples"));
        assert_eq!(
            (p.count, p.p50, p.p90, p.p99, p.max),
            (100, 50.0, 90.0, 99.0, 100.0)
        );
        let one = Percentiles::of([7.0, f64::NAN]).unwrap_or_else(|| panic!("no samples"));
        assert_eq!((one.count, one.p50, one.max), (1, 7.0, 7.0));
        assert!(Percentiles::of([f64::NAN]).is_none());
    }

    #[test]
    fn streaming_percentiles_are_within_a_tenth_of_a_percent() {
        let mut h = LatencyHistogram::default();
        assert!(h.percentiles().is_none());
        for ms in (1..=100).map(f64::from) {
            h.record(ms);
        }
        h.record(f64::NAN);
        h.record(-1.0);
        let p = h.percentiles().unwrap_or_else(|| panic!("no samples"));
        assert_eq!((p.count, p.max), (100, 100.0));
        for (got, want) in [(p.p50, 50.0), (p.p90, 90.0), (p.p99, 99.0)] {
            assert!((got - want).abs() <= want * 1e-3, "{got} vs {want}");
        }
        // A value past an hour is counted, not lost; the maximum stays exact.
        h.record(1e308);
        let p = h.percentiles().unwrap_or_else(|| panic!("no samples"));
        assert_eq!((p.count, p.max), (101, 1e308));
    }

    #[test]
    fn the_summary_says_how_the_run_ended() {
        let dir = std::env::temp_dir().join(format!("linetrack-summary-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
        let summary = Summary {
            end: RunEnd::Failed,
            reason: Some("matcher died 2 times (restart limit 1): giving up".into()),
            report: Report::new(&[frame(0, "pose", 40.0)], &[]),
            metrics: None,
        };
        let path = dir.join("summary.json");
        summary.write(&path).unwrap_or_else(|e| panic!("{e}"));
        let text = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(text.contains("\"end\": \"failed\""), "{text}");
        assert!(
            !text.contains("metrics"),
            "no ground truth, no metrics: {text}"
        );
        assert_eq!(
            Summary::read(&path).unwrap_or_else(|e| panic!("{e}")),
            summary
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn records_round_trip_through_csv_and_add_up() {
        let dir = std::env::temp_dir().join(format!("linetrack-run-record-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
        let mut late = frame(2, "dropped-late", f64::NAN);
        late.dropped_by = "matcher".into();
        late.deadline_miss = true;
        let mut odd = frame(4, "stage-error", f64::NAN);
        odd.dropped_by = "line-detector, \"lsd\"\r\nsecond line".into();
        let frames = [
            frame(0, "pose", 40.0),
            frame(1, "lost", 60.0),
            late,
            FrameRecord::missing(3),
            odd,
        ];
        // Commas, quotes and line breaks are quoted, not mangled.
        let events = [EventRecord {
            time_s: 1.5,
            kind: "fallback".into(),
            stage: "matcher".into(),
            frame_id: Some(1),
            detail: "too few matches, 3 < 12;\n\"lbd\" gave up".into(),
        }];
        {
            // Appended as frames complete: the missing frame 3 comes in before frame 2.
            let mut writer = RecordWriter::create(&dir).unwrap_or_else(|e| panic!("{e}"));
            for f in [&frames[0], &frames[1], &frames[3], &frames[4], &frames[2]] {
                writer.frame(f).unwrap_or_else(|e| panic!("{e}"));
            }
            writer.event(&events[0]).unwrap_or_else(|e| panic!("{e}"));
            // Every row is on disk while the writer is still open (no flush at the end).
            let now = read_frames(&dir.join("frames.csv")).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(now.len(), 5);
            assert_eq!(
                read_events(&dir.join("events.csv"))
                    .unwrap_or_else(|e| panic!("{e}"))
                    .len(),
                1
            );
        }
        let back = read_frames(&dir.join("frames.csv")).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            back.iter().map(|f| f.frame_id).collect::<Vec<_>>(),
            [0, 1, 2, 3, 4],
            "read back in frame order"
        );
        assert_eq!(back[4].dropped_by, frames[4].dropped_by);
        assert_eq!(back[2].dropped_by, "matcher");
        assert!(back[3].end_to_end_ms.is_nan());
        assert_eq!(back[0].end_to_end_ms, 40.0);
        let events_back = read_events(&dir.join("events.csv")).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(events_back, events, "every field round-trips");
        let report = Report::new(&back, &events_back);
        assert_eq!(
            (
                report.frames,
                report.poses,
                report.lost,
                report.dropped(),
                report.deadline_misses,
                report.fallbacks
            ),
            (5, 1, 1, 3, 1, 1)
        );
        assert_eq!(report.end_to_end.map(|p| p.max), Some(60.0));
        assert_eq!(
            report.stage_latency[1].1.map(|p| p.count),
            Some(2),
            "stage latency over the frames with a pose"
        );
        assert!(report.to_text().contains("dropped missing: 1"));
        // A damaged file names the line and the column.
        for (rows, wants) in [
            ("0,pose,,x,,,,,,,0,0,0,,,,\n", "bad.csv:2: frame_source_ms"),
            (
                "0,pose,,,,,,,,,0,0,0,,,,\n1,pose,,,,,,inf,,,0,0,0,,,,\n",
                "bad.csv:3: end_to_end_ms",
            ),
            ("0,pose,,,,,,,,,0,0,2,,,,\n", "bad.csv:2: deadline_miss"),
            (
                "0,pose,,,,,,,,,0,0,0,,,nan,\n",
                "bad.csv:2: matcher_wait_ms",
            ),
            ("0,pose,,,,,,,,,0,0,0,,,\n", "bad.csv:2"),
        ] {
            std::fs::write(dir.join("bad.csv"), format!("{FRAME_HEADER}\n{rows}"))
                .unwrap_or_else(|e| panic!("{e}"));
            let err = read_frames(&dir.join("bad.csv"))
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(err.contains(wants), "{wants}: {err}");
        }
        std::fs::write(dir.join("bad.csv"), "frame,outcome\n").unwrap_or_else(|e| panic!("{e}"));
        let err = read_frames(&dir.join("bad.csv"))
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("bad.csv:1: expected the header"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_cut_record_file_is_read_up_to_its_last_whole_row_and_says_what_is_missing() {
        let dir = std::env::temp_dir().join(format!("linetrack-run-cut-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
        let path = dir.join("frames.csv");
        {
            let mut writer = RecordWriter::create(&dir).unwrap_or_else(|e| panic!("{e}"));
            for id in [0, 1, 2, 4] {
                writer
                    .frame(&frame(id, "pose", 40.0))
                    .unwrap_or_else(|e| panic!("{e}"));
            }
        }
        let whole = std::fs::read(&path).unwrap_or_default();
        // Cut inside the row of frame 4 (as a full disk at a block boundary cut it), and
        // cut inside a quoted field whose line break happens to end the file.
        let last_row = whole[..whole.len() - 1]
            .iter()
            .rposition(|&b| b == b'\n')
            .map_or(0, |i| i + 1);
        let mut quoted = whole[..last_row].to_vec();
        quoted.extend_from_slice(b"4,stage-error,\"line-detector\n");
        for (name, bytes, line) in [
            ("torn", whole[..whole.len() - 7].to_vec(), 5),
            ("no-newline", whole[..whole.len() - 1].to_vec(), 5),
            ("quoted", quoted, 5),
        ] {
            std::fs::write(&path, &bytes).unwrap_or_else(|e| panic!("{e}"));
            let (frames, cut) = read_frames_to_cut(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(
                frames.iter().map(|f| f.frame_id).collect::<Vec<_>>(),
                [0, 1, 2],
                "{name}"
            );
            let cut = cut.unwrap_or_else(|| panic!("{name}: the cut row is not reported"));
            assert_eq!(cut.line, line, "{name}: {cut}");
            assert!(cut.to_string().contains("frames.csv:5"), "{cut}");
            assert!(
                read_frames(&path).is_err(),
                "{name}: strict reading refuses it"
            );
            assert_eq!(
                unrecorded(&frames, 6),
                vec![std::ops::Range { start: 3, end: 6 }],
                "{name}"
            );
        }
        // A bad row with whole rows after it is damage, not a cut.
        let mut damaged = whole[..last_row].to_vec();
        damaged.splice(last_row - 3..last_row - 3, b"x".iter().copied());
        damaged.extend_from_slice(&whole[last_row..]);
        std::fs::write(&path, &damaged).unwrap_or_else(|e| panic!("{e}"));
        let err = read_frames_to_cut(&path)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("frames.csv:4"), "{err}");
        // The whole file: nothing cut, nothing missing but frame 3.
        std::fs::write(&path, &whole).unwrap_or_else(|e| panic!("{e}"));
        let (frames, cut) = read_frames_to_cut(&path).unwrap_or_else(|e| panic!("{e}"));
        assert!(cut.is_none());
        assert_eq!(
            unrecorded(&frames, 5),
            vec![std::ops::Range { start: 3, end: 4 }]
        );
        assert_eq!(unrecorded(&frames, 3), []);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_run_with_ground_truth_is_scored_under_the_metric_names_of_linetrack_vo() {
        use nalgebra::{Isometry3, Translation3};
        let dir =
            std::env::temp_dir().join(format!("linetrack-run-metrics-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
        // Ground truth moves 10 cm a frame along x, every 50 ms from a Unix-epoch stamp;
        // the run's poses 11 cm a frame, and frame 2 never got a pose.
        let start_ns = 1_403_715_273_262_142_976u64;
        let stamp_ns = |k: u64| start_ns + k * 50_000_000;
        let truth: Vec<StampedPose> = (0..20u64)
            .map(|k| StampedPose {
                timestamp_s: stamp_ns(k) as f64 * 1e-9,
                pose: Isometry3::from_parts(
                    Translation3::new(0.1 * k as f64, 0.0, 0.0),
                    nalgebra::UnitQuaternion::identity(),
                ),
            })
            .collect();
        {
            let mut writer = RecordWriter::create(&dir).unwrap_or_else(|e| panic!("{e}"));
            for k in (0..20u64).filter(|&k| k != 2) {
                writer
                    .pose(
                        stamp_ns(k),
                        [0.11 * k as f64, 0.0, 0.0],
                        [0.0, 0.0, 0.0, 1.0],
                    )
                    .unwrap_or_else(|e| panic!("{e}"));
            }
        }
        let poses = dir.join("poses.tum");
        let scored = trajectory_metrics(&poses, &truth)
            .unwrap_or_else(|e| panic!("{e}"))
            .unwrap_or_else(|| panic!("no pose paired with the ground truth"));
        assert_eq!(scored.poses, 19);
        // Final error 0.19 m over a 1.9 m path.
        assert!(
            (scored.drift_percent.unwrap_or(f64::NAN) - 10.0).abs() < 1e-3,
            "{scored:?}"
        );
        assert!(
            trajectory_metrics(&poses, &[])
                .unwrap_or_else(|e| panic!("{e}"))
                .is_none()
        );

        let summary = Summary {
            end: RunEnd::Completed,
            reason: None,
            report: Report::new(&[], &[]),
            metrics: Some(scored),
        };
        let path = dir.join("summary.json");
        summary.write(&path).unwrap_or_else(|e| panic!("{e}"));
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap_or_default())
                .unwrap_or_else(|e| panic!("{e}"));
        let mut names: Vec<&str> = json["metrics"]
            .as_object()
            .map(|m| m.keys().map(String::as_str).collect())
            .unwrap_or_default();
        names.sort_unstable();
        let mut expected = metrics::METRIC_NAMES.to_vec();
        expected.sort_unstable();
        assert_eq!(names, expected, "the names of linetrack-vo's metrics.json");
        // Read back (JSON keeps the figures to about the last bit, not exactly).
        let back = Summary::read(&path).unwrap_or_else(|e| panic!("{e}"));
        let back_metrics = back.metrics.unwrap_or_else(|| panic!("metrics lost"));
        assert_eq!(back_metrics.poses, 19);
        assert!((back_metrics.path_m - scored.path_m).abs() < 1e-12);

        // A damaged poses file is named.
        std::fs::write(&poses, "1 2 3\n").unwrap_or_else(|e| panic!("{e}"));
        let err = trajectory_metrics(&poses, &truth)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("poses.tum:1"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
