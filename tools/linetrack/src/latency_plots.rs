//! A run's latency in two pictures, from its `frames.csv` and `events.csv`:
//!
//! - `latency.png`: per stage and end to end, the distribution over the frames that got a
//!   pose, on one axis (logarithmic when the stages differ by orders of magnitude), with
//!   p50, p99 and the stage's budget marked.
//! - `latency-timeline.png`: every stage's and the end-to-end latency over the frame index
//!   (a linear axis from zero: read against the budget), with the end-to-end budget, deadline misses, dropped frames, frames whose pose was
//!   predicted, matcher fallbacks and recoveries, detector swaps and stage restarts marked.

use linetrack_msgs::StageKind;
use linetrack_pipeline_config::BudgetConfig;
use linetrack_plot::{
    Chart, Distribution, Distributions, EventLine, Marker, PlotError, Reference, Scale, Series,
    Style,
};
use linetrack_run_record::{EventRecord, FrameRecord, Percentiles};
use std::path::{Path, PathBuf};

/// File name of the distributions picture in a run folder.
pub const DISTRIBUTIONS_PNG: &str = "latency.png";
/// File name of the per-frame timeline picture in a run folder.
pub const TIMELINE_PNG: &str = "latency-timeline.png";

/// Event kinds drawn on the timeline, with their legend text.
const MARKED_EVENTS: [(&str, &str); 6] = [
    ("fallback", "matcher falls back to l1"),
    ("recover", "matcher back to LBD"),
    ("swap", "detector swapped"),
    ("restart", "stage restarted"),
    ("crash", "stage crashed"),
    ("hang", "stage hung"),
];

const END_TO_END: &str = "end-to-end";
const MISS_RGB: (u8, u8, u8) = (214, 39, 40);
/// Dropped frames, one shade per reason.
const DROP_RGB: [(u8, u8, u8); 4] = [(180, 0, 0), (230, 120, 0), (120, 60, 20), (200, 0, 160)];
const PREDICTED_RGB: (u8, u8, u8) = (120, 120, 120);
const END_TO_END_RGB: (u8, u8, u8) = (20, 20, 20);

/// Writes both pictures into `run_dir`; returns their paths.
pub fn write(
    run_dir: &Path,
    frames: &[FrameRecord],
    events: &[EventRecord],
    budget: Option<&BudgetConfig>,
) -> Result<[PathBuf; 2], PlotError> {
    let distributions = run_dir.join(DISTRIBUTIONS_PNG);
    let timeline = run_dir.join(TIMELINE_PNG);
    distributions_of(frames, budget).write(&distributions)?;
    timeline_of(frames, events, budget).write(&timeline)?;
    Ok([distributions, timeline])
}

