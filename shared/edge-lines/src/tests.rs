//! The detector on rendered images with known edges, and on degenerate images.

use super::*;

/// Every segment, however many (min length 15 px).
fn all_params() -> Params {
    Params {
        max_segments: usize::MAX,
        ..Params::default()
    }
}

fn detect_with(params: Params, pixels: &[u8], width: usize, height: usize) -> Vec<LineSegment> {
    let mut detector = EdgeLineDetector::new(params);
    let mut out = Vec::new();
    detector.detect(GrayView::packed(pixels, width, height).unwrap(), &mut out);
    out
}

fn detect(pixels: &[u8], width: usize, height: usize) -> Vec<LineSegment> {
    detect_with(all_params(), pixels, width, height)
}

/// A convex polygon (corners clockwise on the screen, pixel-centre coordinates) of level
/// `inside` on `outside`, anti-aliased by 8 × 8 samples per pixel.
fn render_polygon(
    width: usize,
    height: usize,
    corners: &[[f64; 2]],
    inside: u8,
    outside: u8,
) -> Vec<u8> {
    const SAMPLES: usize = 8;
    let contains = |x: f64, y: f64| {
        (0..corners.len()).all(|k| {
            let (a, b) = (corners[k], corners[(k + 1) % corners.len()]);
            (b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0]) >= 0.0
        })
    };
    let mut pixels = vec![0u8; width * height];
    for y in 0..height {
        for x in 0..width {
            let mut hits = 0;
            for sy in 0..SAMPLES {
                for sx in 0..SAMPLES {
                    let px = x as f64 - 0.5 + (sx as f64 + 0.5) / SAMPLES as f64;
                    let py = y as f64 - 0.5 + (sy as f64 + 0.5) / SAMPLES as f64;
                    hits += usize::from(contains(px, py));
                }
            }
            let share = hits as f64 / (SAMPLES * SAMPLES) as f64;
            let level = f64::from(outside) + share * (f64::from(inside) - f64::from(outside));
            pixels[y * width + x] = level.round() as u8;
        }
    }
    pixels
}

