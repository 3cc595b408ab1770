//! The disparities the odometry triangulates, checked against real ground truth.
//!
//! A depth from a disparity that is biased by δ pixels is off by a factor of about
//! 1 + δ / d, so a bias of a fraction of a pixel becomes a scale error of the motion wherever
//! the points are far (small d). This crate runs the odometry's own stereo front end
//! ([`Odometry::track`] on one stereo pair, then [`Odometry::stereo_sightings`]: every
//! point and segment endpoint it triangulated, with the disparity it used) on the
//! Middlebury pairs and compares each disparity with the ground truth under the left pixel
//! (bilinear between pixel centres; left out at depth edges, where the four pixels around
//! it differ by more than a limit, and where it is unknown). The signed errors are summed up
//! per kind (points, segment endpoints), matcher and disparity band.
//!
//! The same check runs on generated frames ([`rendered_pair`]), whose truth is the
//! renderer's exact depth at each pixel centre: no quantisation and no convention to
//! interpret, so a bias found on both is the odometry's, and one found only on Middlebury
//! is the ground truth's.
//!
//! [`repeatability`] scores point extractors instead (OpenCV's ORB against our own
//! corners): how many left points come back in the right image where the truth puts them.

mod repeat;
mod truth_shift;

pub use repeat::{RepeatCounts, RepeatRow, repeat_markdown, repeatability};
pub use truth_shift::{TruthShift, truth_shift};

use linetrack_datasets::{DisparityMap, LoadedPair};
use linetrack_geometry::StereoRig;
use linetrack_odometry::{Odometry, OdometryConfig, SightingKind};
use linetrack_scene_render::{Preset, SequenceRenderer};
use linetrack_vision::GrayImage;
use linetrack_vision::MatcherKind;
use serde::Serialize;

/// Disparity bands the errors are summed up in, pixels: `[low, high)`.
pub const BANDS: [(f64, f64); 4] = [
    (0.0, 10.0),
    (10.0, 30.0),
    (30.0, 60.0),
    (60.0, f64::INFINITY),
];

/// The label of band `i` ("< 10", "10–30", …).
pub fn band_label(i: usize) -> String {
    let (low, high) = BANDS[i];
    if low == 0.0 {
        format!("< {high}")
    } else if high.is_infinite() {
        format!("≥ {low}")
    } else {
        format!("{low}–{high}")
    }
}

/// The band a true disparity falls in.
pub fn band_of(disparity_px: f64) -> Option<usize> {
    BANDS
        .iter()
        .position(|&(low, high)| disparity_px >= low && disparity_px < high)
}

/// One triangulated disparity and the truth under it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Sample {
    /// Point or segment endpoint.
    pub kind: SightingKind,
    /// The odometry's disparity, pixels.
    pub measured_px: f64,
    /// The ground truth, pixels.
    pub true_px: f64,
}

impl Sample {
    /// Measured − true, pixels (negative: the depth comes out too long).
    pub fn error_px(&self) -> f64 {
        self.measured_px - self.true_px
    }
}

/// What the odometry triangulated on one pair, against the ground truth.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PairSamples {
    /// Sightings with a ground truth.
    pub samples: Vec<Sample>,
    /// Sightings left out: unknown ground truth or a depth edge under them.
    pub without_truth: usize,
}

/// A nominal rig for a pair of `width` × `height` images: Middlebury gives no metric
/// calibration, and the disparities compared do not depend on it.
pub fn nominal_rig(width: u32, height: u32) -> StereoRig {
    StereoRig {
        focal_px: 1000.0,
        cx_px: f64::from(width) / 2.0,
        cy_px: f64::from(height) / 2.0,
        baseline_m: 0.1,
        width_px: width,
        height_px: height,
    }
}

/// Frame `index` of the generated sequence `preset` / `seed` (`frames` long) as a stereo
/// pair with its true disparity: `f · b / z` of the renderer's depth at each left pixel
/// centre (unknown where the ray hits nothing: the sky).
pub fn rendered_pair(
    preset: Preset,
    seed: u64,
    frames: usize,
    index: usize,
) -> anyhow::Result<LoadedPair> {
    let renderer = SequenceRenderer::new(preset.config(seed, frames));
    let frame = renderer.render(index);
    let rig = &renderer.config.rig;
    let origin = |side: &str| format!("{} seed {seed} frame {index} {side}", preset.name());
    let image = |view: &linetrack_scene_render::View, side: &str| {
        GrayImage::from_pixels(view.width, view.height, &view.pixels, &origin(side))
    };
    let (left, right) = (image(&frame.left, "left")?, image(&frame.right, "right")?);
    let scale = (rig.focal_px * rig.baseline_m) as f32;
    let values = frame
        .left
        .depth_m
        .iter()
        .map(|&z| if z > 0.0 { scale / z } else { f32::NAN })
        .collect();
    let disparity = DisparityMap::from_values(frame.left.width, frame.left.height, values)
        .ok_or_else(|| anyhow::anyhow!("{}: depth map of the wrong size", origin("left")))?;
    Ok(LoadedPair {
        left,
        right,
        disparity,
    })
}

