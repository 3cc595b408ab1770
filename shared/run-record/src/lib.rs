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

pub mod files;
mod latency;
mod read;
mod report;
mod rows;
mod summary;
mod writer;

pub use latency::{LatencyHistogram, Percentiles};
pub use read::{
    CutRow, ReadToCut, full_message, read_events, read_events_to_cut, read_frames,
    read_frames_to_cut, unrecorded,
};
pub use report::{Report, Tally};
pub use rows::{EventRecord, FrameRecord};
pub use summary::{RunEnd, Summary, trajectory_metrics};
pub use writer::RecordWriter;

use std::path::PathBuf;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rows::{FRAME_HEADER_WITHOUT_OFFSET, FRAME_HEADER_WITHOUT_REASON};
    use linetrack_trajectory::metrics;
    use linetrack_trajectory::tum::StampedPose;

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
    fn l1_rescues_are_counted_and_an_older_summary_without_them_reads_as_none() {
        let rescue = |frame_id: u64| EventRecord {
            time_s: 0.1 * frame_id as f64,
            kind: "l1-rescue".into(),
            stage: "pose-estimator".into(),
            frame_id: Some(frame_id),
            detail: String::new(),
        };
        let report = Report::new(&[frame(0, "pose", 40.0)], &[rescue(20), rescue(78)]);
        assert_eq!((report.l1_rescues, report.fallbacks), (2, 0));
        assert!(
            report.to_text().contains("l1 rescues 2"),
            "{}",
            report.to_text()
        );
        let quiet = Report::new(&[frame(0, "pose", 40.0)], &[]);
        assert!(!quiet.to_text().contains("rescue"), "{}", quiet.to_text());
        // A summary.json written before the count existed has no `l1_rescues`.
        let mut old = serde_json::to_value(&report).unwrap_or_else(|e| panic!("{e}"));
        if let Some(fields) = old.as_object_mut() {
            fields.remove("l1_rescues");
        }
        let back: Report = serde_json::from_value(old).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back.l1_rescues, 0);
    }

    #[test]
    fn the_summary_says_how_the_run_ended() {
        let scratch = linetrack_test_data::Scratch::new("run-record", "summary");
        let dir = scratch.path();
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
    }

    #[test]
    fn records_round_trip_through_csv_and_add_up() {
        let scratch = linetrack_test_data::Scratch::new("run-record", "records");
        let dir = scratch.path();
        let mut late = frame(2, "dropped-late", f64::NAN);
        late.dropped_by = "matcher".into();
        late.deadline_miss = true;
        let mut odd = frame(4, "stage-error", f64::NAN);
        odd.dropped_by = "line-detector, \"lsd\"\r\nsecond line".into();
        let frames = [
            FrameRecord {
                disparity_offset_px: -1.04123,
                ..frame(0, "pose", 40.0)
            },
            FrameRecord {
                lost_reason: "too-few-inliers".into(),
                disparity_offset_px: -0.5,
                ..frame(1, "lost", 60.0)
            },
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
            let mut writer = RecordWriter::create(dir).unwrap_or_else(|e| panic!("{e}"));
            for f in [&frames[0], &frames[1], &frames[3], &frames[4], &frames[2]] {
                writer.frame(f).unwrap_or_else(|e| panic!("{e}"));
            }
            writer.event(&events[0]).unwrap_or_else(|e| panic!("{e}"));
            // Every row is on disk while the writer is still open, once its thread has
            // written what was added (no flush of a buffer at the end).
            writer.flush();
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
        assert_eq!(back[1].lost_reason, "too-few-inliers");
        // The offset to a ten-thousandth of a pixel; none for a frame without a pose.
        assert_eq!(back[0].disparity_offset_px, -1.0412);
        assert!(back[3].disparity_offset_px.is_nan());
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
        // The offset of the latest frame with a pose (frame 1), not the last one written.
        assert_eq!(report.disparity_offset_px, Some(-0.5));
        assert!(
            report.to_text().contains("disparity offset -0.50 px"),
            "{}",
            report.to_text()
        );
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
            std::fs::write(
                dir.join("bad.csv"),
                format!("{FRAME_HEADER_WITHOUT_REASON}\n{rows}"),
            )
            .unwrap_or_else(|e| panic!("{e}"));
            let err = read_frames(&dir.join("bad.csv"))
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(err.contains(wants), "{wants}: {err}");
        }
        // A run recorded before the `lost_reason` column reads, with empty reasons.
        let old = dir.join("old.csv");
        std::fs::write(
            &old,
            format!("{FRAME_HEADER_WITHOUT_REASON}\n0,lost,,,,,,,,,0,0,0,,,,\n"),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let read = read_frames(&old).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            (read[0].outcome.as_str(), read[0].lost_reason.as_str()),
            ("lost", "")
        );
        // …and one recorded before the `disparity_offset_px` column, with none.
        std::fs::write(
            &old,
            format!("{FRAME_HEADER_WITHOUT_OFFSET}\n0,pose,,,,,,,,,0,0,0,,,,,\n"),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let read = read_frames(&old).unwrap_or_else(|e| panic!("{e}"));
        assert!(read[0].disparity_offset_px.is_nan());
        let report = Report::new(&read, &[]);
        assert_eq!(report.disparity_offset_px, None);
        assert!(!report.to_text().contains("disparity offset"));
        std::fs::write(dir.join("bad.csv"), "frame,outcome\n").unwrap_or_else(|e| panic!("{e}"));
        let err = read_frames(&dir.join("bad.csv"))
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("bad.csv:1: expected the header"), "{err}");
    }

    #[test]
    fn a_cut_record_file_is_read_up_to_its_last_whole_row_and_says_what_is_missing() {
        let scratch = linetrack_test_data::Scratch::new("run-record", "cut");
        let dir = scratch.path();
        let path = dir.join("frames.csv");
        {
            let mut writer = RecordWriter::create(dir).unwrap_or_else(|e| panic!("{e}"));
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
    }

    #[test]
    fn a_run_with_ground_truth_is_scored_under_the_metric_names_of_linetrack_vo() {
        use nalgebra::{Isometry3, Translation3};
        let scratch = linetrack_test_data::Scratch::new("run-record", "metrics");
        let dir = scratch.path();
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
            let mut writer = RecordWriter::create(dir).unwrap_or_else(|e| panic!("{e}"));
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
    }
}
