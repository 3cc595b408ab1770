//! FAST-9 on whole rows: each of the 16 circle positions is compared with every centre of a
//! row in one pass, setting one bit of a 16-bit mask per centre ("brighter by more than the
//! threshold", and "darker"), a loop the compiler vectorises; a mask with 9 contiguous bits
//! (around the circle) marks a corner, which is then scored.

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
/// borders: replaces
/// `candidates` with them and `scores` with the image's score map (0 where no corner).
///
/// Each row is first screened with the 8 even positions of the circle (an arc of 9 holds 4
/// contiguous ones), in one vectorised pass; the few centres that pass are tested on the
/// whole circle.
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
        // The even circle positions 0, 2, …, 14.
        let even: [&[u8]; 8] = std::array::from_fn(|k| {
            let (dx, dy) = CIRCLE[2 * k];
            span(dx, dy)
        });
        // Blocks of 16 centres in fixed-size arrays, which the compiler vectorises; the
        // row's tail in a last, partial block (zero-padded, its flags past the row dropped);
        // the few centres that pass are tested on the whole circle.
        for start in (0..inner).step_by(LANES) {
            let block = [
                lane(centre, start),
                lane(even[0], start),
                lane(even[1], start),
                lane(even[2], start),
                lane(even[3], start),
                lane(even[4], start),
                lane(even[5], start),
                lane(even[6], start),
                lane(even[7], start),
            ];
            let flags = compass_block(&block, threshold);
            // One bit per centre that passed, past the row's end cleared.
            let mut passed = flags
                .iter()
                .enumerate()
                .fold(0u32, |bits, (i, &f)| bits | (u32::from(f) << i));
            if inner - start < LANES {
                passed &= (1 << (inner - start)) - 1;
            }
            while passed != 0 {
                let x = edge + start + passed.trailing_zeros() as usize;
                passed &= passed - 1;
                if let Some(score) = corner_score(image, x, y, threshold) {
                    scores[y * width + x] = score;
                    candidates.push(Candidate {
                        x: x as u32,
                        y: y as u32,
                        score,
                    });
                }
            }
        }
    }
}

/// Centres a block of the screening pass holds.
const LANES: usize = 16;

/// `row[start..start + LANES]`, zero-padded past the row's end.
#[inline(always)]
fn lane(row: &[u8], start: usize) -> [u8; LANES] {
    let mut out = [0; LANES];
    match row.get(start..start + LANES) {
        Some(whole) => out.copy_from_slice(whole),
        None => {
            let rest = &row[start.min(row.len())..];
            out[..rest.len()].copy_from_slice(rest);
        }
    }
    out
}

/// The screening of one block: `block[0]` the centres, `block[1 + k]` circle position 2k;
/// per centre 1 when 4 contiguous even positions are all brighter than the centre by more
/// than `threshold`, or all darker, else 0.
#[inline(always)]
fn compass_block(block: &[[u8; LANES]; 9], threshold: u8) -> [u8; LANES] {
    let mut out = [0; LANES];
    for (i, o) in out.iter_mut().enumerate() {
        let c = block[0][i];
        let (high, low) = (c.saturating_add(threshold), c.saturating_sub(threshold));
        let around: [u8; 8] = std::array::from_fn(|k| block[1 + k][i]);
        let bright = four_in_a_row(around.map(|p| u8::from(p > high)));
        let dark = four_in_a_row(around.map(|p| u8::from(p < low)));
        *o = bright | dark;
    }
    out
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

/// Whether `mask` has [`ARC`] contiguous set bits, around the circle.
fn has_arc(mask: u16) -> bool {
    let twice = u32::from(mask) | (u32::from(mask) << 16);
    let mut run = twice & (twice >> 1);
    run &= run >> 2;
    run &= run >> 4;
    run &= twice >> 8;
    run & 0xFFFF != 0
}

/// Whether `(x, y)` is a FAST-9 corner at `threshold`, and if so its score: the largest
/// threshold at which it still is one, i.e. the best, over the arcs of 9, of the smallest
/// difference along the arc (brighter or darker) less one.
pub(crate) fn corner_score(image: GrayView<'_>, x: usize, y: usize, threshold: u8) -> Option<u8> {
    let stride = image.stride();
    let reach = 3 * stride + 3;
    let start = (y * stride + x).checked_sub(reach)?;
    let window = image.pixels().get(start..start + 2 * reach + 1)?;
    let centre = i16::from(window[reach]);
    let around: [i16; 16] = std::array::from_fn(|k| {
        let (dx, dy) = CIRCLE[k];
        let at = (reach as isize + dy * stride as isize + dx) as usize;
        i16::from(window[at]) - centre
    });
    let t = i16::from(threshold);
    let (mut brighter, mut darker) = (0u16, 0u16);
    for (k, &d) in around.iter().enumerate() {
        brighter |= u16::from(d > t) << k;
        darker |= u16::from(d < -t) << k;
    }
    let best = match (has_arc(brighter), has_arc(darker)) {
        (false, false) => return None,
        (true, false) => best_arc_minimum(around),
        (false, true) => best_arc_minimum(around.map(|d| -d)),
        (true, true) => best_arc_minimum(around).max(best_arc_minimum(around.map(|d| -d))),
    };
    Some((best - 1).clamp(1, 255) as u8)
}

/// The largest, over the 16 arcs of [`ARC`] positions, of the arc's smallest value.
fn best_arc_minimum(values: [i16; 16]) -> i16 {
    // Minima over runs of 2, 4, 8 and then 9 positions, by doubling (lane k: the run
    // starting at position k, around the circle).
    let rotate =
        |a: [i16; 16], by: usize| -> [i16; 16] { std::array::from_fn(|k| a[(k + by) % 16]) };
    let lanewise_min =
        |a: [i16; 16], b: [i16; 16]| -> [i16; 16] { std::array::from_fn(|k| a[k].min(b[k])) };
    let two = lanewise_min(values, rotate(values, 1));
    let four = lanewise_min(two, rotate(two, 2));
    let eight = lanewise_min(four, rotate(four, 4));
    let nine = lanewise_min(eight, rotate(values, ARC - 1));
    nine.into_iter().fold(i16::MIN, i16::max)
}
