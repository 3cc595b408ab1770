//! Runs PL-StVO over a dataset folder (EuRoC, KITTI, or a generated sequence) and writes
//! the estimated trajectory in TUM format, the ground truth in the same frame, per-frame
//! statistics as CSV, and a summary with the lost-frame count and, given ground truth, the
//! RPE, ATE, drift and step ratio (definitions in `linetrack_odometry::metrics`).
#![warn(missing_docs)]

use anyhow::Context;
use clap::Parser;
use linetrack_datasets::StereoSequence;
use linetrack_odometry::{Features, FrameResult, Odometry, OdometryConfig, metrics, nees};
use linetrack_progress::Progress;
use linetrack_scene_render::IlluminationConfig;
use linetrack_trajectory::tum::{self, StampedPose};
use linetrack_vision::{DetectorKind, MatcherKind, perturb};
use nalgebra::{Isometry3, Matrix6};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

/// Command-line arguments.
#[derive(Debug, Clone, Parser)]
#[command(
    name = "linetrack-vo",
    version,
    about = "Stereo visual odometry with points and line segments over a dataset folder.",
    after_help = concat!("EXAMPLES:
    linetrack-vo ../shared/data/euroc/V1_01_easy_micro
    linetrack-vo out/sequences/default --matcher l1 --lines-only
    linetrack-vo out/sequences/normal-1 --gain-jumps 2   # the paper's illumination protocol, every 2 s

OUTPUT (<output>/): trajectory.txt (TUM: t tx ty tz qx qy qz qw, left camera, world = first
camera), groundtruth.txt (the same frame, when the dataset has ground truth), frames.csv (one
row per frame: lost, features, matches, inliers, iterations, conditioning, departure from the
prediction, milliseconds per step, whether `[lost] rescue_*` rescued it, the disparity offset
subtracted and its running estimate), metrics.json (the run's settings, lost frames,
disparity_offset_px (the rig's disparity offset at the end, given or self-calibrated:
`[disparity_offset]`) and, with ground truth, under `metrics`: poses, path_m, rpe_m, ate_m,
ate_aligned_m, drift_percent, step_ratio {steps, skipped, overall, median, p10, p90}
(estimated over true step length, steps under 1 cm left out), zero_motion_ate_m — the names
`linetrack run` writes to summary.json; and
step_nees {steps, mean, median, ratio}: each tracked step's error against the truth in units of
its covariance (NEES; consistent: mean 6, ratio 1)).\n\n", linetrack_progress::progress_help!("frames"), "\n\n", linetrack_vision::images_help!())
)]
pub struct Args {
    /// Dataset folder: EuRoC (holding mav0/), a KITTI odometry sequence, or linetrack-synth output.
    pub dataset: PathBuf,
    /// Odometry settings (TOML: the keys of the `[odometry]` section of
    /// configs/pipeline.toml; missing keys take their defaults). Flags below override it.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Line detector: lsd, fld or edgelines (default lsd, or the config's).
    #[arg(long)]
    pub detector: Option<DetectorKind>,
    /// Segment matcher, stereo and frame to frame: lbd or l1 (default lbd, or the config's).
    #[arg(long)]
    pub matcher: Option<MatcherKind>,
    /// Use line segments only (no ORB points).
    #[arg(long)]
    pub lines_only: bool,
    /// Simulated illumination changes: every this many seconds draw a gain α ~ U(0.5, 2.5)
    /// and a bias β ~ U(0, 20) and apply I' = clamp(α·I + β) to both images.
    #[arg(long)]
    pub gain_jumps: Option<f64>,
    /// Seed of the illumination draws.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Process at most this many frames.
    #[arg(long)]
    pub frames: Option<usize>,
    /// Segments closer than this to horizontal are not triangulated, degrees.
    /// (default 10, or the config's).
    #[arg(long)]
    pub min_line_angle_deg: Option<f64>,
    /// Output folder.
    #[arg(long, default_value = "out/vo")]
    pub output: PathBuf,
    /// No progress on stderr (by default a bar with the time left on a terminal, a line per
    /// tenth of the frames otherwise). Frames that cannot be loaded are still named.
    #[arg(long)]
    pub quiet: bool,
}

