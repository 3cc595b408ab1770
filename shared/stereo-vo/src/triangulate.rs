//! Stereo triangulation in a rectified rig: points from their disparity, segments from
//! the disparity of each left endpoint against the right segment's line.

use linetrack_geometry::{Point, Segment, StereoRig};
use nalgebra::Point3;

/// A 3-D point in the left camera frame and how far it can be trusted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Triangulated {
    /// Position, left camera frame (x right, y down, z forward), metres.
    pub position: Point3<f64>,
    /// Disparity it came from, pixels.
    pub disparity_px: f64,
}

/// Limits on what is triangulated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TriangulationLimits {
    /// Smallest disparity accepted, pixels (farther points are too uncertain).
    pub min_disparity_px: f64,
    /// Segments closer than this to horizontal (sine of the angle) are not triangulated:
    /// their endpoints' disparity is ill-defined.
    pub min_sin_from_horizontal: f64,
    /// Subtracted from every measured disparity before it gives a depth, pixels: the rig's
    /// disparity offset (measured minus true disparity).
    pub disparity_offset_px: f64,
}

impl Default for TriangulationLimits {
    fn default() -> Self {
        Self {
            min_disparity_px: 1.0,
            min_sin_from_horizontal: 10f64.to_radians().sin(),
            disparity_offset_px: 0.0,
        }
    }
}

/// The left camera ray through `pixel` scaled to depth `z`.
fn backproject(rig: &StereoRig, pixel: Point, z: f64) -> Point3<f64> {
    Point3::new(
        (pixel.x - rig.cx_px) * z / rig.focal_px,
        (pixel.y - rig.cy_px) * z / rig.focal_px,
        z,
    )
}

/// Triangulates a point seen at `left` and `right` (same row in a rectified pair).
pub fn triangulate_point(
    rig: &StereoRig,
    left: Point,
    right: Point,
    limits: &TriangulationLimits,
) -> Option<Triangulated> {
    let disparity = left.x - right.x - limits.disparity_offset_px;
    if !(disparity >= limits.min_disparity_px) || !disparity.is_finite() {
        return None;
    }
    let z = rig.focal_px * rig.baseline_m / disparity;
    Some(Triangulated {
        position: backproject(rig, left, z),
        disparity_px: disparity,
    })
}

/// Triangulates the endpoints of `left`: each endpoint's disparity is measured against the
/// point of the right segment's (infinite) line on the same row.
pub fn triangulate_segment(
    rig: &StereoRig,
    left: &Segment,
    right: &Segment,
    limits: &TriangulationLimits,
) -> Option<(Triangulated, Triangulated)> {
    let d = right.end - right.start;
    let length = d.norm();
    if !(length > 0.0) || (d.y / length).abs() < limits.min_sin_from_horizontal {
        return None;
    }
    let right_x_at = |y: f64| right.start.x + (y - right.start.y) * d.x / d.y;
    let endpoint = |p: Point| triangulate_point(rig, p, Point::new(right_x_at(p.y), p.y), limits);
    Some((endpoint(left.start)?, endpoint(left.end)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rig() -> StereoRig {
        StereoRig {
            focal_px: 400.0,
            cx_px: 320.0,
            cy_px: 240.0,
            baseline_m: 0.1,
            width_px: 640,
            height_px: 480,
        }
    }

    #[test]
    fn a_point_comes_back_where_it_was() {
        let x = Point3::new(0.3, -0.2, 2.5);
        let left = Point::new(400.0 * 0.3 / 2.5 + 320.0, 400.0 * -0.2 / 2.5 + 240.0);
        let right = Point::new(400.0 * (0.3 - 0.1) / 2.5 + 320.0, left.y);
        let t = triangulate_point(&rig(), left, right, &TriangulationLimits::default()).unwrap();
        assert!((t.position - x).norm() < 1e-12);
        assert!((t.disparity_px - 16.0).abs() < 1e-12);
        assert!(
            triangulate_point(&rig(), right, left, &TriangulationLimits::default()).is_none(),
            "negative disparity"
        );
    }

    #[test]
    fn segment_endpoints_use_the_right_line_not_its_endpoints() {
        // A slanted 3-D segment; the right detection is truncated differently.
        let (p, q) = (Point3::new(-0.2, -0.3, 2.0), Point3::new(0.1, 0.4, 3.0));
        let project = |x: &Point3<f64>, shift: f64| {
            Point::new(
                400.0 * (x.x - shift) / x.z + 320.0,
                400.0 * x.y / x.z + 240.0,
            )
        };
        let left = Segment::new(project(&p, 0.0), project(&q, 0.0));
        let full_right = Segment::new(project(&p, 0.1), project(&q, 0.1));
        let truncated = Segment::new(
            full_right.start + (full_right.end - full_right.start) * 0.2,
            full_right.end - (full_right.end - full_right.start) * 0.1,
        );
        let (a, b) =
            triangulate_segment(&rig(), &left, &truncated, &TriangulationLimits::default())
                .unwrap();
        assert!((a.position - p).norm() < 1e-9 && (b.position - q).norm() < 1e-9);
        let flat = Segment::from_coords(0.0, 100.0, 200.0, 101.0);
        assert!(
            triangulate_segment(&rig(), &flat, &flat, &TriangulationLimits::default()).is_none()
        );
    }
}
