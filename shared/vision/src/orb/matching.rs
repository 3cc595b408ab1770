//! Matching ORB points by descriptor among the pairs the geometry allows (stereo rows
//! and disparities, frame-to-frame displacement), over a grid of the second image's points.

use super::PointFeatures;
use crate::{AppearanceGates, BinaryDescriptors, FeatureMatch, HammingMatcher};
use linetrack_geometry::{MatchCase, Point};

/// Matches points by descriptor among the pairs the geometry allows; keeps its buffers
/// (no allocation per frame once warm).
#[derive(Debug, Clone, Default)]
pub struct PointMatcher {
    hamming: HammingMatcher,
    grid: PointGrid,
}

impl PointMatcher {
    /// A matcher with empty buffers.
    pub fn new() -> Self {
        Self::default()
    }

    /// Replaces `out` with the mutual-best Hamming matches that pass the ratio test, among
    /// pairs on the same rows within the disparity range (stereo) or within the
    /// displacement (frame to frame). Only the second image's points in the cells that
    /// window covers are compared: on a 752 × 480 image with 1500 points a side that is a
    /// few dozen per point instead of all of them, with the same result.
    pub fn match_points(
        &mut self,
        case: MatchCase,
        first: &PointFeatures,
        second: &PointFeatures,
        gates: &AppearanceGates,
        min_ratio: f64,
        out: &mut Vec<FeatureMatch>,
    ) {
        let first = (first.points.as_slice(), &first.descriptors);
        self.match_points_of(case, first, |_| true, second, gates, min_ratio, out);
    }

    /// [`PointMatcher::match_points`] for the first image's points `wanted` says yes to
    /// (the others are neither matched nor compete for the second image's points), their
    /// positions and descriptors given apart (positions moved to where they are predicted,
    /// say).
    #[allow(clippy::too_many_arguments)]
    pub fn match_points_of(
        &mut self,
        case: MatchCase,
        first: (&[Point], &BinaryDescriptors),
        wanted: impl Fn(usize) -> bool,
        second: &PointFeatures,
        gates: &AppearanceGates,
        min_ratio: f64,
        out: &mut Vec<FeatureMatch>,
    ) {
        match PairGate::new(case, gates) {
            PairGate::Stereo(gate) => self.match_gated(first, wanted, second, min_ratio, out, gate),
            PairGate::Displacement(gate) => {
                self.match_gated(first, wanted, second, min_ratio, out, gate)
            }
        }
    }

    /// [`PointMatcher::match_points_of`] with `gate`: the grid buckets the second image's
    /// points into the gate's cells, and each wanted first point is compared with the
    /// points in the cells its window meets that the gate admits, the gate applied while
    /// the cells are listed (over the grid's own copy of the positions, contiguous cell by
    /// cell), so the Hamming matcher sees only admitted pairs.
    fn match_gated(
        &mut self,
        (first_points, first_descriptors): (&[Point], &BinaryDescriptors),
        wanted: impl Fn(usize) -> bool,
        second: &PointFeatures,
        min_ratio: f64,
        out: &mut Vec<FeatureMatch>,
        gate: impl Gate,
    ) {
        self.grid.rebuild(&second.points, gate.cell_px());
        let grid = &self.grid;
        self.hamming.match_mutual_among(
            first_descriptors,
            &second.descriptors,
            min_ratio,
            |i, candidates| {
                if !wanted(i) {
                    return;
                }
                let a = first_points[i];
                let (x, y) = gate.window(a);
                grid.extend_within(x, y, |b| gate.admits(a, b), candidates);
            },
            |_, _| true,
            out,
        );
    }
}

/// Which pairs of points may match: [`points_may_match`] with what it derives from the
/// gates worked out once, and where to look.
trait Gate: Copy {
    /// Whether point `a` of the first image and `b` of the second may match.
    fn admits(&self, a: Point, b: Point) -> bool;

    /// The columns and rows that hold every second-image point `a` may match.
    fn window(&self, a: Point) -> ([f64; 2], [f64; 2]);

    /// Width and height of the grid's cells that suit the windows, pixels.
    fn cell_px(&self) -> [f64; 2];
}

