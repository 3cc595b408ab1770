//! Bilinear resampling of one pyramid level into the next, pixel centres aligned:
//! destination pixel `d` samples source position `(d + ½)·s − ½`. Each source row is
//! blended horizontally once (8-bit weights, into 16 bits, exact), kept while the two
//! destination rows that read it are made, and two such rows are blended vertically (the
//! products rounded away). The vertical pass is a row loop the compiler vectorises; the
//! horizontal one, on CPUs with AVX2, reads 8 destination pixels' neighbours out of 16
//! source bytes with one byte shuffle (16 pixels an instruction), from tables made once a
//! level; elsewhere, and where a group's neighbours span more than 16 bytes, pixel by pixel,
//! the same arithmetic.

use crate::GrayView;

/// Fractional bits of the bilinear weights.
const WEIGHT_BITS: u32 = 8;
/// The weight of a whole pixel.
const WEIGHT_ONE: u16 = 1 << WEIGHT_BITS;
/// Destination pixels a shuffle makes.
const GROUP: usize = 8;

/// Tables kept: one set per level of the deepest pyramid.
const TABLES_KEPT: usize = crate::MAX_LEVELS;

/// The resampling's tables and rows, kept from level to level and image to image.
#[derive(Default)]
pub(crate) struct Resampler {
    /// The tables of the last levels resampled (an image of the same size next time
    /// finds them made).
    tables: Vec<Tables>,
    /// The entry of `tables` made last.
    newest: usize,
    /// Two source rows blended horizontally, and which source rows they are.
    rows: [Vec<u16>; 2],
    tags: [usize; 2],
}

/// The horizontal blend's tables for one level.
#[derive(Default)]
struct Tables {
    /// What they were made for: destination width, source pixels per destination pixel
    /// (its bits), source width.
    key: (usize, u32, usize),
    /// The leading pairs of groups whose neighbours both fit the byte shuffle.
    shuffled_pairs: usize,
    /// Per destination column: left source column and the right one's weight.
    columns: Vec<(u32, u16)>,
    /// Per group of [`GROUP`] destination columns: its first source byte, or `u32::MAX`
    /// when its neighbours do not fit in 16 bytes from there.
    bases: Vec<u32>,
    /// Per group: where each column's left and right neighbours lie from the base, as
    /// byte-shuffle masks widening to 16 bits (0x80: a zero byte).
    lefts: Vec<[u8; 16]>,
    rights: Vec<[u8; 16]>,
    /// Per group: each column's left and right weights.
    left_weights: Vec<[u16; GROUP]>,
    right_weights: Vec<[u16; GROUP]>,
}

impl Resampler {
    /// `source` resampled into `out` (`width` × `height`, packed). `avx2`: the CPU has AVX2
    /// (checked by the caller).
    #[inline(always)]
    pub(crate) fn resample(
        &mut self,
        source: GrayView<'_>,
        out: &mut [u8],
        width: usize,
        avx2: bool,
    ) {
        let height = out.len() / width.max(1);
        if width == 0 || height == 0 || source.width() == 0 || source.height() == 0 {
            return;
        }
        let sx = source.width() as f32 / width as f32;
        let sy = source.height() as f32 / height as f32;
        let key = (width, sx.to_bits(), source.width());
        let found = self.tables.iter().position(|t| t.key == key);
        let at = match found {
            Some(at) => at,
            None => {
                if self.tables.len() < TABLES_KEPT {
                    self.tables.push(Tables::default());
                    self.newest = self.tables.len() - 1;
                } else {
                    self.newest = (self.newest + 1) % TABLES_KEPT;
                }
                self.tables[self.newest].prepare(width, sx, source.width());
                self.newest
            }
        };
        let tables = &self.tables[at];
        for row in &mut self.rows {
            row.resize(width, 0);
        }
        self.tags = [usize::MAX; 2];
        for (y, row_out) in out.chunks_exact_mut(width).enumerate() {
            let (top, w_bottom) = sample_at(y, sy, source.height());
            let top = top as usize;
            let bottom = (top + 1).min(source.height() - 1);
            if self.tags[0] != top {
                if self.tags[1] == top {
                    self.rows.swap(0, 1);
                    self.tags.swap(0, 1);
                } else {
                    tables.blend_row(source.row(top), &mut self.rows[0], avx2);
                    self.tags[0] = top;
                }
            }
            if self.tags[1] != bottom {
                tables.blend_row(source.row(bottom), &mut self.rows[1], avx2);
                self.tags[1] = bottom;
            }
            let w_top = WEIGHT_ONE - w_bottom;
            let [upper, lower] = &self.rows;
            // (sum + 2¹⁵) >> 16 for sum = u·w_top + l·w_bottom, in 16-bit lanes (twice as
            // many a vector as 32-bit ones): with u = 256·u_high + u_low (likewise l),
            // sum = 256·high + low, high and low each at most 255 · 256 (the weights add up
            // to 256), and (sum + 2¹⁵) >> 16 = (high + (low >> 8) + 128) >> 8, whose
            // parts stay below 2¹⁶ (high + (low >> 8) = sum >> 8 ≤ 65 280).
            for ((o, &u), &l) in row_out.iter_mut().zip(upper).zip(lower) {
                let high = (u >> WEIGHT_BITS) * w_top + (l >> WEIGHT_BITS) * w_bottom;
                let low = (u & 0xFF) * w_top + (l & 0xFF) * w_bottom;
                let half = 1 << (WEIGHT_BITS - 1);
                *o = ((high + (low >> WEIGHT_BITS) + half) >> WEIGHT_BITS) as u8;
            }
        }
    }
}

