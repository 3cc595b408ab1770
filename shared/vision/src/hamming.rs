//! Binary descriptors and their matching: mutual best by Hamming distance, accepted only
//! when the second-best distance is clearly larger. Shared by LBD (segments) and ORB
//! (points); which pairs may match at all is decided by the caller's gate.

use crate::cpu::with_popcnt;
use crate::{OpenCvContext, VisionError};
use opencv::core::{Mat, MatTraitConst, MatTraitConstManual};
use serde::{Deserialize, Serialize};

/// One binary descriptor per feature, or none where the descriptor could not be computed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BinaryDescriptors {
    bytes: Vec<u8>,
    row_bytes: usize,
    present: Vec<bool>,
}

impl BinaryDescriptors {
    /// Makes room for `rows` descriptors of `row_bytes` bytes, all absent.
    pub fn reset(&mut self, rows: usize, row_bytes: usize) {
        self.row_bytes = row_bytes;
        self.bytes.clear();
        self.bytes.resize(rows * row_bytes, 0);
        self.present.clear();
        self.present.resize(rows, false);
    }

    /// Makes this a copy of `other`, in the buffers it has (no allocation once they are
    /// large enough).
    pub fn copy_from(&mut self, other: &Self) {
        self.bytes.clone_from(&other.bytes);
        self.row_bytes = other.row_bytes;
        self.present.clone_from(&other.present);
    }

    /// Sets row `row` (of the size [`BinaryDescriptors::reset`] made) to `bytes`.
    pub(crate) fn set_row(&mut self, row: usize, bytes: &[u8]) {
        self.bytes[row * self.row_bytes..(row + 1) * self.row_bytes].copy_from_slice(bytes);
        self.present[row] = true;
    }

    /// Copies row `source_row` of an OpenCV CV_8U descriptor matrix into row `row`.
    pub(crate) fn set_from_mat(
        &mut self,
        row: usize,
        mat: &Mat,
        source_row: i32,
    ) -> Result<(), VisionError> {
        let data = mat.row(source_row).context("reading a descriptor row")?;
        let bytes = data.data_bytes().context("reading descriptor bytes")?;
        if bytes.len() != self.row_bytes || row >= self.present.len() {
            return Ok(());
        }
        self.bytes[row * self.row_bytes..(row + 1) * self.row_bytes].copy_from_slice(bytes);
        self.present[row] = true;
        Ok(())
    }

    /// Copies the first rows of an OpenCV CV_8U descriptor matrix (one per feature, as
    /// many as both have) in one pass when its rows are contiguous, else row by row.
    pub(crate) fn set_rows_from_mat(&mut self, mat: &Mat) -> Result<(), VisionError> {
        let rows = self
            .present
            .len()
            .min(usize::try_from(mat.rows()).unwrap_or(0));
        let row_bytes = self.row_bytes;
        let whole = if mat.is_continuous() && mat.elem_size1() == 1 && mat.channels() == 1 {
            mat.data_bytes().context("reading descriptor bytes")?
        } else {
            &[]
        };
        if usize::try_from(mat.cols()).ok() != Some(row_bytes) || whole.len() < rows * row_bytes {
            for k in 0..rows {
                self.set_from_mat(k, mat, k as i32)?;
            }
            return Ok(());
        }
        self.bytes[..rows * row_bytes].copy_from_slice(&whole[..rows * row_bytes]);
        self.present[..rows].fill(true);
        Ok(())
    }

    /// Number of features (with or without a descriptor).
    pub fn len(&self) -> usize {
        self.present.len()
    }

    /// Whether there are no features.
    pub fn is_empty(&self) -> bool {
        self.present.is_empty()
    }

    /// Descriptor of feature `k`, if it has one.
    pub fn row(&self, k: usize) -> Option<&[u8]> {
        self.present
            .get(k)
            .copied()
            .unwrap_or(false)
            .then(|| &self.bytes[k * self.row_bytes..(k + 1) * self.row_bytes])
    }

    /// Features that have a descriptor.
    pub fn count_present(&self) -> usize {
        self.present.iter().filter(|p| **p).count()
    }
}

/// One correspondence from an appearance or geometric matcher.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FeatureMatch {
    /// Index in the first set.
    pub query: usize,
    /// Index in the second set.
    pub train: usize,
    /// Hamming distance in bits (LBD, ORB) or geometric error (ℓ1).
    pub distance: f64,
}

/// Hamming distance in bits between two equally long byte strings.
#[inline(always)]
pub(crate) fn hamming(a: &[u8], b: &[u8]) -> u32 {
    // ORB's and LBD's 32 bytes: with the length known, the four words are unrolled.
    if let (Ok(x), Ok(y)) = (<&[u8; 32]>::try_from(a), <&[u8; 32]>::try_from(b)) {
        return differing_bits(x, y);
    }
    differing_bits(a, b)
}