/// Each stage's latencies and the end-to-end latency of the frames that got a pose, in
/// [`StageKind::PROCESSING`] order then end to end (a dropped frame's near-zero times would flatter the
/// stages, as in the report).
fn latencies(frames: &[FrameRecord]) -> Vec<(&'static str, Vec<f64>)> {
    let with_pose = || frames.iter().filter(|f| f.has_pose());
    let mut rows: Vec<(&'static str, Vec<f64>)> = StageKind::PROCESSING
        .iter()
        .enumerate()
        .map(|(i, stage)| (stage.name(), with_pose().map(|f| f.stage_ms[i]).collect()))
        .collect();
    rows.push((END_TO_END, with_pose().map(|f| f.end_to_end_ms).collect()));
    rows
}

fn budget_of(budget: Option<&BudgetConfig>, name: &str) -> Option<f64> {
    let budget = budget?;
    if name == END_TO_END {
        Some(budget.end_to_end_ms)
    } else {
        StageKind::from_name(name).and_then(|stage| budget.stage_ms(stage))
    }
}

/// The distributions picture.
pub fn distributions_of(frames: &[FrameRecord], budget: Option<&BudgetConfig>) -> Distributions {
    let rows: Vec<Distribution> = latencies(frames)
        .into_iter()
        .map(|(name, values)| {
            let marks = Percentiles::of(values.iter().copied())
                .map(|p| vec![("p50".to_string(), p.p50), ("p99".to_string(), p.p99)])
                .unwrap_or_default();
            Distribution {
                name: name.to_string(),
                values,
                marks,
                limit: budget_of(budget, name).map(|ms| ("budget".to_string(), ms)),
            }
        })
        .collect();
    let with_pose = frames.iter().filter(|f| f.has_pose()).count();
    Distributions {
        title: format!(
            "Latency of the {with_pose} frames with a pose (bars: frames per bin; black: p50, dashed: p99, red: budget)"
        ),
        x_label: "milliseconds from taking the frame to publishing".to_string(),
        unit: "ms".to_string(),
        rows,
        scale: Scale::Auto,
    }
}

/// The timeline picture.
pub fn timeline_of(
    frames: &[FrameRecord],
    events: &[EventRecord],
    budget: Option<&BudgetConfig>,
) -> Chart {
    let mut frames: Vec<&FrameRecord> = frames.iter().collect();
    frames.sort_by_key(|f| f.frame_id);
    let x = |f: &FrameRecord| f.frame_id as f64;
    let mut chart = Chart::new(
        "Latency per frame, with what happened to the frames and the pipeline",
        "frame",
        "milliseconds",
    );
    // Linear from zero even when the frame source's ~0 ms would ask for a log axis: the
    // timeline is read against the budget, which a log axis squeezes; the distributions
    // show the small stages.
    chart.y_scale = Scale::Linear;
    chart.y_from_zero = true;
    for (i, stage) in StageKind::PROCESSING.iter().enumerate() {
        let points = frames
            .iter()
            .map(|f| {
                (
                    x(f),
                    if f.has_pose() {
                        f.stage_ms[i]
                    } else {
                        f64::NAN
                    },
                )
            })
            .collect();
        chart
            .series
            .push(Series::line(stage.name(), points).styled(Style::Line { width: 1 }));
    }
    let end_to_end = |f: &FrameRecord| {
        if f.has_pose() {
            f.end_to_end_ms
        } else {
            f64::NAN
        }
    };
    chart.series.push(
        Series::line(
            END_TO_END,
            frames.iter().map(|f| (x(f), end_to_end(f))).collect(),
        )
        .styled(Style::Line { width: 2 })
        .coloured(END_TO_END_RGB),
    );
    // A missed frame is marked at its end-to-end latency, or its slowest stage's.
    let misses: Vec<(f64, f64)> = frames
        .iter()
        .filter(|f| f.deadline_miss)
        .map(|f| {
            let slowest = f.stage_ms.iter().copied().filter(|v| v.is_finite());
            let y = if f.end_to_end_ms.is_finite() {
                f.end_to_end_ms
            } else {
                slowest.fold(f64::NAN, f64::max)
            };
            (x(f), y)
        })
        .collect();
    if !misses.is_empty() {
        chart.series.push(
            Series::line(format!("deadline miss ({})", misses.len()), misses)
                .styled(Style::Points(Marker::Triangle))
                .coloured(MISS_RGB),
        );
    }
    let predicted: Vec<(f64, f64)> = frames
        .iter()
        .filter(|f| f.outcome == "lost")
        .map(|f| (x(f), f64::NAN))
        .collect();
    if !predicted.is_empty() {
        chart.series.push(
            Series::line(format!("pose predicted ({})", predicted.len()), predicted)
                .styled(Style::Rug)
                .coloured(PREDICTED_RGB),
        );
    }
    let mut reasons: Vec<&str> = frames
        .iter()
        .filter(|f| !f.has_pose())
        .map(|f| f.outcome.as_str())
        .collect();
    reasons.sort_unstable();
    reasons.dedup();
    for (k, reason) in reasons.iter().enumerate() {
        let dropped: Vec<(f64, f64)> = frames
            .iter()
            .filter(|f| f.outcome == *reason)
            .map(|f| (x(f), f64::NAN))
            .collect();
        chart.series.push(
            Series::line(format!("{reason} ({})", dropped.len()), dropped)
                .styled(Style::Rug)
                .coloured(DROP_RGB[k % DROP_RGB.len()]),
        );
    }
    if let Some(ms) = budget_of(budget, END_TO_END) {
        chart.references.push(Reference {
            y: ms,
            label: format!("end-to-end budget {ms:.0} ms"),
        });
    }
    for (kind, text) in MARKED_EVENTS {
        chart.events.extend(
            events
                .iter()
                .filter(|e| e.kind == kind)
                .filter_map(|e| e.frame_id)
                .map(|frame| EventLine {
                    x: frame as f64,
                    kind: text.to_string(),
                }),
        );
    }
    chart
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(id: u64, outcome: &str, stage_ms: [f64; 4], miss: bool) -> FrameRecord {
        FrameRecord {
            frame_id: id,
            outcome: outcome.to_string(),
            dropped_by: String::new(),
            stage_ms,
            wait_ms: [0.0; 4],
            end_to_end_ms: stage_ms.iter().copied().filter(|v| v.is_finite()).sum(),
            matcher: "lbd".to_string(),
            detector: "lsd".to_string(),
            stereo_matches: 50,
            tracked_matches: 40,
            deadline_miss: miss,
            lost_reason: String::new(),
            disparity_offset_px: 0.0,
        }
    }

    fn event(kind: &str, frame_id: Option<u64>) -> EventRecord {
        EventRecord {
            time_s: 1.0,
            kind: kind.to_string(),
            stage: "matcher".to_string(),
            frame_id,
            detail: String::new(),
        }
    }

    /// Frames 0..20 in shuffled order; 5 dropped late, 6 predicted, 7 over budget.
    fn run() -> (Vec<FrameRecord>, Vec<EventRecord>) {
        let mut frames: Vec<FrameRecord> = (0..20)
            .rev()
            .map(|id| frame(id, "pose", [0.004, 35.0, 23.0, 9.0], false))
            .collect();
        frames[20 - 1 - 5] = frame(
            5,
            "dropped-late",
            [0.004, f64::NAN, f64::NAN, f64::NAN],
            false,
        );
        frames[20 - 1 - 6].outcome = "lost".to_string();
        frames[20 - 1 - 7] = frame(7, "pose", [0.004, 95.0, 23.0, 9.0], true);
        let events = vec![
            event("fallback", Some(8)),
            event("recover", Some(15)),
            event("swap", Some(12)),
            event("stale-cleanup", None),
            event("restart", None),
        ];
        (frames, events)
    }

    fn series<'a>(chart: &'a Chart, name: &str) -> &'a Series {
        chart
            .series
            .iter()
            .find(|s| s.name.starts_with(name))
            .unwrap_or_else(|| panic!("no series {name}: {:?}", chart.series))
    }

    #[test]
    fn the_timeline_marks_drops_predictions_misses_and_pipeline_events() {
        let (frames, events) = run();
        let chart = timeline_of(&frames, &events, Some(&BudgetConfig::default()));
        let e2e = series(&chart, END_TO_END);
        let xs: Vec<f64> = e2e.points.iter().map(|p| p.0).collect();
        assert_eq!(
            xs,
            (0..20).map(f64::from).collect::<Vec<_>>(),
            "in frame order"
        );
        assert!(e2e.points[5].1.is_nan(), "a dropped frame breaks the line");
        assert_eq!(series(&chart, "dropped-late (1)").points[0].0, 5.0);
        assert_eq!(series(&chart, "pose predicted (1)").points[0].0, 6.0);
        let e2e_of_7 = frames
            .iter()
            .find(|f| f.frame_id == 7)
            .map(|f| f.end_to_end_ms);
        assert_eq!(
            series(&chart, "deadline miss (1)").points,
            vec![(7.0, e2e_of_7.unwrap_or(f64::NAN))]
        );
        let marked: Vec<(f64, &str)> = chart
            .events
            .iter()
            .map(|e| (e.x, e.kind.as_str()))
            .collect();
        assert_eq!(
            marked,
            vec![
                (8.0, "matcher falls back to l1"),
                (15.0, "matcher back to LBD"),
                (12.0, "detector swapped"),
            ],
            "events without a frame are not placed"
        );
        assert_eq!(chart.references.len(), 1);
        assert_eq!(chart.references[0].y, BudgetConfig::default().end_to_end_ms);
    }

    #[test]
    fn distributions_mark_p50_p99_and_each_stage_budget() {
        let (frames, _) = run();
        let budget = BudgetConfig {
            line_detector_ms: 80.0,
            end_to_end_ms: 250.0,
            ..BudgetConfig::default()
        };
        let plot = distributions_of(&frames, Some(&budget));
        let names: Vec<&str> = plot.rows.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "frame-source",
                "line-detector",
                "matcher",
                "pose-estimator",
                "end-to-end"
            ]
        );
        let detector = &plot.rows[1];
        assert_eq!(detector.values.len(), 19, "the dropped frame is left out");
        assert_eq!(
            detector.marks,
            vec![("p50".to_string(), 35.0), ("p99".to_string(), 95.0)]
        );
        assert_eq!(detector.limit, Some(("budget".to_string(), 80.0)));
        assert_eq!(plot.rows[4].limit, Some(("budget".to_string(), 250.0)));
    }

    #[test]
    fn pictures_are_written_for_an_empty_run_and_a_single_frame() {
        let scratch = linetrack_test_data::Scratch::new("linetrack", "latency-plots");
        let dir = scratch.path();
        for frames in [
            vec![],
            vec![frame(0, "pose", [0.0, 30.0, 20.0, 9.0], false)],
        ] {
            let written = write(dir, &frames, &[], None).unwrap_or_else(|e| panic!("{e}"));
            for path in written {
                assert!(image::open(&path).is_ok(), "{} unreadable", path.display());
            }
        }
    }
}