/// [`points_may_match`]'s gate for one case.
#[derive(Debug, Clone, Copy)]
enum PairGate {
    Stereo(StereoGate),
    Displacement(DisplacementGate),
}

impl PairGate {
    fn new(case: MatchCase, gates: &AppearanceGates) -> Self {
        match case {
            MatchCase::Stereo => Self::Stereo(StereoGate {
                min_disparity_px: gates.min_disparity_px,
                max_disparity_px: gates.max_disparity_px,
                max_row_difference_px: gates.max_row_difference_px,
            }),
            MatchCase::FrameToFrame => {
                let limit_px = gates.max_displacement_px;
                let squared = limit_px * limit_px;
                // Limits whose square is not a normal number, or that are not a distance,
                // settle nothing on the square: every pair gets the exact test.
                let exact_only = !(1e-100..=1e100).contains(&limit_px);
                Self::Displacement(DisplacementGate {
                    limit_px,
                    surely_within: if exact_only {
                        f64::NEG_INFINITY
                    } else {
                        squared * (1.0 - 1e-9)
                    },
                    surely_beyond: if exact_only {
                        f64::INFINITY
                    } else {
                        squared * (1.0 + 1e-9)
                    },
                })
            }
        }
    }

    fn admits(&self, a: Point, b: Point) -> bool {
        match self {
            Self::Stereo(gate) => gate.admits(a, b),
            Self::Displacement(gate) => gate.admits(a, b),
        }
    }
}

/// Stereo: on the same rows, with a disparity in range.
#[derive(Debug, Clone, Copy)]
struct StereoGate {
    min_disparity_px: f64,
    max_disparity_px: f64,
    max_row_difference_px: f64,
}

impl Gate for StereoGate {
    #[inline(always)]
    fn admits(&self, a: Point, b: Point) -> bool {
        let disparity = a.x - b.x;
        (a.y - b.y).abs() <= self.max_row_difference_px
            && disparity >= self.min_disparity_px
            && disparity <= self.max_disparity_px
    }

    fn window(&self, a: Point) -> ([f64; 2], [f64; 2]) {
        (
            [a.x - self.max_disparity_px, a.x - self.min_disparity_px],
            [
                a.y - self.max_row_difference_px,
                a.y + self.max_row_difference_px,
            ],
        )
    }

    /// Stereo windows are a few rows high and wide along them: flat cells list fewer
    /// points outside the window than square ones.
    fn cell_px(&self) -> [f64; 2] {
        STEREO_CELL_PX
    }
}

/// Frame to frame: at most `limit_px` apart.
#[derive(Debug, Clone, Copy)]
struct DisplacementGate {
    limit_px: f64,
    /// Squared distances below this are within the limit, above `surely_beyond` (or NaN)
    /// beyond it; those between (within a rounding error of the limit) get the exact test.
    surely_within: f64,
    surely_beyond: f64,
}

impl Gate for DisplacementGate {
    #[inline(always)]
    fn admits(&self, a: Point, b: Point) -> bool {
        let (dx, dy) = (a.x - b.x, a.y - b.y);
        let squared = dx * dx + dy * dy;
        if squared < self.surely_within {
            true
        } else if squared > self.surely_beyond || squared.is_nan() {
            false
        } else {
            (a - b).norm() <= self.limit_px
        }
    }

    fn window(&self, a: Point) -> ([f64; 2], [f64; 2]) {
        let r = self.limit_px;
        ([a.x - r, a.x + r], [a.y - r, a.y + r])
    }

    fn cell_px(&self) -> [f64; 2] {
        GRID_CELL_PX
    }
}

/// Whether point `a` of the first image and `b` of the second may match: on the same rows
/// (within `max_row_difference_px`) with a disparity in range (stereo), or at most
/// `max_displacement_px` apart (frame to frame).
pub fn points_may_match(case: MatchCase, gates: &AppearanceGates, a: Point, b: Point) -> bool {
    PairGate::new(case, gates).admits(a, b)
}

/// Side of a square [`PointGrid`] cell for frame-to-frame windows, pixels.
const GRID_CELL_PX: [f64; 2] = [8.0, 8.0];

/// Width and height of a [`PointGrid`] cell for stereo windows (±3 rows by default), pixels.
const STEREO_CELL_PX: [f64; 2] = [32.0, 4.0];

