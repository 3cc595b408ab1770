//! End to end on generated sequences with exact ground truth: accuracy under a stated
//! bound, the repetitive-structure failure that once wrecked the trajectory, and recovery
//! after frames that cannot be tracked.
//!
//! Rendering is most of these tests' time: each renders its frames once and runs every
//! configuration it compares over them.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failure here is a test failure

use linetrack_geometry::StereoRig;
use linetrack_odometry::{Features, LinePrediction, Odometry, OdometryConfig, metrics};
use linetrack_scene_render::{Preset, SequenceRenderer};
use linetrack_vision::{DetectorKind, GrayImage, MatcherKind};
use nalgebra::Isometry3;
use std::ops::Range;

/// Length of the generated sequence the frames are taken from.
const SEQUENCE_FRAMES: usize = 200;

/// One stereo frame as the odometry gets it, and the true pose of its left camera.
struct Frame {
    left: GrayImage,
    right: GrayImage,
    truth: Isometry3<f64>,
}

/// Frames `range` of preset `normal` (a 200-frame sequence of `seed`), rendered once for
/// runs under several configurations; the frames in `blank` are black images (and are not
/// rendered).
fn rendered(seed: u64, range: Range<usize>, blank: &[usize]) -> (StereoRig, Vec<Frame>) {
    let renderer = SequenceRenderer::new(Preset::Normal.config(seed, SEQUENCE_FRAMES));
    let rig = renderer.config.rig;
    let (width, height) = (rig.width_px as usize, rig.height_px as usize);
    let image =
        |pixels: &[u8], name: &str| GrayImage::from_pixels(width, height, pixels, name).unwrap();
    let frames = range
        .map(|k| {
            let (left, right) = if blank.contains(&k) {
                let black = vec![0u8; width * height];
                (image(&black, "left"), image(&black, "right"))
            } else {
                let frame = renderer.render(k);
                (
                    image(&frame.left.pixels, "left"),
                    image(&frame.right.pixels, "right"),
                )
            };
            Frame {
                left,
                right,
                truth: renderer.render_pose(k),
            }
        })
        .collect();
    (rig, frames)
}

/// One run: estimated and true poses, and which frames were lost.
struct Run {
    estimate: Vec<Isometry3<f64>>,
    truth: Vec<Isometry3<f64>>,
    lost: Vec<bool>,
    /// Which frames `lost.rescue_*` rescued.
    rescued: Vec<bool>,
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

    /// ATE, metres.
    fn ate(&self) -> f64 {
        metrics::ate_rmse(&self.estimate, &self.truth).unwrap()
    }

    /// The lost frames, counted from the first frame of the run.
    fn lost_frames(&self) -> Vec<usize> {
        (0..self.lost.len()).filter(|k| self.lost[*k]).collect()
    }
}

/// Runs the odometry under `config` over `frames`.
fn run(config: OdometryConfig, rig: StereoRig, frames: &[Frame]) -> Run {
    let mut vo = Odometry::new(config, rig).unwrap();
    let mut out = Run {
        estimate: Vec::new(),
        truth: Vec::new(),
        lost: Vec::new(),
        rescued: Vec::new(),
    };
    for frame in frames {
        let result = vo.track(&frame.left, &frame.right).unwrap();
        out.estimate.push(result.pose);
        out.truth.push(frame.truth);
        out.lost.push(result.lost);
        out.rescued.push(result.stats.rescued);
    }
    out
}

#[test]
fn a_generated_hand_held_sequence_is_tracked_to_a_centimetre() {
    // Measured (LSD + LBD, points and lines, frames 0–19 of seed 3, 0.21 m of path):
    // ATE 3.5 mm, RPE 0.84 mm per frame, no frame lost (11.3 mm without the landmarks).
    let (rig, frames) = rendered(3, 0..20, &[]);
    let run = run(OdometryConfig::default(), rig, &frames);
    assert!(run.lost.iter().all(|l| !l), "lost frames: {:?}", run.lost);
    let ate = run.ate();
    let rpe = metrics::rpe_translation_rmse(&run.estimate, &run.truth, 1).unwrap();
    eprintln!("ATE {ate:.4} m, RPE {rpe:.4} m");
    assert!(ate < 0.008 && rpe < 0.004, "ATE {ate} m, RPE {rpe} m");
    // The path is under a metre: a drift percentage would mean nothing and is not given.
    assert!(metrics::drift_percent(&run.estimate, &run.truth).is_none());
}