/// [`hamming`] a word at a time, then byte by byte for the tail.
#[inline(always)]
fn differing_bits(a: &[u8], b: &[u8]) -> u32 {
    let ((a_words, a_tail), (b_words, b_tail)) = (a.as_chunks::<8>(), b.as_chunks::<8>());
    let words: u32 = a_words
        .iter()
        .zip(b_words)
        .map(|(x, y)| (u64::from_le_bytes(*x) ^ u64::from_le_bytes(*y)).count_ones())
        .sum();
    let tail: u32 = a_tail
        .iter()
        .zip(b_tail)
        .map(|(x, y)| (x ^ y).count_ones())
        .sum();
    words + tail
}

/// Mutual-best Hamming matcher with a second-best ratio test; keeps its buffers.
#[derive(Debug, Clone, Default)]
pub struct HammingMatcher {
    /// Per first feature: its nearest admitted second feature, that distance and the
    /// second-nearest distance.
    nearest: Vec<(Option<usize>, u32, u32)>,
    /// Per second feature: the distance to its nearest first feature and which one.
    nearest_query_of_train: Vec<(u32, Option<usize>)>,
    candidates: Vec<usize>,
}

const NO_PAIR: u32 = u32::MAX;

impl HammingMatcher {
    /// A matcher with empty buffers.
    pub fn new() -> Self {
        Self::default()
    }

    /// Replaces `out` with the pairs (i, j) such that, among the pairs `admit` allows,
    /// j is i's nearest descriptor, i is j's nearest, and i's second-nearest is at least
    /// `min_ratio` times farther than j. Every pair is compared.
    pub fn match_mutual(
        &mut self,
        first: &BinaryDescriptors,
        second: &BinaryDescriptors,
        min_ratio: f64,
        admit: impl Fn(usize, usize) -> bool,
        out: &mut Vec<FeatureMatch>,
    ) {
        let n = second.len();
        self.match_mutual_among(
            first,
            second,
            min_ratio,
            |_, candidates| candidates.extend(0..n),
            admit,
            out,
        );
    }

    /// [`HammingMatcher::match_mutual`] comparing feature i of `first` only with the
    /// features `candidates(i, list)` puts in the list (in any order, each once): the
    /// caller's spatial index in place of every pair. The result is the one
    /// `match_mutual` gives when every pair `admit` allows is among the candidates;
    /// ties go to the lower index, as there (and a tie for the nearest fails the ratio
    /// test, as there).
    pub fn match_mutual_among(
        &mut self,
        first: &BinaryDescriptors,
        second: &BinaryDescriptors,
        min_ratio: f64,
        candidates: impl FnMut(usize, &mut Vec<usize>),
        admit: impl Fn(usize, usize) -> bool,
        out: &mut Vec<FeatureMatch>,
    ) {
        // (The bit counts, most of a match's work, with the POPCNT instruction where the
        // CPU has it; the same results.)
        with_popcnt(
            #[inline(always)]
            || self.match_portably(first, second, min_ratio, candidates, admit, out),
        );
    }