/// Distance of `p` from the infinite line through `a` and `b`.
fn line_distance(a: [f64; 2], b: [f64; 2], p: [f32; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let (px, py) = (f64::from(p[0]) - a[0], f64::from(p[1]) - a[1]);
    (dx * py - dy * px).abs() / dx.hypot(dy)
}

/// Whether `s` runs along the edge `a`–`b`: both endpoints within `tolerance` of its line.
fn along(s: &LineSegment, a: [f64; 2], b: [f64; 2], tolerance: f64) -> bool {
    line_distance(a, b, s.start) <= tolerance && line_distance(a, b, s.end) <= tolerance
}

fn inside_image(s: &LineSegment, width: usize, height: usize) -> bool {
    [s.start, s.end].iter().all(|p| {
        p[0].is_finite()
            && p[1].is_finite()
            && (0.0..=(width - 1) as f32).contains(&p[0])
            && (0.0..=(height - 1) as f32).contains(&p[1])
    })
}

/// A slanted quadrilateral with sides at fractional positions.
const QUAD: [[f64; 2]; 4] = [[40.3, 30.7], [160.6, 42.2], [150.2, 120.9], [50.8, 110.4]];

#[test]
fn a_rendered_quadrilateral_gives_its_four_sides_within_a_third_of_a_pixel() {
    let (w, h) = (200, 150);
    let pixels = render_polygon(w, h, &QUAD, 200, 40);
    let segments = detect(&pixels, w, h);
    for k in 0..4 {
        let (a, b) = (QUAD[k], QUAD[(k + 1) % 4]);
        let side = (b[0] - a[0]).hypot(b[1] - a[1]);
        let best = segments
            .iter()
            .filter(|s| along(s, a, b, 1.0 / 3.0))
            .map(|s| f64::from(s.length()))
            .fold(0.0, f64::max);
        assert!(
            best >= 0.8 * side,
            "side {k} ({side:.0} px): longest segment within 1/3 px of it is {best:.1} px; \
             all: {segments:?}"
        );
    }
    // Nothing else: every segment lies on a side, within 1 px.
    for s in &segments {
        assert!(
            (0..4).any(|k| along(s, QUAD[k], QUAD[(k + 1) % 4], 1.0)),
            "{s:?} is on no side"
        );
    }
}

#[test]
fn segments_are_oriented_by_their_gradient() {
    let (w, h) = (200, 150);
    let bright_inside = render_polygon(w, h, &QUAD, 200, 40);
    let dark_inside = render_polygon(w, h, &QUAD, 40, 200);
    // Left side of the quadrilateral (corner 3 → corner 0), gradient pointing inwards (+x)
    // for the bright one: turned a quarter, start → end runs down the screen (+y).
    let (a, b) = (QUAD[3], QUAD[0]);
    let left_side = |segments: &[LineSegment]| {
        *segments
            .iter()
            .find(|s| along(s, a, b, 1.0) && s.length() > 40.0)
            .unwrap()
    };
    let bright = left_side(&detect(&bright_inside, w, h));
    let dark = left_side(&detect(&dark_inside, w, h));
    assert!(bright.end[1] > bright.start[1], "{bright:?}");
    assert!(dark.end[1] < dark.start[1], "{dark:?}");
}

#[test]
fn the_test_card_edges_are_found_within_a_pixel() {
    let (w, h) = (752, 480);
    let pixels = linetrack_test_data::test_card(w, h);
    // The card's coordinates put pixel centres at +0.5.
    let truth: Vec<([f64; 2], [f64; 2])> = linetrack_test_data::test_card_edges(w, h)
        .iter()
        .map(|e| ([e[0] - 0.5, e[1] - 0.5], [e[2] - 0.5, e[3] - 0.5]))
        .collect();
    let segments = detect(&pixels, w, h);
    let long: Vec<&LineSegment> = segments.iter().filter(|s| s.length() > 40.0).collect();
    for s in &long {
        assert!(
            truth.iter().any(|&(a, b)| along(s, a, b, 1.0)),
            "{s:?} is on no edge"
        );
    }
    let found = truth
        .iter()
        .filter(|&&(a, b)| long.iter().any(|s| along(s, a, b, 1.0)))
        .count();
    assert_eq!(found, truth.len(), "{found} of {} edges found", truth.len());
}

#[test]
fn the_cap_keeps_the_longest_first_and_the_minimum_length_holds() {
    let (w, h) = (752, 480);
    let pixels = linetrack_test_data::test_card(w, h);
    let all = detect(&pixels, w, h);
    assert!(all.len() > 7);
    let capped = detect_with(
        Params {
            max_segments: 7,
            min_length_px: 30.0,
            ..Params::default()
        },
        &pixels,
        w,
        h,
    );
    assert_eq!(capped.len(), 7);
    assert!(capped.windows(2).all(|p| p[0].length() >= p[1].length()));
    let mut lengths: Vec<f32> = all.iter().map(LineSegment::length).collect();
    lengths.sort_by(|a, b| b.total_cmp(a));
    assert_eq!(capped[6].length(), lengths[6]);
    assert!(all.iter().all(|s| s.length() >= 15.0));
    assert!(
        detect_with(
            Params {
                max_segments: 0,
                ..Params::default()
            },
            &pixels,
            w,
            h
        )
        .is_empty()
    );
}

#[test]
fn a_view_with_padded_rows_reads_the_same_pixels() {
    let (w, h, stride) = (200, 150, 217);
    let packed = render_polygon(w, h, &QUAD, 200, 40);
    let mut padded = vec![255u8; (h - 1) * stride + w];
    for y in 0..h {
        padded[y * stride..y * stride + w].copy_from_slice(&packed[y * w..(y + 1) * w]);
    }
    let mut detector = EdgeLineDetector::new(all_params());
    let (mut a, mut b) = (Vec::new(), Vec::new());
    detector.detect(GrayView::new(&padded, w, h, stride).unwrap(), &mut a);
    detector.detect(GrayView::packed(&packed, w, h).unwrap(), &mut b);
    assert!(!a.is_empty());
    assert_eq!(a, b);
}

#[test]
fn a_reused_detector_gives_the_same_segments_across_sizes() {
    let small = render_polygon(200, 150, &QUAD, 200, 40);
    let card = linetrack_test_data::test_card(752, 480);
    let mut detector = EdgeLineDetector::new(all_params());
    let mut out = Vec::new();
    let mut run = |pixels: &[u8], w, h| {
        detector.detect(GrayView::packed(pixels, w, h).unwrap(), &mut out);
        out.clone()
    };
    let first = run(&small, 200, 150);
    let card_first = run(&card, 752, 480);
    assert_eq!(run(&small, 200, 150), first);
    assert_eq!(run(&card, 752, 480), card_first);
    assert_eq!(first, detect(&small, 200, 150));
}

#[test]
fn one_pixel_lines_give_segments_beside_them() {
    let (w, h) = (120, 100);
    // A horizontal, a vertical and a diagonal bright line one pixel wide.
    let mut pixels = vec![20u8; w * h];
    for x in 10..110 {
        pixels[20 * w + x] = 230;
    }
    for y in 30..95 {
        pixels[y * w + 15] = 230;
    }
    for k in 0..60 {
        pixels[(35 + k) * w + 40 + k] = 230;
    }
    let segments = detect(&pixels, w, h);
    for (a, b) in [
        ([10.0, 20.0], [109.0, 20.0]),
        ([15.0, 30.0], [15.0, 94.0]),
        ([40.0, 35.0], [99.0, 94.0]),
    ] {
        assert!(
            segments
                .iter()
                .any(|s| along(s, a, b, 1.5) && s.length() > 30.0),
            "nothing along {a:?}–{b:?}: {segments:?}"
        );
    }
    assert!(segments.iter().all(|s| inside_image(s, w, h)));
}

#[test]
fn flat_images_have_no_segments() {
    for level in [0u8, 1, 128, 254, 255] {
        assert!(detect(&vec![level; 64 * 48], 64, 48).is_empty(), "{level}");
    }
    // Saturated: a bright square clipped to 255 on 255 is flat too.
    let mut pixels = vec![255u8; 64 * 48];
    for y in 10..30 {
        for x in 10..30 {
            pixels[y * 64 + x] = 255;
        }
    }
    assert!(detect(&pixels, 64, 48).is_empty());
}

#[test]
fn tiny_images_do_not_panic() {
    for (w, h) in [
        (0, 0),
        (0, 5),
        (5, 0),
        (1, 1),
        (2, 2),
        (2, 40),
        (40, 2),
        (3, 3),
        (3, 40),
        (40, 3),
        (4, 4),
        (5, 5),
        (6, 200),
    ] {
        // A step edge through the middle, and a checkerboard.
        let step: Vec<u8> = (0..w * h)
            .map(|i| if i % w.max(1) < w / 2 { 0 } else { 255 })
            .collect();
        let checker: Vec<u8> = (0..w * h)
            .map(|i| {
                if (i % w.max(1) + i / w.max(1)) % 2 == 0 {
                    0
                } else {
                    255
                }
            })
            .collect();
        for pixels in [&step, &checker] {
            let segments = detect(pixels, w, h);
            assert!(segments.iter().all(|s| inside_image(s, w, h)), "{w}×{h}");
            if w < 3 || h < 3 {
                assert!(segments.is_empty());
            }
        }
    }
}

#[test]
fn noise_and_extreme_parameters_do_not_panic() {
    let (w, h) = (160, 120);
    // A deterministic LCG.
    let mut state = 12345u32;
    let noise: Vec<u8> = (0..w * h)
        .map(|_| {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 24) as u8
        })
        .collect();
    let salt: Vec<u8> = noise
        .iter()
        .map(|&v| if v > 127 { 255 } else { 0 })
        .collect();
    for params in [
        all_params(),
        Params {
            gradient_threshold: 0,
            anchor_threshold: 0,
            scan_interval: 0,
            max_fit_error_px: 0.0,
            max_outlier_run: 0,
            min_length_px: 0.0,
            min_aligned_fraction: 0.0,
            max_segments: usize::MAX,
        },
        Params {
            gradient_threshold: u16::MAX,
            anchor_threshold: u16::MAX,
            scan_interval: usize::MAX,
            max_fit_error_px: f32::NAN,
            max_outlier_run: usize::MAX,
            min_length_px: f32::INFINITY,
            min_aligned_fraction: 2.0,
            max_segments: 1,
        },
    ] {
        for pixels in [&noise, &salt] {
            let segments = detect_with(params, pixels, w, h);
            assert!(segments.iter().all(|s| inside_image(s, w, h)), "{params:?}");
        }
    }
}

