//! Learning the descriptor's sampling pattern from corners' patches, by the greedy search
//! of ORB's paper (Rublee et al. 2011, §4.3; our own code):
//!
//! 1. each patch is turned to its corner's orientation, and read at every integer point of
//!    the disc of `radius`;
//! 2. a candidate comparison is two of those points at least `min_pair_distance` apart;
//!    its mean over the patches says how often its first point is the darker;
//! 3. the candidates are taken in order of their mean's distance from ½ (a comparison that
//!    splits the corners evenly says the most), each kept when the correlation of its bits
//!    with those of every comparison kept before is within a bound. The bound starts at
//!    `first_bound` and is raised by `bound_step` until `pairs` are kept.
//!
//! `examples/learn_pattern.rs` runs it on images and writes `src/learned_pattern.rs`.

use crate::describe::turned;
use crate::{CornersError, PATCH_CENTRE, PATCH_SIDE, Patch};

/// The search's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LearnSettings {
    /// The points lie within this radius of the corner, pixels (at most 15: turned and
    /// rounded, they stay inside the patch).
    pub radius: i32,
    /// The two points of a comparison are at least this far apart, pixels.
    pub min_pair_distance: f64,
    /// Comparisons wanted.
    pub pairs: usize,
    /// The first bound on the correlation of two kept comparisons.
    pub first_bound: f64,
    /// How much the bound is raised when too few comparisons pass it.
    pub bound_step: f64,
}

impl Default for LearnSettings {
    /// What `src/learned_pattern.rs` was learned with: radius 15, pairs 5 px apart, 256
    /// comparisons, the bound from 0.2 in steps of 0.025.
    fn default() -> Self {
        Self {
            radius: 15,
            min_pair_distance: 5.0,
            pairs: crate::DESCRIPTOR_BYTES * 8,
            first_bound: 0.2,
            bound_step: 0.025,
        }
    }
}

/// A learned pattern.
#[derive(Debug, Clone, PartialEq)]
pub struct LearnedPattern {
    /// The comparisons, unturned: `(dx, dy)` of the first point and of the second.
    pub pairs: Vec<[(i8, i8); 2]>,
    /// The correlation bound they were kept at.
    pub bound: f64,
}

/// Learns a pattern from `patches` (see the module's text). Errs when the settings are out
/// of range, or when even a bound of 1 keeps fewer than `settings.pairs` comparisons (too
/// few patches, or patches that do not vary).
pub fn learn_pattern(
    patches: &[Patch],
    settings: &LearnSettings,
) -> Result<LearnedPattern, CornersError> {
    let fail = |name, value: String, reason| {
        Err(CornersError::Param {
            name,
            value,
            reason,
        })
    };
    if !(1..=PATCH_CENTRE as i32).contains(&settings.radius) {
        return fail("radius", settings.radius.to_string(), "must be 1 to 15");
    }
    if !(settings.first_bound > 0.0 && settings.bound_step > 0.0) {
        return fail(
            "first_bound",
            format!("{} (step {})", settings.first_bound, settings.bound_step),
            "the bound and its step must be above 0",
        );
    }
    let positions = disc_positions(settings.radius);
    let values = turned_values(patches, &positions);
    let candidates = ranked_candidates(&values, &positions, settings.min_pair_distance);
    let mut bits = Vec::new();
    let mut bound = settings.first_bound;
    loop {
        let kept = greedy(&values, &candidates, bound, settings.pairs, &mut bits);
        if kept.len() == settings.pairs {
            let pairs = kept
                .into_iter()
                .map(|(a, b)| [offset(positions[a]), offset(positions[b])])
                .collect();
            return Ok(LearnedPattern { pairs, bound });
        }
        if bound >= 1.0 {
            return fail(
                "pairs",
                settings.pairs.to_string(),
                "more comparisons than these patches tell apart",
            );
        }
        bound += settings.bound_step;
    }
}

/// A point as the pattern stores it (the radius is at most 15: it fits).
fn offset((x, y): (i32, i32)) -> (i8, i8) {
    (x as i8, y as i8)
}