    /// [`HammingMatcher::match_mutual_among`] for any CPU; inlined into the callers that
    /// are compiled for more.
    #[inline(always)]
    fn match_portably(
        &mut self,
        first: &BinaryDescriptors,
        second: &BinaryDescriptors,
        min_ratio: f64,
        mut candidates: impl FnMut(usize, &mut Vec<usize>),
        admit: impl Fn(usize, usize) -> bool,
        out: &mut Vec<FeatureMatch>,
    ) {
        out.clear();
        let (m, n) = (first.len(), second.len());
        self.nearest.clear();
        self.nearest.resize(m, (None, NO_PAIR, NO_PAIR));
        self.nearest_query_of_train.clear();
        self.nearest_query_of_train.resize(n, (NO_PAIR, None));
        for i in 0..m {
            let Some(a) = first.row(i) else { continue };
            self.candidates.clear();
            candidates(i, &mut self.candidates);
            let (mut best, mut best_d, mut second_d) = (None, NO_PAIR, NO_PAIR);
            for &j in &self.candidates {
                let Some(b) = second.row(j) else { continue };
                if a.len() != b.len() || !admit(i, j) {
                    continue;
                }
                let d = hamming(a, b);
                if d < best_d {
                    second_d = best_d;
                    best_d = d;
                    best = Some(j);
                } else {
                    if d == best_d && best.is_some_and(|b| j < b) {
                        best = Some(j);
                    }
                    second_d = second_d.min(d);
                }
                // Rows are visited in increasing i: a strict improvement keeps the
                // lowest i among equals.
                let of_train = &mut self.nearest_query_of_train[j];
                if d < of_train.0 {
                    *of_train = (d, Some(i));
                }
            }
            self.nearest[i] = (best, best_d, second_d);
        }
        for (i, &(best, best_d, second_d)) in self.nearest.iter().enumerate() {
            let Some(j) = best else { continue };
            let distinct = second_d == NO_PAIR
                || (second_d > best_d && f64::from(second_d) >= min_ratio * f64::from(best_d));
            if distinct && self.nearest_query_of_train[j].1 == Some(i) {
                out.push(FeatureMatch {
                    query: i,
                    train: j,
                    distance: f64::from(best_d),
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn descriptors(rows: &[[u8; 4]]) -> BinaryDescriptors {
        let mut d = BinaryDescriptors::default();
        d.reset(rows.len(), 4);
        for (k, r) in rows.iter().enumerate() {
            d.set_row(k, r);
        }
        d
    }

    #[test]
    fn hamming_counts_differing_bits_across_words_and_tail() {
        let a = [0xFFu8; 11];
        let mut b = [0xFFu8; 11];
        b[0] = 0x0F;
        b[10] = 0xFE;
        assert_eq!(hamming(&a, &b), 5);
        assert_eq!(hamming(&a, &a), 0);
    }

    /// ORB's and LBD's 32 bytes take the unrolled path: each bit of each word counts once.
    #[test]
    fn hamming_of_32_bytes_counts_every_bit() {
        let bitwise = |a: &[u8], b: &[u8]| -> u32 {
            a.iter()
                .zip(b)
                .map(|(x, y)| (0..8).filter(|k| (x ^ y) >> k & 1 == 1).count() as u32)
                .sum()
        };
        let a = [0u8; 32];
        for k in 0..256 {
            let mut b = [0u8; 32];
            b[k / 8] = 1 << (k % 8);
            b[31 - k / 8] |= 0x80;
            assert_eq!(hamming(&a, &b), bitwise(&a, &b), "bit {k}");
        }
        let (x, y) = ([0x5Au8; 32], [0xC3u8; 32]);
        assert_eq!(hamming(&x, &y), bitwise(&x, &y));
        assert_eq!(hamming(&x, &y), 4 * 32);
    }

    #[test]
    fn mutual_best_with_ratio() {
        let first = descriptors(&[[0, 0, 0, 0], [0xFF, 0xFF, 0, 0]]);
        let second = descriptors(&[[0xFF, 0xFF, 0, 1], [0, 0, 0, 1], [0xFF, 0xFF, 0xFF, 0xFF]]);
        let mut out = Vec::new();
        HammingMatcher::new().match_mutual(&first, &second, 2.0, |_, _| true, &mut out);
        let pairs: Vec<(usize, usize)> = out.iter().map(|m| (m.query, m.train)).collect();
        assert_eq!(pairs, vec![(0, 1), (1, 0)]);
    }

    #[test]
    fn close_second_best_and_gates_reject() {
        let first = descriptors(&[[0, 0, 0, 0]]);
        let second = descriptors(&[[1, 0, 0, 0], [3, 0, 0, 0]]);
        let mut out = Vec::new();
        let mut matcher = HammingMatcher::new();
        // Distances 1 and 2: ratio 2 passes, 2.5 does not.
        matcher.match_mutual(&first, &second, 2.0, |_, _| true, &mut out);
        assert_eq!(out.len(), 1);
        matcher.match_mutual(&first, &second, 2.5, |_, _| true, &mut out);
        assert!(out.is_empty());
        // Gating the best away leaves the other, unique candidate.
        matcher.match_mutual(&first, &second, 2.5, |_, j| j == 1, &mut out);
        assert_eq!(out.first().map(|m| m.train), Some(1));
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_popcnt_build_matches_as_the_portable_one() {
        // Every x86-64 CPU since 2008 has the instruction; one without it would not test
        // the build this is about.
        assert!(std::arch::is_x86_feature_detected!("popcnt"));
        use rand::{Rng, SeedableRng};
        // ORB-sized descriptors, near copies of shared patterns (close pairs,
        // ties and ratio-test calls), a few missing.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let patterns: Vec<[u8; 32]> = (0..200).map(|_| rng.random()).collect();
        let mut noisy = |n: usize| {
            let mut d = BinaryDescriptors::default();
            d.reset(n, 32);
            for k in 0..n {
                let mut row = patterns[rng.random_range(0..patterns.len())];
                for _ in 0..rng.random_range(0..24) {
                    row[rng.random_range(0..32)] ^= 1 << rng.random_range(0..8);
                }
                d.set_row(k, &row);
                d.present[k] = rng.random_range(0..20) > 0;
            }
            d
        };
        let (first, second) = (noisy(300), noisy(280));
        let admit = |i: usize, j: usize| !(i + 2 * j).is_multiple_of(7);
        let (mut popcnt, mut portable) = (Vec::new(), Vec::new());
        let mut matcher = HammingMatcher::new();
        for ratio in [1.0, 1.2, 1.5] {
            let all = |_: usize, c: &mut Vec<usize>| c.extend(0..280);
            matcher.match_mutual_among(&first, &second, ratio, all, admit, &mut popcnt);
            matcher.match_portably(&first, &second, ratio, all, admit, &mut portable);
            assert!(popcnt.len() > 20, "{}", popcnt.len());
            assert_eq!(popcnt, portable, "ratio {ratio}");
        }
    }

    #[test]
    fn missing_descriptors_never_match() {
        let mut first = descriptors(&[[0, 0, 0, 0]]);
        first.present[0] = false;
        let second = descriptors(&[[0, 0, 0, 0]]);
        let mut out = Vec::new();
        HammingMatcher::new().match_mutual(&first, &second, 1.0, |_, _| true, &mut out);
        assert!(out.is_empty());
    }
}
