//! Orientation by intensity centroid and the steered binary descriptor, with its sampling
//! pattern: 256 pixel pairs learned once (`learn.rs`) and kept as a table
//! (`learned_pattern.rs`).

use crate::learned_pattern::LEARNED_PAIRS;
#[cfg(doc)]
use crate::patch::smoothed_patch;
use crate::patch::{CENTRE, PATCH};
use crate::{DESCRIPTOR_BYTES, GrayView};
use std::f64::consts::TAU;

/// Radius of the disc the orientation's centroid is taken over, pixels.
const ORIENTATION_RADIUS: i32 = 15;
/// Orientations the pattern is precomputed for: steps of 2.8°, so that a point 15 px out
/// lies within 0.37 px of where the measured angle puts it. (32 steps until 2026-12-07:
/// two views of a corner whose angles fell on either side of a step compared pixels
/// 11.25° apart; measured, 128 track more corners from frame to frame.)
pub(crate) const ANGLE_STEPS: usize = 128;
/// Comparisons in a descriptor.
const PAIRS: usize = DESCRIPTOR_BYTES * 8;

/// The sampling pattern, rotated to each of [`ANGLE_STEPS`] orientations: per orientation,
/// the pairs' points as `(dx, dy)`, first and second point of pair k at 2k and 2k + 1.
pub(crate) struct Pattern {
    #[cfg(test)]
    rotated: Vec<[(i8, i8); 2 * PAIRS]>,
    /// The rotated points as indices into the corner's smoothed patch (row by row).
    cells: Vec<[u16; 2 * PAIRS]>,
    /// The points arranged for AVX-512 VBMI's byte permutes, per orientation.
    #[cfg(target_arch = "x86_64")]
    permuted: Vec<PermutedCells>,
    /// Per row of the orientation disc (−R..=R), per column of the 32 from −R: 1 inside
    /// the disc, else 0 (the last column is always out).
    inside: [[u16; WINDOW]; DISC_ROWS],
}

/// One orientation's points for AVX-512 VBMI: the patch as 8 tables of 128 bytes (two
/// 512-bit registers each), every point looked up in all 8 by a byte permute and kept from
/// the one it lies in.
#[cfg(target_arch = "x86_64")]
struct PermutedCells {
    /// Per vector of 64 points (the first points of pairs 64v .. 64v + 63 for v < 4, the
    /// second ones of pairs 64(v − 4) .. for v ≥ 4): each point's byte within its table.
    low: [[u8; 64]; 8],
    /// Per vector, per table t (patch bytes 128t .. 128t + 127): the lanes whose point lies
    /// in it.
    tables: [[u64; 8]; 8],
}

/// Rows of the orientation disc.
const DISC_ROWS: usize = 2 * ORIENTATION_RADIUS as usize + 1;
/// Columns read per row of the disc: 2R + 1, and one more to make a round 32.
const WINDOW: usize = 32;

impl Pattern {
    /// The pattern (the same on every call and every build).
    pub(crate) fn new() -> Self {
        let points = pattern_points();
        let rotated: Vec<[(i8, i8); 2 * PAIRS]> = (0..ANGLE_STEPS)
            .map(|step| {
                let turn = (step as f64 * TAU / ANGLE_STEPS as f64).sin_cos();
                points.map(|point| turned(point, turn))
            })
            .collect();
        let r = f64::from(ORIENTATION_RADIUS);
        let inside: [[u16; WINDOW]; DISC_ROWS] = std::array::from_fn(|k| {
            let dy = k as f64 - r;
            let half = (r * r - dy * dy).sqrt().round() as i32;
            std::array::from_fn(|c| u16::from((c as i32 - ORIENTATION_RADIUS).abs() <= half))
        });
        let cells: Vec<[u16; 2 * PAIRS]> = rotated
            .iter()
            .map(|points: &[(i8, i8); 2 * PAIRS]| {
                points.map(|(dx, dy)| {
                    let at = |d: i8| (CENTRE as i32 + i32::from(d)).clamp(0, PATCH as i32 - 1);
                    (at(dy) * PATCH as i32 + at(dx)) as u16
                })
            })
            .collect();
        #[cfg(target_arch = "x86_64")]
        let permuted = cells
            .iter()
            .map(|cells: &[u16; 2 * PAIRS]| {
                // Vector v's lane i: point 2(64v + i) (a first point) for v < 4, else
                // point 2(64(v − 4) + i) + 1 (a second one).
                let point = |v: usize, i: usize| usize::from(cells[2 * (64 * (v % 4) + i) + v / 4]);
                PermutedCells {
                    low: std::array::from_fn(|v| {
                        std::array::from_fn(|i| (point(v, i) % 128) as u8)
                    }),
                    tables: std::array::from_fn(|v| {
                        std::array::from_fn(|t| {
                            (0..64).fold(0u64, |m, i| m | u64::from(point(v, i) / 128 == t) << i)
                        })
                    }),
                }
            })
            .collect();
        Self {
            #[cfg(test)]
            rotated,
            cells,
            #[cfg(target_arch = "x86_64")]
            permuted,
            inside,
        }
    }

