//! A pipeline run's records and the latency report computed from them.
//!
//! The supervisor writes one [`FrameRecord`] per frame of the sequence to `frames.csv`
//! (what became of it, per-stage and end-to-end latency, matcher mode) and one
//! [`EventRecord`] per notable event to `events.csv` (fallbacks, restarts, hot swaps).
//! [`Report`] turns them into percentiles, deadline misses, drops and counts.

use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

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
}

/// The stages with a latency of their own, in pipeline order.
pub const STAGES: [&str; 4] = ["frame-source", "line-detector", "matcher", "pose-estimator"];

/// What became of one frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameRecord {
    /// Frame number.
    pub frame_id: u64,
    /// `pose`, `lost` (pose predicted), or a drop: `corrupt`, `dropped-late`,
    /// `dropped-behind`, `stage-error`, `missing` (never reached the end: a stage was down).
    pub outcome: String,
    /// The stage that dropped it, or empty.
    pub dropped_by: String,
    /// Per stage in [`STAGES`] order: milliseconds from taking the frame to publishing
    /// (NaN when the stage did not handle it).
    pub stage_ms: [f64; 4],
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

const FRAME_HEADER: &str = "frame_id,outcome,dropped_by,frame_source_ms,line_detector_ms,matcher_ms,pose_estimator_ms,end_to_end_ms,matcher,detector,stereo_matches,tracked_matches,deadline_miss";
const EVENT_HEADER: &str = "time_s,kind,stage,frame_id,detail";

fn clean(text: &str) -> String {
    text.replace([',', '\n', '\r'], ";")
}

fn ms(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3}")
    } else {
        String::new()
    }
}

/// Writes `frames.csv`.
pub fn write_frames(path: &Path, frames: &[FrameRecord]) -> Result<(), RecordError> {
    let mut out = String::from(FRAME_HEADER);
    out.push('\n');
    for f in frames {
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{},{},{}",
            f.frame_id,
            clean(&f.outcome),
            clean(&f.dropped_by),
            ms(f.stage_ms[0]),
            ms(f.stage_ms[1]),
            ms(f.stage_ms[2]),
            ms(f.stage_ms[3]),
            ms(f.end_to_end_ms),
            clean(&f.matcher),
            clean(&f.detector),
            f.stereo_matches,
            f.tracked_matches,
            u8::from(f.deadline_miss)
        );
    }
    std::fs::write(path, out).map_err(|source| RecordError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes `events.csv`.
pub fn write_events(path: &Path, events: &[EventRecord]) -> Result<(), RecordError> {
    let mut out = String::from(EVENT_HEADER);
    out.push('\n');
    for e in events {
        let frame = e.frame_id.map(|f| f.to_string()).unwrap_or_default();
        let _ = writeln!(
            out,
            "{:.3},{},{},{frame},{}",
            e.time_s,
            clean(&e.kind),
            clean(&e.stage),
            clean(&e.detail)
        );
    }
    std::fs::write(path, out).map_err(|source| RecordError::Io {
        path: path.to_path_buf(),
        source,
    })
}

fn read_rows(
    path: &Path,
    header: &str,
    columns: usize,
) -> Result<Vec<(usize, Vec<String>)>, RecordError> {
    let text = std::fs::read_to_string(path).map_err(|source| RecordError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, first)) if first.trim() == header => {}
        _ => {
            return Err(RecordError::Parse {
                path: path.to_path_buf(),
                line: 1,
                message: format!("expected the header {header:?}"),
            });
        }
    }
    let mut rows = Vec::new();
    for (i, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let fields: Vec<String> = line.split(',').map(|s| s.trim().to_string()).collect();
        if fields.len() != columns {
            return Err(RecordError::Parse {
                path: path.to_path_buf(),
                line: i + 1,
                message: format!("{} fields, expected {columns}", fields.len()),
            });
        }
        rows.push((i + 1, fields));
    }
    Ok(rows)
}

/// Reads `frames.csv`.
pub fn read_frames(path: &Path) -> Result<Vec<FrameRecord>, RecordError> {
    let rows = read_rows(path, FRAME_HEADER, 13)?;
    let mut frames = Vec::with_capacity(rows.len());
    for (line, f) in rows {
        let bad = |what: &str, v: &str| RecordError::Parse {
            path: path.to_path_buf(),
            line,
            message: format!("{what}: {v:?} is not a number"),
        };
        let float = |v: &str, what: &str| -> Result<f64, RecordError> {
            if v.is_empty() {
                return Ok(f64::NAN);
            }
            v.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| bad(what, v))
        };
        let int = |v: &str, what: &str| v.parse::<u32>().map_err(|_| bad(what, v));
        frames.push(FrameRecord {
            frame_id: f[0].parse().map_err(|_| bad("frame_id", &f[0]))?,
            outcome: f[1].clone(),
            dropped_by: f[2].clone(),
            stage_ms: [
                float(&f[3], STAGES[0])?,
                float(&f[4], STAGES[1])?,
                float(&f[5], STAGES[2])?,
                float(&f[6], STAGES[3])?,
            ],
            end_to_end_ms: float(&f[7], "end_to_end_ms")?,
            matcher: f[8].clone(),
            detector: f[9].clone(),
            stereo_matches: int(&f[10], "stereo_matches")?,
            tracked_matches: int(&f[11], "tracked_matches")?,
            deadline_miss: match f[12].as_str() {
                "0" => false,
                "1" => true,
                v => return Err(bad("deadline_miss", v)),
            },
        });
    }
    Ok(frames)
}

