//! Which corners are kept: 3×3 non-maximum suppression of the FAST score, each level's
//! share of the wanted count, and a grid that spreads a level's share over the image.

use crate::pyramid::Pyramid;
use crate::{Candidate, GrayView, MAX_LEVELS};

/// Each level's share of `wanted` corners, proportional to its width (a geometric series
/// of ratio 1 / scale factor, as OpenCV's ORB divides its points: coarse levels get more
/// than their area would give them); the last level takes what rounding leaves.
pub(crate) fn level_shares(pyramid: &Pyramid, count: usize, wanted: usize) -> [usize; MAX_LEVELS] {
    let mut shares = [0; MAX_LEVELS];
    let weight = |level: usize| 1.0 / f64::from(pyramid.scale(level));
    let total: f64 = (0..count).map(weight).sum();
    if count == 0 {
        return shares;
    }
    let mut given = 0;
    for (level, share) in shares.iter_mut().enumerate().take(count) {
        *share = if level + 1 == count {
            wanted - given
        } else {
            let exact = wanted as f64 * weight(level) / total;
            (exact.round() as usize).min(wanted - given)
        };
        given += *share;
    }
    shares
}

/// Keeps the candidates (in raster order, as FAST lists them) whose score is a strict
/// maximum of their 3×3 neighbourhood in `scores` (ties go to the first in raster order),
/// and orders them best first, then in raster order: a counting sort on the 8-bit score
/// (stable, so raster order holds within a score), through `scratch`.
#[inline(always)]
pub(crate) fn suppress_and_sort(
    image: GrayView<'_>,
    scores: &[u8],
    candidates: &mut Vec<Candidate>,
    scratch: &mut Vec<Candidate>,
) {
    let width = image.width();
    // (A loop rather than `retain`, whose closure is not inlined into the AVX2 build; no
    // branch on the outcome, which the branch predictor cannot guess: every candidate is
    // written, and the count moves on past the kept ones.)
    let mut kept = 0;
    #[cfg(target_arch = "x86_64")]
    {
        // The maxima of 16 neighbouring columns at once, once for all the candidates
        // among them (about 5 of them where there are any).
        let (mut group, mut maxima) = (usize::MAX, 0u32);
        for k in 0..candidates.len() {
            let c = candidates[k];
            let (lane, first) = (
                c.x as usize % 16,
                c.y as usize * width + c.x as usize / 16 * 16,
            );
            if first != group {
                group = first;
                maxima = sse2::maxima(scores, first, width);
            }
            candidates[kept] = c;
            kept += ((maxima >> lane) & 1) as usize;
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    for k in 0..candidates.len() {
        let c = candidates[k];
        candidates[kept] = c;
        kept += usize::from(is_maximum(
            scores,
            c.y as usize * width + c.x as usize,
            width,
        ));
    }
    candidates.truncate(kept);
    let mut counts = [0usize; 256];
    for c in candidates.iter() {
        counts[usize::from(c.score)] += 1;
    }
    // Where each score's run starts, best score first.
    let mut starts = [0usize; 256];
    let mut before = 0;
    for score in (0..256).rev() {
        starts[score] = before;
        before += counts[score];
    }
    scratch.clear();
    scratch.resize(
        candidates.len(),
        Candidate {
            x: 0,
            y: 0,
            score: 0,
        },
    );
    for &c in candidates.iter() {
        let start = &mut starts[usize::from(c.score)];
        scratch[*start] = c;
        *start += 1;
    }
    std::mem::swap(candidates, scratch);
}

/// Whether the score at `at` of `scores` (rows `width` apart, `at` not on the border) is a
/// maximum of its 3 × 3 neighbourhood: above every neighbour before it in raster order, at
/// least every one after it.
#[cfg_attr(target_arch = "x86_64", allow(dead_code))] // the reference of `sse2::maxima`
pub(crate) fn is_maximum(scores: &[u8], at: usize, width: usize) -> bool {
    let around = &scores[at - width - 1..][..2 * width + 3];
    let (above, row, below) = (
        &around[..3],
        &around[width..width + 3],
        &around[2 * width..],
    );
    let before = above[0].max(above[1]).max(above[2]).max(row[0]);
    let after = row[2].max(below[0]).max(below[1]).max(below[2]);
    (row[1] > before) & (row[1] >= after)
}

/// The suppression 16 columns at a time, with SSE2 (part of every x86-64 CPU).
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
pub(crate) mod sse2 {
    use std::arch::x86_64::*;

    /// Bit `i` set where the score at `first + i` of `scores` (rows `width` apart) is a
    /// maximum of its 3 × 3 neighbourhood: above every neighbour before it in raster order,
    /// at least every one after it. The 16 columns and their neighbours lie inside
    /// `scores` (panics if not: a candidate is at least [`crate::BORDER_PX`] from the
    /// borders, and its group of 16 starts at a multiple of 16 at or before it).
    #[inline(always)]
    pub(crate) fn maxima(scores: &[u8], first: usize, width: usize) -> u32 {
        let (above, row, below) = (
            &scores[first - width - 1..][..18],
            &scores[first - 1..][..18],
            &scores[first + width - 1..][..18],
        );
        // SAFETY: SSE2 is part of every x86-64 CPU; every load reads 16 of a row's 18
        // bytes, from its first, second or third.
        unsafe {
            let load = |row: &[u8], shift: usize| {
                _mm_loadu_si128(row.as_ptr().add(shift).cast::<__m128i>())
            };
            let score = load(row, 1);
            let before = _mm_max_epu8(
                _mm_max_epu8(load(above, 0), load(above, 1)),
                _mm_max_epu8(load(above, 2), load(row, 0)),
            );
            let after = _mm_max_epu8(
                _mm_max_epu8(load(row, 2), load(below, 0)),
                _mm_max_epu8(load(below, 1), load(below, 2)),
            );
            let zero = _mm_setzero_si128();
            // `score − before`, saturated, is 0 where the score is not above; `after −
            // score`, where it is at least.
            let not_above = _mm_cmpeq_epi8(_mm_subs_epu8(score, before), zero);
            let at_least = _mm_cmpeq_epi8(_mm_subs_epu8(after, score), zero);
            _mm_movemask_epi8(_mm_andnot_si128(not_above, at_least)) as u32
        }
    }
}

/// The grid's buffers, kept between levels and images.
#[derive(Default)]
pub(crate) struct Grid {
    /// Corners taken per cell.
    taken: Vec<u32>,
    /// Candidates passed over on the first pass, best first.
    rest: Vec<Candidate>,
    /// The grid column of each image column, and the first cell of each image row's row.
    column_of: Vec<u32>,
    row_start_of: Vec<u32>,
}

impl Grid {
    /// Moves the (at most) `wanted` corners kept to the front of `candidates` (sorted best
    /// first) and returns how many: first, best first, at most an even share of `wanted` per
    /// occupied `cell_px` cell; then the best of the others (no grid when `cell_px` is 0:
    /// the best).
    pub(crate) fn select(
        &mut self,
        image: GrayView<'_>,
        cell_px: usize,
        wanted: usize,
        candidates: &mut [Candidate],
    ) -> usize {
        if candidates.len() <= wanted || cell_px == 0 {
            return candidates.len().min(wanted);
        }
        let columns = image.width().div_ceil(cell_px);
        let cells = columns * image.height().div_ceil(cell_px);
        self.column_of.clear();
        self.column_of
            .extend((0..image.width()).map(|x| (x / cell_px) as u32));
        self.row_start_of.clear();
        self.row_start_of
            .extend((0..image.height()).map(|y| (y / cell_px * columns) as u32));
        let (column_of, row_start_of) = (&self.column_of, &self.row_start_of);
        let cell = |c: &Candidate| (row_start_of[c.y as usize] + column_of[c.x as usize]) as usize;
        self.taken.clear();
        self.taken.resize(cells, 0);
        for c in candidates.iter() {
            self.taken[cell(c)] = 1;
        }
        let occupied = self.taken.iter().sum::<u32>() as usize;
        let share = wanted.div_ceil(occupied.max(1)) as u32;
        self.taken.fill(0);
        self.rest.clear();
        let mut kept = 0;
        for k in 0..candidates.len() {
            let c = candidates[k];
            let taken = &mut self.taken[cell(&c)];
            if kept < wanted && *taken < share {
                *taken += 1;
                candidates[kept] = c;
                kept += 1;
            } else {
                self.rest.push(c);
            }
        }
        for &c in self.rest.iter().take(wanted - kept) {
            candidates[kept] = c;
            kept += 1;
        }
        kept
    }
}