/// Runs the odometry configured by `config` with `matcher` on `pair` (one frame) and
/// pairs each of its triangulated sightings with the ground truth; truth whose four
/// surrounding pixels spread over more than `max_spread_px` is a depth edge and left out.
pub fn check_pair(
    pair: &LoadedPair,
    config: &OdometryConfig,
    matcher: MatcherKind,
    max_spread_px: f64,
) -> anyhow::Result<PairSamples> {
    let size = |v: i32| u32::try_from(v).unwrap_or(0);
    let rig = nominal_rig(size(pair.left.width()), size(pair.left.height()));
    let mut config = config.clone();
    config.matcher = matcher;
    let mut odometry = Odometry::new(config, rig)?;
    odometry.track(&pair.left, &pair.right)?;
    let mut out = PairSamples::default();
    for sighting in odometry.stereo_sightings() {
        match pair
            .disparity
            .interpolated(sighting.left.x, sighting.left.y, max_spread_px)
        {
            Some(true_px) => out.samples.push(Sample {
                kind: sighting.kind,
                measured_px: sighting.disparity_px,
                true_px,
            }),
            None => out.without_truth += 1,
        }
    }
    Ok(out)
}

/// The signed errors of one band, summed up.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Summary {
    /// Samples.
    pub count: usize,
    /// Mean signed error, pixels.
    pub mean_px: f64,
    /// Half-width of the mean's 95 % confidence interval (1.96 standard errors), pixels.
    pub mean_ci95_px: f64,
    /// Median signed error, pixels.
    pub median_px: f64,
    /// Standard deviation, pixels.
    pub std_px: f64,
    /// 10th and 90th percentiles, pixels.
    pub p10_px: f64,
    /// See `p10_px`.
    pub p90_px: f64,
}

impl Summary {
    /// The summary of `errors`; `None` without any.
    pub fn of(errors: &[f64]) -> Option<Self> {
        let n = errors.len();
        if n == 0 {
            return None;
        }
        let mut sorted = errors.to_vec();
        sorted.sort_by(f64::total_cmp);
        let mean = sorted.iter().sum::<f64>() / n as f64;
        let variance = if n > 1 {
            sorted.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (n - 1) as f64
        } else {
            0.0
        };
        let std = variance.sqrt();
        Some(Self {
            count: n,
            mean_px: mean,
            mean_ci95_px: 1.96 * std / (n as f64).sqrt(),
            median_px: quantile(&sorted, 0.5),
            std_px: std,
            p10_px: quantile(&sorted, 0.1),
            p90_px: quantile(&sorted, 0.9),
        })
    }
}

/// The `q` quantile of sorted values, linear between ranks.
fn quantile(sorted: &[f64], q: f64) -> f64 {
    let position = q * (sorted.len() - 1) as f64;
    let (low, high) = (position.floor() as usize, position.ceil() as usize);
    sorted[low] + (sorted[high] - sorted[low]) * (position - low as f64)
}

/// One row of the report: a kind of sighting, a matcher, a band.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Row {
    /// Point or segment endpoint.
    pub kind: SightingKind,
    /// The segment matcher the odometry ran with.
    pub matcher: String,
    /// The band's label.
    pub band: String,
    /// Sightings in the band.
    pub count: usize,
    /// Mean signed error of them all, mismatches included, pixels (`None`: no sighting).
    pub mean_all_px: Option<f64>,
    /// Sightings off by more than the inlier limit: wrong matches, not a bias.
    pub mismatched: usize,
    /// The signed errors of the others (correct matches); `None` when there is none.
    pub correct: Option<Summary>,
}

/// Rows per band (and one for all bands) of `samples` of `kind`; a sighting off by more
/// than `inlier_px` counts as a mismatch and is left out of the `correct` summary.
pub fn rows(kind: SightingKind, matcher: &str, samples: &[Sample], inlier_px: f64) -> Vec<Row> {
    let row = |band: String, keep: &dyn Fn(&Sample) -> bool| {
        let errors: Vec<f64> = samples
            .iter()
            .filter(|s| s.kind == kind && keep(s))
            .map(Sample::error_px)
            .collect();
        let correct: Vec<f64> = errors
            .iter()
            .copied()
            .filter(|e| e.abs() <= inlier_px)
            .collect();
        Row {
            kind,
            matcher: matcher.to_string(),
            band,
            count: errors.len(),
            mean_all_px: Summary::of(&errors).map(|s| s.mean_px),
            mismatched: errors.len() - correct.len(),
            correct: Summary::of(&correct),
        }
    };
    let mut rows: Vec<Row> = (0..BANDS.len())
        .map(|band| row(band_label(band), &|s| band_of(s.true_px) == Some(band)))
        .collect();
    rows.push(row("all".to_string(), &|_| true));
    rows
}

