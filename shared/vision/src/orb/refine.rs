//! Sub-pixel refinement of point matches: the stereo partner's column, and a tracked
//! point's position in the next frame.

use crate::GrayImage;
use crate::cpu::with_avx2;
use linetrack_geometry::Point;

/// Half the side of the windows the sub-pixel refinements compare (11 × 11).
pub(super) const HALF: i64 = 5;
pub(super) const SIDE: usize = (2 * HALF + 1) as usize;

/// The window of `pixels` (an image `width` wide) centred on pixel `(u, v)`, which the caller
/// has checked lies at least [`HALF`] pixels inside the image (on the stack: this runs for
/// every point match of every frame).
pub(super) fn window<T: From<u8> + Copy + Default>(
    pixels: &[u8],
    width: i64,
    u: i64,
    v: i64,
) -> [T; SIDE * SIDE] {
    let mut values = [T::default(); SIDE * SIDE];
    for (row_values, y) in values.chunks_exact_mut(SIDE).zip(v - HALF..=v + HALF) {
        let start = (y * width + u - HALF) as usize;
        widen(&pixels[start..start + SIDE], row_values);
    }
    values
}

/// `pixels` into `values` as integers.
pub(super) fn widen<T: From<u8>>(pixels: &[u8], values: &mut [T]) {
    for (value, &p) in values.iter_mut().zip(pixels) {
        *value = T::from(p);
    }
}

/// The sum of the products of `a`'s and `b`'s values, pair by pair. Exact for windows of
/// pixels: 121 products of at most 255² stay far below `i32::MAX`. (Wrapping operations,
/// which cannot wrap here, so that the sum is vectorised in builds with overflow checks
/// too, such as the tests'.)
#[inline(always)]
pub(super) fn sum_of_products(a: &[i16], b: &[i16]) -> i32 {
    a.iter().zip(b).fold(0i32, |sum, (&a, &b)| {
        sum.wrapping_add(i32::from(a).wrapping_mul(i32::from(b)))
    })
}

/// The sum of `values` (exact for a window of pixels, see [`sum_of_products`]).
#[inline(always)]
pub(super) fn sum_of(values: &[i16]) -> i32 {
    values
        .iter()
        .fold(0i32, |sum, &v| sum.wrapping_add(i32::from(v)))
}

/// Whether the windows centred on pixel `(u, v)` and shifted by up to `reach` (columns,
/// rows) either way all lie inside an image of `size` (width, height).
pub(super) fn windows_inside(
    u: i64,
    v: i64,
    reach: (i64, i64),
    (width, height): (i64, i64),
) -> bool {
    // (Compared so that no sum overflows: a point at infinity rounds to i64::MAX.)
    u >= HALF + reach.0
        && u < width - HALF - reach.0
        && v >= HALF + reach.1
        && v < height - HALF - reach.1
}

/// The fraction of a pixel, within ±0.5, by which a parabola through three costs at
/// shifts −1, 0 and 1 puts its minimum (0 when they do not curve upwards).
fn parabola_minimum(before: f64, at: f64, after: f64) -> f64 {
    let curvature = before - 2.0 * at + after;
    if curvature > 0.0 {
        (0.5 * (before - after) / curvature).clamp(-0.5, 0.5)
    } else {
        0.0
    }
}

/// The two images' pixels and their common size, or `None` when they differ in size or are
/// not stored in one block.
pub(super) fn pixels_of_pair<'a>(
    first: &'a GrayImage,
    second: &'a GrayImage,
) -> Option<(&'a [u8], &'a [u8], i64, i64)> {
    let size = |image: &GrayImage| (i64::from(image.width()), i64::from(image.height()));
    if size(first) != size(second) {
        return None;
    }
    let (width, height) = size(first);
    Some((first.pixels()?, second.pixels()?, width, height))
}

/// Refines the right image's column of a stereo point match to a fraction of a pixel.
///
/// Detected keypoints sit on whole pixels (of their pyramid level), so disparities come in
/// whole pixels too, and every point of a surface at one depth is rounded the same way:
/// a depth bias that averaging cannot remove. Here an 11 × 11 window around the pixel
/// nearest `left` is compared with windows of the right image on the same row, up to 3 px
/// either side of `right`, by the sum of absolute differences after removing each window's
/// mean (so a gain offset between the cameras does not matter), and a parabola through the
/// best shift and its two neighbours gives the fraction. The result is the column of `left`
/// itself: a keypoint of a coarser pyramid level lies between pixels, and its offset from
/// the window's centre is carried over. `None` when a window leaves an image or the best
/// shift is at the end of the search (the match is then left as it was).
pub fn refine_stereo_column(
    left_image: &GrayImage,
    right_image: &GrayImage,
    left: Point,
    right: Point,
) -> Option<f64> {
    with_avx2(
        #[inline(always)]
        || refine_stereo_column_portably(left_image, right_image, left, right),
    )
}

