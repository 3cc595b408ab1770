//! The image pyramid (bilinear, `resample.rs`, each level from the one before as OpenCV's
//! ORB does) and the smoothing the descriptor reads (a 7-tap Gaussian, σ = 2 cut at ±3, as
//! ORB, in both directions), its passes over whole rows in 16-bit integers, which the
//! compiler vectorises.

use crate::Candidate;
use crate::patch::{CENTRE, PATCH};
use crate::resample::Resampler;
use crate::{BORDER_PX, GrayView, MAX_LEVELS, Params};

/// Levels 1.. of the pyramid (level 0 is the caller's image) and the resampling buffers.
#[derive(Default)]
pub(crate) struct Pyramid {
    /// Pixels of levels 1.., packed.
    levels: Vec<Vec<u8>>,
    /// Width and height of every level.
    sizes: [(usize, usize); MAX_LEVELS],
    /// Full-resolution pixels per pixel of every level.
    scales: [f32; MAX_LEVELS],
    /// The resampling's tables and rows.
    resampler: Resampler,
}

impl Pyramid {
    /// Builds the levels of `image` that are large enough to hold a corner; returns how many
    /// there are (0 when even `image` is too small). `avx2`: the CPU has AVX2 (checked by
    /// the caller), and the resampling uses its byte shuffles.
    #[inline(always)]
    pub(crate) fn build(&mut self, image: GrayView<'_>, params: &Params, avx2: bool) -> usize {
        let (width, height) = (image.width(), image.height());
        // The smallest level worth building: room for one corner inside the border.
        let min_side = 2 * params.edge_px.max(BORDER_PX) + 1;
        let mut count = 0;
        for level in 0..params.levels {
            let scale = params.scale_factor.powi(level as i32);
            let size = (
                (width as f32 / scale).round() as usize,
                (height as f32 / scale).round() as usize,
            );
            if size.0 < min_side || size.1 < min_side {
                break;
            }
            self.sizes[level] = if level == 0 { (width, height) } else { size };
            self.scales[level] = scale;
            count = level + 1;
        }
        if self.levels.len() < count.saturating_sub(1) {
            self.levels.resize_with(count - 1, Vec::new);
        }
        for level in 1..count {
            let (width, height) = self.sizes[level];
            let (done, rest) = self.levels.split_at_mut(level - 1);
            let pixels = &mut rest[0];
            pixels.resize(width * height, 0);
            let source = match level {
                1 => Ok(image),
                _ => {
                    let (w, h) = self.sizes[level - 1];
                    GrayView::packed(&done[level - 2], w, h)
                }
            };
            let Ok(source) = source else {
                return level; // cannot happen: the buffer was sized for it
            };
            self.resampler.resample(source, pixels, width, avx2);
        }
        count
    }

    /// Level `level`'s pixels (`image` itself at level 0). `level` < the count `build` gave
    /// (`None` otherwise).
    pub(crate) fn plane<'a>(&'a self, level: usize, image: GrayView<'a>) -> Option<GrayView<'a>> {
        if level == 0 {
            return Some(image);
        }
        let (width, height) = self.sizes[level];
        GrayView::packed(self.levels.get(level - 1)?, width, height).ok()
    }

    /// Full-resolution pixels per pixel of level `level`.
    pub(crate) fn scale(&self, level: usize) -> f32 {
        self.scales[level]
    }
}

/// The smoothed copy of one level, the image the descriptor compares: only where the
/// kept corners' patches lie (about a third of the pixels on the EuRoC images: the
/// corners cluster), band by band of rows.
#[derive(Default)]
pub(crate) struct Smoother {
    pixels: Vec<u8>,
    column_sums: Vec<u16>,
    /// Per band of [`BAND_ROWS`] rows, the columns the patches crossing it cover (first,
    /// last; empty when first > last).
    bands: Vec<(usize, usize)>,
}

/// Rows of a band of the smoothing.
const BAND_ROWS: usize = 8;

impl Smoother {
    /// `image` smoothed in both directions (edges clamped, as over the whole image), packed,
    /// at every pixel of the patch ([`crate::patch::patch`]) of each corner of `corners`;
    /// other pixels hold anything. (`None` never: the buffer is sized for it.)
    #[inline(always)]
    pub(crate) fn smooth<'a>(
        &'a mut self,
        image: GrayView<'_>,
        corners: &[Candidate],
    ) -> Option<GrayView<'a>> {
        let (width, height) = (image.width(), image.height());
        // Grown, never shrunk: a smaller level after a larger one costs no memset.
        if self.pixels.len() < width * height {
            self.pixels.resize(width * height, 0);
        }
        if self.column_sums.len() < width {
            self.column_sums.resize(width, 0);
        }
        self.bands.clear();
        self.bands
            .resize(height.div_ceil(BAND_ROWS), (usize::MAX, 0));
        if width == 0 {
            return GrayView::packed(&self.pixels[..0], width, height).ok();
        }
        for c in corners {
            let (x, y) = (c.x as usize, c.y as usize);
            let (left, top) = (x.saturating_sub(CENTRE), y.saturating_sub(CENTRE));
            let (right, bottom) = (
                (left + PATCH - 1).min(width - 1),
                (top + PATCH - 1).min(height - 1),
            );
            for band in &mut self.bands[top / BAND_ROWS..=bottom / BAND_ROWS] {
                band.0 = band.0.min(left);
                band.1 = band.1.max(right);
            }
        }
        let last_row = height - 1;
        for (b, &(left, right)) in self.bands.iter().enumerate() {
            if left > right {
                continue;
            }
            // The vertical sums 3 columns either side (inside the image), so the
            // horizontal pass clamps only where the image ends.
            let (first, last) = (left.saturating_sub(3), (right + 3).min(width - 1));
            let span = first..last + 1;
            let rows = b * BAND_ROWS..((b + 1) * BAND_ROWS).min(height);
            for y in rows {
                // (A loop, not `from_fn`, whose `try_from_fn` is not inlined into the AVX2
                // build.)
                let mut taps: [&[u8]; 7] = [&[]; 7];
                for (k, tap) in taps.iter_mut().enumerate() {
                    *tap = &image.row((y + k).saturating_sub(3).min(last_row))[span.clone()];
                }
                let sums = &mut self.column_sums[..span.len()];
                vertical(taps, sums);
                let edges = (first == 0, last == width - 1);
                smooth_row(sums, &mut self.pixels[y * width..][span.clone()], edges);
            }
        }
        GrayView::packed(&self.pixels[..width * height], width, height).ok()
    }
}

