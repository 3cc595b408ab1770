//! The extractor on rendered images with known corners, rotated and brightened copies, and
//! degenerate images.

use super::*;

/// A view of packed pixels (the tests' images are well formed).
fn view(pixels: &[u8], width: usize, height: usize) -> GrayView<'_> {
    GrayView::packed(pixels, width, height).unwrap()
}

fn extract(params: Params, pixels: &[u8], width: usize, height: usize) -> Corners {
    let mut extractor = CornerExtractor::new(params).unwrap();
    let mut out = Corners::default();
    extractor.extract(view(pixels, width, height), &mut out);
    out
}

/// Full resolution only, every corner.
fn one_level() -> Params {
    Params {
        levels: 1,
        max_corners: 10_000,
        ..Params::default()
    }
}

/// `value` inside the axis-aligned rectangle `[x0, x1) × [y0, y1)`, `background` outside.
fn rectangle(
    (width, height): (usize, usize),
    [x0, y0, x1, y1]: [usize; 4],
    value: u8,
    background: u8,
) -> Vec<u8> {
    let mut pixels = vec![background; width * height];
    for y in y0..y1 {
        pixels[y * width + x0..y * width + x1].fill(value);
    }
    pixels
}

/// Smooth random texture in 40..=215 (no saturation when brightened by up to 40): a sum of
/// blobs (one per 60 pixels) from a fixed seed.
fn texture(width: usize, height: usize, seed: u64) -> Vec<u8> {
    let mut state = seed;
    let mut next = || describe::tests_support::uniform(&mut state);
    let blobs: Vec<[f64; 4]> = (0..width * height / 60)
        .map(|_| {
            [
                next() * width as f64,
                next() * height as f64,
                2.0 + 5.0 * next(),
                next() - 0.5,
            ]
        })
        .collect();
    let mut field = vec![0.0; width * height];
    for y in 0..height {
        for x in 0..width {
            field[y * width + x] = blobs
                .iter()
                .map(|&[bx, by, r, a]| {
                    let d2 = (x as f64 - bx).powi(2) + (y as f64 - by).powi(2);
                    a * (-d2 / (2.0 * r * r)).exp()
                })
                .sum::<f64>();
        }
    }
    let (lo, hi) = field
        .iter()
        .fold((f64::MAX, f64::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    field
        .iter()
        .map(|v| (40.0 + 175.0 * (v - lo) / (hi - lo)).round() as u8)
        .collect()
}

#[test]
fn fast_fires_at_a_rectangles_corners_and_not_on_its_edges_or_flat_areas() {
    let size = (160, 120);
    let box_px = [50, 40, 110, 90];
    for (inside, outside) in [(200, 40), (40, 200)] {
        let pixels = rectangle(size, box_px, inside, outside);
        let out = extract(one_level(), &pixels, size.0, size.1);
        let truth = [[50.0, 40.0], [109.0, 40.0], [50.0, 89.0], [109.0, 89.0]];
        // Every corner found is at one of the rectangle's, and every one of the rectangle's
        // is found. Within 2 px: on a sharp step the pixels along the edges next to the
        // corner pixel score the same, and the first of them in raster order is kept.
        for c in &out.corners {
            let nearest = truth
                .iter()
                .map(|t: &[f32; 2]| (c.x - t[0]).hypot(c.y - t[1]))
                .fold(f32::MAX, f32::min);
            assert!(
                nearest <= 2.0,
                "corner at ({}, {}) off the corners",
                c.x,
                c.y
            );
        }
        for t in truth {
            assert!(
                out.corners
                    .iter()
                    .any(|c| (c.x - t[0]).hypot(c.y - t[1]) <= 2.0),
                "no corner at {t:?} (inside {inside})"
            );
        }
        assert_eq!(out.descriptors.len(), out.corners.len());
    }
}

#[test]
fn the_fast_test_is_exact_on_hand_made_circles() {
    // A centre of 100 on a 7×7 patch; `bright` circle positions (clockwise from the top)
    // set to 100 + 30, the others to 100.
    let patch = |bright: &[usize]| {
        let mut pixels = vec![100u8; 49];
        for &k in bright {
            let (dx, dy) = fast::CIRCLE[k];
            pixels[((3 + dy) * 7 + 3 + dx) as usize] = 130;
        }
        pixels
    };
    let arc = |start: usize, len: usize| (start..start + len).map(|k| k % 16).collect::<Vec<_>>();
    for start in [0, 5, 11, 15] {
        // 9 contiguous (around the wrap too): a corner, scored 30 − 1.
        let pixels = patch(&arc(start, 9));
        assert_eq!(fast::corner_score(view(&pixels, 7, 7), 3, 3, 20), Some(29));
        // At a threshold of 30 it is not one.
        assert_eq!(fast::corner_score(view(&pixels, 7, 7), 3, 3, 30), None);
        // 8 contiguous: not a corner (an edge's half circle has 7).
        let pixels = patch(&arc(start, 8));
        assert_eq!(fast::corner_score(view(&pixels, 7, 7), 3, 3, 20), None);
    }
    // 12 bright but broken into two runs of 6: not a corner.
    let mut broken = arc(0, 6);
    broken.extend(arc(8, 6));
    let pixels = patch(&broken);
    assert_eq!(fast::corner_score(view(&pixels, 7, 7), 3, 3, 20), None);
}

/// [`fast::detect`] with its AVX2 row loop, compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn detect_with_avx2(
    image: GrayView<'_>,
    threshold: u8,
    scores: &mut Vec<u8>,
    found: &mut Vec<crate::Candidate>,
) {
    fast::detect(image, threshold, 0, scores, found, true);
}

#[test]
fn the_screened_detector_finds_exactly_the_corners_of_the_whole_circle_test() {
    // Every pixel tested on its whole circle, against the row detector with its two
    // screening steps: the same corners with the same scores, on noise (full range, so the
    // thresholds saturate at 0 and 255), on smooth texture, across widths that leave a
    // partial block at the end of a row.
    let mut state = 99;
    // (Widths whose rows of centres are a whole number of 32-centre blocks, not, and
    // shorter than one: 133 − 32 = 101, 96 − 32 = 64, 201 − 32 = 169, 60 − 32 = 28.)
    for (width, height) in [(133, 77), (96, 60), (201, 50), (60, 40)] {
        let noise: Vec<u8> = (0..width * height)
            .map(|_| (describe::tests_support::uniform(&mut state) * 256.0) as u8)
            .collect();
        for (kind, pixels) in [("noise", noise), ("texture", texture(width, height, 3))] {
            for threshold in [1, 5, 20, 60, 200] {
                let image = view(&pixels, width, height);
                let (mut scores, mut found) = (Vec::new(), Vec::new());
                fast::detect(image, threshold, 0, &mut scores, &mut found, false);
                // The AVX2 row loop where the CPU has it: the same corners and score map.
                #[cfg(target_arch = "x86_64")]
                if std::arch::is_x86_feature_detected!("avx2") {
                    let (mut avx2_scores, mut avx2_found) = (Vec::new(), Vec::new());
                    // SAFETY: the CPU has AVX2, as just checked.
                    #[allow(unsafe_code)]
                    unsafe {
                        detect_with_avx2(image, threshold, &mut avx2_scores, &mut avx2_found);
                    }
                    assert_eq!(
                        avx2_found, found,
                        "AVX2, {kind} {width}×{height}, threshold {threshold}"
                    );
                    assert!(
                        avx2_scores == scores,
                        "AVX2 score map, {kind} {width}×{height}"
                    );
                }
                let mut expected = Vec::new();
                for y in BORDER_PX..height - BORDER_PX {
                    for x in BORDER_PX..width - BORDER_PX {
                        if let Some(score) = fast::corner_score(image, x, y, threshold) {
                            expected.push(crate::Candidate {
                                x: x as u32,
                                y: y as u32,
                                score,
                            });
                        }
                    }
                }
                let case = format!("{kind} {width}×{height}, threshold {threshold}");
                assert_eq!(found, expected, "{case}");
                if kind == "noise" && threshold <= 20 {
                    assert!(!found.is_empty(), "{case}: no corners to compare");
                }
            }
        }
    }
}

#[test]
fn the_build_for_the_cpu_finds_what_the_baseline_build_finds() {
    // `extract` runs the work compiled for AVX2 where the CPU has it; the baseline build
    // (`extract_on_any_cpu`, what other CPUs run) must give the same corners and
    // descriptors, every level, with and without the grid.
    let mut state = 5;
    let (width, height) = (300, 220);
    let noise: Vec<u8> = (0..width * height)
        .map(|_| (describe::tests_support::uniform(&mut state) * 256.0) as u8)
        .collect();
    for pixels in [noise, texture(width, height, 11)] {
        for cell_px in [0, 24] {
            let params = Params {
                max_corners: 400,
                fast_threshold: 12,
                cell_px,
                ..Params::default()
            };
            let mut extractor = CornerExtractor::new(params).unwrap();
            let (mut dispatched, mut baseline) = (Corners::default(), Corners::default());
            extractor.extract(view(&pixels, width, height), &mut dispatched);
            extractor.extract_on_any_cpu(view(&pixels, width, height), &mut baseline);
            assert!(dispatched.len() > 100, "{} corners", dispatched.len());
            assert_eq!(dispatched, baseline, "grid {cell_px}");
        }
    }
}

#[test]
fn a_corner_scores_the_best_arcs_weakest_difference() {
    // Random circles, against the score written out: over the 16 arcs of 9 positions, the
    // best of each arc's smallest difference (brighter, or darker), less one.
    let mut state = 17;
    let mut checked = 0;
    for _ in 0..20_000 {
        let mut pixels = vec![0u8; 49];
        for p in &mut pixels {
            *p = (describe::tests_support::uniform(&mut state) * 256.0) as u8;
        }
        let centre = i16::from(pixels[24]);
        let around: Vec<i16> = fast::CIRCLE
            .iter()
            .map(|&(dx, dy)| i16::from(pixels[((3 + dy) * 7 + 3 + dx) as usize]) - centre)
            .collect();
        let best = |sign: i16| {
            (0..16)
                .map(|start| {
                    (0..9)
                        .map(|k| sign * around[(start + k) % 16])
                        .min()
                        .unwrap()
                })
                .max()
                .unwrap()
        };
        let strongest = best(1).max(best(-1));
        let expected = (strongest > 10).then(|| (strongest - 1).clamp(1, 255) as u8);
        assert_eq!(fast::corner_score(view(&pixels, 7, 7), 3, 3, 10), expected);
        checked += usize::from(expected.is_some());
    }
    assert!(checked > 100, "{checked} corners among the random circles");
}

#[test]
fn a_straight_edge_and_a_flat_image_have_no_corners() {
    let (width, height) = (120, 80);
    let mut pixels = vec![30u8; width * height];
    for row in pixels.chunks_exact_mut(width) {
        row[60..].fill(220);
    }
    assert!(extract(Params::default(), &pixels, width, height).is_empty());
    let flat = vec![128u8; width * height];
    assert!(extract(Params::default(), &flat, width, height).is_empty());
}

/// Hamming distance of two descriptors.
fn distance(a: &[u8; DESCRIPTOR_BYTES], b: &[u8; DESCRIPTOR_BYTES]) -> u32 {
    a.iter().zip(b).map(|(x, y)| (x ^ y).count_ones()).sum()
}

/// For each corner of `a` with a corner of `b` within 1 px of `map(a)`: the Hamming
/// distance of their descriptors.
fn paired_distances(a: &Corners, b: &Corners, map: impl Fn(f32, f32) -> (f32, f32)) -> Vec<u32> {
    a.corners
        .iter()
        .zip(&a.descriptors)
        .filter_map(|(c, d)| {
            let (x, y) = map(c.x, c.y);
            b.corners
                .iter()
                .position(|o| (o.x - x).hypot(o.y - y) <= 1.0)
                .map(|j| distance(d, &b.descriptors[j]))
        })
        .collect()
}

#[test]
fn descriptors_survive_a_brightness_shift_and_a_quarter_turn() {
    let (width, height) = (200, 200);
    let pixels = texture(width, height, 7);
    let params = Params {
        max_corners: 300,
        fast_threshold: 5,
        ..one_level()
    };
    let original = extract(params, &pixels, width, height);
    assert!(original.len() >= 50, "{} corners", original.len());

    // A brightness shift changes no comparison: the same corners, the same descriptors.
    let brighter: Vec<u8> = pixels.iter().map(|&p| p + 40).collect();
    let shifted = extract(params, &brighter, width, height);
    assert_eq!(shifted, Corners { ..shifted.clone() });
    assert_eq!(shifted.corners.len(), original.corners.len());
    assert_eq!(shifted.descriptors, original.descriptors);

    // A quarter turn clockwise: (x, y) → (height − 1 − y, x). Descriptors steer with the
    // corner's orientation, so a corner's descriptor stays close to its own, far from
    // others'.
    let mut turned = vec![0u8; width * height];
    for y in 0..height {
        for x in 0..width {
            turned[x * height + (height - 1 - y)] = pixels[y * width + x];
        }
    }
    let rotated = extract(params, &turned, height, width);
    let same = paired_distances(&original, &rotated, |x, y| (height as f32 - 1.0 - y, x));
    assert!(same.len() >= 30, "{} corners found again", same.len());
    let mean_same = same.iter().sum::<u32>() as f64 / same.len() as f64;
    let others: Vec<u32> = original
        .descriptors
        .iter()
        .zip(original.descriptors.iter().skip(1))
        .map(|(a, b)| distance(a, b))
        .collect();
    let mean_other = others.iter().sum::<u32>() as f64 / others.len() as f64;
    assert!(
        mean_same < 40.0 && mean_other > 70.0,
        "mean distance {mean_same:.1} to itself turned, {mean_other:.1} to another"
    );
}

#[test]
fn the_pattern_is_fixed_and_its_turned_points_inside_the_patch() {
    let a = describe::Pattern::new();
    let b = describe::Pattern::new();
    assert!(a == b);
    // The patch reaches 15 pixels left of and above the corner (16 right and below).
    assert!(a.max_offset() <= patch::CENTRE as i32);
}

#[test]
fn the_learned_pairs_are_distinct_within_15_px_and_at_least_5_px_apart() {
    let pairs = &crate::learned_pattern::LEARNED_PAIRS;
    assert_eq!(pairs.len(), DESCRIPTOR_BYTES * 8);
    for [(x1, y1), (x2, y2)] in pairs {
        for (x, y) in [(x1, y1), (x2, y2)] {
            assert!(i32::from(*x).pow(2) + i32::from(*y).pow(2) <= 15 * 15);
        }
        assert!(f64::from(x1 - x2).hypot(f64::from(y1 - y2)) >= 5.0);
    }
    let mut sorted: Vec<_> = pairs
        .iter()
        .map(|&[a, b]| if a < b { [a, b] } else { [b, a] })
        .collect();
    sorted.sort();
    sorted.dedup();
    assert_eq!(sorted.len(), pairs.len());
}

#[test]
fn corners_are_kept_to_the_count_spread_over_the_image_and_inside_the_border() {
    let (width, height) = (320, 240);
    let pixels = texture(width, height, 3);
    for levels in [1, 3, 8] {
        let params = Params {
            max_corners: 200,
            levels,
            fast_threshold: 5,
            cell_px: 32,
            ..Params::default()
        };
        let out = extract(params, &pixels, width, height);
        assert!(
            out.len() <= 200 && out.len() >= 150,
            "{} corners",
            out.len()
        );
        let mut quadrants = [0; 4];
        for c in &out.corners {
            let scale = params.scale_factor.powi(i32::from(c.level));
            let border = BORDER_PX as f32 * scale - 0.5;
            assert!(c.x >= border && c.x <= width as f32 - 1.0 - border + scale);
            assert!(c.y >= border && c.y <= height as f32 - 1.0 - border + scale);
            let q = usize::from(c.x >= width as f32 / 2.0)
                + 2 * usize::from(c.y >= height as f32 / 2.0);
            quadrants[q] += 1;
        }
        assert!(
            quadrants.iter().all(|&n| n * 8 >= out.len()),
            "{quadrants:?} of {} corners",
            out.len()
        );
    }
}

#[test]
fn degenerate_images_give_no_corners_and_bad_buffers_errors() {
    let params = Params::default();
    let mut extractor = CornerExtractor::new(params).unwrap();
    let mut out = Corners::default();
    let noise: Vec<u8> = (0..200 * 150u32)
        .map(|k| (k.wrapping_mul(2_654_435_761) >> 24) as u8)
        .collect();
    for (width, height) in [
        (0, 0),
        (0, 7),
        (7, 0),
        (1, 1),
        (2, 5),
        (5, 3),
        (33, 33),
        (34, 100),
        (100, 34),
        (67, 41),
    ] {
        let pixels = &noise[..width * height];
        extractor.extract(view(pixels, width, height), &mut out);
        assert!(out.len() == out.descriptors.len());
        if width <= 2 * BORDER_PX || height <= 2 * BORDER_PX {
            assert!(out.is_empty(), "{width}×{height}");
        }
    }
    // Noise, saturated, strided (rows 7 bytes apart with padding): no panic.
    extractor.extract(view(&noise, 200, 150), &mut out);
    assert!(!out.is_empty());
    let white = vec![255u8; 200 * 150];
    extractor.extract(view(&white, 200, 150), &mut out);
    assert!(out.is_empty());
    let strided = GrayView::new(&noise, 193, 150, 200).unwrap();
    extractor.extract(strided, &mut out);
    assert!(!out.is_empty());

    assert!(matches!(
        GrayView::new(&noise, 201, 150, 200),
        Err(EdgeLinesError::Size { .. })
    ));
    assert!(matches!(
        GrayView::packed(&noise, 200, 151),
        Err(EdgeLinesError::Size { .. })
    ));
    assert!(GrayView::new(&noise, 10, usize::MAX / 2, 10).is_err());
    for bad in [
        Params {
            levels: 0,
            ..params
        },
        Params {
            levels: MAX_LEVELS + 1,
            ..params
        },
        Params {
            scale_factor: 1.0,
            ..params
        },
        Params {
            scale_factor: f32::NAN,
            ..params
        },
        Params {
            fast_threshold: 0,
            ..params
        },
    ] {
        let error = CornerExtractor::new(bad).err().unwrap();
        assert!(matches!(error, CornersError::Param { .. }), "{error}");
        assert!(error.to_string().contains("corner parameter"));
    }
}

#[cfg(target_arch = "x86_64")]
#[test]
fn the_resampling_with_byte_shuffles_gives_the_pixels_of_the_plain_one() {
    // The AVX2 horizontal pass against the pixel-by-pixel one, at scales where every group
    // of 8 columns fits one shuffle (1.2, 1.44), where some do not (2.1) and none do (3.7),
    // on widths that leave partial groups; and both against bilinear sampling written out.
    assert!(
        std::arch::is_x86_feature_detected!("avx2"),
        "this test compares the AVX2 build; the CPU has no AVX2"
    );
    let mut state = 23;
    for (width, height) in [(301, 97), (160, 120), (77, 41)] {
        let pixels: Vec<u8> = (0..width * height)
            .map(|_| (describe::tests_support::uniform(&mut state) * 256.0) as u8)
            .collect();
        let source = view(&pixels, width, height);
        for scale in [1.2f32, 1.44, 2.1, 3.7] {
            let (w, h) = (
                (width as f32 / scale).round() as usize,
                (height as f32 / scale).round() as usize,
            );
            let mut resampler = resample::Resampler::default();
            let (mut shuffled, mut plain) = (vec![0u8; w * h], vec![0u8; w * h]);
            resampler.resample(source, &mut shuffled, w, true);
            resampler.resample(source, &mut plain, w, false);
            assert_eq!(shuffled, plain, "{width}×{height} at {scale}");
            // Bilinear with the same 8-bit weights, rounded once.
            let (sx, sy) = (width as f32 / w as f32, height as f32 / h as f32);
            let at = |d: usize, s: f32, len: usize| {
                let p = ((d as f32 + 0.5) * s - 0.5).max(0.0);
                let before = (p.floor() as usize).min(len - 1);
                let weight = (((p - before as f32) * 256.0).round() as u32).min(256);
                (before, (before + 1).min(len - 1), weight)
            };
            for y in 0..h {
                let (t, b, wy) = at(y, sy, height);
                for x in 0..w {
                    let (l, r, wx) = at(x, sx, width);
                    let p = |yy: usize, xx: usize| u32::from(pixels[yy * width + xx]);
                    let row = |yy| p(yy, l) * (256 - wx) + p(yy, r) * wx;
                    let sum = row(t) * (256 - wy) + row(b) * wy;
                    let expected = ((sum + (1 << 15)) >> 16) as u8;
                    assert_eq!(
                        plain[y * w + x],
                        expected,
                        "({x}, {y}) {width}×{height} at {scale}"
                    );
                }
            }
        }
    }
}

#[test]
fn the_orientation_is_the_discs_intensity_centroid_summed_pixel_by_pixel() {
    // The reference: the moments of the disc of radius 15 (rows of half-width
    // round(√(15² − dy²))) written out pixel by pixel, against the lane-wise sums, on
    // texture and on saturated noise (the sums' largest values).
    let (width, height) = (96, 80);
    let mut state = 7;
    let noise: Vec<u8> = (0..width * height)
        .map(|_| {
            if describe::tests_support::uniform(&mut state) < 0.5 {
                0
            } else {
                255
            }
        })
        .collect();
    let white = vec![255u8; width * height];
    let pattern = describe::Pattern::new();
    for pixels in [texture(width, height, 3), noise, white] {
        let image = view(&pixels, width, height);
        for y in BORDER_PX..height - BORDER_PX {
            for x in BORDER_PX..width - BORDER_PX {
                let (mut m10, mut m01) = (0i64, 0i64);
                for dy in -15i64..=15 {
                    let half = ((225 - dy * dy) as f64).sqrt().round() as i64;
                    for dx in -half..=half {
                        let p = i64::from(
                            image.row((y as i64 + dy) as usize)[(x as i64 + dx) as usize],
                        );
                        m10 += dx * p;
                        m01 += dy * p;
                    }
                }
                let expected = (m01 as f64).atan2(m10 as f64) as f32;
                assert_eq!(pattern.orientation(image, x, y), expected, "at ({x}, {y})");
            }
        }
    }
}

#[test]
fn the_smoothing_around_the_corners_is_the_whole_images_at_their_patches() {
    // The reference: the 7-tap kernel (sum 64) down the columns and then along the rows,
    // each pass rounded, edges clamped, written out pixel by pixel over the whole image;
    // the smoother works only band by band where patches lie, and must give the same
    // pixels over every patch: corners few and many, at the border and in clusters.
    const TAPS: [u32; 7] = [4, 9, 12, 14, 12, 9, 4];
    let mut state = 13;
    for (width, height) in [(120, 90), (61, 40), (300, 33)] {
        let noise: Vec<u8> = (0..width * height)
            .map(|_| (describe::tests_support::uniform(&mut state) * 256.0) as u8)
            .collect();
        let clamp = |v: isize, len: usize| v.clamp(0, len as isize - 1) as usize;
        let columns: Vec<u32> = (0..width * height)
            .map(|at| {
                let (x, y) = (at % width, at / width);
                let s: u32 = (0..7)
                    .map(|k| {
                        TAPS[k]
                            * u32::from(
                                noise[clamp(y as isize + k as isize - 3, height) * width + x],
                            )
                    })
                    .sum();
                (s + 32) >> 6
            })
            .collect();
        let smooth: Vec<u8> = (0..width * height)
            .map(|at| {
                let (x, y) = (at % width, at / width);
                let s: u32 = (0..7)
                    .map(|k| {
                        TAPS[k] * columns[y * width + clamp(x as isize + k as isize - 3, width)]
                    })
                    .sum();
                ((s + 32) >> 6) as u8
            })
            .collect();
        let inside = |n: usize, len: usize| BORDER_PX + n % (len - 2 * BORDER_PX);
        for count in [1, 5, 40] {
            let corners: Vec<crate::Candidate> = (0..count)
                .map(|_| {
                    let r = describe::tests_support::uniform(&mut state);
                    let s = describe::tests_support::uniform(&mut state);
                    crate::Candidate {
                        x: inside((r * 1e6) as usize, width) as u32,
                        y: inside((s * 1e6) as usize, height) as u32,
                        score: 1,
                    }
                })
                .chain(
                    [
                        (BORDER_PX, BORDER_PX),
                        (width - BORDER_PX - 1, height - BORDER_PX - 1),
                    ]
                    .map(|(x, y)| crate::Candidate {
                        x: x as u32,
                        y: y as u32,
                        score: 1,
                    }),
                )
                .collect();
            let mut smoother = pyramid::Smoother::default();
            // Twice, with a larger image before: the buffers reused.
            let large = vec![7u8; 400 * 100];
            smoother.smooth(view(&large, 400, 100), &corners[..1]);
            let got = smoother
                .smooth(view(&noise, width, height), &corners)
                .unwrap();
            for c in &corners {
                let (x, y) = (c.x as usize, c.y as usize);
                let patch = patch::patch(got, x, y).unwrap();
                for r in 0..patch::PATCH {
                    let top = y - patch::CENTRE + r;
                    let left = x - patch::CENTRE;
                    assert_eq!(
                        patch[r * patch::PATCH..][..patch::PATCH],
                        smooth[top * width + left..][..patch::PATCH],
                        "{width}×{height}, {count} corners, ({x}, {y}), patch row {r}"
                    );
                }
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[test]
fn the_suppression_16_columns_at_a_time_is_the_one_at_a_time() {
    // Scores with ties and plateaus (few distinct values), at every group of 16 columns
    // inside the border: the SSE2 maxima against the 3 × 3 test written out.
    let (width, height) = (90, 40);
    let mut state = 21;
    for levels in [2.0, 4.0, 256.0] {
        let scores: Vec<u8> = (0..width * height)
            .map(|_| (describe::tests_support::uniform(&mut state) * levels) as u8)
            .collect();
        for y in 1..height - 1 {
            for first in (16..width - 17).step_by(16) {
                let maxima = select::sse2::maxima(&scores, y * width + first, width);
                for lane in 0..16 {
                    let at = y * width + first + lane;
                    assert_eq!(
                        (maxima >> lane) & 1 == 1,
                        select::is_maximum(&scores, at, width),
                        "({}, {y}), {levels} levels",
                        first + lane
                    );
                }
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[test]
fn the_descriptor_with_byte_permutes_is_the_one_read_point_by_point() {
    // Where the CPU has AVX-512 VBMI: random patches (and flat and saturated ones, whose
    // comparisons all tie), at every one of the pattern's orientations.
    if !(std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512bw")
        && std::arch::is_x86_feature_detected!("avx512vbmi"))
    {
        return;
    }
    let pattern = describe::Pattern::new();
    let mut state = 17;
    let mut patches: Vec<[u8; patch::PATCH * patch::PATCH]> = (0..20)
        .map(|_| {
            std::array::from_fn(|_| (describe::tests_support::uniform(&mut state) * 256.0) as u8)
        })
        .collect();
    patches.push([0; patch::PATCH * patch::PATCH]);
    patches.push([255; patch::PATCH * patch::PATCH]);
    for (k, patch) in patches.iter().enumerate() {
        for step in 0..describe::ANGLE_STEPS {
            let angle_rad = step as f32 * std::f32::consts::TAU / describe::ANGLE_STEPS as f32;
            let rows: [&[u8; patch::PATCH]; patch::PATCH] = std::array::from_fn(|r| {
                patch[r * patch::PATCH..][..patch::PATCH]
                    .try_into()
                    .unwrap()
            });
            // SAFETY: the CPU has AVX-512 F, BW and VBMI, as checked above.
            #[allow(unsafe_code)]
            let permuted = unsafe { pattern.describe_vbmi(&rows, angle_rad) };
            assert_eq!(
                permuted,
                pattern.describe(patch, angle_rad),
                "patch {k}, step {step}"
            );
        }
    }
}