#[test]
fn reprojecting_into_the_right_image_too_tracks_as_well() {
    // Measured on frames 0–19 of seed 3: ATE 2.3 mm with the right image, 3.5 mm without.
    // The option changes the estimate (its rows are used) and stays within the same bar.
    let (rig, frames) = rendered(3, 0..20, &[]);
    let mut config = OdometryConfig::default();
    config.motion.stereo_reprojection = true;
    let on = run(config, rig, &frames);
    let off = run(OdometryConfig::default(), rig, &frames);
    assert!(on.lost.iter().all(|l| !l), "lost frames: {:?}", on.lost);
    let (ate_on, ate_off) = (on.ate(), off.ate());
    eprintln!("ATE with the right image {ate_on:.4} m, without {ate_off:.4} m");
    assert!(ate_on < 0.008, "ATE {ate_on} m");
    assert!(
        on.estimate
            .iter()
            .zip(&off.estimate)
            .any(|(a, b)| (a.translation.vector - b.translation.vector).norm() > 1e-9),
        "the option changed no pose: its rows were not used"
    );
}

#[test]
fn predicting_segments_from_the_points_first_tracks_as_well() {
    // The segments are matched where the frame's own point motion puts them, not where the
    // last motion does: a different prediction, so different matches, within the same bar.
    let (rig, frames) = rendered(3, 0..20, &[]);
    let config = OdometryConfig {
        line_prediction: LinePrediction::PointsFirst,
        ..OdometryConfig::default()
    };
    let points_first = run(config, rig, &frames);
    let constant_velocity = run(OdometryConfig::default(), rig, &frames);
    assert!(
        points_first.lost.iter().all(|l| !l),
        "lost frames: {:?}",
        points_first.lost
    );
    let (ate, ate_cv) = (points_first.ate(), constant_velocity.ate());
    eprintln!("ATE points first {ate:.4} m, constant velocity {ate_cv:.4} m");
    assert!(ate < 0.008, "ATE {ate} m");
    assert!(
        points_first
            .estimate
            .iter()
            .zip(&constant_velocity.estimate)
            .any(|(a, b)| (a.translation.vector - b.translation.vector).norm() > 1e-9),
        "the option changed no pose: the points' motion predicted nothing"
    );
}

#[test]
fn the_rescue_leaves_frames_that_are_not_lost_as_they_were() {
    // Lines only, ℓ1: no frame of these is lost, so the rescue (a wider predicted window,
    // then fewer inliers) must not act on any, and every pose must be bit for bit the same.
    let (rig, frames) = rendered(3, 0..20, &[]);
    let lines_only = OdometryConfig {
        features: Features::LinesOnly,
        matcher: MatcherKind::L1,
        ..OdometryConfig::default()
    };
    let mut rescuing = lines_only.clone();
    rescuing.lost.rescue_window_px = 30.0;
    rescuing.lost.rescue_min_inliers = 4;
    let plain = run(lines_only, rig, &frames);
    let rescued = run(rescuing, rig, &frames);
    assert!(
        plain.lost.iter().all(|l| !l),
        "lost frames: {:?}",
        plain.lost
    );
    assert!(rescued.rescued.iter().all(|r| !r), "{:?}", rescued.rescued);
    assert_eq!(plain.estimate, rescued.estimate);
}

