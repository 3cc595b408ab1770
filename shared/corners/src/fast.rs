//! FAST-9 on whole rows, 32 centres at a time: screened on the compass and then the even
//! circle positions, and a block that passes scored whole (the best arc's weakest
//! difference per centre, in byte lanes), loops the compiler vectorises; no pixel is
//! tested on its own.

use crate::select::Candidate;
use crate::{BORDER_PX, GrayView};

/// The circle of radius 3 (Bresenham), clockwise from the top, `(dx, dy)`.
pub(crate) const CIRCLE: [(isize, isize); 16] = [
    (0, -3),
    (1, -3),
    (2, -2),
    (3, -1),
    (3, 0),
    (3, 1),
    (2, 2),
    (1, 3),
    (0, 3),
    (-1, 3),
    (-2, 2),
    (-3, 1),
    (-3, 0),
    (-3, -1),
    (-2, -2),
    (-1, -3),
];

/// Contiguous circle pixels a corner needs.
const ARC: usize = 9;

/// Finds the FAST-9 corners of `image` at least `edge_px` (and [`BORDER_PX`]) from its
/// borders: replaces `candidates` with them and `scores` with the image's score map (0 where
/// no corner).
///
/// Each row is worked [`LANES`] centres at a time in loops the compiler vectorises: first
/// the 4 compass positions (0, 4, 8, 12: an arc of 9 holds 2 neighbouring ones), and a
/// block none of whose centres passes is done; then the 8 even positions (an arc of 9 holds
/// 4 contiguous ones); a block with a centre passing both is scored whole, every centre on
/// its whole circle ([`block_scores`]), and its corners are listed.
#[inline(always)]
pub(crate) fn detect(
    image: GrayView<'_>,
    threshold: u8,
    edge_px: usize,
    scores: &mut Vec<u8>,
    candidates: &mut Vec<Candidate>,
) {
    let (width, height) = (image.width(), image.height());
    candidates.clear();
    scores.clear();
    scores.resize(width * height, 0);
    let edge = edge_px.max(BORDER_PX);
    if width <= 2 * edge || height <= 2 * edge {
        return;
    }
    let inner = width - 2 * edge;
    for y in edge..height - edge {
        let span = |dx: isize, dy: isize| {
            let start = edge.wrapping_add_signed(dx);
            &image.row(y.wrapping_add_signed(dy))[start..start + inner]
        };
        let centre = span(0, 0);
        let circle: [&[u8]; 16] = std::array::from_fn(|k| {
            let (dx, dy) = CIRCLE[k];
            span(dx, dy)
        });
        let score_row = &mut scores[y * width + edge..][..inner];
        // Blocks of LANES centres in fixed-size arrays, which the compiler vectorises; the
        // row's tail in a last, partial block (zero-padded, its centres past the row
        // dropped).
        for start in (0..inner).step_by(LANES) {
            let c = lane(centre, start);
            // (Arrays built with `from_fn`, not `map`, which is not inlined into the AVX2
            // build.)
            let (p0, p4, p8, p12) = (
                lane(circle[0], start),
                lane(circle[4], start),
                lane(circle[8], start),
                lane(circle[12], start),
            );
            let high: [u8; LANES] = std::array::from_fn(|i| c[i].saturating_add(threshold));
            let low: [u8; LANES] = std::array::from_fn(|i| c[i].saturating_sub(threshold));
            if !any_compass(&high, &low, [&p0, &p4, &p8, &p12]) {
                continue;
            }
            let (p2, p6, p10, p14) = (
                lane(circle[2], start),
                lane(circle[6], start),
                lane(circle[10], start),
                lane(circle[14], start),
            );
            let around = [&p0, &p2, &p4, &p6, &p8, &p10, &p12, &p14];
            if !even_screen(&high, &low, around) {
                continue;
            }

            let block = block_scores(&c, &circle, start, threshold);
            let count = (inner - start).min(LANES);
            score_row[start..start + count].copy_from_slice(&block[..count]);
            for (i, &score) in block[..count].iter().enumerate() {
                if score != 0 {
                    candidates.push(Candidate {
                        x: (edge + start + i) as u32,
                        y: y as u32,
                        score,
                    });
                }
            }
        }
    }
}

