//! The photometric check: profiles along the segments, and candidates whose content sits
//! off their line.

use super::*;

/// A 200 × 120 image: four vertical edges at x = 40, 80, 120 and 160 between bands of
/// different grey levels and textures, each band's texture its own, shifted left by
/// `disparity` and changed by gain and bias (clamped).
fn banded(disparity: f64, gain: f64, bias: f64) -> Vec<u8> {
    let (w, h) = (200usize, 120usize);
    let mut pixels = vec![0u8; w * h];
    for y in 0..h {
        for x in 0..w {
            let u = x as f64 + disparity;
            let band = (u / 40.0).floor() as i64;
            let level = [40.0, 150.0, 70.0, 170.0, 60.0, 140.0][band.clamp(0, 5) as usize];
            let texture = ((u as i64 * (3 + band) + y as i64 * (5 + 2 * band)) % 13) as f64;
            pixels[y * w + x] = (gain * (level + 3.0 * texture) + bias)
                .round()
                .clamp(0.0, 255.0) as u8;
        }
    }
    pixels
}

fn profiles(pixels: &[u8], segments: &[Segment]) -> SegmentProfiles {
    let mut p = SegmentProfiles::default();
    p.extract(
        GrayView::new(pixels, 200, 120, 200).unwrap(),
        segments,
        20.0,
    );
    p
}

#[test]
fn the_photometric_check_picks_the_edge_geometry_cannot_tell_apart() {
    // Left: the edges at x = 80 and x = 160 (both dark-to-bright, same rows and length).
    // Right, 20 px of disparity and a gain/bias change: the same two edges at 60 and 140.
    // The left edge at 160 has both right edges as equally good geometric candidates
    // (disparities 20 and 100); the one at 80 has only one within the disparity range.
    let vertical = |x: f64| seg(x, 10.0, x, 110.0);
    let left = [vertical(80.0), vertical(160.0)];
    let right = [vertical(140.0), vertical(60.0)];
    let (l_pixels, r_pixels) = (banded(0.0, 1.0, 0.0), banded(20.0, 1.4, 12.0));
    let (pl, pr) = (profiles(&l_pixels, &left), profiles(&r_pixels, &right));

    let mut matcher = L1Matcher::new(MatcherConfig::default()).unwrap();
    let mut out = Vec::new();
    let stats = matcher.match_segments(MatchCase::Stereo, &left, &right, &mut out);
    assert_eq!(pairs(&out), vec![(0, 1)], "geometry alone: {stats:?}");
    assert_eq!(stats.ambiguous, 1);
    let stats =
        matcher.match_with_profiles(MatchCase::Stereo, &left, &right, Some((&pl, &pr)), &mut out);
    assert_eq!(pairs(&out), vec![(0, 1), (1, 0)], "{stats:?}");

    // Switched off in the config, the profiles are ignored.
    let mut off = MatcherConfig::default();
    off.photometric.enabled = false;
    let mut matcher = L1Matcher::new(off).unwrap();
    matcher.match_with_profiles(MatchCase::Stereo, &left, &right, Some((&pl, &pr)), &mut out);
    assert_eq!(pairs(&out), vec![(0, 1)]);
}

#[test]
fn describe_extracts_the_profiles_only_when_the_check_is_on_and_an_image_is_given() {
    let segments = [seg(80.0, 10.0, 80.0, 110.0), seg(160.0, 10.0, 160.0, 110.0)];
    let pixels = banded(0.0, 1.0, 0.0);
    let view = GrayView::new(&pixels, 200, 120, 200).unwrap();
    let mut config = MatcherConfig::default();
    config.photometric.min_angle_from_horizontal_deg = 20.0;
    let on = L1Matcher::new(config.clone()).unwrap();
    let mut out = SegmentProfiles::default();
    on.describe(Some(view), &segments, &mut out);
    assert_eq!(out.len(), 2);
    assert!(out.has_profile(0) && out.has_profile(1));
    assert_eq!(
        (0..2)
            .map(|i| out.offset_px(i, &profiles(&pixels, &segments), i))
            .collect::<Vec<_>>(),
        vec![Some(0.0), Some(0.0)],
        "the same profiles as extracting them directly"
    );
    on.describe(None, &segments, &mut out);
    assert!(out.is_empty(), "no image, no profiles");
    config.photometric.enabled = false;
    let off = L1Matcher::new(config).unwrap();
    off.describe(Some(view), &segments, &mut out);
    assert!(out.is_empty(), "check off, no profiles");
}

#[test]
fn a_candidate_whose_content_sits_off_its_line_is_dropped() {
    // The right segment drawn 2 px left of the edge it belongs to: same geometry class,
    // but the image content across it is shifted by 2 px against the query's.
    let left = [seg(80.0, 10.0, 80.0, 110.0)];
    let (l_pixels, r_pixels) = (banded(0.0, 1.0, 0.0), banded(20.0, 1.0, 0.0));
    let pl = profiles(&l_pixels, &left);
    for (x, kept) in [(60.0, true), (58.0, false), (62.0, false)] {
        let right = [seg(x, 10.0, x, 110.0)];
        let pr = profiles(&r_pixels, &right);
        let offset = pl.offset_px(0, &pr, 0).unwrap();
        assert_eq!(offset.abs() <= 1.0, kept, "x = {x}: offset {offset}");
        let mut matcher = L1Matcher::new(MatcherConfig::default()).unwrap();
        let mut out = Vec::new();
        let stats = matcher.match_with_profiles(
            MatchCase::Stereo,
            &left,
            &right,
            Some((&pl, &pr)),
            &mut out,
        );
        assert_eq!(out.len(), usize::from(kept), "x = {x}: {stats:?}");
        assert_eq!(stats.misaligned, usize::from(!kept));
    }
}

#[test]
fn profiles_of_the_wrong_size_are_ignored_not_trusted() {
    let left = [seg(80.0, 10.0, 80.0, 110.0), seg(160.0, 10.0, 160.0, 110.0)];
    let right = [seg(60.0, 10.0, 60.0, 110.0), seg(140.0, 10.0, 140.0, 110.0)];
    let pl = profiles(&banded(0.0, 1.0, 0.0), &left[..1]);
    let pr = profiles(&banded(20.0, 1.0, 0.0), &right);
    let mut matcher = L1Matcher::new(MatcherConfig::default()).unwrap();
    let (mut with, mut without) = (Vec::new(), Vec::new());
    matcher.match_with_profiles(
        MatchCase::Stereo,
        &left,
        &right,
        Some((&pl, &pr)),
        &mut with,
    );
    matcher.match_segments(MatchCase::Stereo, &left, &right, &mut without);
    assert_eq!(with, without);
}
