//! Line segments in the image plane and the four geometric terms the ℓ1 matcher compares
//! them by (SPEC §2, paper §III-A).
//!
//! Every stage of linetrack that handles segments speaks [`Segment`]: detectors produce
//! them, the matchers compare them, the visual odometry triangulates them. The matcher
//! compares a query segment `i` (first image) against a candidate `j` (second image) with
//!
//! | term | meaning | ideal |
//! |---|---|---|
//! | [`direction_angle`] θ | unsigned angle between the two directions, in [0, π/2] | 0 |
//! | [`epipolar_angle`] θ^epip | angle of the midpoint flow `m_i − m_j` with the epipolar axis | 0 |
//! | [`overlap`] ρ | common over union extent, in [0, 1] | 1 |
//! | [`length_ratio`] μ | longer over shorter length, ≥ 1 | 1 |
//!
//! The terms are computed from [`SegmentFeatures`], the per-segment quantities (midpoint,
//! unit direction, length, extents) that are worth computing once per segment rather than
//! once per pair. Building features is where degenerate input is caught: a segment with a
//! non-finite coordinate or (almost) no length has no direction and is refused with a
//! [`GeometryError`].
#![warn(missing_docs)]

use nalgebra::{Point2, Vector2};
use serde::{Deserialize, Serialize};

/// A point in pixel coordinates (x to the right, y down).
pub type Point = Point2<f64>;
/// A vector in pixel coordinates.
pub type Vector = Vector2<f64>;

/// Segments shorter than this (pixels) have no reliable direction and are refused.
pub const MIN_LENGTH_PX: f64 = 1e-6;

/// Half-height (pixels) added to each end of a segment's vertical extent in the stereo
/// overlap: a segment covers at least one pixel row, so two horizontal segments on the
/// same row overlap fully instead of dividing zero by zero.
pub const ROW_FOOTPRINT_PX: f64 = 0.5;

/// Flows shorter than this (pixels) have no direction; their epipolar angle is 0.
pub const MIN_FLOW_PX: f64 = 1e-9;

/// The ideal value of the term vector β = [θ, θ^epip, ρ, μ]: parallel, on the epipolar
/// axis, fully overlapping, equally long.
pub const IDEAL_TERMS: [f64; 4] = [0.0, 0.0, 1.0, 1.0];

/// A line segment given by its two endpoints, in pixels.
///
/// The endpoint order may carry the gradient polarity (LSD orients segments so that the
/// brighter side is on a fixed hand); the geometric terms ignore it, the optional polarity
/// gate of the matcher uses it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Segment {
    /// First endpoint `s`.
    pub start: Point,
    /// Second endpoint `e`.
    pub end: Point,
}

impl Segment {
    /// A segment from its two endpoints.
    pub fn new(start: Point, end: Point) -> Self {
        Self { start, end }
    }

    /// A segment from endpoint coordinates `(x0, y0)` → `(x1, y1)`.
    pub fn from_coords(x0: f64, y0: f64, x1: f64, y1: f64) -> Self {
        Self::new(Point::new(x0, y0), Point::new(x1, y1))
    }

    /// Euclidean length `L = |s − e|` in pixels.
    pub fn length(&self) -> f64 {
        (self.start - self.end).norm()
    }

    /// Midpoint `m = (s + e) / 2`.
    pub fn midpoint(&self) -> Point {
        nalgebra::center(&self.start, &self.end)
    }

    /// The same segment with its endpoints swapped.
    pub fn reversed(&self) -> Self {
        Self::new(self.end, self.start)
    }

    /// The part of the segment inside the rectangle [0, width] × [0, height]
    /// (Liang–Barsky clipping), or `None` when no part of it is inside.
    pub fn clipped_to(&self, width: f64, height: f64) -> Option<Segment> {
        let (p, d) = (self.start, self.end - self.start);
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for (denominator, numerator) in [
            (-d.x, p.x),
            (d.x, width - p.x),
            (-d.y, p.y),
            (d.y, height - p.y),
        ] {
            if denominator == 0.0 {
                if numerator < 0.0 {
                    return None;
                }
            } else {
                let t = numerator / denominator;
                if denominator < 0.0 {
                    t0 = t0.max(t)
                } else {
                    t1 = t1.min(t)
                }
            }
        }
        (t0 < t1).then(|| Segment::new(p + d * t0, p + d * t1))
    }

