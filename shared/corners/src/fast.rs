//! FAST-9 on whole rows, 32 centres at a time: screened on the compass and then the even
//! circle positions, and a block that passes scored whole (the best arc's weakest
//! difference per centre, in byte lanes), loops the compiler vectorises; no pixel is
//! tested on its own.

use crate::Candidate;
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
/// block none of whose centres passes is done; then the 8 even positions and the 8 odd
/// ones (an arc of 9 holds 4 contiguous of each), each way (brighter, darker); a block with
/// a centre passing both is scored whole, every centre on its whole circle, the ways that
/// passed only ([`block_scores`]), and its corners are listed. With `avx2` (the CPU has
/// it, checked by the caller), rows of at least [`LANES`] centres go through the AVX2
/// loop (`avx2::row`), which screens on the compass and even positions only and scores
/// both ways (measured faster: the odd screen and the choice of ways cost more, in tests
/// and branches the predictor cannot guess, than the scoring they spare).
#[inline(always)]
pub(crate) fn detect(
    image: GrayView<'_>,
    threshold: u8,
    edge_px: usize,
    scores: &mut Vec<u8>,
    candidates: &mut Vec<Candidate>,
    avx2: bool,
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
        // (A loop, not `from_fn`, whose `try_from_fn` is not inlined into the AVX2 build.)
        let mut circle: [&[u8]; 16] = [centre; 16];
        for (span_k, &(dx, dy)) in circle.iter_mut().zip(&CIRCLE) {
            *span_k = span(dx, dy);
        }
        let score_row = &mut scores[y * width + edge..][..inner];
        #[cfg(target_arch = "x86_64")]
        if avx2 && inner >= LANES {
            // SAFETY: the CPU has AVX2 (the caller's word); every span is `inner` long.
            #[allow(unsafe_code)]
            unsafe {
                avx2::row(centre, &circle, threshold, (edge, y), score_row, candidates);
            }
            continue;
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = avx2;
        // Blocks of LANES centres in fixed-size arrays, which the compiler vectorises; the
        // row's tail in a last, partial block (zero-padded, its centres past the row
        // dropped).
        for start in (0..inner).step_by(LANES) {
            let c = lane(centre, start);
            let (p0, p4, p8, p12) = (
                lane(circle[0], start),
                lane(circle[4], start),
                lane(circle[8], start),
                lane(circle[12], start),
            );
            let mut high = [0u8; LANES];
            let mut low = [0u8; LANES];
            for i in 0..LANES {
                high[i] = c[i].saturating_add(threshold);
                low[i] = c[i].saturating_sub(threshold);
            }
            if !any_compass(&high, &low, [&p0, &p4, &p8, &p12]) {
                continue;
            }
            let mut p = [[0u8; LANES]; 16];
            for (k, p) in p.iter_mut().enumerate() {
                *p = lane(circle[k], start);
            }
            let even = Screen::new(&high, &low, [0, 2, 4, 6, 8, 10, 12, 14].map(|k| &p[k]));
            if !even.any() {
                continue;
            }
            let odd = Screen::new(&high, &low, [1, 3, 5, 7, 9, 11, 13, 15].map(|k| &p[k]));
            let polarities = even.and(&odd).polarities();
            if !(polarities.bright || polarities.dark) {
                continue;
            }

            let block = block_scores(&c, &p, threshold, polarities);
            let mut found = nonzero_mask(&block);
            if let Some(whole) = score_row.get_mut(start..start + LANES) {
                whole.copy_from_slice(&block);
            } else {
                let count = inner - start;
                score_row[start..].copy_from_slice(&block[..count]);
                found &= (1 << count) - 1;
            }
            list_found(found, edge + start, y, &block, candidates);
        }
    }
}

/// Lists a block's corners: for each bit `i` set in `found` (lowest first), the pixel
/// (`x0 + i`, `y`) with score `scores[i]`.
#[inline(always)]
fn list_found(mut found: u32, x0: usize, y: usize, scores: &[u8; LANES], out: &mut Vec<Candidate>) {
    while found != 0 {
        let i = found.trailing_zeros() as usize;
        found &= found - 1;
        out.push(Candidate {
            x: (x0 + i) as u32,
            y: y as u32,
            score: scores[i],
        });
    }
}