#[test]
fn views_that_do_not_fit_their_pixels_are_refused() {
    let pixels = [0u8; 100];
    assert!(GrayView::packed(&pixels, 10, 10).is_ok());
    assert!(GrayView::new(&pixels, 10, 10, 10).is_ok());
    assert!(GrayView::new(&pixels, 9, 11, 9).is_ok());
    assert!(GrayView::packed(&pixels, 10, 11).is_err());
    assert!(GrayView::new(&pixels, 10, 10, 9).is_err());
    assert!(GrayView::new(&pixels, 5, 10, 11).is_err());
    assert!(GrayView::new(&pixels, 1, usize::MAX, usize::MAX).is_err());
    assert!(GrayView::packed(&[], 0, 0).is_ok());
}

/// FNV-1a over the bits of every endpoint coordinate, segment by segment.
fn digest(segments: &[LineSegment], mut hash: u64) -> u64 {
    for s in segments {
        for v in s.start.iter().chain(&s.end) {
            for byte in v.to_bits().to_le_bytes() {
                hash = (hash ^ u64::from(byte)).wrapping_mul(0x0000_0100_0000_01b3);
            }
        }
    }
    hash
}

#[test]
fn the_euroc_segments_are_bit_for_bit_the_recorded_ones() {
    // Recorded from the detector before its row loops were rewritten for speed (wrapping
    // arithmetic, word-wide anchor scan): a faster detector must find exactly the same
    // segments. Both images of the excerpt's first 12 frames, and uniform noise.
    const RECORDED: (usize, u64) = (9619, 7_414_623_098_850_200_773);
    let mut detector = EdgeLineDetector::new(all_params());
    let mut out = Vec::new();
    let (mut count, mut hash) = (0, 0xcbf2_9ce4_8422_2325);
    let mut images = Vec::new();
    for index in 0..12 {
        let (left, right) = linetrack_test_data::euroc_stereo_pair(index).unwrap();
        for path in [left, right] {
            let image = image::open(&path).unwrap().to_luma8();
            let (w, h) = (image.width() as usize, image.height() as usize);
            images.push((image.into_raw(), w, h));
        }
    }
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let noise: Vec<u8> = (0..320 * 240)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 56) as u8
        })
        .collect();
    images.push((noise, 320, 240));
    for (pixels, w, h) in &images {
        detector.detect(GrayView::packed(pixels, *w, *h).unwrap(), &mut out);
        count += out.len();
        hash = digest(&out, hash);
    }
    assert_eq!((count, hash), RECORDED);
}