    /// Whether all four coordinates are finite.
    pub fn is_finite(&self) -> bool {
        self.start
            .iter()
            .chain(self.end.iter())
            .all(|c| c.is_finite())
    }
}

/// Why a segment cannot take part in geometric matching.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum GeometryError {
    /// A coordinate is NaN or infinite.
    #[error("segment has a non-finite coordinate")]
    NonFinite,
    /// The endpoints (almost) coincide, so the segment has no direction.
    #[error("segment length {length_px} px is below the minimum {MIN_LENGTH_PX} px")]
    ZeroLength {
        /// The measured length in pixels.
        length_px: f64,
    },
}

/// A rectified pinhole stereo rig (what the rest of the system sees after rectification):
/// square pixels, both cameras with the same intrinsics, the right camera `baseline_m`
/// along +x of the left.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StereoRig {
    /// Focal length in pixels (square pixels).
    pub focal_px: f64,
    /// Principal point x, pixels.
    pub cx_px: f64,
    /// Principal point y, pixels.
    pub cy_px: f64,
    /// Distance between the two optical centres, metres.
    pub baseline_m: f64,
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
}

impl Default for StereoRig {
    /// Roughly the rectified EuRoC MAV rig: 752×480, f ≈ 458 px, 11 cm baseline.
    fn default() -> Self {
        Self {
            focal_px: 458.0,
            cx_px: 376.0,
            cy_px: 240.0,
            baseline_m: 0.11,
            width_px: 752,
            height_px: 480,
        }
    }
}

impl StereoRig {
    /// Projects a point in the left camera's frame (x right, y down, z forward) to left
    /// image pixels; `None` behind the camera.
    pub fn project_left(&self, p: &nalgebra::Point3<f64>) -> Option<Point> {
        (p.z > 0.0).then(|| {
            Point::new(
                self.focal_px * p.x / p.z + self.cx_px,
                self.focal_px * p.y / p.z + self.cy_px,
            )
        })
    }

    /// Disparity in pixels of a point at depth `depth_m`.
    pub fn disparity_px(&self, depth_m: f64) -> f64 {
        self.focal_px * self.baseline_m / depth_m
    }
}

/// Which pair of images two segment sets come from; decides the epipolar axis and the
/// overlap definition.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MatchCase {
    /// Left and right image of a rectified stereo pair: epipolar lines are image rows.
    Stereo,
    /// Two consecutive frames of one camera, separated by a small motion.
    FrameToFrame,
}

/// Per-segment quantities computed once and reused for every pair the segment is in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentFeatures {
    /// The segment's first endpoint.
    pub start: Point,
    /// The segment's second endpoint.
    pub end: Point,
    /// Midpoint.
    pub mid: Point,
    /// Unit direction `(s − e) / L`.
    pub dir: Vector,
    /// Length in pixels.
    pub length: f64,
    /// Smallest y of the two endpoints.
    pub y_min: f64,
    /// Largest y of the two endpoints.
    pub y_max: f64,
    /// Smallest x of the two endpoints.
    pub x_min: f64,
    /// Largest x of the two endpoints.
    pub x_max: f64,
}

impl SegmentFeatures {
    /// Features of `segment`, or why it cannot be matched.
    pub fn new(segment: &Segment) -> Result<Self, GeometryError> {
        if !segment.is_finite() {
            return Err(GeometryError::NonFinite);
        }
        let delta = segment.start - segment.end;
        let length = delta.norm();
        // `!(length >= MIN)` also refuses a NaN length (overflowing coordinates).
        if !(length >= MIN_LENGTH_PX) || !length.is_finite() {
            return Err(GeometryError::ZeroLength { length_px: length });
        }
        let (s, e) = (segment.start, segment.end);
        Ok(Self {
            start: s,
            end: e,
            mid: segment.midpoint(),
            dir: delta / length,
            length,
            y_min: s.y.min(e.y),
            y_max: s.y.max(e.y),
            x_min: s.x.min(e.x),
            x_max: s.x.max(e.x),
        })
    }
}