/// Reads `events.csv`.
pub fn read_events(path: &Path) -> Result<Vec<EventRecord>, RecordError> {
    let rows = read_rows(path, EVENT_HEADER, 5)?;
    rows.into_iter()
        .map(|(line, f)| {
            let bad = |message: String| RecordError::Parse {
                path: path.to_path_buf(),
                line,
                message,
            };
            Ok(EventRecord {
                time_s: f[0]
                    .parse()
                    .map_err(|_| bad(format!("time_s {:?}", f[0])))?,
                kind: f[1].clone(),
                stage: f[2].clone(),
                frame_id: if f[3].is_empty() {
                    None
                } else {
                    Some(
                        f[3].parse()
                            .map_err(|_| bad(format!("frame_id {:?}", f[3])))?,
                    )
                },
                detail: f[4].clone(),
            })
        })
        .collect()
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
    /// Per stage in [`STAGES`] order, over the frames that got a pose.
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
}

impl Report {
    /// The report of `frames` and `events`.
    pub fn new(frames: &[FrameRecord], events: &[EventRecord]) -> Self {
        let mut drops: std::collections::BTreeMap<String, usize> = Default::default();
        for f in frames.iter().filter(|f| !f.has_pose()) {
            *drops.entry(f.outcome.clone()).or_default() += 1;
        }
        let count = |kind: &str| events.iter().filter(|e| e.kind == kind).count();
        Self {
            frames: frames.len(),
            poses: frames.iter().filter(|f| f.outcome == "pose").count(),
            lost: frames.iter().filter(|f| f.outcome == "lost").count(),
            drops: drops.into_iter().collect(),
            // Over the frames every stage worked on: a dropped frame's near-zero times
            // would flatter the stages.
            stage_latency: STAGES
                .iter()
                .enumerate()
                .map(|(i, s)| {
                    (
                        s.to_string(),
                        Percentiles::of(
                            frames
                                .iter()
                                .filter(|f| f.has_pose())
                                .map(|f| f.stage_ms[i]),
                        ),
                    )
                })
                .collect(),
            end_to_end: Percentiles::of(
                frames
                    .iter()
                    .filter(|f| f.has_pose())
                    .map(|f| f.end_to_end_ms),
            ),
            deadline_misses: frames.iter().filter(|f| f.deadline_miss).count(),
            l1_frames: frames.iter().filter(|f| f.matcher == "l1").count(),
            fallbacks: count("fallback"),
            recoveries: count("recover"),
            restarts: count("restart"),
            swaps: count("swap"),
        }
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
        out
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
    fn records_round_trip_through_csv_and_add_up() {
        let dir = std::env::temp_dir().join(format!("linetrack-run-record-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
        let mut late = frame(2, "dropped-late", f64::NAN);
        late.dropped_by = "matcher".into();
        late.deadline_miss = true;
        let frames = vec![
            frame(0, "pose", 40.0),
            frame(1, "lost", 60.0),
            late,
            FrameRecord::missing(3),
        ];
        let events = vec![EventRecord {
            time_s: 1.5,
            kind: "fallback".into(),
            stage: "matcher".into(),
            frame_id: Some(1),
            detail: "too few matches, 3 < 12".into(),
        }];
        write_frames(&dir.join("frames.csv"), &frames).unwrap_or_else(|e| panic!("{e}"));
        write_events(&dir.join("events.csv"), &events).unwrap_or_else(|e| panic!("{e}"));
        let back = read_frames(&dir.join("frames.csv")).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back.len(), 4);
        assert_eq!(back[2].dropped_by, "matcher");
        assert!(back[3].end_to_end_ms.is_nan());
        assert_eq!(back[0].end_to_end_ms, 40.0);
        let events_back = read_events(&dir.join("events.csv")).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            events_back[0].detail, "too few matches; 3 < 12",
            "commas cannot break the columns"
        );
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
            (4, 1, 1, 2, 1, 1)
        );
        assert_eq!(report.end_to_end.map(|p| p.max), Some(60.0));
        assert_eq!(
            report.stage_latency[1].1.map(|p| p.count),
            Some(2),
            "stage latency over the frames with a pose"
        );
        assert!(report.to_text().contains("dropped missing: 1"));
        // A damaged file names the line.
        std::fs::write(
            dir.join("bad.csv"),
            format!("{FRAME_HEADER}\n0,pose,,x,,,,,,,0,0,0\n"),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let err = read_frames(&dir.join("bad.csv"))
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            err.contains("bad.csv:2") && err.contains("frame-source"),
            "{err}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
