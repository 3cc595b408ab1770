//! Hand-computed cases for each term, and invariances checked on random segments.

use super::*;
use proptest::prelude::*;
use std::f64::consts::FRAC_PI_4;

const TOL: f64 = 1e-12;

fn features(x0: f64, y0: f64, x1: f64, y1: f64) -> SegmentFeatures {
    SegmentFeatures::new(&Segment::from_coords(x0, y0, x1, y1)).unwrap()
}

fn close(actual: f64, expected: f64) -> bool {
    (actual - expected).abs() <= TOL
}

#[test]
fn identical_vertical_pair_shifted_along_the_row_is_ideal_in_stereo() {
    let a = features(10.0, 0.0, 10.0, 10.0);
    let b = features(5.0, 0.0, 5.0, 10.0);
    assert_eq!(
        Terms::between(&a, &b, MatchCase::Stereo).to_array(),
        IDEAL_TERMS
    );
}

#[test]
fn reversed_endpoints_give_the_same_terms() {
    let a = features(0.0, 0.0, 10.0, 10.0);
    let b = features(3.0, 1.0, 12.0, 8.0);
    let b_rev = SegmentFeatures::new(&Segment::from_coords(12.0, 8.0, 3.0, 1.0)).unwrap();
    for case in [MatchCase::Stereo, MatchCase::FrameToFrame] {
        let forward = Terms::between(&a, &b, case).to_array();
        let backward = Terms::between(&a, &b_rev, case).to_array();
        for (f, r) in forward.iter().zip(backward) {
            assert!(close(*f, r), "{case:?}: {forward:?} vs {backward:?}");
        }
    }
}

#[test]
fn direction_angle_of_diagonal_and_horizontal_is_a_quarter_turn_half() {
    let a = features(0.0, 0.0, 10.0, 10.0);
    let b = features(0.0, 0.0, 10.0, 0.0);
    assert!(close(direction_angle(&a, &b), FRAC_PI_4));
    // Perpendicular segments: π/2, whichever way round.
    let c = features(0.0, 0.0, 0.0, 7.0);
    assert!(close(direction_angle(&b, &c), std::f64::consts::FRAC_PI_2));
}

#[test]
fn epipolar_angle_measures_flow_against_x_in_stereo_and_y_frame_to_frame() {
    // Midpoints (10, 10) and (7, 6): flow (3, 4).
    let a = features(10.0, 5.0, 10.0, 15.0);
    let b = features(7.0, 1.0, 7.0, 11.0);
    assert!(close(
        epipolar_angle(&a, &b, MatchCase::Stereo),
        (4.0f64 / 5.0).asin()
    ));
    assert!(close(
        epipolar_angle(&a, &b, MatchCase::FrameToFrame),
        (3.0f64 / 5.0).asin()
    ));
}

#[test]
fn null_flow_has_zero_epipolar_angle() {
    let a = features(0.0, 0.0, 4.0, 4.0);
    assert_eq!(epipolar_angle(&a, &a, MatchCase::Stereo), 0.0);
    assert_eq!(epipolar_angle(&a, &a, MatchCase::FrameToFrame), 0.0);
}

#[test]
fn stereo_overlap_compares_row_extents_with_half_pixel_footprint() {
    // Rows [0, 10] and [5, 20], widened to [-0.5, 10.5] and [4.5, 20.5]: 6 / 21.
    let a = features(0.0, 0.0, 0.0, 10.0);
    let b = features(3.0, 5.0, 3.0, 20.0);
    assert!(close(overlap(&a, &b, MatchCase::Stereo), 6.0 / 21.0));
}

#[test]
fn horizontal_segments_overlap_fully_on_the_same_row_and_not_two_rows_apart() {
    let a = features(0.0, 3.0, 10.0, 3.0);
    let same_row = features(20.0, 3.0, 25.0, 3.0);
    let two_rows_down = features(0.0, 5.0, 10.0, 5.0);
    assert!(close(overlap(&a, &same_row, MatchCase::Stereo), 1.0));
    assert_eq!(overlap(&a, &two_rows_down, MatchCase::Stereo), 0.0);
}

#[test]
fn frame_to_frame_overlap_projects_onto_the_query_line() {
    // Query spans t ∈ [-5, 5] around (5, 0); candidate projects to t ∈ [-15, 0]:
    // common 5, union 20.
    let a = features(0.0, 0.0, 10.0, 0.0);
    let b = features(5.0, 1.0, 20.0, 1.0);
    assert!(close(overlap(&a, &b, MatchCase::FrameToFrame), 0.25));
    let disjoint = features(30.0, 0.0, 40.0, 0.0);
    assert_eq!(overlap(&a, &disjoint, MatchCase::FrameToFrame), 0.0);
}

