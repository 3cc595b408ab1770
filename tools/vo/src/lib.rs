//! Runs PL-StVO over a dataset folder (EuRoC, KITTI, or a generated sequence) and writes
//! the estimated trajectory in TUM format, the ground truth in the same frame, per-frame
//! statistics as CSV, and a summary with the lost-frame count and, given ground truth, the
//! RPE, ATE and drift (definitions in `linetrack_odometry::metrics`).
#![warn(missing_docs)]

use anyhow::Context;
use clap::Parser;
use linetrack_datasets::StereoSequence;
use linetrack_datasets::tum::{self, StampedPose};
use linetrack_odometry::{Features, Odometry, OdometryConfig, metrics};
use linetrack_scene_render::IlluminationConfig;
use linetrack_vision::{DetectorKind, MatcherKind, perturb};
use nalgebra::Isometry3;
use std::fmt::Write as _;
use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::Instant;

/// Command-line arguments.
#[derive(Debug, Clone, Parser)]
#[command(
    name = "linetrack-vo",
    version,
    about = "Stereo visual odometry with points and line segments over a dataset folder.",
    after_help = "EXAMPLES:
    linetrack-vo ../shared/data/euroc/V1_01_easy_micro
    linetrack-vo out/sequences/default --matcher l1 --lines-only
    linetrack-vo out/sequences/normal-1 --gain-jumps 2   # the paper's illumination protocol, every 2 s

OUTPUT (<output>/): trajectory.txt (TUM: t tx ty tz qx qy qz qw, left camera, world = first
camera), groundtruth.txt (the same frame, when the dataset has ground truth), frames.csv (one
row per frame: lost, features, matches, inliers, iterations, milliseconds per step)."
)]
pub struct Args {
    /// Dataset folder: EuRoC (holding mav0/), a KITTI odometry sequence, or linetrack-synth output.
    pub dataset: PathBuf,
    /// Line detector.
    #[arg(long, default_value = "lsd")]
    pub detector: DetectorKind,
    /// Segment matcher (stereo and frame to frame).
    #[arg(long, default_value = "lbd")]
    pub matcher: MatcherKind,
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
    #[arg(long, default_value_t = 10.0)]
    pub min_line_angle_deg: f64,
    /// Output folder.
    #[arg(long, default_value = "out/vo")]
    pub output: PathBuf,
}

/// Runs the odometry; returns the summary.
pub fn run(args: &Args) -> anyhow::Result<String> {
    let sequence = StereoSequence::open(&args.dataset)
        .with_context(|| format!("cannot open dataset {}", args.dataset.display()))?;
    let features = if args.lines_only {
        Features::LinesOnly
    } else {
        Features::PointsAndLines
    };
    let config = OdometryConfig {
        detector: args.detector,
        matcher: args.matcher,
        features,
        min_line_angle_deg: args.min_line_angle_deg,
        ..OdometryConfig::default()
    };
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

    let mut csv = String::from(
        "index,timestamp_ns,lost,points_left,points_right,segments_left,segments_right,triangulated_points,triangulated_segments,observed_points,observed_segments,inlier_points,inlier_segments,iterations,rms_px,detect_ms,describe_ms,stereo_ms,f2f_ms,motion_ms,reason\n",
    );
    let (mut estimate, mut truth, mut stamps) = (Vec::new(), Vec::new(), Vec::new());
    let (mut lost, mut skipped, mut busy_ms) = (0usize, Vec::new(), 0.0);
    let started = Instant::now();
    let live = std::io::stderr().is_terminal();
    let mut stream = sequence.into_stream(0, 4);
    for item in stream.by_ref().take(total) {
        let frame = match item {
            Ok(frame) => frame,
            Err(error) => {
                eprintln!("{error}");
                skipped.push(error.index);
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
        let s = &result.stats;
        writeln!(
            csv,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{:.3},{:.2},{:.2},{:.2},{:.2},{:.2},{}",
            frame.index,
            frame.timestamp_ns,
            u8::from(result.lost),
            s.points[0],
            s.points[1],
            s.segments[0],
            s.segments[1],
            s.triangulated[0],
            s.triangulated[1],
            s.observations[0],
            s.observations[1],
            s.inliers[0],
            s.inliers[1],
            s.iterations,
            s.rms_px,
            s.ms[0],
            s.ms[1],
            s.ms[2],
            s.ms[3],
            s.ms[4],
            result.reason.unwrap_or_default().replace(',', ";")
        )?;
        estimate.push(result.pose);
        stamps.push(frame.timestamp_ns as f64 * 1e-9);
        truth.push(frame.pose);
        let done = estimate.len() + skipped.len();
        if live {
            eprint!("\rframe {done}/{total}, {lost} lost");
        } else if done % 50 == 0 {
            eprintln!("frame {done}/{total}, {lost} lost");
        }
    }
    if live {
        eprintln!();
    }
    std::fs::write(args.output.join("frames.csv"), &csv)
        .with_context(|| format!("cannot write {}", args.output.display()))?;
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

    let mut summary = format!(
        "{name}: {} frames ({} skipped), {lost} lost, {:.1} ms/frame tracking, {:.1} s in all",
        estimate.len(),
        skipped.len(),
        busy_ms / estimate.len().max(1) as f64,
        started.elapsed().as_secs_f64()
    );
    if let Some(truth) = truth
        .iter()
        .copied()
        .collect::<Option<Vec<_>>>()
        .filter(|t| !t.is_empty())
    {
        let first = truth[0].inverse();
        let truth: Vec<Isometry3<f64>> = truth.iter().map(|p| first * p).collect();
        tum::write(&args.output.join("groundtruth.txt"), &stamped(&truth))?;
        let fmt =
            |v: Option<f64>, unit: &str| v.map_or("n/a".to_string(), |v| format!("{v:.4}{unit}"));
        write!(
            summary,
            " | RPE {} per frame, ATE {}, drift {}",
            fmt(metrics::rpe_translation_rmse(&estimate, &truth, 1), " m"),
            fmt(metrics::ate_rmse(&estimate, &truth), " m"),
            fmt(metrics::drift_percent(&estimate, &truth), " %")
        )?;
    }
    write!(summary, " | wrote {}", args.output.display())?;
    Ok(summary)
}
