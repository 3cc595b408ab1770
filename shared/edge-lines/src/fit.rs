//! Lines fitted along a drawn chain, validated by the gradient, and the longest kept.

use crate::gradient::{Planes, VERTICAL, sobel_at};
use crate::{LineSegment, Params};

/// tan 22.5°: a pixel's gradient is across the line when its component along the line is
/// at most this times its component across.
const TAN_ALIGNMENT: f32 = 0.414_213_57;

/// The fewest chain pixels a line is started from.
const MIN_WINDOW_PIXELS: usize = 5;

/// The start window is accepted when the points' RMS distance from its line is at most
/// this fraction of `max_fit_error_px`.
const WINDOW_RMS_FRACTION: f64 = 0.5;

/// While a line grows it is refitted every this many pixels (and once at its end).
const REFIT_EVERY: usize = 4;

/// Chain points and the segments fitted so far, reused from frame to frame.
#[derive(Debug, Default)]
pub(crate) struct Fitting {
    /// The chain's pixels refined across the edge, `[x, y]`.
    points: Vec<[f32; 2]>,
    /// The validated segments of the frame, at least `min_length_px` long.
    pub(crate) candidates: Vec<LineSegment>,
    /// The candidates' lengths and places, sorted longest first.
    ranked: Vec<(f32, u32)>,
}

/// Running sums of a least-squares (total least squares) line fit.
#[derive(Debug, Default, Clone, Copy)]
struct LineFit {
    n: f64,
    sx: f64,
    sy: f64,
    sxx: f64,
    syy: f64,
    sxy: f64,
}

/// A fitted line: a point on it and its unit direction.
#[derive(Debug, Clone, Copy)]
struct Line {
    centre: [f64; 2],
    direction: [f64; 2],
}

impl LineFit {
    fn add(&mut self, [x, y]: [f32; 2], sign: f64) {
        let (x, y) = (f64::from(x), f64::from(y));
        self.n += sign;
        self.sx += sign * x;
        self.sy += sign * y;
        self.sxx += sign * x * x;
        self.syy += sign * y * y;
        self.sxy += sign * x * y;
    }

    /// The centre, the covariance `(a, b, c)` (xx, xy, yy) and the root of the eigenvalue
    /// equation: what both [`LineFit::line`] and [`LineFit::across_variance`] start from.
    fn moments(&self) -> ([f64; 2], [f64; 3], f64) {
        let n = self.n.max(1.0);
        let (cx, cy) = (self.sx / n, self.sy / n);
        let a = (self.sxx / n - cx * cx).max(0.0);
        let c = (self.syy / n - cy * cy).max(0.0);
        let b = self.sxy / n - cx * cy;
        let half_gap = 0.5 * (a - c);
        let root = half_gap.hypot(b);
        ([cx, cy], [a, b, c], root)
    }

    /// The points' spread across their principal axis (the smaller eigenvalue), pixels²;
    /// no direction computed (one `hypot` less in the start window's sliding loop).
    fn across_variance(&self) -> f64 {
        let (_, [a, _, c], root) = self.moments();
        (0.5 * (a + c) - root).max(0.0)
    }

    /// The principal axis of the points (their largest-variance direction).
    fn line(&self) -> Line {
        let ([cx, cy], [a, b, c], root) = self.moments();
        let largest = 0.5 * (a + c) + root;
        // Eigenvector of the largest eigenvalue, from whichever row is better conditioned.
        let (u, v) = if a >= c {
            (largest - c, b)
        } else {
            (b, largest - a)
        };
        let norm = u.hypot(v);
        let direction = if norm > 1e-12 {
            [u / norm, v / norm]
        } else {
            [1.0, 0.0]
        };
        Line {
            centre: [cx, cy],
            direction,
        }
    }
}

impl Line {
    /// Distance of `p` from the line, pixels.
    fn distance(&self, [x, y]: [f32; 2]) -> f64 {
        let (dx, dy) = (f64::from(x) - self.centre[0], f64::from(y) - self.centre[1]);
        (dx * self.direction[1] - dy * self.direction[0]).abs()
    }

    /// `p` projected onto the line.
    fn project(&self, [x, y]: [f32; 2]) -> [f64; 2] {
        let (dx, dy) = (f64::from(x) - self.centre[0], f64::from(y) - self.centre[1]);
        let t = dx * self.direction[0] + dy * self.direction[1];
        [
            self.centre[0] + t * self.direction[0],
            self.centre[1] + t * self.direction[1],
        ]
    }
}

impl Fitting {
    /// Fits lines along `chain` (pixel indices in drawing order) and keeps the valid ones
    /// in `candidates`.
    pub(crate) fn fit_chain(&mut self, planes: &Planes, params: &Params, chain: &[u32]) {
        let window = start_window(params);
        if chain.len() < window {
            return;
        }
        self.refine(planes, chain);
        let points = &self.points;
        let n = points.len();
        let tolerance = f64::from(params.max_fit_error_px.max(0.0));
        let window_variance = (WINDOW_RMS_FRACTION * tolerance).powi(2);
        let mut start = 0;
        while start + window <= n {
            // Slide the start window until its points are straight.
            let mut fit = LineFit::default();
            for &p in &points[start..start + window] {
                fit.add(p, 1.0);
            }
            while fit.across_variance() > window_variance {
                if start + window >= n {
                    return;
                }
                fit.add(points[start], -1.0);
                fit.add(points[start + window], 1.0);
                start += 1;
            }
            // Grow it while the chain stays within the tolerance.
            let mut line = fit.line();
            let mut last = start + window - 1;
            let (mut outliers, mut since_fit) = (0, 0);
            for (i, &p) in points.iter().enumerate().skip(start + window) {
                if line.distance(p) <= tolerance {
                    fit.add(p, 1.0);
                    last = i;
                    outliers = 0;
                    since_fit += 1;
                    if since_fit == REFIT_EVERY {
                        line = fit.line();
                        since_fit = 0;
                    }
                } else {
                    outliers += 1;
                    if outliers > params.max_outlier_run {
                        break;
                    }
                }
            }
            let line = fit.line();
            if let Some(segment) = validate(planes, params, &line, points, chain, start, last) {
                self.candidates.push(segment);
            }
            start = last + 1;
        }
    }