/// The FAST score of every centre of the block at `start` of a row (`centre`, and
/// `circle[k]`: the row's span under circle position k), 0 where it is no corner: over the
/// 16 arcs of [`ARC`] positions, the best of each arc's smallest difference from the centre
/// (brighter, or darker; a difference of the other sign counts as 0, which no arc of a
/// corner holds), less one, when that best is above `threshold`. An arc of 9 brighter and
/// one of 9 darker cannot share a circle of 16, so the better of the two is the corner's.
/// Lane-wise byte arithmetic (saturating differences, minima over runs of 2, 4, 8 and then
/// 9 positions by doubling), so the compiler vectorises it.
#[inline(always)]
fn block_scores(c: &[u8; LANES], circle: &[&[u8]; 16], start: usize, threshold: u8) -> [u8; LANES] {
    let mut brighter = [[0u8; LANES]; 16];
    let mut darker = [[0u8; LANES]; 16];
    for k in 0..16 {
        let p = lane(circle[k], start);
        for i in 0..LANES {
            brighter[k][i] = p[i].saturating_sub(c[i]);
            darker[k][i] = c[i].saturating_sub(p[i]);
        }
    }
    let (b, d) = (best_arc(&brighter), best_arc(&darker));
    let mut out = [0u8; LANES];
    for i in 0..LANES {
        let best = b[i].max(d[i]);
        out[i] = if best > threshold { best - 1 } else { 0 };
    }
    out
}

/// Per lane, the largest over the 16 arcs of [`ARC`] circle positions of the arc's
/// smallest value (`values[k]`: circle position k).
#[inline(always)]
fn best_arc(values: &[[u8; LANES]; 16]) -> [u8; LANES] {
    let mut two = [[0u8; LANES]; 16];
    let mut four = [[0u8; LANES]; 16];
    for k in 0..16 {
        let (a, b) = (&values[k], &values[(k + 1) % 16]);
        for i in 0..LANES {
            two[k][i] = a[i].min(b[i]);
        }
    }
    for k in 0..16 {
        let (a, b) = (&two[k], &two[(k + 2) % 16]);
        for i in 0..LANES {
            four[k][i] = a[i].min(b[i]);
        }
    }
    let mut best = [0u8; LANES];
    for k in 0..16 {
        let (a, b, last) = (&four[k], &four[(k + 4) % 16], &values[(k + ARC - 1) % 16]);
        for i in 0..LANES {
            best[i] = best[i].max(a[i].min(b[i]).min(last[i]));
        }
    }
    best
}

/// Centres a block of the screening pass holds (a 256-bit vector of bytes).
const LANES: usize = 32;

/// `row[start..start + LANES]`, zero-padded past the row's end.
#[inline(always)]
fn lane(row: &[u8], start: usize) -> [u8; LANES] {
    // (`first_chunk`, not `from_fn`, whose `try_from_fn` was not inlined into the AVX2
    // build.)
    match row.get(start..).and_then(<[u8]>::first_chunk::<LANES>) {
        Some(&whole) => whole,
        None => partial_lane(row, start),
    }
}

/// [`lane`] at the end of a row (out of line: once a row).
#[cold]
fn partial_lane(row: &[u8], start: usize) -> [u8; LANES] {
    let mut out = [0; LANES];
    let rest = &row[start.min(row.len())..];
    out[..rest.len()].copy_from_slice(rest);
    out
}

/// Whether any centre of a block has two neighbouring compass positions (`compass[k]`:
/// circle position 4k) both above its `high` (the centre plus the threshold, saturated),
/// or both below its `low`. Whole-lane byte masks (0 or 255), so the loop vectorises.
#[inline(always)]
fn any_compass(high: &[u8; LANES], low: &[u8; LANES], compass: [&[u8; LANES]; 4]) -> bool {
    let [p0, p4, p8, p12] = compass;
    let mut any = [0u8; LANES];
    for i in 0..LANES {
        let (h, l) = (high[i], low[i]);
        let above = |p: &[u8; LANES]| if p[i] > h { 0xFF } else { 0 };
        let below = |p: &[u8; LANES]| if p[i] < l { 0xFF } else { 0 };
        let (b0, b4, b8, b12) = (above(p0), above(p4), above(p8), above(p12));
        let (d0, d4, d8, d12) = (below(p0), below(p4), below(p8), below(p12));
        any[i] = (b0 & b4)
            | (b4 & b8)
            | (b8 & b12)
            | (b12 & b0)
            | (d0 & d4)
            | (d4 & d8)
            | (d8 & d12)
            | (d12 & d0);
    }
    any.iter().fold(0, |a, &b| a | b) != 0
}

/// The screening of one block on the 8 even circle positions (`around[k]`: position 2k):
/// whether any centre has 4 contiguous ones all above its `high`, or all below its `low`.
#[inline(always)]
fn even_screen(high: &[u8; LANES], low: &[u8; LANES], around: [&[u8; LANES]; 8]) -> bool {
    let mut out = [0; LANES];
    for i in 0..LANES {
        let (h, l) = (high[i], low[i]);
        let bright: [u8; 8] = std::array::from_fn(|k| u8::from(around[k][i] > h));
        let dark: [u8; 8] = std::array::from_fn(|k| u8::from(around[k][i] < l));
        out[i] = four_in_a_row(bright) | four_in_a_row(dark);
    }
    out.iter().fold(0, |a, &b| a | b) != 0
}

