//! Table II: the odometry per sequence and configuration, with and without the simulated
//! illumination changes.

use anyhow::Context;
use linetrack_datasets::StereoSequence;
use linetrack_odometry::{Features, Odometry, OdometryConfig, metrics};
use linetrack_vision::MatcherKind;
use nalgebra::Isometry3;

/// The odometry configurations compared (all with LSD).
pub const CONFIGURATIONS: [(&str, Features, MatcherKind); 4] = [
    ("P+L, LBD", Features::PointsAndLines, MatcherKind::Lbd),
    ("P+L, ℓ1", Features::PointsAndLines, MatcherKind::L1),
    ("L, LBD", Features::LinesOnly, MatcherKind::Lbd),
    ("L, ℓ1", Features::LinesOnly, MatcherKind::L1),
];

/// One run of the odometry.
#[derive(Debug, Clone, Default)]
pub struct OdometryRun {
    /// Estimated poses (world = first camera).
    pub estimate: Vec<Isometry3<f64>>,
    /// Ground truth in the same frame, when known.
    pub truth: Option<Vec<Isometry3<f64>>>,
    /// Frames lost.
    pub lost: usize,
    /// Every metric, when there is ground truth.
    pub metrics: Option<metrics::Summary>,
}

/// The summaries in increasing ATE (a run without an ATE last).
fn by_ate<'a>(summaries: &[&'a metrics::Summary]) -> Vec<&'a metrics::Summary> {
    let mut sorted = summaries.to_vec();
    sorted.sort_by(|a, b| {
        a.ate_m
            .unwrap_or(f64::NAN)
            .total_cmp(&b.ate_m.unwrap_or(f64::NAN))
    });
    sorted
}

/// One Table II cell: RPE / ATE / drift of a single run, or, over several seeds, the median
/// and worst ATE and drift; lost frames (summed) in bold.
pub fn cell(runs: &[OdometryRun]) -> String {
    let summaries: Vec<&metrics::Summary> =
        runs.iter().filter_map(|r| r.metrics.as_ref()).collect();
    let drift = |s: &metrics::Summary| {
        s.drift_percent
            .map_or("–".to_string(), |d| format!("{d:.2} %"))
    };
    let mut text = match summaries.as_slice() {
        [] => "no ground truth".to_string(),
        [one] => format!(
            "{:.1} mm / {:.1} cm / {}",
            one.rpe_m.unwrap_or(f64::NAN) * 1e3,
            one.ate_m.unwrap_or(f64::NAN) * 1e2,
            drift(one)
        ),
        many => {
            let by_ate = by_ate(many);
            let median = by_ate[by_ate.len() / 2];
            let worst = by_ate[by_ate.len() - 1];
            let worst_drift = many
                .iter()
                .filter_map(|s| s.drift_percent)
                .max_by(f64::total_cmp)
                .map_or("–".to_string(), |d| format!("{d:.2} %"));
            format!(
                "{:.1} cm / {} (worst {:.1} cm / {worst_drift})",
                median.ate_m.unwrap_or(f64::NAN) * 1e2,
                drift(median),
                worst.ate_m.unwrap_or(f64::NAN) * 1e2,
            )
        }
    };
    let lost: usize = runs.iter().map(|r| r.lost).sum();
    if lost > 0 {
        text.push_str(&format!(" (**{lost} lost**)"));
    }
    text
}

/// The Table II step-ratio cell beside [`cell`]: the overall ratio / median (p10–p90) of
/// a single run; over several seeds, those of the run with the median ATE (the run [`cell`]
/// reports) and the overall ratio furthest from 1 among them. "–" without a ratio (no
/// ground truth, or too few steps that move).
pub fn step_ratio_cell(runs: &[OdometryRun]) -> String {
    let summaries: Vec<&metrics::Summary> =
        runs.iter().filter_map(|r| r.metrics.as_ref()).collect();
    let one = |s: &metrics::Summary| {
        s.step_ratio.map_or("–".to_string(), |r| {
            format!(
                "{:.3} / {:.3} ({:.3}–{:.3})",
                r.overall, r.median, r.p10, r.p90
            )
        })
    };
    match summaries.as_slice() {
        [] => "–".to_string(),
        [single] => one(single),
        many => {
            let by_ate = by_ate(many);
            let median = by_ate[by_ate.len() / 2];
            let worst = many
                .iter()
                .filter_map(|s| s.step_ratio)
                .map(|r| r.overall)
                .max_by(|a, b| a.ln().abs().total_cmp(&b.ln().abs()));
            match worst {
                Some(worst) => format!("{} (worst {worst:.3})", one(median)),
                None => one(median),
            }
        }
    }
}