/// Unsigned angle θ between the two directions, `atan(|l_i × l_j| / |l_i · l_j|)` in
/// [0, π/2]: reversing either segment does not change it.
pub fn direction_angle(a: &SegmentFeatures, b: &SegmentFeatures) -> f64 {
    cross(&a.dir, &b.dir).abs().atan2(a.dir.dot(&b.dir).abs())
}

/// Angle θ^epip of the midpoint flow `x = m_a − m_b` with the epipolar axis, in [0, π/2]:
/// the X axis for stereo (paper eq. 3), the Y axis frame to frame (eq. 4). A null flow
/// has angle 0.
pub fn epipolar_angle(a: &SegmentFeatures, b: &SegmentFeatures, case: MatchCase) -> f64 {
    let flow = a.mid - b.mid;
    if flow.norm() < MIN_FLOW_PX {
        return 0.0;
    }
    // asin(|x × η| / |x|) written as atan2 of the off-axis and on-axis components,
    // which is the same angle without asin's loss of precision near π/2.
    let (off_axis, on_axis) = match case {
        MatchCase::Stereo => (flow.y, flow.x),
        MatchCase::FrameToFrame => (flow.x, flow.y),
    };
    off_axis.abs().atan2(on_axis.abs())
}

/// Overlap ρ in [0, 1]: common extent over union extent.
///
/// Stereo: the vertical (row) extents, each widened by [`ROW_FOOTPRINT_PX`] at both ends.
/// Frame to frame: `b`'s endpoints projected onto the line of `a`, compared with `a`'s
/// own extent along its line.
pub fn overlap(a: &SegmentFeatures, b: &SegmentFeatures, case: MatchCase) -> f64 {
    let (a_lo, a_hi, b_lo, b_hi) = match case {
        MatchCase::Stereo => (
            a.y_min - ROW_FOOTPRINT_PX,
            a.y_max + ROW_FOOTPRINT_PX,
            b.y_min - ROW_FOOTPRINT_PX,
            b.y_max + ROW_FOOTPRINT_PX,
        ),
        MatchCase::FrameToFrame => {
            let t_start = (b.start - a.mid).dot(&a.dir);
            let t_end = (b.end - a.mid).dot(&a.dir);
            let half = 0.5 * a.length;
            (-half, half, t_start.min(t_end), t_start.max(t_end))
        }
    };
    let common = a_hi.min(b_hi) - a_lo.max(b_lo);
    if common <= 0.0 {
        return 0.0;
    }
    // The union is at least `a`'s extent, which is positive for a valid segment.
    common / (a_hi.max(b_hi) - a_lo.min(b_lo))
}

/// Length ratio μ = max(L_a, L_b) / min(L_a, L_b) ≥ 1.
pub fn length_ratio(a: &SegmentFeatures, b: &SegmentFeatures) -> f64 {
    a.length.max(b.length) / a.length.min(b.length)
}

/// The four geometric terms of one (query, candidate) pair.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Terms {
    /// θ, radians, in [0, π/2].
    pub angle_rad: f64,
    /// θ^epip, radians, in [0, π/2].
    pub epipolar_angle_rad: f64,
    /// ρ in [0, 1].
    pub overlap: f64,
    /// μ ≥ 1.
    pub length_ratio: f64,
}

impl Terms {
    /// All four terms of the pair (`a` from the first image, `b` from the second).
    pub fn between(a: &SegmentFeatures, b: &SegmentFeatures, case: MatchCase) -> Self {
        Self {
            angle_rad: direction_angle(a, b),
            epipolar_angle_rad: epipolar_angle(a, b, case),
            overlap: overlap(a, b, case),
            length_ratio: length_ratio(a, b),
        }
    }

    /// β = [θ, θ^epip, ρ, μ], the column of the matcher's matrix A (before weighting).
    pub fn to_array(&self) -> [f64; 4] {
        [
            self.angle_rad,
            self.epipolar_angle_rad,
            self.overlap,
            self.length_ratio,
        ]
    }
}

/// z-component of the 2-D cross product.
pub fn cross(a: &Vector, b: &Vector) -> f64 {
    a.x * b.y - a.y * b.x
}

#[cfg(test)]
mod tests;