/// Most cells along one side of a [`PointGrid`]: points spread wider share cells.
const GRID_MAX_CELLS: usize = 1024;

/// Points bucketed into cells (a counting sort by cell), to list the points in a window
/// without visiting every point.
#[derive(Debug, Clone, Default)]
struct PointGrid {
    origin: Point,
    /// Cell width and height, pixels.
    cell: [f64; 2],
    cols: usize,
    rows: usize,
    /// Where each cell's points start in `order` (one more entry than cells).
    starts: Vec<usize>,
    /// Point indices, cell by cell, increasing within a cell.
    order: Vec<usize>,
    /// The positions of `order`'s points, in its order.
    ordered: Vec<Point>,
    cell_of: Vec<usize>,
}

impl PointGrid {
    /// Buckets `points` into cells of `cell` (width, height) pixels at least (non-finite
    /// positions are left out: no window holds them).
    fn rebuild(&mut self, points: &[Point], cell: [f64; 2]) {
        let finite = || points.iter().filter(|p| p.x.is_finite() && p.y.is_finite());
        let (mut lo, mut hi) = (
            Point::new(f64::MAX, f64::MAX),
            Point::new(f64::MIN, f64::MIN),
        );
        for p in finite() {
            lo = Point::new(lo.x.min(p.x), lo.y.min(p.y));
            hi = Point::new(hi.x.max(p.x), hi.y.max(p.y));
        }
        if lo.x > hi.x {
            (lo, hi) = (Point::origin(), Point::origin());
        }
        let spread = [hi.x - lo.x, hi.y - lo.y];
        for axis in 0..2 {
            self.cell[axis] = cell[axis]
                .max(spread[axis] / (GRID_MAX_CELLS - 1) as f64)
                .max(f64::MIN_POSITIVE);
        }
        self.origin = lo;
        self.cols = self.index(spread[0], 0, GRID_MAX_CELLS) + 1;
        self.rows = self.index(spread[1], 1, GRID_MAX_CELLS) + 1;
        self.starts.clear();
        self.starts.resize(self.cols * self.rows + 1, 0);
        self.cell_of.clear();
        for p in points {
            let k = if p.x.is_finite() && p.y.is_finite() {
                self.index(p.y - lo.y, 1, self.rows) * self.cols
                    + self.index(p.x - lo.x, 0, self.cols)
            } else {
                usize::MAX
            };
            self.cell_of.push(k);
            if k != usize::MAX {
                self.starts[k + 1] += 1;
            }
        }
        for k in 1..self.starts.len() {
            self.starts[k] += self.starts[k - 1];
        }
        self.order.clear();
        self.order.resize(self.starts[self.starts.len() - 1], 0);
        // Each point goes to its cell's next free place; that moves every start to the
        // following cell's, put back after.
        for (j, &k) in self.cell_of.iter().enumerate() {
            if k != usize::MAX {
                self.order[self.starts[k]] = j;
                self.starts[k] += 1;
            }
        }
        let cells = self.starts.len() - 1;
        self.starts.copy_within(..cells, 1);
        self.starts[0] = 0;
        self.ordered.clear();
        self.ordered.extend(self.order.iter().map(|&j| points[j]));
    }

    /// The cell along `axis` (0: x, 1: y) of an offset from the origin, clamped to
    /// `count` cells.
    fn index(&self, offset: f64, axis: usize, count: usize) -> usize {
        let k = (offset / self.cell[axis]).floor();
        if k.is_nan() || k <= 0.0 {
            0
        } else {
            (k as usize).min(count.saturating_sub(1))
        }
    }