impl Tables {
    /// The column table and the shuffle tables for `width` destination columns at `sx`
    /// source pixels each, from a source `source_width` wide.
    fn prepare(&mut self, width: usize, sx: f32, source_width: usize) {
        self.key = (width, sx.to_bits(), source_width);
        self.columns.clear();
        self.columns
            .extend((0..width).map(|x| sample_at(x, sx, source_width)));
        let groups = width / GROUP;
        self.bases.clear();
        self.lefts.clear();
        self.rights.clear();
        self.left_weights.clear();
        self.right_weights.clear();
        for group in self.columns.chunks_exact(GROUP).take(groups) {
            let base = group[0].0 as usize;
            let reach = group[GROUP - 1].0 as usize + 1 - base;
            let fits = reach < 16 && base + 16 <= source_width;
            self.bases.push(if fits { base as u32 } else { u32::MAX });
            let mut left = [0x80u8; 16];
            let mut right = [0x80u8; 16];
            for (i, &(l, _)) in group.iter().enumerate() {
                let offset = (l as usize - base).min(15) as u8;
                left[2 * i] = offset;
                right[2 * i] = (offset + 1).min(15);
            }
            self.lefts.push(left);
            self.rights.push(right);
            self.left_weights
                .push(std::array::from_fn(|i| WEIGHT_ONE - group[i].1));
            self.right_weights.push(std::array::from_fn(|i| group[i].1));
        }
        let fitting = self.bases.iter().take_while(|&&b| b != u32::MAX).count();
        self.shuffled_pairs = fitting / 2;
    }

    /// Source `row` blended horizontally into `out` (one value per destination column).
    #[inline(always)]
    fn blend_row(&self, row: &[u8], out: &mut [u16], avx2: bool) {
        let last = row.len() - 1;
        let groups = self.bases.len();
        let mut group = 0;
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            for pair in 0..self.shuffled_pairs {
                // SAFETY: the CPU has AVX2 (the caller's word); both groups' 16 source
                // bytes lie inside `row` (their bases were checked against its width) and
                // their 16 destination values inside `out` (whole groups of columns).
                #[allow(unsafe_code)]
                unsafe {
                    shuffle::two_groups(self, row, 2 * pair, out);
                }
            }
            group = 2 * self.shuffled_pairs;
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = avx2;
        while group < groups {
            let start = group * GROUP;
            let columns = &self.columns[start..start + GROUP];
            for (o, &column) in out[start..start + GROUP].iter_mut().zip(columns) {
                *o = blend_pixel(row, column, last);
            }
            group += 1;
        }
        let tail = groups * GROUP;
        for (o, &column) in out[tail..].iter_mut().zip(&self.columns[tail..]) {
            *o = blend_pixel(row, column, last);
        }
    }
}

/// A destination pixel blended from its two source neighbours (the right one clamped to
/// the row), exact in 16 bits.
#[inline(always)]
fn blend_pixel(row: &[u8], (left, w_right): (u32, u16), last: usize) -> u16 {
    let left = left as usize;
    let right = (left + 1).min(last);
    u16::from(row[left]) * (WEIGHT_ONE - w_right) + u16::from(row[right]) * w_right
}

/// For destination index `d` at `scale` source pixels per destination pixel: the source
/// index before the sample position and the weight of the one after it.
fn sample_at(d: usize, scale: f32, source_len: usize) -> (u32, u16) {
    let position = ((d as f32 + 0.5) * scale - 0.5).max(0.0);
    let before = (position.floor() as usize).min(source_len - 1);
    let weight = ((position - before as f32) * f32::from(WEIGHT_ONE)).round() as u16;
    (before as u32, weight.min(WEIGHT_ONE))
}

/// The horizontal blend with AVX2 byte shuffles.
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod shuffle {
    use super::{GROUP, Tables};
    use std::arch::x86_64::*;

    /// Groups `group` and `group + 1` of source `row` blended into `out`.
    ///
    /// # Safety
    /// The CPU has AVX2; both groups have a base (their 16 source bytes lie in `row`).
    ///
    /// Not itself compiled for AVX2 (`#[target_feature]` functions cannot be inlined
    /// always): inlined into the extractor's AVX2 build, where its intrinsics are inlined
    /// too (a call per 16 pixels had cost a tenth of the extraction).
    #[inline(always)]
    pub(super) unsafe fn two_groups(r: &Tables, row: &[u8], group: usize, out: &mut [u16]) {
        let (low, high) = (r.bases[group] as usize, r.bases[group + 1] as usize);
        let (low_bytes, high_bytes) = (&row[low..low + 16], &row[high..high + 16]);
        let pair = |tables: &[[u8; 16]]| [tables[group], tables[group + 1]];
        let (lefts, rights) = (pair(&r.lefts), pair(&r.rights));
        let weights = |tables: &[[u16; GROUP]]| [tables[group], tables[group + 1]];
        let (w_left, w_right) = (weights(&r.left_weights), weights(&r.right_weights));
        let out = &mut out[group * GROUP..][..2 * GROUP];
        // SAFETY: every pointer reads or writes exactly the 16 or 32 bytes of the slice
        // or array it comes from.
        unsafe {
            let bytes = _mm256_loadu2_m128i(high_bytes.as_ptr().cast(), low_bytes.as_ptr().cast());
            let left = _mm256_shuffle_epi8(bytes, _mm256_loadu_si256(lefts.as_ptr().cast()));
            let right = _mm256_shuffle_epi8(bytes, _mm256_loadu_si256(rights.as_ptr().cast()));
            let sum = _mm256_add_epi16(
                _mm256_mullo_epi16(left, _mm256_loadu_si256(w_left.as_ptr().cast())),
                _mm256_mullo_epi16(right, _mm256_loadu_si256(w_right.as_ptr().cast())),
            );
            _mm256_storeu_si256(out.as_mut_ptr().cast(), sum);
        }
    }
}