    /// The descriptor of a corner from its smoothed patch ([`smoothed_patch`]), oriented
    /// at `angle_rad`: bit `j` of byte `i` is set when pair `8i + j`'s first point is
    /// darker than its second.
    #[inline(always)]
    pub(crate) fn describe(
        &self,
        patch: &[u8; PATCH * PATCH],
        angle_rad: f32,
    ) -> [u8; DESCRIPTOR_BYTES] {
        let cells = &self.cells[angle_step(angle_rad)];
        // (The masks cannot change a cell, all inside the patch; they spare the reads
        // their bounds checks.)
        let at = |cell: u16| patch[usize::from(cell) % (PATCH * PATCH)];
        let mut out = [0; DESCRIPTOR_BYTES];
        for (byte, pairs) in out.iter_mut().zip(cells.chunks_exact(16)) {
            for (bit, pair) in pairs.chunks_exact(2).enumerate() {
                *byte |= u8::from(at(pair[0]) < at(pair[1])) << bit;
            }
        }
        out
    }

    /// [`Pattern::describe`] with AVX-512 VBMI's byte permutes, the patch read in place
    /// (`rows`, [`crate::patch::rows`]) into 16 registers, 64 points looked up at a time,
    /// the 256 comparisons in four (their mask is the descriptor's bit layout).
    ///
    /// # Safety
    /// The CPU has AVX-512 F, BW and VBMI.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512bw,avx512vbmi")]
    #[allow(unsafe_code)]
    pub(crate) unsafe fn describe_vbmi(
        &self,
        rows: &[&[u8; PATCH]; PATCH],
        angle_rad: f32,
    ) -> [u8; DESCRIPTOR_BYTES] {
        use std::arch::x86_64::*;
        let cells = &self.permuted[angle_step(angle_rad)];
        let mut table = [_mm512_setzero_si512(); 16];
        for (k, t) in table.iter_mut().enumerate() {
            let (upper, lower) = (rows[2 * k], rows[2 * k + 1]);
            // SAFETY: each load reads the 32 bytes of a patch row; the CPU has AVX-512 F
            // (the caller's word).
            *t = unsafe {
                let upper = _mm256_loadu_si256(upper.as_ptr().cast());
                let lower = _mm256_loadu_si256(lower.as_ptr().cast());
                _mm512_inserti64x4::<1>(_mm512_castsi256_si512(upper), lower)
            };
        }
        let mut points = [_mm512_setzero_si512(); 8];
        for (v, p) in points.iter_mut().enumerate() {
            // SAFETY: reads the 64 bytes of the array; the CPU has AVX-512 F (the caller's
            // word).
            let low = unsafe { _mm512_loadu_si512(cells.low[v].as_ptr().cast()) };
            for t in 0..8 {
                let part = _mm512_maskz_permutex2var_epi8(
                    cells.tables[v][t],
                    table[2 * t],
                    low,
                    table[2 * t + 1],
                );
                *p = _mm512_or_si512(*p, part);
            }
        }
        let mut out = [0u8; DESCRIPTOR_BYTES];
        for (v, bytes) in out.chunks_exact_mut(8).enumerate() {
            let darker = _mm512_cmplt_epu8_mask(points[v], points[v + 4]);
            bytes.copy_from_slice(&darker.to_le_bytes());
        }
        out
    }

