//! Anchors and edge drawing: chains of pixels along the gradient ridge.

use crate::Params;
use crate::gradient::{DRAWN, Planes, SMOOTH_SHIFT, VERTICAL};

/// Counting-sort buckets for anchors: gradient magnitudes in 8-bit Sobel units.
const BUCKETS: usize = 2041;

/// The eight steps, in ring order: E, SE, S, SW, W, NW, N, NE (image y down).
const STEPS: [(isize, isize); 8] = [
    (1, 0),
    (1, 1),
    (0, 1),
    (-1, 1),
    (-1, 0),
    (-1, -1),
    (0, -1),
    (1, -1),
];

/// The ring index of E, S, W and N in [`STEPS`].
const EAST: usize = 0;
const SOUTH: usize = 2;
const WEST: usize = 4;
const NORTH: usize = 6;

/// Anchors and the chain being drawn, reused from frame to frame.
#[derive(Debug, Default)]
pub(crate) struct Drawing {
    /// Anchor pixel indices, as found.
    found: Vec<u32>,
    /// Anchor pixel indices, strongest first.
    sorted: Vec<u32>,
    /// Per column, 1 when horizontal edges are looked for on it.
    scanned_columns: Vec<u16>,
    /// Per pixel of the row being scanned, 1 for an anchor.
    mask: Vec<u8>,
    /// Counting-sort histogram.
    counts: Vec<u32>,
    /// The walk from an anchor in its first direction.
    forward: Vec<u32>,
    /// The walk in the other direction.
    backward: Vec<u32>,
    /// The whole chain: backward reversed, anchor, forward.
    chain: Vec<u32>,
}

impl Drawing {
    /// Finds the anchors of `planes` and sorts them strongest first.
    pub(crate) fn anchors(&mut self, planes: &Planes, params: &Params) {
        let (w, h) = (planes.width, planes.height);
        let threshold = gradient_threshold(params);
        let rise = params.anchor_threshold.saturating_mul(1 << SMOOTH_SHIFT);
        let step = params.scan_interval.max(1);
        let (g, flags) = (&planes.magnitude, &planes.flags);
        self.found.clear();
        // A horizontal edge crosses every column: it is looked for on every step-th column.
        self.scanned_columns.clear();
        self.scanned_columns
            .extend((0..w).map(|x| u16::from(x % step == 0)));
        self.mask.clear();
        self.mask.resize(w, 0);
        for y in 1..h - 1 {
            // A vertical edge crosses every row: it is looked for on every step-th row.
            let vertical_row = u16::from(y % step == 0);
            let n = w - 2;
            let row = y * w;
            let (up, at, down) = (
                &g[row - w + 1..row - w + 1 + n],
                &g[row..row + n + 2],
                &g[row + w + 1..row + w + 1 + n],
            );
            let (left, centre, right) = (&at[..n], &at[1..n + 1], &at[2..n + 2]);
            let row_flags = &flags[row + 1..row + 1 + n];
            let columns = &self.scanned_columns[1..n + 1];
            let mask = &mut self.mask[..n];
            // Branch-free over the row (vectorised); the rare hits are collected below.
            for x in 0..n {
                // All ones for a vertical edge, else zero: selects by masking.
                let vertical = 0u16.wrapping_sub(u16::from(row_flags[x] & VERTICAL));
                let before = (left[x] & vertical) | (up[x] & !vertical);
                let after = (right[x] & vertical) | (down[x] & !vertical);
                let scanned = (vertical_row & vertical) | (columns[x] & !vertical);
                let m = centre[x];
                mask[x] = (scanned
                    & u16::from(m >= threshold)
                    & u16::from(m >= before.saturating_add(rise))
                    & u16::from(m >= after.saturating_add(rise))) as u8;
            }
            collect_hits(mask, row + 1, &mut self.found);
        }
        // Counting sort by magnitude (8-bit Sobel units), strongest first.
        self.counts.clear();
        self.counts.resize(BUCKETS + 1, 0);
        let bucket =
            |i: u32| BUCKETS - 1 - usize::from(g[i as usize] >> SMOOTH_SHIFT).min(BUCKETS - 1);
        for &i in &self.found {
            self.counts[bucket(i) + 1] += 1;
        }
        for b in 1..=BUCKETS {
            self.counts[b] += self.counts[b - 1];
        }
        self.sorted.clear();
        self.sorted.resize(self.found.len(), 0);
        for &i in &self.found {
            let slot = &mut self.counts[bucket(i)];
            self.sorted[*slot as usize] = i;
            *slot += 1;
        }
    }