/// One row of frames.csv.
#[derive(Debug, Serialize)]
struct FrameRow {
    index: usize,
    timestamp_ns: u64,
    lost: u8,
    points_left: usize,
    points_right: usize,
    segments_left: usize,
    segments_right: usize,
    triangulated_points: usize,
    triangulated_segments: usize,
    observed_points: usize,
    observed_segments: usize,
    inlier_points: usize,
    inlier_segments: usize,
    iterations: usize,
    rms_px: f64,
    conditioning: f64,
    departure_m: f64,
    departure_deg: f64,
    detect_ms: f64,
    describe_ms: f64,
    stereo_ms: f64,
    f2f_ms: f64,
    motion_ms: f64,
    rescued: u8,
    disparity_offset_px: f64,
    disparity_offset_estimate_px: f64,
    reason: String,
}

impl FrameRow {
    fn new(index: usize, timestamp_ns: u64, result: &FrameResult) -> Self {
        let s = &result.stats;
        Self {
            index,
            timestamp_ns,
            lost: u8::from(result.lost),
            points_left: s.points[0],
            points_right: s.points[1],
            segments_left: s.segments[0],
            segments_right: s.segments[1],
            triangulated_points: s.triangulated[0],
            triangulated_segments: s.triangulated[1],
            observed_points: s.observations[0],
            observed_segments: s.observations[1],
            inlier_points: s.inliers[0],
            inlier_segments: s.inliers[1],
            iterations: s.iterations,
            rms_px: s.rms_px,
            conditioning: s.conditioning,
            departure_m: s.departure[0],
            departure_deg: s.departure[1],
            detect_ms: s.detect_ms,
            describe_ms: s.describe_ms,
            stereo_ms: s.stereo_ms,
            f2f_ms: s.frame_to_frame_ms,
            motion_ms: s.motion_ms,
            rescued: u8::from(s.rescued),
            disparity_offset_px: s.disparity_offset_px,
            disparity_offset_estimate_px: s.disparity_offset_estimate_px,
            reason: result.reason.clone().unwrap_or_default(),
        }
    }
}

/// metrics.json: what was run and how well it did.
#[derive(Debug, Serialize)]
struct RunRecord {
    dataset: String,
    detector: &'static str,
    matcher: &'static str,
    lines_only: bool,
    gain_jumps_s: Option<f64>,
    seed: u64,
    frames: usize,
    skipped: usize,
    lost: usize,
    tracking_ms_per_frame: f64,
    /// The disparity offset the last frame was triangulated with, pixels (`[disparity_offset]`).
    disparity_offset_px: f64,
    metrics: Option<metrics::Summary>,
    /// With ground truth: how honest the per-frame motion covariance is.
    step_nees: Option<StepNees>,
}

/// The normalised estimation error squared of each tracked frame's motion against its
/// covariance (`linetrack_odometry::nees`), over the frames that have both a covariance
/// and the truth of the step: a consistent covariance averages 6 (the bar: 3–12).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StepNees {
    /// Steps scored.
    pub steps: usize,
    /// Their mean NEES.
    pub mean: f64,
    /// Their median NEES (χ²₆'s is 5.35).
    pub median: f64,
    /// The mean over 6: 1 for a consistent covariance, above 1 overconfident.
    pub ratio: f64,
}

impl StepNees {
    /// The NEES of each `(estimated motion, true motion, covariance)`; `None` without any
    /// that can be scored.
    pub fn of(steps: &[(Isometry3<f64>, Isometry3<f64>, Matrix6<f64>)]) -> Option<Self> {
        let mut values: Vec<f64> = steps
            .iter()
            .filter_map(|(estimate, truth, covariance)| nees::nees(estimate, truth, covariance))
            .collect();
        if values.is_empty() {
            return None;
        }
        values.sort_by(f64::total_cmp);
        let mean = values.iter().sum::<f64>() / values.len() as f64;
        let middle = values.len() / 2;
        let median = if values.len().is_multiple_of(2) {
            0.5 * (values[middle - 1] + values[middle])
        } else {
            values[middle]
        };
        Some(Self {
            steps: values.len(),
            mean,
            median,
            ratio: mean / nees::MOTION_DOF,
        })
    }
}