    /// Direction from `(x, y)` to the intensity centroid of the disc of radius 15 around it
    /// in `image`, radians, image axes. The point is at least `BORDER_PX` from the borders.
    ///
    /// The moments are summed lane by lane over the disc's rows and reduced once at the
    /// end: per column, the sum of its pixels inside the disc (for m10 = Σ dx·column), and
    /// per column the rows' pixels times |dy|, below the centre and above it apart (for
    /// m01). Each fits 16 bits (31 × 255, and 255 × Σ 1..=15 = 30 600), so the row loops
    /// vectorise on 16-bit lanes; integer sums, so the result does not depend on the order.
    #[inline(always)]
    pub(crate) fn orientation(&self, image: GrayView<'_>, x: usize, y: usize) -> f32 {
        let start = x - ORIENTATION_RADIUS as usize;
        let mut columns = [0u16; WINDOW];
        // The rows `rows` of the disc: their pixels added to `columns`, and returned
        // weighted by |dy| (in an array of its own, so the row loop keeps it in registers).
        let mut weighted_rows = |rows: std::ops::Range<usize>| {
            let mut side = [0u16; WINDOW];
            for k in rows {
                let dy = k as i32 - ORIENTATION_RADIUS;
                let row = &image.row(y.wrapping_add_signed(dy as isize))[start..start + WINDOW];
                let weight = dy.unsigned_abs() as u16;
                let inside = &self.inside[k];
                for i in 0..WINDOW {
                    let d = inside[i] * u16::from(row[i]);
                    columns[i] += d;
                    side[i] += weight * d;
                }
            }
            side
        };
        let radius = ORIENTATION_RADIUS as usize;
        let above = weighted_rows(0..radius);
        let below = weighted_rows(radius..DISC_ROWS);
        let mut m10 = 0i64;
        for (c, &sum) in columns.iter().enumerate() {
            m10 += (c as i64 - i64::from(ORIENTATION_RADIUS)) * i64::from(sum);
        }
        let total = |lanes: &[u16; WINDOW]| lanes.iter().map(|&v| i64::from(v)).sum::<i64>();
        let m01 = total(&below) - total(&above);
        (m01 as f64).atan2(m10 as f64) as f32
    }
}

#[cfg(test)]
impl PartialEq for Pattern {
    fn eq(&self, other: &Self) -> bool {
        self.rotated == other.rotated && self.inside == other.inside
    }
}

#[cfg(test)]
impl Pattern {
    /// The largest |dx| or |dy| of any rotated point, pixels.
    pub(crate) fn max_offset(&self) -> i32 {
        self.rotated
            .iter()
            .flatten()
            .map(|&(dx, dy)| i32::from(dx.unsigned_abs().max(dy.unsigned_abs())))
            .max()
            .unwrap_or(0)
    }
}

/// The nearest of the [`ANGLE_STEPS`] orientations to `angle_rad`.
#[inline(always)]
fn angle_step(angle_rad: f32) -> usize {
    let steps = ANGLE_STEPS as f64;
    let step = (f64::from(angle_rad) / TAU * steps).round() as i64;
    step.rem_euclid(ANGLE_STEPS as i64) as usize
}

/// The pattern's 2 × 256 points, unturned: the learned table's pairs, first point of pair k
/// at 2k, second at 2k + 1.
fn pattern_points() -> [(i8, i8); 2 * PAIRS] {
    std::array::from_fn(|i| LEARNED_PAIRS[i / 2][i % 2])
}

/// Pattern point `(x, y)` turned by the angle whose sine and cosine `turn` holds, rounded to
/// the pixel. The pattern's learning turns its patches the same way (`learn.rs`).
pub(crate) fn turned((x, y): (i8, i8), (sin, cos): (f64, f64)) -> (i8, i8) {
    let (x, y) = (f64::from(x), f64::from(y));
    (
        (cos * x - sin * y).round() as i8,
        (sin * x + cos * y).round() as i8,
    )
}

/// What the tests borrow: a generator of numbers.
#[cfg(test)]
pub(crate) mod tests_support {
    /// A number in [0, 1) from the SplitMix64 generator (Steele, Lea & Flood 2014).
    pub(crate) fn uniform(state: &mut u64) -> f64 {
        *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = *state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
}
