//! End to end on generated sequences with exact ground truth: accuracy under a stated
//! bound, the repetitive-structure failure that once wrecked the trajectory, and recovery
//! after frames that cannot be tracked.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure here is a test failure

use linetrack_odometry::{Features, Odometry, OdometryConfig, metrics};
use linetrack_scene_render::{Preset, SequenceRenderer};
use linetrack_vision::{GrayImage, MatcherKind};
use nalgebra::Isometry3;
use std::ops::Range;

/// One run: estimated and true poses, and which frames were lost.
struct Run {
    estimate: Vec<Isometry3<f64>>,
    truth: Vec<Isometry3<f64>>,
    lost: Vec<bool>,
}

impl Run {
    /// Largest error of a frame-to-frame translation, metres.
    fn worst_step_error(&self) -> f64 {
        (1..self.estimate.len())
            .map(|k| {
                let truth = self.truth[k - 1].inverse() * self.truth[k];
                let estimate = self.estimate[k - 1].inverse() * self.estimate[k];
                (truth.inverse() * estimate).translation.vector.norm()
            })
            .fold(0.0, f64::max)
    }
}

/// Runs the odometry over `frames` of preset `normal` (a 200-frame sequence of `seed`),
/// replacing the frames in `blank` by black images.
fn run(config: OdometryConfig, seed: u64, frames: Range<usize>, blank: &[usize]) -> Run {
    let renderer = SequenceRenderer::new(Preset::Normal.config(seed, 200));
    let rig = renderer.config.rig;
    let mut vo = Odometry::new(config, rig).unwrap();
    let mut out = Run {
        estimate: Vec::new(),
        truth: Vec::new(),
        lost: Vec::new(),
    };
    for k in frames {
        let frame = renderer.render(k);
        let image = |pixels: &[u8], name: &str| {
            let black = vec![0u8; pixels.len()];
            let pixels = if blank.contains(&k) {
                &black[..]
            } else {
                pixels
            };
            GrayImage::from_pixels(frame.left.width, frame.left.height, pixels, name).unwrap()
        };
        let result = vo
            .track(
                &image(&frame.left.pixels, "left"),
                &image(&frame.right.pixels, "right"),
            )
            .unwrap();
        out.estimate.push(result.pose);
        out.truth.push(frame.world_from_left);
        out.lost.push(result.lost);
    }
    out
}

#[test]
fn a_generated_hand_held_sequence_is_tracked_to_a_centimetre() {
    // Measured (LSD + LBD, points and lines, frames 0–29 of seed 3, 0.75 m of path):
    // ATE 4.0 mm, RPE 1.4 mm per frame, no frame lost (9.0 mm before the landmarks).
    let run = run(OdometryConfig::default(), 3, 0..30, &[]);
    assert!(run.lost.iter().all(|l| !l), "lost frames: {:?}", run.lost);
    let ate = metrics::ate_rmse(&run.estimate, &run.truth).unwrap();
    let rpe = metrics::rpe_translation_rmse(&run.estimate, &run.truth, 1).unwrap();
    eprintln!("ATE {ate:.4} m, RPE {rpe:.4} m");
    assert!(ate < 0.008 && rpe < 0.004, "ATE {ate} m, RPE {rpe} m");
    // The path is under a metre: a drift percentage would mean nothing and is not given.
    assert!(metrics::drift_percent(&run.estimate, &run.truth).is_none());
}

/// Frames 150–170 of `normal`, seed 1: the camera passes the striped radiator, where stereo
/// matches fall one stripe period off (7.5 m instead of 2.7 m) and agree with each other.
/// Gauss–Newton alone followed them to steps of 79–94 mm against a true 31 mm. Measured
/// now (worst frame-to-frame translation error, ATE): LBD points and lines 4.3 / 3.3 mm,
/// LBD lines only 5.8 / 3.6 mm, ℓ1 lines only 5.3 / 7.2 mm. Without the robust start and
/// the look-alike check (PL-StVO's scheme), LBD with points and lines alone gets 89 mm and
/// 565 mm.
#[test]
fn repetitive_stripes_do_not_pull_the_motion_away() {
    for (matcher, features) in [
        (MatcherKind::Lbd, Features::PointsAndLines),
        (MatcherKind::Lbd, Features::LinesOnly),
        (MatcherKind::L1, Features::LinesOnly),
    ] {
        let config = OdometryConfig {
            matcher,
            features,
            ..OdometryConfig::default()
        };
        let run = run(config, 1, 150..171, &[]);
        let lost = run.lost.iter().filter(|l| **l).count();
        let worst = run.worst_step_error();
        let ate = metrics::ate_rmse(&run.estimate, &run.truth).unwrap();
        eprintln!(
            "{matcher:?} {features:?}: worst step error {:.1} mm, ATE {:.1} mm, {lost} lost",
            worst * 1e3,
            ate * 1e3
        );
        assert!(
            lost == 0 && worst < 0.015 && ate < 0.025,
            "{matcher:?} {features:?}: worst step error {worst} m, ATE {ate} m, {lost} lost"
        );
    }
}