#[test]
fn length_ratio_is_longer_over_shorter_either_way() {
    let a = features(0.0, 0.0, 10.0, 0.0);
    let b = features(0.0, 0.0, 0.0, 4.0);
    assert!(close(length_ratio(&a, &b), 2.5));
    assert!(close(length_ratio(&b, &a), 2.5));
}

#[test]
fn degenerate_segments_are_refused_with_the_reason() {
    let zero = Segment::from_coords(3.0, 4.0, 3.0, 4.0);
    assert!(matches!(
        SegmentFeatures::new(&zero),
        Err(GeometryError::ZeroLength { .. })
    ));
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let seg = Segment::from_coords(0.0, bad, 1.0, 1.0);
        assert_eq!(SegmentFeatures::new(&seg), Err(GeometryError::NonFinite));
    }
    // Finite coordinates whose difference overflows.
    let huge = Segment::from_coords(-f64::MAX, 0.0, f64::MAX, 0.0);
    assert!(matches!(
        SegmentFeatures::new(&huge),
        Err(GeometryError::ZeroLength { .. })
    ));
}

#[test]
fn clipping_keeps_the_inside_part_and_drops_outside_segments() {
    let crossing = Segment::from_coords(-10.0, 5.0, 30.0, 5.0)
        .clipped_to(20.0, 10.0)
        .unwrap();
    assert_eq!(crossing, Segment::from_coords(0.0, 5.0, 20.0, 5.0));
    let diagonal = Segment::from_coords(-5.0, -5.0, 25.0, 25.0)
        .clipped_to(20.0, 10.0)
        .unwrap();
    assert!(
        close(diagonal.start.x, 0.0) && close(diagonal.end.x, 10.0) && close(diagonal.end.y, 10.0)
    );
    let inside = Segment::from_coords(1.0, 2.0, 3.0, 4.0);
    assert_eq!(inside.clipped_to(20.0, 10.0), Some(inside));
    assert_eq!(
        Segment::from_coords(30.0, 0.0, 40.0, 5.0).clipped_to(20.0, 10.0),
        None
    );
    assert_eq!(
        Segment::from_coords(5.0, -3.0, 8.0, -3.0).clipped_to(20.0, 10.0),
        None
    );
}

fn coord() -> impl Strategy<Value = f64> {
    -1000.0..1000.0f64
}

fn segment() -> impl Strategy<Value = Segment> {
    (coord(), coord(), coord(), coord())
        .prop_map(|(a, b, c, d)| Segment::from_coords(a, b, c, d))
        .prop_filter("needs a direction", |s| s.length() > 1e-3)
}

fn case() -> impl Strategy<Value = MatchCase> {
    prop_oneof![Just(MatchCase::Stereo), Just(MatchCase::FrameToFrame)]
}

proptest! {
    #[test]
    fn terms_stay_in_their_ranges(a in segment(), b in segment(), case in case()) {
        let t = Terms::between(&SegmentFeatures::new(&a).unwrap(), &SegmentFeatures::new(&b).unwrap(), case);
        let half_pi = std::f64::consts::FRAC_PI_2 + 1e-12;
        prop_assert!((0.0..=half_pi).contains(&t.angle_rad));
        prop_assert!((0.0..=half_pi).contains(&t.epipolar_angle_rad));
        prop_assert!((0.0..=1.0).contains(&t.overlap));
        prop_assert!(t.length_ratio >= 1.0);
    }

    #[test]
    fn endpoint_order_never_matters(a in segment(), b in segment(), case in case()) {
        let fa = SegmentFeatures::new(&a).unwrap();
        let fb = SegmentFeatures::new(&b).unwrap();
        let fa_rev = SegmentFeatures::new(&a.reversed()).unwrap();
        let fb_rev = SegmentFeatures::new(&b.reversed()).unwrap();
        let reference = Terms::between(&fa, &fb, case).to_array();
        for (x, y) in [(&fa_rev, &fb), (&fa, &fb_rev), (&fa_rev, &fb_rev)] {
            let other = Terms::between(x, y, case).to_array();
            for (r, o) in reference.iter().zip(other) {
                prop_assert!((r - o).abs() <= 1e-9 * (1.0 + r.abs()), "{reference:?} vs {other:?}");
            }
        }
    }

    #[test]
    fn stereo_terms_are_symmetric_in_the_pair(a in segment(), b in segment()) {
        let fa = SegmentFeatures::new(&a).unwrap();
        let fb = SegmentFeatures::new(&b).unwrap();
        let ab = Terms::between(&fa, &fb, MatchCase::Stereo).to_array();
        let ba = Terms::between(&fb, &fa, MatchCase::Stereo).to_array();
        for (x, y) in ab.iter().zip(ba) {
            prop_assert!((x - y).abs() <= 1e-9 * (1.0 + x.abs()));
        }
    }
}
