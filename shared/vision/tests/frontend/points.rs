//! Points: the grid search against comparing every pair, and sub-pixel tracking and stereo
//! columns.

use super::*;

#[test]
fn point_grid_finds_exactly_the_matches_of_comparing_every_pair() {
    // 1500 ORB points a side on a real EuRoC pair, stereo and frame to frame (the right
    // image standing in for the next frame), wide and narrow windows: the matcher that
    // compares only the grid's candidates returns the very matches of the one comparing
    // every pair the gates admit.
    let (left, right) = euroc_images(0);
    let options = OrbOptions {
        features: 1500,
        ..OrbOptions::default()
    };
    let mut orb = OrbExtractor::new(&options).unwrap();
    let (mut a, mut b) = (PointFeatures::default(), PointFeatures::default());
    orb.extract(&left, &mut a).unwrap();
    orb.extract(&right, &mut b).unwrap();
    assert!(a.points.len() > 1000 && b.points.len() > 1000);
    let (mut grid, mut every_pair) = (PointMatcher::new(), HammingMatcher::new());
    let (mut from_grid, mut from_every_pair) = (Vec::new(), Vec::new());
    let mut compared = 0;
    for (case, gates) in [
        (MatchCase::Stereo, AppearanceGates::default()),
        (
            MatchCase::Stereo,
            AppearanceGates {
                max_row_difference_px: 0.5,
                min_disparity_px: 3.0,
                max_disparity_px: 40.0,
                ..AppearanceGates::default()
            },
        ),
        (MatchCase::FrameToFrame, AppearanceGates::default()),
        // The odometry's window once a motion is known.
        (
            MatchCase::FrameToFrame,
            AppearanceGates {
                max_displacement_px: 30.0,
                ..AppearanceGates::default()
            },
        ),
        (
            MatchCase::FrameToFrame,
            AppearanceGates {
                max_displacement_px: 7.5,
                ..AppearanceGates::default()
            },
        ),
        (
            MatchCase::FrameToFrame,
            AppearanceGates {
                max_displacement_px: 2000.0,
                ..AppearanceGates::default()
            },
        ),
    ] {
        grid.match_points(case, &a, &b, &gates, 1.25, &mut from_grid);
        every_pair.match_mutual(
            &a.descriptors,
            &b.descriptors,
            1.25,
            |i, j| points_may_match(case, &gates, a.points[i], b.points[j]),
            &mut from_every_pair,
        );
        assert_eq!(from_grid, from_every_pair, "{case:?} {gates:?}");
        compared += from_grid.len();
    }
    assert!(compared > 200, "{compared} matches in all");
}

#[test]
fn point_grid_skips_non_finite_points_and_an_empty_side() {
    let mut orb = OrbExtractor::new(&OrbOptions::default()).unwrap();
    let (left, _) = euroc_images(0);
    let mut a = PointFeatures::default();
    orb.extract(&left, &mut a).unwrap();
    let mut b = a.clone();
    // A corrupt position never matches, and the rest still match themselves.
    b.points[0] = linetrack_geometry::Point::new(f64::NAN, 3.0);
    b.points[1] = linetrack_geometry::Point::new(f64::INFINITY, f64::NEG_INFINITY);
    let gates = AppearanceGates {
        max_displacement_px: 1.0,
        ..AppearanceGates::default()
    };
    let mut out = Vec::new();
    let mut matcher = PointMatcher::new();
    matcher.match_points(MatchCase::FrameToFrame, &a, &b, &gates, 1.0, &mut out);
    assert!(out.iter().all(|m| m.train > 1));
    assert!(
        out.len() > a.points.len() / 2,
        "{} of {}",
        out.len(),
        a.points.len()
    );
    // No points at all on one side.
    matcher.match_points(
        MatchCase::Stereo,
        &a,
        &PointFeatures::default(),
        &gates,
        1.0,
        &mut out,
    );
    assert!(out.is_empty());
}

/// A smooth texture sampled at `(x − dx, y − dy)`, times `gain` plus `bias`: the same scene
/// moved by a known fraction of a pixel, under another exposure.
fn smooth_texture(dx: f64, dy: f64, gain: f64, bias: f64) -> GrayImage {
    let (w, h) = (320, 240);
    let pixels: Vec<u8> = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f64 - dx, (i / w) as f64 - dy);
            let value =
                110.0 + 45.0 * (0.31 * x + 0.17 * y).sin() + 35.0 * (0.13 * x - 0.27 * y).cos();
            (gain * value + bias).round().clamp(0.0, 255.0) as u8
        })
        .collect();
    GrayImage::from_pixels(w, h, &pixels, "smooth texture").unwrap()
}

#[test]
fn a_tracked_point_is_found_to_a_tenth_of_a_pixel_under_another_exposure() {
    let before = smooth_texture(0.0, 0.0, 1.0, 0.0);
    let now = smooth_texture(1.3, -0.6, 1.2, -15.0);
    // A keypoint of a coarse pyramid level lies between pixels; its match is a whole
    // pixel off where it went.
    let from = linetrack_geometry::Point::new(100.4, 80.7);
    let to = linetrack_geometry::Point::new(102.0, 80.0);
    let found = refine_track(&before, &now, from, to).expect("refined");
    assert!((found.x - 101.7).abs() < 0.1, "{found:?}");
    assert!((found.y - 80.1).abs() < 0.1, "{found:?}");
    // Nothing alike nearby, a window off the image, or images of two sizes: no answer.
    let noise: Vec<u8> = (0..320 * 240_u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8)
        .collect();
    let noise = GrayImage::from_pixels(320, 240, &noise, "noise").unwrap();
    assert_eq!(refine_track(&before, &noise, from, to), None);
    let edge = linetrack_geometry::Point::new(2.0, 80.0);
    assert_eq!(refine_track(&before, &now, edge, edge), None);
    let small = GrayImage::from_pixels(10, 10, &[0; 100], "small").unwrap();
    assert_eq!(refine_track(&before, &small, from, to), None);
}

#[test]
fn a_stereo_column_is_refined_for_the_keypoint_itself_not_its_pixel() {
    let left = smooth_texture(0.0, 0.0, 1.0, 0.0);
    // The right camera sees each point 7.4 px further left.
    let right = smooth_texture(-7.4, 0.0, 1.0, 10.0);
    for x in [150.0, 150.6, 151.3] {
        let keypoint = linetrack_geometry::Point::new(x, 100.0);
        let guess = linetrack_geometry::Point::new((x - 7.4).round(), 100.0);
        let column = refine_stereo_column(&left, &right, keypoint, guess).expect("refined");
        assert!((column - (x - 7.4)).abs() < 0.1, "{x}: {column}");
    }
}