/// [`refine_stereo_column`] for any CPU; inlined where it is compiled for more
/// ([`with_avx2`]).
#[inline(always)]
fn refine_stereo_column_portably(
    left_image: &GrayImage,
    right_image: &GrayImage,
    left: Point,
    right: Point,
) -> Option<f64> {
    const SEARCH: i64 = 3;
    let (lp, rp, width, height) = pixels_of_pair(left_image, right_image)?;
    let (ul, v) = (left.x.round() as i64, left.y.round() as i64);
    let ur = right.x.round() as i64;
    let size = (width, height);
    if !(windows_inside(ul, v, (0, 0), size) && windows_inside(ur, v, (SEARCH, 0), size)) {
        return None;
    }
    let mean_removed = |pixels: &[u8], u: i64| {
        let mut values: [i32; SIDE * SIDE] = window(pixels, width, u, v);
        let mean = values.iter().sum::<i32>() / values.len() as i32;
        values.iter_mut().for_each(|p| *p -= mean);
        values
    };
    let reference = mean_removed(lp, ul);
    let mut costs = [0.0f64; (2 * SEARCH + 1) as usize];
    for (cost, shift) in costs.iter_mut().zip(-SEARCH..=SEARCH) {
        let candidate = mean_removed(rp, ur + shift);
        // Summed as integers, then converted: the same value as summing them as f64 (a sum
        // of small integers is exact in f64, in any order). At most 121 × 510: no wrap.
        let sum = reference
            .iter()
            .zip(&candidate)
            .fold(0i32, |sum, (a, b)| sum.wrapping_add((a - b).abs()));
        *cost = f64::from(sum);
    }
    let best = (0..costs.len()).min_by(|&a, &b| costs[a].total_cmp(&costs[b]))?;
    if best == 0 || best == costs.len() - 1 {
        return None;
    }
    let fraction = parabola_minimum(costs[best - 1], costs[best], costs[best + 1]);
    Some((ur + best as i64 - SEARCH) as f64 + fraction + (left.x - ul as f64))
}

/// Smallest normalised correlation at which [`refine_track`] believes its best shift.
pub const MIN_TRACK_CORRELATION: f64 = 0.8;

/// Where `from` (a point of the previous image) lies in the current image, to a fraction
/// of a pixel, given `to`, the keypoint it was matched to there.
///
/// A frame-to-frame point match pairs two detections, each on a whole pixel of its own
/// pyramid level: up to half a pixel (several full-resolution pixels at a coarse level)
/// from where the other one's point really is. Here the 11 × 11 window around the pixel
/// nearest `from` is looked for around `to`, up to 2 px either way in both directions, by
/// zero-mean normalised correlation (the exposure may change between frames: gain and
/// offset do not matter); a parabola through the best shift and its neighbours gives the
/// fraction along each axis, and `from`'s offset from its window's centre is carried over.
/// `None` when a window leaves an image, the best shift is at the edge of the search, or
/// its correlation is under [`MIN_TRACK_CORRELATION`] (the match is then left as it was).
pub fn refine_track(
    previous_image: &GrayImage,
    current_image: &GrayImage,
    from: Point,
    to: Point,
) -> Option<Point> {
    with_avx2(
        #[inline(always)]
        || refine_track_portably(previous_image, current_image, from, to),
    )
}