/// Bit `i` set where lane `i` of `block` is not 0.
#[inline(always)]
fn nonzero_mask(block: &[u8; LANES]) -> u32 {
    #[cfg(target_arch = "x86_64")]
    #[allow(unsafe_code)]
    {
        use std::arch::x86_64::{
            __m128i, _mm_cmpeq_epi8, _mm_loadu_si128, _mm_movemask_epi8, _mm_setzero_si128,
        };
        let (low, high) = block.split_at(LANES / 2);
        // SAFETY: SSE2 is part of every x86-64 CPU; each load reads the 16 bytes of its
        // half of `block`.
        let zeros = unsafe {
            let low = _mm_loadu_si128(low.as_ptr().cast::<__m128i>());
            let high = _mm_loadu_si128(high.as_ptr().cast::<__m128i>());
            let zero = _mm_setzero_si128();
            let low = _mm_movemask_epi8(_mm_cmpeq_epi8(low, zero)) as u32;
            let high = _mm_movemask_epi8(_mm_cmpeq_epi8(high, zero)) as u32;
            low | high << 16
        };
        !zeros
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let mut mask = 0u32;
        for (i, &v) in block.iter().enumerate() {
            mask |= u32::from(v != 0) << i;
        }
        mask
    }
}

/// The FAST score of every centre of a block (`c`, and `p[k]`: the pixels under circle
/// position k), 0 where it is no corner: over the 16 arcs of [`ARC`] positions, the best of
/// each arc's smallest difference from the centre (brighter, or darker; a difference of the
/// other sign counts as 0, which no arc of a corner holds), less one, when that best is
/// above `threshold`. An arc of 9 brighter and one of 9 darker cannot share a circle of 16,
/// so the better of the two is the corner's. Lane-wise byte arithmetic (saturating
/// differences, minima over runs of 2, 4, 8 and then 9 positions by doubling), so the
/// compiler vectorises it.
///
/// `polarities` says which ways some lane passed the screens; a way none passed is not
/// worked out: its best arc is at most `threshold` in every lane, so it can neither make a
/// corner nor be the better of the two in one.
#[inline(always)]
fn block_scores(
    c: &[u8; LANES],
    p: &[[u8; LANES]; 16],
    threshold: u8,
    polarities: Polarities,
) -> [u8; LANES] {
    let mut best = [0u8; LANES];
    if polarities.bright {
        let mut brighter = [[0u8; LANES]; 16];
        for k in 0..16 {
            for i in 0..LANES {
                brighter[k][i] = p[k][i].saturating_sub(c[i]);
            }
        }
        best = best_arc(&brighter);
    }
    if polarities.dark {
        let mut darker = [[0u8; LANES]; 16];
        for k in 0..16 {
            for i in 0..LANES {
                darker[k][i] = c[i].saturating_sub(p[k][i]);
            }
        }
        let d = best_arc(&darker);
        for i in 0..LANES {
            best[i] = best[i].max(d[i]);
        }
    }
    let mut out = [0u8; LANES];
    for i in 0..LANES {
        out[i] = if best[i] > threshold { best[i] - 1 } else { 0 };
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

/// Which ways a block can hold a corner: some lane can have an arc of [`ARC`] brighter
/// positions (`bright`), some lane one of darker ones (`dark`).
#[derive(Debug, Clone, Copy)]
struct Polarities {
    bright: bool,
    dark: bool,
}

/// A screen of one block on 8 circle positions, every other one: per lane, 1 where 4
/// contiguous of them (around the circle) are above the centre's `high`, as every arc of
/// [`ARC`] positions has (`bright`), or below its `low` (`dark`); else 0.
struct Screen {
    bright: [u8; LANES],
    dark: [u8; LANES],
}

impl Screen {
    /// The screen on `around` (`around[k]`: circle position 2k, or 2k + 1): an arc of
    /// [`ARC`] holds 4 contiguous even positions and 4 contiguous odd ones.
    #[inline(always)]
    fn new(high: &[u8; LANES], low: &[u8; LANES], around: [&[u8; LANES]; 8]) -> Self {
        let mut out = Screen {
            bright: [0; LANES],
            dark: [0; LANES],
        };
        for i in 0..LANES {
            let (h, l) = (high[i], low[i]);
            let mut bright = [0u8; 8];
            let mut dark = [0u8; 8];
            for k in 0..8 {
                bright[k] = u8::from(around[k][i] > h);
                dark[k] = u8::from(around[k][i] < l);
            }
            out.bright[i] = four_in_a_row(bright);
            out.dark[i] = four_in_a_row(dark);
        }
        out
    }

    /// Whether any lane passes, either way.
    #[inline(always)]
    fn any(&self) -> bool {
        let mut any = 0;
        for i in 0..LANES {
            any |= self.bright[i] | self.dark[i];
        }
        any != 0
    }

    /// The lanes that pass both screens, each way.
    #[inline(always)]
    fn and(&self, other: &Screen) -> Screen {
        let mut out = Screen {
            bright: [0; LANES],
            dark: [0; LANES],
        };
        for i in 0..LANES {
            out.bright[i] = self.bright[i] & other.bright[i];
            out.dark[i] = self.dark[i] & other.dark[i];
        }
        out
    }

    /// Which ways some lane passes.
    #[inline(always)]
    fn polarities(&self) -> Polarities {
        let (mut bright, mut dark) = (0, 0);
        for i in 0..LANES {
            bright |= self.bright[i];
            dark |= self.dark[i];
        }
        Polarities {
            bright: bright != 0,
            dark: dark != 0,
        }
    }
}

/// 1 when 4 contiguous of 8 every-other circle positions (around the circle) are 1, as
/// every arc of 9 positions has; else 0. Plain byte arithmetic, so the row loop vectorises.
#[inline(always)]
fn four_in_a_row([e0, e1, e2, e3, e4, e5, e6, e7]: [u8; 8]) -> u8 {
    let (a, b, c, d) = (e0 & e1, e2 & e3, e4 & e5, e6 & e7);
    let (ab, bc, cd, da) = (e1 & e2, e3 & e4, e5 & e6, e7 & e0);
    // Runs starting at an even position (pairs of pairs), then at an odd one.
    (a & b) | (b & c) | (c & d) | (d & a) | (ab & bc) | (bc & cd) | (cd & da) | (da & ab)
}

/// The row loop with AVX2 intrinsics: the same scores as the portable loop (tested
/// against it and against the whole-circle test), in registers; screened on the compass
/// and the even positions only.
///
/// The screens and the score work on the pixels' excess over the centre's `high` (the
/// centre plus the threshold, saturated), `subs(p, high)`, and the centre's `low` over
/// them, `subs(low, p)`, nonzero exactly where the FAST test counts a position brighter
/// (darker). The best arc of the excess is the best arc of the differences less the
/// threshold, and 0 exactly where that is not above the threshold (if the centre plus the
/// threshold saturates, no difference can exceed the threshold and every excess is 0;
/// likewise for `low`); so a lane's score is its best excess plus the threshold less one,
/// or 0 where the best excess is 0.
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod avx2 {
    use super::{Candidate, LANES};
    use std::arch::x86_64::*;

    /// The FAST corners of one row: `centre` the row's span of centres, `circle[k]` the span
    /// under circle position k (all as long); their scores into `score_row`, the corners
    /// (`(edge, y)`: the span's first column, and the row) onto `candidates` in order.
    ///
    /// # Safety
    /// The CPU has AVX2; every span is `centre.len()` ≥ [`LANES`] bytes long, and so is
    /// `score_row`.
    ///
    /// Not itself compiled for AVX2 (that would forbid inlining it): `#[inline(always)]`
    /// into the extractor's AVX2 build, where its intrinsics inline.
    #[inline(always)]
    pub(super) unsafe fn row(
        centre: &[u8],
        circle: &[&[u8]; 16],
        threshold: u8,
        (edge, y): (usize, usize),
        score_row: &mut [u8],
        candidates: &mut Vec<Candidate>,
    ) {
        let inner = centre.len();
        // SAFETY (the whole body): the CPU has AVX2 (the caller's word); every load and
        // store covers `at..at + LANES` of a span or of `score_row`, with
        // `at + LANES <= inner`, their length.
        unsafe {
            let t = _mm256_set1_epi8(threshold as i8);
            let t_less_one = _mm256_set1_epi8(threshold.wrapping_sub(1) as i8);
            let zero = _mm256_setzero_si256();
            let mut start = 0;
            while start < inner {
                // The last block ends at the row's end, over part of the one before it;
                // its lanes before `start` were listed already (their scores are rewritten
                // the same).
                let at = start.min(inner - LANES);
                let first_new = start - at;
                start += LANES;
                // (A macro, not a closure: a closure is not compiled for AVX2, and its
                // intrinsics would not inline into it.)
                macro_rules! load {
                    ($row:expr) => {
                        _mm256_loadu_si256($row.as_ptr().add(at).cast())
                    };
                }
                let c = load!(centre);
                let high = _mm256_adds_epu8(c, t);
                let low = _mm256_subs_epu8(c, t);
                let mut bright = [zero; 16];
                let mut dark = [zero; 16];
                for k in [0, 4, 8, 12] {
                    let p = load!(circle[k]);
                    bright[k] = _mm256_subs_epu8(p, high);
                    dark[k] = _mm256_subs_epu8(low, p);
                }
                let any = _mm256_or_si256(compass(&bright), compass(&dark));
                if _mm256_testz_si256(any, any) == 1 {
                    continue;
                }
                for k in [2, 6, 10, 14] {
                    let p = load!(circle[k]);
                    bright[k] = _mm256_subs_epu8(p, high);
                    dark[k] = _mm256_subs_epu8(low, p);
                }
                let (even_bright, even_dark) = (four_in_a_row(&bright, 0), four_in_a_row(&dark, 0));
                let any = _mm256_or_si256(even_bright, even_dark);
                if _mm256_testz_si256(any, any) == 1 {
                    continue;
                }
                for k in [1, 3, 5, 7, 9, 11, 13, 15] {
                    let p = load!(circle[k]);
                    bright[k] = _mm256_subs_epu8(p, high);
                    dark[k] = _mm256_subs_epu8(low, p);
                }
                // Both ways, without a branch on which passed, and no screen on the odd
                // positions (measured: each cost more than the scoring it spared).
                let best = _mm256_max_epu8(best_arc(&bright), best_arc(&dark));
                let none = _mm256_cmpeq_epi8(best, zero);
                let scores = _mm256_andnot_si256(none, _mm256_add_epi8(best, t_less_one));
                _mm256_storeu_si256(score_row.as_mut_ptr().add(at).cast(), scores);
                let found = !(_mm256_movemask_epi8(none) as u32) >> first_new << first_new;
                if found == 0 {
                    continue;
                }
                let mut lanes = [0u8; LANES];
                _mm256_storeu_si256(lanes.as_mut_ptr().cast(), scores);
                super::list_found(found, edge + at, y, &lanes, candidates);
            }
        }
    }

    /// Per lane, nonzero where two neighbouring compass positions (0, 4, 8, 12) of `v` are
    /// nonzero.
    #[inline(always)]
    unsafe fn compass(v: &[__m256i; 16]) -> __m256i {
        // SAFETY: the CPU has AVX2 (the caller's word).
        unsafe {
            let a = _mm256_max_epu8(_mm256_min_epu8(v[0], v[4]), _mm256_min_epu8(v[4], v[8]));
            let b = _mm256_max_epu8(_mm256_min_epu8(v[8], v[12]), _mm256_min_epu8(v[12], v[0]));
            _mm256_max_epu8(a, b)
        }
    }

    /// Per lane, nonzero where 4 contiguous (around the circle) of the 8 positions
    /// `first`, `first + 2`, .. of `v` are nonzero: the largest over the runs of 4 of the
    /// run's smallest.
    #[inline(always)]
    unsafe fn four_in_a_row(v: &[__m256i; 16], first: usize) -> __m256i {
        // SAFETY: the CPU has AVX2 (the caller's word).
        unsafe {
            // (Indexing, not arrays built with `map`, which is not inlined.)
            let e = |k: usize| v[(first + 2 * k) % 16];
            let mut two = [v[0]; 8];
            for (k, two) in two.iter_mut().enumerate() {
                *two = _mm256_min_epu8(e(k), e(k + 1));
            }
            let mut best = _mm256_min_epu8(two[0], two[2]);
            for k in 1..8 {
                best = _mm256_max_epu8(best, _mm256_min_epu8(two[k], two[(k + 2) % 8]));
            }
            best
        }
    }

    /// Per lane, the largest over the 16 arcs of [`super::ARC`] circle positions of the
    /// arc's smallest value (`v[k]`: circle position k); minima over runs of 2, 4 and 8 by
    /// doubling.
    #[inline(always)]
    unsafe fn best_arc(v: &[__m256i; 16]) -> __m256i {
        // SAFETY: the CPU has AVX2 (the caller's word).
        unsafe {
            let mut two = [v[0]; 16];
            for k in 0..16 {
                two[k] = _mm256_min_epu8(v[k], v[(k + 1) % 16]);
            }
            let mut four = [v[0]; 16];
            for k in 0..16 {
                four[k] = _mm256_min_epu8(two[k], two[(k + 2) % 16]);
            }
            let mut best = _mm256_setzero_si256();
            for k in 0..16 {
                let eight = _mm256_min_epu8(four[k], four[(k + 4) % 16]);
                let nine = _mm256_min_epu8(eight, v[(k + super::ARC - 1) % 16]);
                best = _mm256_max_epu8(best, nine);
            }
            best
        }
    }
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
