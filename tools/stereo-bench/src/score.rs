//! The scoring rule: is a stereo segment match correct under the ground-truth disparity?
//!
//! A match (left segment `i`, right segment `j`) is **correct** when the left segment,
//! shifted by the ground-truth disparity read along it, lies within [`Scorer::tolerance_px`]
//! of the right segment's line and overlaps the right segment:
//!
//! 1. [`SAMPLES`] points are taken evenly along the left segment.
//! 2. A line segment in a real image is often a depth edge: the pixels under it may belong
//!    to either surface. So the disparity is read under each point and, as separate
//!    hypotheses, 1, 2 and 3 px to either side along the segment's normal. For each
//!    hypothesis every point with a known disparity is shifted (x − d, y) and its distance
//!    to the right segment's infinite line taken; the hypothesis with the smallest median
//!    distance is the surface that fits (ties go to the one nearest the segment).
//! 3. The match is correct when that median is within the tolerance and the shifted left
//!    segment, projected on the right segment's line, overlaps the right segment.
//!
//! A hypothesis needs a known disparity under at least half the points (and 3); when none
//! has, the match is **unjudged** and left out of the precision. A left segment is
//! **matchable** when some right segment would be a correct match for it; recall is the
//! number of correct matches over the number of matchable left segments.

use linetrack_datasets::DisparityMap;
use linetrack_geometry::{Point, Segment, Vector};

/// Points sampled along a left segment.
pub const SAMPLES: usize = 11;

/// Offsets (pixels along the left segment's normal) at which the disparity is read, one
/// hypothesis each, nearest first.
const SIDE_OFFSETS_PX: [f64; 7] = [0.0, -1.0, 1.0, -2.0, 2.0, -3.0, 3.0];

/// What the ground truth says of one match.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Within the tolerance of the right segment's line, and overlapping it.
    Correct,
    /// Judged and not correct.
    Wrong,
    /// Too little ground truth under the left segment to judge.
    Unjudged,
}

/// The scoring rule with its tolerance.
#[derive(Debug, Clone, Copy)]
pub struct Scorer {
    /// Largest median distance (pixels) of the shifted left segment to the right line.
    pub tolerance_px: f64,
}

impl Default for Scorer {
    fn default() -> Self {
        Self { tolerance_px: 1.0 }
    }
}

/// The left segment carried into the right image by the best-fitting surface.
struct Shifted {
    /// Median distance of the shifted points to the right segment's line.
    median_distance_px: f64,
    /// Median disparity of the hypothesis.
    disparity_px: f64,
}

impl Scorer {
    /// Judges the match of `left` (left image) with `right` (right image).
    pub fn judge(&self, left: &Segment, right: &Segment, disparity: &DisparityMap) -> Verdict {
        let (Some(right_dir), Some(normal)) = (unit(right.end - right.start), left_normal(left))
        else {
            return Verdict::Unjudged;
        };
        let Some(best) = best_hypothesis(left, normal, right, right_dir, disparity) else {
            return Verdict::Unjudged;
        };
        if best.median_distance_px > self.tolerance_px {
            return Verdict::Wrong;
        }
        let shift = Vector::new(best.disparity_px, 0.0);
        let along = |p: Point| (p - right.start).dot(&right_dir);
        let (a, b) = (along(left.start - shift), along(left.end - shift));
        let (low, high) = (a.min(b), a.max(b));
        let overlap = high.min(right.length()) - low.max(0.0);
        if overlap > 0.0 {
            Verdict::Correct
        } else {
            Verdict::Wrong
        }
    }

    /// The median distance (pixels) of the left segment, carried by the best-fitting
    /// surface, to the right segment's line; `None` when it cannot be judged.
    pub fn distance_px(
        &self,
        left: &Segment,
        right: &Segment,
        disparity: &DisparityMap,
    ) -> Option<f64> {
        let right_dir = unit(right.end - right.start)?;
        let normal = left_normal(left)?;
        best_hypothesis(left, normal, right, right_dir, disparity).map(|b| b.median_distance_px)
    }

    /// For each left segment, whether some right segment is a correct match for it.
    pub fn matchable(
        &self,
        left: &[Segment],
        right: &[Segment],
        disparity: &DisparityMap,
    ) -> Vec<bool> {
        left.iter()
            .map(|l| {
                right
                    .iter()
                    .any(|r| self.judge(l, r, disparity) == Verdict::Correct)
            })
            .collect()
    }
}

fn unit(v: Vector) -> Option<Vector> {
    let n = v.norm();
    (n.is_finite() && n > 1e-9).then(|| v / n)
}

fn left_normal(left: &Segment) -> Option<Vector> {
    unit(left.end - left.start).map(|d| Vector::new(-d.y, d.x))
}