    /// Appends the points `keep` accepts among those of every cell meeting the window
    /// `x` × `y` (so every point inside the window that `keep` accepts).
    fn extend_within(
        &self,
        x: [f64; 2],
        y: [f64; 2],
        keep: impl Fn(Point) -> bool,
        out: &mut Vec<usize>,
    ) {
        let outside = |range: [f64; 2], low: f64, cell: f64, cells: usize| {
            !(range[1] >= low && range[0] <= low + cell * cells as f64)
        };
        if self.order.is_empty()
            || outside(x, self.origin.x, self.cell[0], self.cols)
            || outside(y, self.origin.y, self.cell[1], self.rows)
        {
            return;
        }
        let [c0, c1] = x.map(|v| self.index(v - self.origin.x, 0, self.cols));
        let [r0, r1] = y.map(|v| self.index(v - self.origin.y, 1, self.rows));
        for r in r0..=r1 {
            let row = r * self.cols;
            let span = self.starts[row + c0]..self.starts[row + c1 + 1];
            out.extend(
                self.order[span.clone()]
                    .iter()
                    .zip(&self.ordered[span])
                    .filter(|&(_, &p)| keep(p))
                    .map(|(&j, _)| j),
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    /// Points the caller does not want are neither matched nor compete: here the second
    /// image's only point is nearer to the first image's point 0, which wins it unless it
    /// is left out.
    #[test]
    fn unwanted_points_do_not_compete_for_a_match() {
        let features = |points: &[(f64, f64)], rows: &[[u8; 4]]| {
            let mut f = PointFeatures {
                points: points.iter().map(|&(x, y)| Point::new(x, y)).collect(),
                levels: vec![0; points.len()],
                ..PointFeatures::default()
            };
            f.descriptors.reset(rows.len(), 4);
            for (k, row) in rows.iter().enumerate() {
                f.descriptors.set_row(k, row);
            }
            f
        };
        let first = features(&[(10.0, 10.0), (12.0, 10.0)], &[[0, 0, 0, 1], [0, 0, 0, 7]]);
        let second = features(&[(11.0, 10.0)], &[[0, 0, 0, 0]]);
        let gates = AppearanceGates::default();
        let mut matcher = PointMatcher::new();
        let mut out = Vec::new();
        let pairs = |out: &[FeatureMatch]| -> Vec<(usize, usize)> {
            out.iter().map(|m| (m.query, m.train)).collect()
        };
        matcher.match_points(
            MatchCase::FrameToFrame,
            &first,
            &second,
            &gates,
            1.0,
            &mut out,
        );
        assert_eq!(pairs(&out), [(0, 0)]);
        matcher.match_points_of(
            MatchCase::FrameToFrame,
            (&first.points, &first.descriptors),
            |i| i == 1,
            &second,
            &gates,
            1.0,
            &mut out,
        );
        assert_eq!(pairs(&out), [(1, 0)]);
    }

    /// The frame-to-frame gate settles most pairs on the squared distance; at the limit and
    /// for limits that are not a distance it answers as `|a − b| ≤ limit` does.
    #[test]
    fn the_frame_to_frame_gate_is_the_distance_test() {
        let exact = |a: Point, b: Point, limit: f64| (a - b).norm() <= limit;
        let (a, b) = (Point::new(10.0, 20.0), Point::new(13.0, 24.0)); // 5 px apart
        for limit in [
            5.0,
            5.0 - 1e-12,
            5.0 + 1e-12,
            4.999_999_999,
            5.000_000_001,
            0.0,
            -5.0,
            f64::NAN,
            f64::INFINITY,
            1e-300,
            1e300,
        ] {
            let gates = AppearanceGates {
                max_displacement_px: limit,
                ..AppearanceGates::default()
            };
            for (p, q) in [
                (a, b),
                (a, a),
                (a, Point::new(f64::NAN, 0.0)),
                (a, Point::new(f64::INFINITY, 0.0)),
            ] {
                assert_eq!(
                    points_may_match(MatchCase::FrameToFrame, &gates, p, q),
                    exact(p, q, limit),
                    "{p:?} {q:?} within {limit}"
                );
            }
        }
        // Many distances near one limit.
        let gates = AppearanceGates {
            max_displacement_px: 40.0,
            ..AppearanceGates::default()
        };
        for k in 0..20_000 {
            let angle = f64::from(k) * 0.001;
            let r = 40.0 + (f64::from(k % 200) - 100.0) * 1e-14;
            let q = Point::new(a.x + r * angle.cos(), a.y + r * angle.sin());
            assert_eq!(
                points_may_match(MatchCase::FrameToFrame, &gates, a, q),
                exact(a, q, 40.0),
                "{q:?}"
            );
        }
    }
}
