//! The disparity offset's evidence ([`crate::OffsetEvidence`]) on synthetic road scenes.

use super::*;

/// A road scene on KITTI's rig, 1 m forward with a slight turn: points `near_m` to `far_m`
/// away (and segments among them) whose previous positions were triangulated from
/// disparities off by `offset_px` (measured minus true), each seen now with 0.1 px of
/// Gaussian noise. With `near_m == far_m` every feature sits at that depth.
fn road_with_offset(
    offset_px: f64,
    near_m: f64,
    far_m: f64,
) -> (Vec<PointObservation>, Vec<LineObservation>) {
    let rig = kitti_rig();
    let truth = pose(0.0, 0.01, 0.0, 0.02, 0.0, -1.0);
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let fb = rig.focal_px * rig.baseline_m;
    let feature = |rng: &mut ChaCha8Rng| {
        let z: f64 = if near_m < far_m {
            rng.random_range(near_m..far_m)
        } else {
            near_m
        };
        let x = Point3::new(
            rng.random_range(-0.8..0.8) * z,
            rng.random_range(-0.25..0.2) * z,
            z,
        );
        let seen_at = Point3::from(x.coords * (fb / z) / (fb / z + offset_px));
        (x, seen_at)
    };
    let project = |x: &Point3<f64>, rng: &mut ChaCha8Rng| {
        let p = truth * x;
        Point::new(
            rig.focal_px * p.x / p.z + rig.cx_px + gaussian(rng, 0.1),
            rig.focal_px * p.y / p.z + rig.cy_px + gaussian(rng, 0.1),
        )
    };
    let points = (0..150)
        .map(|_| {
            let (x, position) = feature(&mut rng);
            PointObservation {
                position,
                pixel: project(&x, &mut rng),
                right_x: None,
                weight: 1.0,
            }
        })
        .collect();
    let lines = (0..30)
        .filter_map(|_| {
            let (a, a_seen) = feature(&mut rng);
            let b = Point3::new(a.x + 0.3, a.y - 2.0, a.z);
            let b_seen = Point3::from(b.coords * (a_seen.z / a.z));
            let seen = Segment::new(project(&a, &mut rng), project(&b, &mut rng));
            LineObservation::new([a_seen, b_seen], &seen, 1.0)
        })
        .collect();
    (points, lines)
}

#[test]
fn a_disparity_offset_shows_in_the_estimate_and_a_scene_at_one_depth_hides_it() {
    let rig = kitti_rig();
    let evidence = |offset_px: f64, one_depth: bool| {
        let (near_m, far_m) = if one_depth { (30.0, 30.0) } else { (5.0, 80.0) };
        let (points, lines) = road_with_offset(offset_px, near_m, far_m);
        let e = estimate_motion(
            &rig,
            &points,
            &lines,
            &Isometry3::identity(),
            &MotionConfig::default(),
        )
        .unwrap_or_else(|e| panic!("offset {offset_px}: {e}"));
        e.disparity_offset
    };
    for offset_px in [-0.5, 0.0, 0.5] {
        let e = evidence(offset_px, false).unwrap_or_else(|| panic!("offset {offset_px}: none"));
        // One linearised step: within a tenth of the offset, and sure of it.
        assert!(
            (e.correction_px - offset_px).abs() <= 0.02 + 0.1 * offset_px.abs()
                && e.variance_px2 < 0.01,
            "offset {offset_px}: {e:?}"
        );
    }
    // Every depth off by the same fraction looks like a longer step: no evidence.
    let flat = evidence(0.5, true);
    assert!(flat.is_none_or(|e| e.variance_px2 > 1.0), "{flat:?}");
    // The points alone bear on it: segments whose depths carry the opposite offset leave
    // it where the points put it.
    let (points, _) = road_with_offset(0.5, 5.0, 80.0);
    let (_, opposite) = road_with_offset(-0.5, 5.0, 80.0);
    let beside = estimate_motion(
        &rig,
        &points,
        &opposite,
        &Isometry3::identity(),
        &MotionConfig::default(),
    )
    .unwrap()
    .disparity_offset
    .unwrap();
    assert!((beside.correction_px - 0.5).abs() <= 0.07, "{beside:?}");
    // Segments alone bear no evidence (under the prior, which keeps their estimate defined),
    // nor do they with too few points.
    let (_, lines) = road_with_offset(0.5, 5.0, 80.0);
    let e = estimate_motion_near(
        &rig,
        &[],
        &lines,
        &Isometry3::identity(),
        &MotionConfig::default(),
    );
    assert_eq!(e.map(|e| e.disparity_offset), Ok(None));
    let (points, _) = road_with_offset(0.5, 5.0, 80.0);
    let e = estimate_motion_near(
        &rig,
        &points[..19],
        &lines,
        &Isometry3::identity(),
        &MotionConfig::default(),
    );
    assert_eq!(e.map(|e| e.disparity_offset), Ok(None));
    // With the right image's rows the evidence is not given (their own offset is not modelled).
    let (points, lines) = road_with_offset(0.5, 5.0, 80.0);
    let stereo = MotionConfig {
        stereo_reprojection: true,
        ..MotionConfig::default()
    };
    let e = estimate_motion(&rig, &points, &lines, &Isometry3::identity(), &stereo).unwrap();
    assert_eq!(e.disparity_offset, None);
}

/// The prior's prediction is the last step, measured through the same disparities, so an
/// offset stretches it as it stretches this one. On a far road (20–150 m) the prior then
/// holds the step's length and the evidence reads only part of the offset; with its
/// translation left out (`offset_evidence_prior = 0`) the points read the whole of it.
#[test]
fn a_prior_stretched_by_the_offset_holds_the_evidence_back_unless_left_out() {
    let rig = kitti_rig();
    let offset_px = -1.0;
    let (points, lines) = road_with_offset(offset_px, 20.0, 150.0);
    // Real points weigh less against the prior than these: weighted as if each had a
    // pixel of noise where these have a tenth.
    let points: Vec<PointObservation> = points
        .iter()
        .map(|p| PointObservation { weight: 0.01, ..*p })
        .collect();
    let alone = MotionConfig {
        prior_translation_m: 0.0,
        prior_rotation_deg: 0.0,
        ..MotionConfig::default()
    };
    let stretched = estimate_motion(&rig, &points, &lines, &Isometry3::identity(), &alone)
        .unwrap()
        .motion;
    assert!(
        stretched.translation.vector.norm() > 1.05,
        "the offset stretches the step: {stretched:?}"
    );
    let evidence = |share: f64| {
        let config = MotionConfig {
            offset_evidence_prior: share,
            ..MotionConfig::default()
        };
        estimate_motion_near(&rig, &points, &lines, &stretched, &config)
            .unwrap()
            .disparity_offset
            .unwrap()
            .correction_px
    };
    let (whole, none) = (evidence(1.0), evidence(0.0));
    // One linearised step at 20–150 m (2.6–19 px of disparity) reads within a fifth.
    assert!((none - offset_px).abs() <= 0.2, "without the prior: {none}");
    assert!(
        whole.abs() < 0.5 * none.abs(),
        "with the prior: {whole}, without: {none}"
    );
}
