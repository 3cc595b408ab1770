//! Which corners are kept: 3×3 non-maximum suppression of the FAST score, each level's
//! share of the wanted count, and a grid that spreads a level's share over the image.

use crate::pyramid::Pyramid;
use crate::{GrayView, MAX_LEVELS};

/// A corner of one level before it is described, level pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Candidate {
    /// Column.
    pub(crate) x: u32,
    /// Row.
    pub(crate) y: u32,
    /// FAST score.
    pub(crate) score: u8,
}

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
    for k in 0..candidates.len() {
        let c = candidates[k];
        let at = c.y as usize * width + c.x as usize;
        // The 3 × 3 neighbourhood, rows `width` apart (the candidates lie inside the
        // border, so it is whole).
        let around = &scores[at - width - 1..][..2 * width + 3];
        let (above, row, below) = (
            &around[..3],
            &around[width..width + 3],
            &around[2 * width..],
        );
        let before = above[0].max(above[1]).max(above[2]).max(row[0]);
        let after = row[2].max(below[0]).max(below[1]).max(below[2]);
        candidates[kept] = c;
        kept += usize::from((c.score > before) & (c.score >= after));
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