/// One Table II run in `odometry-runs.csv`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RunRow {
    /// Row of Table II (a starred one: simulated illumination changes).
    pub sequence: String,
    /// Seed of a generated sequence (1 for a real one).
    pub seed: u64,
    /// Features and matcher.
    pub configuration: String,
    /// Frames lost.
    pub lost: usize,
    /// Absolute trajectory error, metres.
    pub ate_m: Option<f64>,
    /// End-point drift, per cent of the path.
    pub drift_percent: Option<f64>,
    /// Estimated over true path length.
    pub step_ratio: Option<f64>,
    /// Median per-step ratio.
    pub step_ratio_median: Option<f64>,
}

impl RunRow {
    /// The row of `run`.
    pub fn new(sequence: &str, seed: u64, configuration: &str, run: &OdometryRun) -> Self {
        let m = run.metrics.as_ref();
        let ratio = m.and_then(|m| m.step_ratio);
        Self {
            sequence: sequence.to_string(),
            seed,
            configuration: configuration.to_string(),
            lost: run.lost,
            ate_m: m.and_then(|m| m.ate_m),
            drift_percent: m.and_then(|m| m.drift_percent),
            step_ratio: ratio.map(|r| r.overall),
            step_ratio_median: ratio.map(|r| r.median),
        }
    }
}

/// Writes `rows` (of this table or another) as CSV to `path`.
pub fn write_rows<T: serde::Serialize>(path: &std::path::Path, rows: &[T]) -> anyhow::Result<()> {
    let context = || format!("cannot write {}", path.display());
    let mut writer = csv::Writer::from_path(path).with_context(context)?;
    for row in rows {
        writer.serialize(row).with_context(context)?;
    }
    writer.flush().with_context(context)?;
    Ok(())
}

/// Runs one configuration (`base` with the given features and matcher) over the first
/// `frames` frames.
pub fn run(
    sequence: &StereoSequence,
    (base, features, matcher): (&OdometryConfig, Features, MatcherKind),
    frames: usize,
    illumination: crate::tracking::Illumination<'_>,
) -> anyhow::Result<OdometryRun> {
    let config = OdometryConfig {
        matcher,
        features,
        ..base.clone()
    };
    let mut odometry = Odometry::new(config, sequence.rig)?;
    let mut run = OdometryRun::default();
    let mut truth = Vec::new();
    for k in 0..frames.min(sequence.frames.len()) {
        let frame = crate::tracking::load_frame(sequence, k, illumination)?;
        let result = odometry.track(&frame.left, &frame.right)?;
        run.lost += usize::from(result.lost);
        run.estimate.push(result.pose);
        truth.push(frame.pose);
    }
    if let Some(truth) = truth
        .into_iter()
        .collect::<Option<Vec<_>>>()
        .filter(|t| !t.is_empty())
    {
        let first = truth[0].inverse();
        let truth: Vec<_> = truth.iter().map(|p| first * p).collect();
        run.metrics = Some(metrics::Summary::new(&run.estimate, &truth));
        run.truth = Some(truth);
    }
    Ok(run)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(ate_m: f64, drift_percent: Option<f64>) -> OdometryRun {
        OdometryRun {
            metrics: Some(metrics::Summary {
                poses: 10,
                path_m: 1.0,
                rpe_m: Some(0.001),
                ate_m: Some(ate_m),
                ate_aligned_m: Some(ate_m),
                drift_percent,
                step_ratio: None,
                zero_motion_ate_m: Some(1.0),
            }),
            ..OdometryRun::default()
        }
    }

    #[test]
    fn seeds_without_a_drift_figure_say_so_instead_of_minus_infinity() {
        // Paths too short for a drift figure (under `MIN_DRIFT_PATH_M`).
        let text = cell(&[run(0.01, None), run(0.03, None), run(0.02, None)]);
        assert_eq!(text, "2.0 cm / – (worst 3.0 cm / –)");
        let text = cell(&[run(0.01, Some(0.5)), run(0.03, Some(0.2)), run(0.02, None)]);
        assert_eq!(text, "2.0 cm / – (worst 3.0 cm / 0.50 %)");
    }
}