/// [`refine_track`] for any CPU; inlined where it is compiled for more ([`with_avx2`]).
#[inline(always)]
fn refine_track_portably(
    previous_image: &GrayImage,
    current_image: &GrayImage,
    from: Point,
    to: Point,
) -> Option<Point> {
    const SEARCH: i64 = 2;
    const SHIFTS: usize = (2 * SEARCH + 1) as usize;
    let (pp, cp, width, height) = pixels_of_pair(previous_image, current_image)?;
    let (uf, vf) = (from.x.round() as i64, from.y.round() as i64);
    let (ut, vt) = (to.x.round() as i64, to.y.round() as i64);
    let size = (width, height);
    if !(windows_inside(uf, vf, (0, 0), size) && windows_inside(ut, vt, (SEARCH, SEARCH), size)) {
        return None;
    }
    // Correlations from integer sums (11 × 11 × 255² fits an i32): Σa, Σa², then per
    // candidate Σb, Σb² and Σab.
    let n = (SIDE * SIDE) as f64;
    // (Pixels as i16: products of two fit an i32, and the sums of products of 16-bit
    // values are what the vector units multiply-add fastest.)
    let reference: [i16; SIDE * SIDE] = window(pp, width, uf, vf);
    let sum_a = sum_of(&reference);
    let sum_aa = sum_of_products(&reference, &reference);
    let var_a = f64::from(sum_aa) - f64::from(sum_a).powi(2) / n;
    if var_a < 1.0 {
        return None;
    }
    // Costs are 1 − correlation, row-major over the shifts (dy, dx). For each dx the
    // columns the windows of that dx cover are copied once, row after row, for all five
    // dy: the window at dy is then the 121 values from row dy on.
    let mut costs = [[0.0f64; SHIFTS]; SHIFTS];
    let mut columns = [[0i16; SIDE * (SIDE + SHIFTS - 1)]; SHIFTS];
    for (strip, dx) in columns.iter_mut().zip(-SEARCH..=SEARCH) {
        let left = (ut + dx - HALF) as usize;
        for (values, y) in strip.chunks_exact_mut(SIDE).zip(vt - HALF - SEARCH..) {
            let start = (y * width) as usize + left;
            widen(&cp[start..start + SIDE], values);
        }
    }
    for (row, dy) in costs.iter_mut().zip(0..) {
        for (cost, strip) in row.iter_mut().zip(&columns) {
            let candidate = &strip[dy * SIDE..dy * SIDE + SIDE * SIDE];
            let sum_b = sum_of(candidate);
            let sum_bb = sum_of_products(candidate, candidate);
            let sum_ab = sum_of_products(&reference, candidate);
            let var_b = f64::from(sum_bb) - f64::from(sum_b).powi(2) / n;
            let covariance = f64::from(sum_ab) - f64::from(sum_a) * f64::from(sum_b) / n;
            *cost = if var_b > 0.0 {
                1.0 - covariance / (var_a * var_b).sqrt()
            } else {
                2.0
            };
        }
    }
    let (by, bx) = (0..SHIFTS)
        .flat_map(|y| (0..SHIFTS).map(move |x| (y, x)))
        .min_by(|&(ay, ax), &(by, bx)| costs[ay][ax].total_cmp(&costs[by][bx]))?;
    let last = SHIFTS - 1;
    if bx == 0 || by == 0 || bx == last || by == last || 1.0 - costs[by][bx] < MIN_TRACK_CORRELATION
    {
        return None;
    }
    let fx = parabola_minimum(costs[by][bx - 1], costs[by][bx], costs[by][bx + 1]);
    let fy = parabola_minimum(costs[by - 1][bx], costs[by][bx], costs[by + 1][bx]);
    Some(Point::new(
        (ut + bx as i64 - SEARCH) as f64 + fx + (from.x - uf as f64),
        (vt + by as i64 - SEARCH) as f64 + fy + (from.y - vf as f64),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sub-pixel refinements give the same answers, bit for bit, built for AVX2 (where
    /// this CPU has it: what the public functions run) and for the baseline CPU, at every
    /// position of a grid over two textured images that differ by a shift, a gain and
    /// noise: both refined and refused matches. Points at infinity or NaN are refused.
    #[test]
    fn the_refinements_answer_the_same_for_every_cpu() {
        let textured = |shift: f64, gain: f64, seed: u32| {
            let (width, height) = (160, 120);
            let pixels: Vec<u8> = (0..width * height)
                .map(|i| {
                    let (x, y) = ((i % width) as f64 + shift, (i / width) as f64);
                    let smooth = 120.0 + 60.0 * (x / 5.0).sin() * (y / 7.0).cos();
                    let noise = (i as u32 ^ seed).wrapping_mul(2_654_435_761) >> 29;
                    (gain * smooth + f64::from(noise)).clamp(0.0, 255.0) as u8
                })
                .collect();
            GrayImage::from_pixels(width, height, &pixels, "texture").unwrap()
        };
        let (first, second) = (textured(0.0, 1.0, 1), textured(1.6, 1.1, 2));
        let (mut refined, mut refused) = (0, 0);
        for y in (0..120).step_by(3) {
            for x in (0..160).step_by(3) {
                let from = Point::new(f64::from(x) + 0.3, f64::from(y) - 0.2);
                let to = Point::new(f64::from(x) - 2.0, f64::from(y) + 1.0);
                let track = refine_track(&first, &second, from, to);
                assert_eq!(track, refine_track_portably(&first, &second, from, to));
                let column = refine_stereo_column(&first, &second, from, to);
                assert_eq!(
                    column.map(f64::to_bits),
                    refine_stereo_column_portably(&first, &second, from, to).map(f64::to_bits)
                );
                match track {
                    Some(_) => refined += 1,
                    None => refused += 1,
                }
            }
        }
        assert!(
            refined > 100 && refused > 100,
            "{refined} refined, {refused} refused"
        );
        // A point at infinity or NaN is refused, not an overflow or an index out of range.
        for odd in [f64::INFINITY, f64::NEG_INFINITY, f64::NAN, 1e300] {
            let (good, bad) = (Point::new(50.0, 50.0), Point::new(odd, odd));
            assert_eq!(refine_track(&first, &second, bad, good), None);
            assert_eq!(refine_track(&first, &second, good, bad), None);
            assert_eq!(refine_stereo_column(&first, &second, bad, good), None);
            assert_eq!(refine_stereo_column(&first, &second, good, bad), None);
        }
    }
}
