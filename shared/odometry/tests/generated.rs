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
    // ATE 9.0 mm, RPE 1.5 mm per frame, no frame lost.
    let run = run(OdometryConfig::default(), 3, 0..30, &[]);
    assert!(run.lost.iter().all(|l| !l), "lost frames: {:?}", run.lost);
    let ate = metrics::ate_rmse(&run.estimate, &run.truth).unwrap();
    let rpe = metrics::rpe_translation_rmse(&run.estimate, &run.truth, 1).unwrap();
    eprintln!("ATE {ate:.4} m, RPE {rpe:.4} m");
    assert!(ate < 0.015 && rpe < 0.005, "ATE {ate} m, RPE {rpe} m");
    // The path is under a metre: a drift percentage would mean nothing and is not given.
    assert!(metrics::drift_percent(&run.estimate, &run.truth).is_none());
}

/// Frames 150–170 of `normal`, seed 1: the camera passes the striped radiator, where stereo
/// matches fall one stripe period off (7.5 m instead of 2.7 m) and agree with each other.
/// Gauss–Newton alone followed them to steps of 79–94 mm against a true 31 mm. Measured
/// now (worst frame-to-frame translation error, ATE): LBD points and lines 6.7 / 9.2 mm,
/// LBD lines only 8.0 / 17.7 mm, ℓ1 lines only 2.2 / 8.8 mm. Without the robust start and
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
    // Measured: 6.8 mm.
    eprintln!("ATE with two lost frames: {ate:.4} m");
    assert!(ate < 0.02, "ATE {ate} m");
}