/// The rows as a Markdown table.
pub fn markdown(rows: &[Row]) -> String {
    let mut out = String::from(
        "| sightings | matcher | true disparity, px | count | mismatched | mean error, all | correct: mean error, px (95 % CI) | median | std | p10 – p90 |\n|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for row in rows {
        let kind = match row.kind {
            SightingKind::Point => "points",
            SightingKind::SegmentEndpoint => "segment endpoints",
        };
        let mismatched = if row.count > 0 {
            format!(
                "{} ({:.1} %)",
                row.mismatched,
                100.0 * row.mismatched as f64 / row.count as f64
            )
        } else {
            String::new()
        };
        let all = row
            .mean_all_px
            .map(|m| format!("{m:+.3}"))
            .unwrap_or_default();
        let correct = match &row.correct {
            Some(s) => format!(
                "{:+.3} (± {:.3}) | {:+.3} | {:.3} | {:+.2} – {:+.2}",
                s.mean_px, s.mean_ci95_px, s.median_px, s.std_px, s.p10_px, s.p90_px
            ),
            None => " | | | ".to_string(),
        };
        out += &format!(
            "| {kind} | {} | {} | {} | {mismatched} | {all} | {correct} |\n",
            row.matcher, row.band, row.count
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_cover_every_disparity_once_with_readable_labels() {
        assert_eq!(band_of(0.5), Some(0));
        assert_eq!(band_of(9.999), Some(0));
        assert_eq!(band_of(10.0), Some(1));
        assert_eq!(band_of(59.9), Some(2));
        assert_eq!(band_of(250.0), Some(3));
        assert_eq!(band_of(f64::NAN), None);
        let labels: Vec<String> = (0..BANDS.len()).map(band_label).collect();
        assert_eq!(labels, ["< 10", "10–30", "30–60", "≥ 60"]);
    }

    #[test]
    fn a_summary_gives_the_mean_its_interval_and_the_quantiles() {
        assert_eq!(Summary::of(&[]), None);
        let errors: Vec<f64> = (0..=10).map(|i| f64::from(i) / 10.0 - 0.4).collect();
        let s = Summary::of(&errors).unwrap();
        assert_eq!(s.count, 11);
        assert!((s.mean_px - 0.1).abs() < 1e-12);
        assert!((s.median_px - 0.1).abs() < 1e-12);
        assert!((s.p10_px - (-0.3)).abs() < 1e-12);
        assert!((s.p90_px - 0.5).abs() < 1e-12);
        // Sample standard deviation of 0, 0.1, …, 1: sqrt(0.11).
        assert!((s.std_px - 0.11f64.sqrt()).abs() < 1e-12);
        assert!((s.mean_ci95_px - 1.96 * 0.11f64.sqrt() / 11f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn rows_split_by_kind_and_band_and_keep_mismatches_out_of_the_bias() {
        let sample = |kind, true_px: f64, error: f64| Sample {
            kind,
            measured_px: true_px + error,
            true_px,
        };
        let samples = [
            sample(SightingKind::Point, 5.0, -0.5),
            sample(SightingKind::Point, 6.0, -0.3),
            sample(SightingKind::Point, 7.0, 4.0),
            sample(SightingKind::Point, 40.0, 0.2),
            sample(SightingKind::SegmentEndpoint, 5.0, 0.1),
        ];
        let rows = rows(SightingKind::Point, "lbd", &samples, 2.0);
        assert_eq!(rows.len(), BANDS.len() + 1);
        let near = &rows[0];
        assert_eq!((near.count, near.mismatched), (3, 1));
        assert!((near.mean_all_px.unwrap() - 3.2 / 3.0).abs() < 1e-12);
        let correct = near.correct.unwrap();
        assert_eq!(correct.count, 2);
        assert!((correct.mean_px - (-0.4)).abs() < 1e-12);
        assert_eq!((rows[1].count, rows[1].correct), (0, None));
        assert_eq!(rows[2].correct.unwrap().count, 1);
        assert_eq!(rows[4].count, 4, "all bands, points only");
        let table = markdown(&rows);
        assert!(
            table.contains("| points | lbd | < 10 | 3 | 1 (33.3 %) | +1.067 | -0.400"),
            "{table}"
        );
        assert!(table.contains("| points | lbd | 10–30 | 0 |"), "{table}");
    }
}