/// Weights of the 7-tap kernel (sum 64): a Gaussian of σ = 2 cut at ±3, as ORB smooths
/// before its comparisons.
const TAPS: [u16; 7] = [4, 9, 12, 14, 12, 9, 4];
/// log2 of the kernel's sum.
const TAP_BITS: u32 = 6;

/// Values a chunk of the smoothing's row loops makes (16-bit lanes: a 256-bit vector).
const CHUNK: usize = 16;

/// The chunks of a row `len` long: their starts, [`CHUNK`] apart, the last one ending at
/// the row's end (over part of the one before it, which it rewrites the same). None when
/// `len < CHUNK`.
#[inline(always)]
fn chunk_starts(len: usize) -> impl Iterator<Item = usize> {
    let last = len.wrapping_sub(CHUNK);
    (0..len.div_ceil(CHUNK))
        .map(move |k| (k * CHUNK).min(last))
        .take_while(move |_| len >= CHUNK)
}

/// The vertical pass of one row: `sums[x]` from `rows[0..7][x]` (as long as `sums`), in
/// fixed chunks the compiler makes vector code of (no scalar tail).
#[inline(always)]
fn vertical(rows: [&[u8]; 7], sums: &mut [u16]) {
    let n = sums.len();
    let sum = |[a, b, c, d, e, f, g]: [u8; 7]| {
        let pair = |p: u8, q: u8| u16::from(p) + u16::from(q);
        let s = TAPS[0] * pair(a, g)
            + TAPS[1] * pair(b, f)
            + TAPS[2] * pair(c, e)
            + TAPS[3] * u16::from(d);
        (s + (1 << (TAP_BITS - 1))) >> TAP_BITS
    };
    if n < CHUNK {
        for (x, out) in sums.iter_mut().enumerate() {
            *out = sum([0, 1, 2, 3, 4, 5, 6].map(|k| rows[k][x]));
        }
        return;
    }
    for at in chunk_starts(n) {
        let [a, b, c, d, e, f, g] = rows;
        let (a, b, c, d) = (
            &a[at..at + CHUNK],
            &b[at..at + CHUNK],
            &c[at..at + CHUNK],
            &d[at..at + CHUNK],
        );
        let (e, f, g) = (&e[at..at + CHUNK], &f[at..at + CHUNK], &g[at..at + CHUNK]);
        let out = &mut sums[at..at + CHUNK];
        for i in 0..CHUNK {
            out[i] = sum([a[i], b[i], c[i], d[i], e[i], f[i], g[i]]);
        }
    }
}

/// One row smoothed horizontally: `out[x]` from `sums[x − 3 ..= x + 3]`, edges clamped;
/// the 3 values at the row's start (end) only where `edges.0` (`edges.1`) says the row
/// starts (ends) where the image does: elsewhere no patch reads them.
#[inline(always)]
fn smooth_row(sums: &[u16], out: &mut [u8], edges: (bool, bool)) {
    let width = sums.len();
    let tap_sum = |x: usize| {
        let mut s = 0;
        for (k, tap) in TAPS.iter().enumerate() {
            s += sums[(x + k).saturating_sub(3).min(width - 1)] * tap;
        }
        ((s + (1 << (TAP_BITS - 1))) >> TAP_BITS) as u8
    };
    if width < TAPS.len() + CHUNK {
        for (x, o) in out.iter_mut().enumerate() {
            *o = tap_sum(x);
        }
        return;
    }
    // The columns 3 ..= width − 4, whose taps lie inside, in fixed chunks (no scalar
    // tail); `at`: the chunk's first column less 3.
    for at in chunk_starts(width - 6) {
        let window = &sums[at..at + CHUNK + 6];
        let out = &mut out[at + 3..at + 3 + CHUNK];
        for i in 0..CHUNK {
            let s = TAPS[0] * (window[i] + window[i + 6])
                + TAPS[1] * (window[i + 1] + window[i + 5])
                + TAPS[2] * (window[i + 2] + window[i + 4])
                + TAPS[3] * window[i + 3];
            out[i] = ((s + (1 << (TAP_BITS - 1))) >> TAP_BITS) as u8;
        }
    }
    let (starts, ends) = edges;
    let clamped = (0..3)
        .filter(|_| starts)
        .chain((width - 3..width).filter(|_| ends));
    for x in clamped {
        out[x] = tap_sum(x);
    }
}