    /// The chain's pixel positions, each refined across its edge by a parabola through the
    /// gradient magnitudes of it and its two neighbours.
    fn refine(&mut self, planes: &Planes, chain: &[u32]) {
        let (w, g) = (planes.width, &planes.magnitude);
        self.points.clear();
        self.points.extend(chain.iter().map(|&i| {
            let i = i as usize;
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            if planes.flags[i] & VERTICAL != 0 {
                [x + peak_offset(g[i - 1], g[i], g[i + 1]), y]
            } else {
                [x, y + peak_offset(g[i - w], g[i], g[i + w])]
            }
        }));
    }

    /// The `max_segments` longest candidates into `out`, longest first (equally long ones
    /// in the order they were found).
    pub(crate) fn keep_longest(&mut self, params: &Params, out: &mut Vec<LineSegment>) {
        if params.max_segments == 0 {
            return;
        }
        // Each length computed once (not at every comparison), with the candidate's place
        // as the tie-break: the order is the one a stable sort by length gives.
        let ranked = &mut self.ranked;
        ranked.clear();
        ranked.extend(
            self.candidates
                .iter()
                .enumerate()
                .map(|(k, s)| (s.length(), k as u32)),
        );
        let longest_first =
            |a: &(f32, u32), b: &(f32, u32)| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1));
        if ranked.len() > params.max_segments {
            ranked.select_nth_unstable_by(params.max_segments - 1, longest_first);
            ranked.truncate(params.max_segments);
        }
        ranked.sort_unstable_by(longest_first);
        out.extend(ranked.iter().map(|&(_, k)| self.candidates[k as usize]));
    }
}

/// Chain pixels a line is started from: about `min_length_px` of a diagonal chain, at least
/// [`MIN_WINDOW_PIXELS`].
fn start_window(params: &Params) -> usize {
    let diagonal_pixels = (params.min_length_px.max(0.0) / std::f32::consts::SQRT_2).ceil();
    (diagonal_pixels.min(1e6) as usize).max(MIN_WINDOW_PIXELS)
}

/// The offset, in (−0.5, 0.5), of the peak of the parabola through `(−1, before)`,
/// `(0, at)`, `(1, after)`; 0 when `at` is not above the chord.
fn peak_offset(before: u16, at: u16, after: u16) -> f32 {
    let (b, a, c) = (f32::from(before), f32::from(at), f32::from(after));
    let curvature = b - 2.0 * a + c;
    if curvature < 0.0 {
        (0.5 * (b - c) / curvature).clamp(-0.5, 0.5)
    } else {
        0.0
    }
}

/// The segment of `line` from `points[start]` to `points[last]`, oriented by its gradient,
/// if it is long enough and enough of its pixels have a gradient across it of one sign.
fn validate(
    planes: &Planes,
    params: &Params,
    line: &Line,
    points: &[[f32; 2]],
    chain: &[u32],
    start: usize,
    last: usize,
) -> Option<LineSegment> {
    let (a, b) = (line.project(points[start]), line.project(points[last]));
    let length = (b[0] - a[0]).hypot(b[1] - a[1]);
    if !(length >= f64::from(params.min_length_px)) || length == 0.0 {
        return None;
    }
    let [dx, dy] = line.direction.map(|d| d as f32);
    let (nx, ny) = (-dy, dx);
    let (mut positive, mut negative) = (0usize, 0usize);
    for &i in &chain[start..=last] {
        let (gx, gy) = sobel_at(&planes.smooth, planes.width, i as usize);
        let (gx, gy) = (gx as f32, gy as f32);
        let across = gx * nx + gy * ny;
        let along = gx * dx + gy * dy;
        if along.abs() <= TAN_ALIGNMENT * across.abs() {
            if across > 0.0 {
                positive += 1;
            } else if across < 0.0 {
                negative += 1;
            }
        }
    }
    let pixels = (last - start + 1) as f32;
    if (positive.max(negative) as f32) < params.min_aligned_fraction * pixels {
        return None;
    }
    // The gradient is along +normal when positive wins. Order the endpoints so that the
    // direction start → end is the gradient turned a quarter clockwise on the screen
    // ((gx, gy) → (−gy, gx), image y down): LSD's orientation.
    let gradient = if positive >= negative {
        [nx, ny]
    } else {
        [-nx, -ny]
    };
    let wanted = [-gradient[1], gradient[0]];
    let (a, b) = (a.map(|v| v as f32), b.map(|v| v as f32));
    let forward = (b[0] - a[0]) * wanted[0] + (b[1] - a[1]) * wanted[1] >= 0.0;
    let (start, end) = if forward { (a, b) } else { (b, a) };
    Some(LineSegment { start, end })
}
