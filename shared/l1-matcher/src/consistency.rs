//! Disparity consistency of stereo matches with their neighbours (not in the paper).
//!
//! A stereo match of two segments that are not near-horizontal has a disparity: the
//! horizontal distance between the two lines on the middle row they share. Neighbouring
//! segments mostly lie on the same surfaces, so a correct match usually has a neighbour of
//! about the same disparity, while a segment matched to a look-alike elsewhere on its rows
//! stands out. A match is dropped when enough of its nearest neighbours (by left
//! midpoint, within a distance) have a disparity and none of them agrees with its own.

use crate::{Consistency, Match};
use linetrack_geometry::SegmentFeatures;

#[derive(Debug, Clone)]
pub(crate) struct DisparityCheck {
    config: Consistency,
    /// Disparity per tentative match (NaN where it has none).
    disparity: Vec<f64>,
    /// Scratch: (squared distance, disparity) of the other matches.
    nearest: Vec<(f64, f64)>,
    keep: Vec<bool>,
}

impl DisparityCheck {
    pub(crate) fn new(config: Consistency) -> Self {
        Self {
            config,
            disparity: Vec::new(),
            nearest: Vec::new(),
            keep: Vec::new(),
        }
    }

    /// Removes the inconsistent stereo matches; returns how many were removed.
    pub(crate) fn retain(
        &mut self,
        matches: &mut Vec<Match>,
        first: &[Option<SegmentFeatures>],
        second: &[Option<SegmentFeatures>],
    ) -> usize {
        if !self.config.enabled {
            return 0;
        }
        let min_sin = self.config.min_angle_from_horizontal_deg.to_radians().sin();
        let max_distance_sq = self.config.max_distance_px.powi(2);
        self.disparity.clear();
        self.disparity.extend(
            matches
                .iter()
                .map(|m| match (&first[m.query], &second[m.train]) {
                    (Some(a), Some(b)) => disparity(a, b, min_sin),
                    _ => f64::NAN,
                }),
        );
        self.keep.clear();
        for (k, m) in matches.iter().enumerate() {
            let d = self.disparity[k];
            let Some(a) = first[m.query].as_ref().filter(|_| d.is_finite()) else {
                self.keep.push(true);
                continue;
            };
            self.nearest.clear();
            for (other, n) in matches.iter().enumerate() {
                let dn = self.disparity[other];
                if other == k || !dn.is_finite() {
                    continue;
                }
                if let Some(b) = &first[n.query] {
                    let distance_sq = (a.mid - b.mid).norm_squared();
                    if distance_sq <= max_distance_sq {
                        self.nearest.push((distance_sq, dn));
                    }
                }
            }
            let count = self.config.neighbours.min(self.nearest.len());
            if count < self.config.min_neighbours {
                self.keep.push(true);
                continue;
            }
            if count < self.nearest.len() {
                self.nearest
                    .select_nth_unstable_by(count, |p, q| p.0.total_cmp(&q.0));
            }
            let tolerance = self
                .config
                .max_difference_px
                .max(self.config.max_relative_difference * d.abs());
            let agreed = self.nearest[..count]
                .iter()
                .any(|(_, dn)| (dn - d).abs() <= tolerance);
            self.keep.push(agreed);
        }
        let before = matches.len();
        let mut flags = self.keep.iter();
        matches.retain(|_| flags.next().copied().unwrap_or(true));
        before - matches.len()
    }
}

/// The disparity of a stereo pair of segments at the middle of the rows they share, or
/// NaN when either is within the angle of horizontal or they share no row.
pub(crate) fn disparity(a: &SegmentFeatures, b: &SegmentFeatures, min_sin: f64) -> f64 {
    if a.dir.y.abs() < min_sin || b.dir.y.abs() < min_sin || a.dir.y == 0.0 || b.dir.y == 0.0 {
        return f64::NAN;
    }
    let (low, high) = (a.y_min.max(b.y_min), a.y_max.min(b.y_max));
    if low > high {
        return f64::NAN;
    }
    let row = 0.5 * (low + high);
    let x_at = |f: &SegmentFeatures| f.mid.x + (row - f.mid.y) * f.dir.x / f.dir.y;
    x_at(a) - x_at(b)
}