/// The integer points of the disc of `radius`, row by row.
fn disc_positions(radius: i32) -> Vec<(i32, i32)> {
    (-radius..=radius)
        .flat_map(|y| (-radius..=radius).map(move |x| (x, y)))
        .filter(|&(x, y)| x * x + y * y <= radius * radius)
        .collect()
}

/// Per position, the value of every patch there once the patch is turned to its corner's
/// orientation (positions major: `values[p][k]` for patch k).
fn turned_values(patches: &[Patch], positions: &[(i32, i32)]) -> Vec<Vec<u8>> {
    let mut values = vec![Vec::with_capacity(patches.len()); positions.len()];
    let centre = PATCH_CENTRE as i32;
    let last = PATCH_SIDE as i32 - 1;
    for patch in patches {
        let turn = f64::from(patch.angle_rad).sin_cos();
        for (column, &position) in values.iter_mut().zip(positions) {
            let (rx, ry) = turned(offset(position), turn);
            let (rx, ry) = (i32::from(rx), i32::from(ry));
            let (px, py) = ((centre + rx).clamp(0, last), (centre + ry).clamp(0, last));
            column.push(patch.pixels[py as usize * PATCH_SIDE + px as usize]);
        }
    }
    values
}

/// Every comparison `(a, b)` of positions at least `min_distance` apart, the most even
/// first (ties in the order of the positions).
fn ranked_candidates(
    values: &[Vec<u8>],
    positions: &[(i32, i32)],
    min_distance: f64,
) -> Vec<(usize, usize)> {
    let n = values.first().map_or(0, Vec::len).max(1) as f64;
    let mut ranked: Vec<(f64, usize, usize)> = Vec::new();
    for (a, &(xa, ya)) in positions.iter().enumerate() {
        for (b, &(xb, yb)) in positions.iter().enumerate().skip(a + 1) {
            if f64::from(xa - xb).hypot(f64::from(ya - yb)) < min_distance {
                continue;
            }
            let darker = values[a]
                .iter()
                .zip(&values[b])
                .filter(|(p, q)| p < q)
                .count();
            ranked.push(((darker as f64 / n - 0.5).abs(), a, b));
        }
    }
    ranked.sort_by(|p, q| p.0.total_cmp(&q.0).then((p.1, p.2).cmp(&(q.1, q.2))));
    ranked.into_iter().map(|(_, a, b)| (a, b)).collect()
}

/// A comparison's bits over the patches and how often it is 1.
struct Bits {
    words: Vec<u64>,
    mean: f64,
}

impl Bits {
    fn of(values: &[Vec<u8>], (a, b): (usize, usize)) -> Self {
        let n = values[a].len();
        let mut words = vec![0u64; n.div_ceil(64)];
        for (k, (p, q)) in values[a].iter().zip(&values[b]).enumerate() {
            words[k / 64] |= u64::from(p < q) << (k % 64);
        }
        let ones: u32 = words.iter().map(|w| w.count_ones()).sum();
        Self {
            words,
            mean: f64::from(ones) / n.max(1) as f64,
        }
    }

    /// The correlation of the two comparisons' bits (1 when either never varies).
    fn correlation(&self, other: &Bits, n: usize) -> f64 {
        let both: u32 = self
            .words
            .iter()
            .zip(&other.words)
            .map(|(x, y)| (x & y).count_ones())
            .sum();
        let (p, q) = (self.mean, other.mean);
        let spread = (p * (1.0 - p) * q * (1.0 - q)).sqrt();
        if spread == 0.0 {
            return 1.0;
        }
        (f64::from(both) / n as f64 - p * q) / spread
    }
}