#[test]
fn blank_frames_are_reported_lost_and_tracking_resumes() {
    let run = run(OdometryConfig::default(), 3, 0..30, &[12]);
    // Frame 12 has no features; frame 13's reference (frame 12) has none either.
    let lost_frames: Vec<usize> = run
        .lost
        .iter()
        .enumerate()
        .filter(|(_, l)| **l)
        .map(|(k, _)| k)
        .collect();
    assert_eq!(lost_frames, vec![12, 13]);
    // After the gap, frame-to-frame motion is right again (RPE over frames 14..).
    let rpe_after =
        metrics::rpe_translation_rmse(&run.estimate[14..], &run.truth[14..], 1).unwrap();
    assert!(rpe_after < 0.005, "RPE after recovery {rpe_after}");
    // And the whole trajectory has not diverged: the two predicted frames cost little.
    let ate = metrics::ate_rmse(&run.estimate, &run.truth).unwrap();
    // Measured: 4.9 mm.
    eprintln!("ATE with two lost frames: {ate:.4} m");
    assert!(ate < 0.02, "ATE {ate} m");
}

/// Frames `range` of `normal` (`seed`), rendered once, for runs under several configs.
fn rendered(seed: u64, range: Range<usize>) -> (linetrack_geometry::StereoRig, Vec<Frame>) {
    let renderer = SequenceRenderer::new(Preset::Normal.config(seed, 200));
    let frames = range
        .map(|k| {
            let frame = renderer.render(k);
            let image = |pixels: &[u8], name: &str| {
                GrayImage::from_pixels(frame.left.width, frame.left.height, pixels, name).unwrap()
            };
            Frame {
                left: image(&frame.left.pixels, "left"),
                right: image(&frame.right.pixels, "right"),
                truth: frame.world_from_left,
            }
        })
        .collect();
    (renderer.config.rig, frames)
}

struct Frame {
    left: GrayImage,
    right: GrayImage,
    truth: Isometry3<f64>,
}

/// ATE of the odometry under `config` over `frames`, and how many frames it lost.
fn ate_of(
    config: OdometryConfig,
    rig: linetrack_geometry::StereoRig,
    frames: &[Frame],
) -> (f64, usize) {
    let mut vo = Odometry::new(config, rig).unwrap();
    let mut estimate = Vec::new();
    let mut lost = 0;
    for frame in frames {
        let result = vo.track(&frame.left, &frame.right).unwrap();
        estimate.push(result.pose);
        lost += usize::from(result.lost);
    }
    let truth: Vec<_> = frames.iter().map(|f| f.truth).collect();
    (metrics::ate_rmse(&estimate, &truth).unwrap(), lost)
}

/// Following features as landmarks (positions fused over their sightings) against
/// re-triangulating every frame (PL-StVO), same frames, same front end. Measured over the
/// first 100 frames of seed 1 (LSD + LBD, points and lines): ATE 3.8 mm with landmarks,
/// 14.0 mm without.
#[test]
fn landmarks_drift_less_than_chained_frame_to_frame_motions() {
    let (rig, frames) = rendered(1, 0..100);
    let (with, lost_with) = ate_of(OdometryConfig::default(), rig, &frames);
    let chained = OdometryConfig {
        landmarks: false,
        ..OdometryConfig::default()
    };
    let (without, lost_without) = ate_of(chained, rig, &frames);
    eprintln!("ATE with landmarks {with:.4} m, without {without:.4} m");
    assert_eq!((lost_with, lost_without), (0, 0));
    assert!(with < 0.75 * without, "with {with} m, without {without} m");
}

/// A scene with its light dimmed to 15 % (grey levels 0–38): the detectors threshold
/// absolute gradients, so without the contrast stretch most segments vanish. Measured on
/// frame 0 of seed 1 (left segments, ORB points): 100 and 478 as rendered, 72 and 112
/// dimmed and stretched, 2 and 0 dimmed.
#[test]
fn a_dimmed_scene_keeps_its_segments() {
    let (rig, frames) = rendered(1, 0..1);
    let dim = |image: &GrayImage| linetrack_vision::perturb(image, 0.15, 0.0).unwrap();
    let (left, right) = (dim(&frames[0].left), dim(&frames[0].right));
    let segments = |max_contrast_gain: f64, left: &GrayImage, right: &GrayImage| {
        let config = OdometryConfig {
            max_contrast_gain,
            ..OdometryConfig::default()
        };
        let mut vo = Odometry::new(config, rig).unwrap();
        let stats = vo.track(left, right).unwrap().stats;
        (stats.segments[0], stats.points[0])
    };
    let bright = segments(4.0, &frames[0].left, &frames[0].right);
    let stretched = segments(4.0, &left, &right);
    let raw = segments(1.0, &left, &right);
    eprintln!(
        "segments, points: bright {bright:?}, dimmed and stretched {stretched:?}, dimmed {raw:?}"
    );
    assert!(
        stretched.0 as f64 >= 0.7 * bright.0 as f64 && stretched.0 >= 2 * raw.0,
        "bright {bright:?}, stretched {stretched:?}, dimmed {raw:?}"
    );
}