fn best_hypothesis(
    left: &Segment,
    normal: Vector,
    right: &Segment,
    right_dir: Vector,
    disparity: &DisparityMap,
) -> Option<Shifted> {
    let needed = (SAMPLES / 2).max(3);
    let mut distances = Vec::with_capacity(SAMPLES);
    let mut disparities = Vec::with_capacity(SAMPLES);
    let mut best: Option<Shifted> = None;
    for offset in SIDE_OFFSETS_PX {
        distances.clear();
        disparities.clear();
        for k in 0..SAMPLES {
            let t = (k as f64 + 0.5) / SAMPLES as f64;
            let p = left.start + (left.end - left.start) * t;
            let read = p + normal * offset;
            let Some(d) = disparity.at(read.x, read.y) else {
                continue;
            };
            let shifted = p - Vector::new(d, 0.0);
            let off_line = shifted - right.start;
            distances.push((off_line.x * right_dir.y - off_line.y * right_dir.x).abs());
            disparities.push(d);
        }
        if distances.len() < needed {
            continue;
        }
        let candidate = Shifted {
            median_distance_px: median(&mut distances),
            disparity_px: median(&mut disparities),
        };
        if best
            .as_ref()
            .is_none_or(|b| candidate.median_distance_px < b.median_distance_px)
        {
            best = Some(candidate);
        }
    }
    best
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A slanted plane: d(x, y) = 20 + 0.05·x − 0.02·y over 200 × 100 pixels.
    fn plane() -> DisparityMap {
        let (w, h) = (200, 100);
        let values = (0..h)
            .flat_map(|y| (0..w).map(move |x| (20.0 + 0.05 * x as f64 - 0.02 * y as f64) as f32))
            .collect();
        DisparityMap::from_values(w, h, values).unwrap()
    }

    /// The left segment carried exactly into the right image by the plane.
    fn carried(left: &Segment) -> Segment {
        let d = |p: Point| 20.0 + 0.05 * p.x.round() - 0.02 * p.y.round();
        Segment::new(
            left.start - Vector::new(d(left.start), 0.0),
            left.end - Vector::new(d(left.end), 0.0),
        )
    }

    #[test]
    fn a_segment_carried_by_the_plane_is_correct_and_a_shifted_one_is_not() {
        let scorer = Scorer::default();
        let map = plane();
        for left in [
            Segment::from_coords(100.0, 10.0, 110.0, 90.0),
            Segment::from_coords(60.0, 20.0, 150.0, 70.0),
            Segment::from_coords(150.0, 80.0, 140.0, 15.0),
        ] {
            let right = carried(&left);
            assert_eq!(
                scorer.judge(&left, &right, &map),
                Verdict::Correct,
                "{left:?}"
            );
            assert_eq!(
                scorer.judge(&left, &right.reversed(), &map),
                Verdict::Correct,
                "endpoint order does not matter"
            );
            let shift = |s: &Segment, dx: f64| {
                Segment::new(s.start + Vector::new(dx, 0.0), s.end + Vector::new(dx, 0.0))
            };
            // 0.6 px off is within the 1 px tolerance; 2.5 px is not.
            assert_eq!(
                scorer.judge(&left, &shift(&right, 0.6), &map),
                Verdict::Correct
            );
            assert_eq!(
                scorer.judge(&left, &shift(&right, 2.5), &map),
                Verdict::Wrong
            );
            assert_eq!(
                scorer.judge(&left, &shift(&right, -2.5), &map),
                Verdict::Wrong
            );
        }
    }

    #[test]
    fn a_horizontal_segment_must_overlap_at_the_true_disparity() {
        let scorer = Scorer::default();
        let map = plane();
        let left = Segment::from_coords(100.0, 50.0, 140.0, 50.0);
        let right = carried(&left);
        assert_eq!(scorer.judge(&left, &right, &map), Verdict::Correct);
        // Same row, 60 px further left: on the line, but no overlap.
        let far = Segment::from_coords(right.start.x - 60.0, 50.0, right.end.x - 60.0, 50.0);
        assert_eq!(scorer.judge(&left, &far, &map), Verdict::Wrong);
        // A short piece of the carried segment still overlaps.
        let piece = Segment::from_coords(right.start.x + 5.0, 50.0, right.start.x + 12.0, 50.0);
        assert_eq!(scorer.judge(&left, &piece, &map), Verdict::Correct);
    }

    #[test]
    fn a_depth_edge_is_judged_by_the_surface_that_fits() {
        // Foreground (d = 30) left of x = 100, background (d = 10) from x = 100 on. The
        // segment lies on the boundary; the right image sees it at either disparity
        // depending on which surface it belongs to.
        let (w, h) = (200, 100);
        let values = (0..h)
            .flat_map(|_| (0..w).map(|x| if x < 100 { 30.0 } else { 10.0 }))
            .collect();
        let map = DisparityMap::from_values(w, h, values).unwrap();
        let scorer = Scorer::default();
        let left = Segment::from_coords(100.0, 10.0, 100.0, 90.0);
        let at = |d: f64| Segment::from_coords(100.0 - d, 10.0, 100.0 - d, 90.0);
        assert_eq!(scorer.judge(&left, &at(30.0), &map), Verdict::Correct);
        assert_eq!(scorer.judge(&left, &at(10.0), &map), Verdict::Correct);
        assert_eq!(scorer.judge(&left, &at(20.0), &map), Verdict::Wrong);
    }

    #[test]
    fn unknown_disparity_is_unjudged_and_degenerate_segments_too() {
        let map = DisparityMap::from_values(50, 50, vec![0.0; 2500]).unwrap();
        let scorer = Scorer::default();
        let left = Segment::from_coords(10.0, 10.0, 10.0, 40.0);
        assert_eq!(scorer.judge(&left, &left, &map), Verdict::Unjudged);
        let point = Segment::from_coords(10.0, 10.0, 10.0, 10.0);
        assert_eq!(scorer.judge(&point, &left, &plane()), Verdict::Unjudged);
        assert_eq!(scorer.judge(&left, &point, &plane()), Verdict::Unjudged);
    }

    #[test]
    fn matchable_means_some_right_segment_is_correct() {
        let map = plane();
        let scorer = Scorer::default();
        let a = Segment::from_coords(100.0, 10.0, 110.0, 90.0);
        let b = Segment::from_coords(30.0, 10.0, 35.0, 90.0);
        let right = [carried(&a), Segment::from_coords(0.0, 0.0, 5.0, 60.0)];
        assert_eq!(scorer.matchable(&[a, b], &right, &map), vec![true, false]);
    }
}