/// The candidates kept, in order, at `bound`, up to `wanted` of them. `bits` caches the
/// candidates' bits from one bound to the next (index: rank).
fn greedy(
    values: &[Vec<u8>],
    candidates: &[(usize, usize)],
    bound: f64,
    wanted: usize,
    bits: &mut Vec<Bits>,
) -> Vec<(usize, usize)> {
    let n = values.first().map_or(0, Vec::len);
    let mut kept: Vec<usize> = Vec::with_capacity(wanted);
    for (rank, &candidate) in candidates.iter().enumerate() {
        if rank == bits.len() {
            bits.push(Bits::of(values, candidate));
        }
        let mine = &bits[rank];
        // (A comparison that never varies tells no corner from another.)
        if mine.mean <= 0.0 || mine.mean >= 1.0 {
            continue;
        }
        let free = kept
            .iter()
            .all(|&k| mine.correlation(&bits[k], n).abs() <= bound);
        if free {
            kept.push(rank);
            if kept.len() == wanted {
                break;
            }
        }
    }
    kept.into_iter().map(|rank| candidates[rank]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Patches at orientation 0 whose pixels rise by 7 a column, plus noise under 15: two
    /// points of one column compare either way as often, one or two columns apart mostly
    /// one way (about 86 % and 99 % of the time), three or more always the same way.
    fn ramps(count: usize) -> Vec<Patch> {
        let mut state = 7u64;
        (0..count)
            .map(|_| Patch {
                pixels: std::array::from_fn(|i| {
                    let column = (i % PATCH_SIDE) as u64;
                    let noise = crate::describe::tests_support::uniform(&mut state) * 15.0;
                    (column * 7 + noise as u64) as u8
                }),
                angle_rad: 0.0,
            })
            .collect()
    }

    #[test]
    fn the_most_even_comparisons_are_learned_and_they_are_spread_apart() {
        let settings = LearnSettings {
            radius: 6,
            pairs: 24,
            ..LearnSettings::default()
        };
        let learned = learn_pattern(&ramps(400), &settings).unwrap();
        assert_eq!(learned.pairs.len(), 24);
        for [(x1, y1), (x2, y2)] in &learned.pairs {
            // The even ones: one column (enough of them lie in the disc, 188 pairs).
            assert_eq!(x1, x2, "{:?}", learned.pairs);
            let distance = f64::from(x1 - x2).hypot(f64::from(y1 - y2));
            assert!(distance >= settings.min_pair_distance);
            for (x, y) in [(x1, y1), (x2, y2)] {
                assert!(i32::from(*x).pow(2) + i32::from(*y).pow(2) <= 36);
            }
        }
        let mut unique = learned.pairs.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(unique.len(), learned.pairs.len());
    }

    #[test]
    fn kept_comparisons_are_no_more_correlated_than_the_bound() {
        let patches = ramps(300);
        let settings = LearnSettings {
            radius: 5,
            pairs: 16,
            ..LearnSettings::default()
        };
        let learned = learn_pattern(&patches, &settings).unwrap();
        let positions = disc_positions(settings.radius);
        let index = |(x, y): (i8, i8)| {
            positions
                .iter()
                .position(|&p| p == (i32::from(x), i32::from(y)))
                .unwrap()
        };
        let values = turned_values(&patches, &positions);
        let bits: Vec<Bits> = learned
            .pairs
            .iter()
            .map(|[a, b]| Bits::of(&values, (index(*a), index(*b))))
            .collect();
        for (i, a) in bits.iter().enumerate() {
            for b in &bits[..i] {
                assert!(a.correlation(b, patches.len()).abs() <= learned.bound + 1e-12);
            }
        }
    }

    #[test]
    fn patches_that_do_not_vary_are_refused() {
        let flat = vec![
            Patch {
                pixels: [90; PATCH_SIDE * PATCH_SIDE],
                angle_rad: 0.0,
            };
            50
        ];
        let settings = LearnSettings {
            radius: 4,
            pairs: 8,
            ..LearnSettings::default()
        };
        assert!(matches!(
            learn_pattern(&flat, &settings),
            Err(CornersError::Param { name: "pairs", .. })
        ));
        let too_wide = LearnSettings {
            radius: 16,
            ..LearnSettings::default()
        };
        assert!(learn_pattern(&flat, &too_wide).is_err());
    }
}