/// Frames 154–163 of `normal`, seed 1: the camera comes up to the striped radiator, where
/// stereo matches fall one stripe period off (7.5 m instead of 2.7 m) and agree with each
/// other. Gauss–Newton alone followed them to steps of 79–94 mm against a true 31 mm.
/// Measured now (worst frame-to-frame translation error, ATE): LBD points and lines 4.5 /
/// 4.8 mm, LBD lines only 5.3 / 4.8 mm, ℓ1 lines only 4.5 / 8.1 mm. Without the robust
/// start and the look-alike check (PL-StVO's scheme), LBD with points and lines gets
/// 91 mm and 268 mm: run here too, so the frames are known to hold the trap.
#[test]
fn repetitive_stripes_do_not_pull_the_motion_away() {
    // Largest frame-to-frame translation error and ATE allowed, metres.
    const MAX_STEP_ERROR_M: f64 = 0.015;
    const MAX_ATE_M: f64 = 0.025;
    let (rig, frames) = rendered(1, 154..164, &[]);
    let figures = |config: OdometryConfig| {
        let run = run(config, rig, &frames);
        (run.worst_step_error(), run.ate(), run.lost_frames().len())
    };
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
        let (worst, ate, lost) = figures(config);
        eprintln!(
            "{matcher:?} {features:?}: worst step error {:.1} mm, ATE {:.1} mm, {lost} lost",
            worst * 1e3,
            ate * 1e3
        );
        assert!(
            lost == 0 && worst < MAX_STEP_ERROR_M && ate < MAX_ATE_M,
            "{matcher:?} {features:?}: worst step error {worst} m, ATE {ate} m, {lost} lost"
        );
    }
    let mut pl_stvo = OdometryConfig {
        reject_look_alikes: false,
        ..OdometryConfig::default()
    };
    pl_stvo.motion.ransac_draws = 0;
    let (worst, ate, lost) = figures(pl_stvo);
    eprintln!(
        "PL-StVO's scheme: worst step error {:.1} mm, ATE {:.1} mm, {lost} lost",
        worst * 1e3,
        ate * 1e3
    );
    assert!(
        worst > MAX_STEP_ERROR_M && ate > MAX_ATE_M,
        "the frames no longer pull PL-StVO's scheme away: worst step error {worst} m, ATE {ate} m"
    );
}

#[test]
fn blank_frames_are_reported_lost_and_tracking_resumes() {
    let (rig, frames) = rendered(3, 0..20, &[10]);
    let run = run(OdometryConfig::default(), rig, &frames);
    // Frame 10 has no features; frame 11's reference (frame 10) has none either.
    assert_eq!(run.lost_frames(), vec![10, 11]);
    // After the gap, frame-to-frame motion is right again (RPE over frames 12..).
    let rpe_after =
        metrics::rpe_translation_rmse(&run.estimate[12..], &run.truth[12..], 1).unwrap();
    assert!(rpe_after < 0.005, "RPE after recovery {rpe_after}");
    // And the whole trajectory has not diverged: the two predicted frames cost little.
    let ate = run.ate();
    // Measured: RPE after recovery 0.65 mm, ATE 3.4 mm.
    eprintln!("RPE after recovery {rpe_after:.4} m, ATE with two lost frames: {ate:.4} m");
    assert!(ate < 0.02, "ATE {ate} m");
}

/// Following features as landmarks (positions fused over their sightings) against
/// re-triangulating every frame (PL-StVO), same frames, same front end: FLD, not the
/// default LSD, which is not what is compared here and takes nearly twice its time per
/// frame (the default front end with landmarks is held to its bound in the hand-held test,
/// which it misses without them). Measured over the first 20 frames of seed 1 (FLD + LBD,
/// points and lines): ATE 1.6 mm with landmarks, 4.4 mm without; LSD gives 2.0 and 4.9 mm,
/// and over the first 100 frames 2.4 and 14.8 mm.
#[test]
fn landmarks_drift_less_than_chained_frame_to_frame_motions() {
    let (rig, frames) = rendered(1, 0..20, &[]);
    let landmarks = OdometryConfig {
        detector: DetectorKind::Fld,
        ..OdometryConfig::default()
    };
    let chained = OdometryConfig {
        landmarks: false,
        ..landmarks.clone()
    };
    // The two runs are independent: one on a thread of its own.
    let (with, without) = std::thread::scope(|scope| {
        let without = scope.spawn(|| run(chained, rig, &frames));
        let with = run(landmarks, rig, &frames);
        (with, without.join().unwrap())
    });
    let lost = (with.lost_frames(), without.lost_frames());
    let (with, without) = (with.ate(), without.ate());
    eprintln!("ATE with landmarks {with:.4} m, without {without:.4} m");
    assert_eq!(lost, (vec![], vec![]));
    assert!(with < 0.75 * without, "with {with} m, without {without} m");
}

/// A scene with its light dimmed to 15 % (grey levels 0–38): the detectors threshold
/// absolute gradients, so without the contrast stretch most segments vanish. Measured on
/// frame 0 of seed 1 (left segments, ORB points): 100 and 478 as rendered, 72 and 112
/// dimmed and stretched, 2 and 0 dimmed.
#[test]
fn a_dimmed_scene_keeps_its_segments() {
    let (rig, frames) = rendered(1, 0..1, &[]);
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