    /// Draws a chain from every anchor not yet on an edge and hands each to `fit`.
    pub(crate) fn draw_all(
        &mut self,
        planes: &mut Planes,
        params: &Params,
        mut fit: impl FnMut(&Planes, &[u32]),
    ) {
        let threshold = gradient_threshold(params);
        let w = planes.width;
        let offsets = STEPS.map(|(dx, dy)| dx + dy * w as isize);
        for k in 0..self.sorted.len() {
            let anchor = self.sorted[k] as usize;
            let flag = planes.flags[anchor];
            if flag & DRAWN != 0 {
                continue;
            }
            // An anchor beside an edge already drawn (across it) would draw its twin.
            let across = if flag & VERTICAL != 0 { 1 } else { w };
            if (planes.flags[anchor - across] | planes.flags[anchor + across]) & DRAWN != 0 {
                continue;
            }
            planes.flags[anchor] |= DRAWN;
            let (first, second) = if flag & VERTICAL != 0 {
                (SOUTH, NORTH)
            } else {
                (EAST, WEST)
            };
            walk(
                planes,
                &offsets,
                threshold,
                anchor,
                first,
                &mut self.forward,
            );
            walk(
                planes,
                &offsets,
                threshold,
                anchor,
                second,
                &mut self.backward,
            );
            self.chain.clear();
            self.chain.extend(self.backward.iter().rev());
            self.chain.push(anchor as u32);
            self.chain.extend(&self.forward);
            fit(planes, &self.chain);
        }
    }
}

/// Appends `first + x` for every `x` where `mask[x]` (each 0 or 1) is 1, in increasing
/// order: eight mask bytes tested as one word, so the mostly empty row costs a compare per
/// eight pixels.
fn collect_hits(mask: &[u8], first: usize, found: &mut Vec<u32>) {
    let (words, rest) = mask.as_chunks::<8>();
    for (k, word) in words.iter().enumerate() {
        // Little-endian: byte j is bits 8j..8j + 8, and a hit is its lowest bit.
        let mut bits = u64::from_le_bytes(*word);
        while bits != 0 {
            let j = (bits.trailing_zeros() / 8) as usize;
            found.push((first + k * 8 + j) as u32);
            bits &= bits - 1;
        }
    }
    let tail = words.len() * 8;
    for (j, &hit) in rest.iter().enumerate() {
        if hit != 0 {
            found.push((first + tail + j) as u32);
        }
    }
}

/// The gradient threshold in the planes' units, at least 1 (so the zero border stops every
/// walk and no step ever leaves the image).
fn gradient_threshold(params: &Params) -> u16 {
    (params.gradient_threshold.max(1)).saturating_mul(1 << SMOOTH_SHIFT)
}

/// Walks from `start` heading `heading` (a [`STEPS`] index) along the ridge, each step to
/// the strongest of the three pixels ahead (straight on wins ties), marking each pixel
/// drawn; stops under `threshold` or at a pixel already drawn. The pixels after `start`
/// go into `out`.
fn walk(
    planes: &mut Planes,
    offsets: &[isize; 8],
    threshold: u16,
    start: usize,
    mut heading: usize,
    out: &mut Vec<u32>,
) {
    out.clear();
    let (g, flags) = (&planes.magnitude, &mut planes.flags);
    let mut at = start;
    loop {
        let mut best = heading;
        let mut best_g = g[at.wrapping_add_signed(offsets[heading])];
        for turn in [(heading + 7) % 8, (heading + 1) % 8] {
            let m = g[at.wrapping_add_signed(offsets[turn])];
            if m > best_g {
                best = turn;
                best_g = m;
            }
        }
        if best_g < threshold {
            return;
        }
        // Above the threshold, so an interior pixel: its neighbours are in the image.
        let next = at.wrapping_add_signed(offsets[best]);
        if flags[next] & DRAWN != 0 {
            return;
        }
        flags[next] |= DRAWN;
        out.push(next as u32);
        at = next;
        heading = best;
    }
}