/// Runs the odometry; returns the summary.
pub fn run(args: &Args) -> anyhow::Result<String> {
    let base = match &args.config {
        Some(path) => OdometryConfig::from_file(path).map_err(anyhow::Error::msg)?,
        None => OdometryConfig::default(),
    };
    let config = OdometryConfig {
        detector: args.detector.unwrap_or(base.detector),
        matcher: args.matcher.unwrap_or(base.matcher),
        features: if args.lines_only {
            Features::LinesOnly
        } else {
            base.features
        },
        min_line_angle_deg: args.min_line_angle_deg.unwrap_or(base.min_line_angle_deg),
        ..base
    };
    let sequence = StereoSequence::open(&args.dataset)
        .with_context(|| format!("cannot open dataset {}", args.dataset.display()))?;
    let (config_detector, config_matcher, config_features) =
        (config.detector, config.matcher, config.features);
    let mut odometry = Odometry::new(config, sequence.rig)?;
    let total = args.frames.unwrap_or(usize::MAX).min(sequence.frames.len());
    let start_ns = sequence.frames.first().map_or(0, |f| f.timestamp_ns);
    let name = sequence.name.clone();
    let illumination = IlluminationConfig {
        seed: args.seed,
        gain_jump_period_s: args.gain_jumps,
        ..IlluminationConfig::default()
    };
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("cannot create {}", args.output.display()))?;

    let frames_path = args.output.join("frames.csv");
    let mut csv = csv::Writer::from_path(&frames_path)
        .with_context(|| format!("cannot write {}", frames_path.display()))?;
    let (mut estimate, mut truth, mut stamps) = (Vec::new(), Vec::new(), Vec::new());
    // Per frame: the covariance of its motion, when it was measured.
    let mut covariances: Vec<Option<Matrix6<f64>>> = Vec::new();
    let (mut lost, mut skipped, mut busy_ms) = (0usize, Vec::new(), 0.0);
    let mut disparity_offset_px = 0.0;
    let started = Instant::now();
    let progress = Progress::new(&format!("{name} frames"), total as u64, args.quiet);
    let mut stream = sequence.into_stream(0, 4);
    for item in stream.by_ref().take(total) {
        let frame = match item {
            Ok(frame) => frame,
            Err(error) => {
                progress.warn(&error.to_string());
                skipped.push(error.index);
                progress.inc(1);
                continue;
            }
        };
        let t = (frame.timestamp_ns - start_ns) as f64 * 1e-9;
        let (left, right) = if illumination.gain_jump_period_s.is_some() {
            let il = illumination.at(t, 0);
            (
                perturb(&frame.left, il.gain[0], il.bias[0])?,
                perturb(&frame.right, il.gain[1], il.bias[1])?,
            )
        } else {
            (frame.left, frame.right)
        };
        let tick = Instant::now();
        let result = odometry.track(&left, &right)?;
        busy_ms += tick.elapsed().as_secs_f64() * 1e3;
        lost += usize::from(result.lost);
        disparity_offset_px = result.stats.disparity_offset_px;
        csv.serialize(FrameRow::new(frame.index, frame.timestamp_ns, &result))
            .with_context(|| format!("cannot write {}", frames_path.display()))?;
        // The step from the last frame tracked (the estimate before this one).
        covariances.push(result.step_covariance);
        estimate.push(result.pose);
        stamps.push(frame.timestamp_ns as f64 * 1e-9);
        truth.push(frame.pose);
        progress.step(format!("{lost} lost"));
        progress.inc(1);
    }
    progress.finish();
    csv.flush()
        .with_context(|| format!("cannot write {}", frames_path.display()))?;
    let stamped = |poses: &[Isometry3<f64>]| -> Vec<StampedPose> {
        stamps
            .iter()
            .zip(poses)
            .map(|(t, p)| StampedPose {
                timestamp_s: *t,
                pose: *p,
            })
            .collect()
    };
    tum::write(&args.output.join("trajectory.txt"), &stamped(&estimate))?;

    let mut record = RunRecord {
        dataset: args.dataset.display().to_string(),
        detector: config_detector.name(),
        matcher: config_matcher.name(),
        lines_only: config_features == Features::LinesOnly,
        gain_jumps_s: args.gain_jumps,
        seed: args.seed,
        frames: estimate.len(),
        skipped: skipped.len(),
        lost,
        tracking_ms_per_frame: busy_ms / estimate.len().max(1) as f64,
        disparity_offset_px,
        metrics: None,
        step_nees: None,
    };
    let mut summary = format!(
        "{name}: {} frames ({} skipped), {lost} lost, {:.1} ms/frame tracking, {:.1} s in all",
        estimate.len(),
        skipped.len(),
        busy_ms / estimate.len().max(1) as f64,
        started.elapsed().as_secs_f64()
    );
    if disparity_offset_px != 0.0 {
        write!(summary, ", disparity offset {disparity_offset_px:+.3} px")?;
    }
    if let Some(truth) = truth
        .iter()
        .copied()
        .collect::<Option<Vec<_>>>()
        .filter(|t| !t.is_empty())
    {
        let first = truth[0].inverse();
        let truth: Vec<Isometry3<f64>> = truth.iter().map(|p| first * p).collect();
        tum::write(&args.output.join("groundtruth.txt"), &stamped(&truth))?;
        let m = metrics::Summary::new(&estimate, &truth);
        let fmt =
            |v: Option<f64>, unit: &str| v.map_or("n/a".to_string(), |v| format!("{v:.4}{unit}"));
        let step_ratio = m.step_ratio.map_or("n/a".to_string(), |r| {
            format!(
                "{:.3} (median {:.3}, p10–p90 {:.3}–{:.3}, {} steps)",
                r.overall, r.median, r.p10, r.p90, r.steps
            )
        });
        write!(
            summary,
            " | path {:.2} m, RPE {} per frame, ATE {} (SE(3)-aligned {}), drift {}, \
             step ratio {step_ratio}; staying put would score ATE {}",
            m.path_m,
            fmt(m.rpe_m, " m"),
            fmt(m.ate_m, " m"),
            fmt(m.ate_aligned_m, " m"),
            fmt(m.drift_percent, " %"),
            fmt(m.zero_motion_ate_m, " m"),
        )?;
        record.metrics = Some(m);
        // p_curr = motion · p_prev: the motion is pose_curr⁻¹ · pose_prev.
        let steps: Vec<_> = (1..estimate.len())
            .filter_map(|k| {
                let covariance = covariances[k]?;
                let motion = |poses: &[Isometry3<f64>]| poses[k].inverse() * poses[k - 1];
                Some((motion(&estimate), motion(&truth), covariance))
            })
            .collect();
        record.step_nees = StepNees::of(&steps);
        if let Some(n) = record.step_nees {
            write!(
                summary,
                "; step NEES mean {:.2} (median {:.2}, {:.2}× its 6 dof, {} steps)",
                n.mean, n.median, n.ratio, n.steps
            )?;
        }
    }
    let json_path = args.output.join("metrics.json");
    std::fs::write(&json_path, serde_json::to_string_pretty(&record)?)
        .with_context(|| format!("cannot write {}", json_path.display()))?;
    write!(summary, " | wrote {}", args.output.display())?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, Vector6};

    #[test]
    fn step_nees_averages_the_steps_that_have_a_positive_definite_covariance() {
        let truth = Isometry3::translation(0.0, 0.0, -0.1);
        let sigma = 0.01;
        let cov = Matrix6::from_diagonal(&Vector6::repeat(sigma * sigma));
        // Errors of 1σ, 2σ and 3σ along x: NEES 1, 4, 9.
        let off = |k: f64| {
            Isometry3::from_parts(Translation3::new(-k * sigma, 0.0, 0.0), Default::default())
                * truth
        };
        let steps = [
            (off(1.0), truth, cov),
            (off(2.0), truth, cov),
            (off(3.0), truth, cov),
            (off(5.0), truth, Matrix6::zeros()),
        ];
        let n = StepNees::of(&steps).unwrap_or_else(|| panic!("no figure"));
        assert_eq!(n.steps, 3);
        assert!((n.mean - 14.0 / 3.0).abs() < 1e-9, "{n:?}");
        assert!((n.median - 4.0).abs() < 1e-9, "{n:?}");
        assert!((n.ratio - 14.0 / 18.0).abs() < 1e-9, "{n:?}");
        assert_eq!(StepNees::of(&steps[3..]), None);
    }
}