/// 1 when 4 contiguous of the 8 even circle positions (around the circle) are 1, as every
/// arc of 9 positions has; else 0. Plain byte arithmetic, so the row loop vectorises.
#[inline(always)]
fn four_in_a_row([e0, e1, e2, e3, e4, e5, e6, e7]: [u8; 8]) -> u8 {
    let (a, b, c, d) = (e0 & e1, e2 & e3, e4 & e5, e6 & e7);
    let (ab, bc, cd, da) = (e1 & e2, e3 & e4, e5 & e6, e7 & e0);
    // Runs starting at an even position (pairs of pairs), then at an odd one.
    (a & b) | (b & c) | (c & d) | (d & a) | (ab & bc) | (bc & cd) | (cd & da) | (da & ab)
}

#[cfg(test)]
pub(crate) use whole_circle::corner_score;

/// The FAST test written out for one pixel on its whole circle, the reference the row
/// detector is tested against.
#[cfg(test)]
mod whole_circle {
    use super::{ARC, CIRCLE};
    use crate::GrayView;

    /// `values` with their signs turned.
    fn negated(mut values: [i16; 16]) -> [i16; 16] {
        for v in &mut values {
            *v = -*v;
        }
        values
    }

    /// Whether `mask` has [`ARC`] contiguous set bits, around the circle.
    fn has_arc(mask: u16) -> bool {
        let twice = u32::from(mask) | (u32::from(mask) << 16);
        let mut run = twice & (twice >> 1);
        run &= run >> 2;
        run &= run >> 4;
        run &= twice >> 8;
        run & 0xFFFF != 0
    }

    /// The circle's 16 pixels as offsets into an image of rows `stride` bytes apart, from
    /// `reach` bytes before the centre (so none is negative).
    pub(crate) struct Ring {
        offsets: [usize; 16],
        reach: usize,
    }

    impl Ring {
        /// The circle in an image of rows `stride` bytes apart.
        pub(crate) fn new(stride: usize) -> Self {
            let reach = 3 * stride + 3;
            let offsets =
                CIRCLE.map(|(dx, dy)| (reach as isize + dy * stride as isize + dx) as usize);
            Self { offsets, reach }
        }

        /// Whether the pixel `at` of `pixels` (rows of the ring's stride) is a FAST-9 corner
        /// at `threshold`, and if so its score: the largest threshold at which it still is one,
        /// i.e. the best, over the arcs of 9, of the smallest difference along the arc (brighter
        /// or darker) less one. `None` too when the circle leaves `pixels`.
        pub(crate) fn score(&self, pixels: &[u8], at: usize, threshold: u8) -> Option<u8> {
            let start = at.checked_sub(self.reach)?;
            let window = pixels.get(start..start + 2 * self.reach + 1)?;
            let centre = i16::from(window[self.reach]);
            let mut around = [0i16; 16];
            for (d, &at) in around.iter_mut().zip(&self.offsets) {
                *d = i16::from(window[at]) - centre;
            }
            let t = i16::from(threshold);
            let (mut brighter, mut darker) = (0u16, 0u16);
            for (k, &d) in around.iter().enumerate() {
                brighter |= u16::from(d > t) << k;
                darker |= u16::from(d < -t) << k;
            }
            let best = match (has_arc(brighter), has_arc(darker)) {
                (false, false) => return None,
                (true, false) => best_arc_minimum(around),
                (false, true) => best_arc_minimum(negated(around)),
                (true, true) => best_arc_minimum(around).max(best_arc_minimum(negated(around))),
            };
            Some((best - 1).clamp(1, 255) as u8)
        }
    }

    /// Whether `(x, y)` is a FAST-9 corner of `image` at `threshold`, and if so its score
    /// ([`Ring::score`]).
    pub(crate) fn corner_score(
        image: GrayView<'_>,
        x: usize,
        y: usize,
        threshold: u8,
    ) -> Option<u8> {
        Ring::new(image.stride()).score(image.pixels(), y * image.stride() + x, threshold)
    }

    /// The largest, over the 16 arcs of [`ARC`] positions, of the arc's smallest value.
    fn best_arc_minimum(values: [i16; 16]) -> i16 {
        // The circle twice over, so that every run is a window of one array; minima over runs
        // of 2, 4, 8 and then 9 positions by doubling (entry k: the run starting at position
        // k), each a lane-wise minimum of two windows (loops the compiler vectorises).
        let mut twice = [0i16; 32];
        twice[..16].copy_from_slice(&values);
        twice[16..].copy_from_slice(&values);
        let two: [i16; 24] = std::array::from_fn(|k| twice[k].min(twice[k + 1]));
        let four: [i16; 20] = std::array::from_fn(|k| two[k].min(two[k + 2]));
        let eight: [i16; 16] = std::array::from_fn(|k| four[k].min(four[k + 4]));
        let nine: [i16; 16] = std::array::from_fn(|k| eight[k].min(twice[k + ARC - 1]));
        nine.into_iter().fold(i16::MIN, i16::max)
    }
}
