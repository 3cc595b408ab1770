//! Ground truth for frame-to-frame segment matches: where a segment of frame k − 1 must lie
//! in frame k.
//!
//! A previous segment's physical line is given by 3-D samples along it, in the previous
//! left camera's frame: from an exact depth map ([`samples_from_depth`], generated
//! sequences) or from the segment's stereo partner ([`samples_from_stereo`], real
//! sequences). [`judge`] moves the samples by the true relative motion, projects them into
//! frame k and calls a match correct when the matched segment's line passes within
//! [`MAX_ERROR_PX`] of them (median over the samples) and the two overlap along it.

use linetrack_datasets::depth::DepthMap;
use linetrack_geometry::{Point, Segment, StereoRig};
use linetrack_stereo_vo::{TriangulationLimits, triangulate_segment};
use nalgebra::{Isometry3, Point3};

/// A match is correct when the median distance of the projected samples to the matched
/// segment's line is at most this, pixels.
pub const MAX_ERROR_PX: f64 = 2.0;
/// Fewest samples (with depth, and in front of the current camera) a judgement needs.
const MIN_SAMPLES: usize = 3;
/// Depth samples along a segment: one per this many pixels, …
const SAMPLE_SPACING_PX: f64 = 4.0;
/// … at least this many, …
const MIN_DEPTH_SAMPLES: usize = 5;
/// … at most this many.
const MAX_DEPTH_SAMPLES: usize = 20;
/// Samples along a triangulated segment.
const STEREO_SAMPLES: usize = 9;
/// Points closer than this to the current camera's plane are not projected, metres.
const MIN_DEPTH_M: f64 = 0.05;

/// What [`judge`] says of a match.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// The same physical segment: on its projected line and overlapping it.
    Correct,
    /// On the projected line but not overlapping it: another part of the same straight
    /// edge (a dashed lane marking's next dash, another fragment of a long edge).
    Disjoint,
    /// Off the projected line: another edge.
    Off,
}

/// The left camera ray through `pixel` at depth `z`.
fn back_project(rig: &StereoRig, pixel: Point, z: f64) -> Point3<f64> {
    Point3::new(
        (pixel.x - rig.cx_px) * z / rig.focal_px,
        (pixel.y - rig.cy_px) * z / rig.focal_px,
        z,
    )
}

/// 3-D samples along `segment` from the exact `depth` map of its image, or `None` when
/// fewer than half of them (or fewer than three) have a depth (the generated maps hold
/// nothing beyond 13.1 m). Each sample takes the nearest depth among its pixel's 3×3
/// neighbours: a segment on an occluding contour belongs to the nearer surface, and on a
/// crease or a painted edge the neighbours agree.
pub fn samples_from_depth(
    rig: &StereoRig,
    depth: &DepthMap,
    segment: &Segment,
) -> Option<Vec<Point3<f64>>> {
    let length = (segment.end - segment.start).norm();
    if !length.is_finite() {
        return None;
    }
    let count = ((length / SAMPLE_SPACING_PX) as usize).clamp(MIN_DEPTH_SAMPLES, MAX_DEPTH_SAMPLES);
    let samples: Vec<Point3<f64>> = (0..count)
        .filter_map(|i| {
            let t = (i as f64 + 0.5) / count as f64;
            let q = segment.start + (segment.end - segment.start) * t;
            let (u, v) = (q.x.round(), q.y.round());
            let inside = |x: f64, size: usize| x >= 1.0 && x < size as f64;
            if !(inside(u, depth.width) && inside(v, depth.height)) {
                return None;
            }
            let (u, v) = (u as usize, v as usize);
            let z = (u - 1..=u + 1)
                .flat_map(|x| (v - 1..=v + 1).filter_map(move |y| depth.at(x, y)))
                .min_by(f32::total_cmp)?;
            Some(back_project(rig, q, f64::from(z)))
        })
        .collect();
    (samples.len() >= MIN_SAMPLES && 2 * samples.len() >= count).then_some(samples)
}

/// 3-D samples along left segment `left`, triangulated with its stereo partner `right` as
/// the odometry triangulates segments (`limits`); `None` where that fails.
pub fn samples_from_stereo(
    rig: &StereoRig,
    left: &Segment,
    right: &Segment,
    limits: &TriangulationLimits,
) -> Option<Vec<Point3<f64>>> {
    let (a, b) = triangulate_segment(rig, left, right, limits)?;
    let (a, b) = (a.position, b.position);
    Some(
        (0..STEREO_SAMPLES)
            .map(|i| a + (b - a) * (i as f64 / (STEREO_SAMPLES - 1) as f64))
            .collect(),
    )
}

/// Whether `matched` (a segment of frame k) is where the previous segment whose 3-D
/// `samples` (previous left camera frame) are given lies after the true motion
/// `current_from_previous`: correct when the samples' median distance to its line is at
/// most [`MAX_ERROR_PX`] and their extent along it overlaps it. `None` when it cannot be
/// judged (a degenerate segment, or too few samples in front of the camera).
pub fn judge(
    rig: &StereoRig,
    samples: &[Point3<f64>],
    current_from_previous: &Isometry3<f64>,
    matched: &Segment,
) -> Option<Verdict> {
    let d = matched.end - matched.start;
    let length = d.norm();
    if !(length > 0.0 && length.is_finite()) {
        return None;
    }
    let along = d / length;
    let projected: Vec<Point> = samples
        .iter()
        .map(|x| current_from_previous * x)
        .filter(|x| x.z > MIN_DEPTH_M)
        .filter_map(|x| rig.project_left(&x))
        .collect();
    if projected.len() < MIN_SAMPLES {
        return None;
    }
    let mut distances: Vec<f64> = projected
        .iter()
        .map(|p| {
            let r = p - matched.start;
            (r.x * along.y - r.y * along.x).abs()
        })
        .collect();
    distances.sort_by(f64::total_cmp);
    let median = distances[distances.len() / 2];
    let positions = projected.iter().map(|p| (p - matched.start).dot(&along));
    let (low, high) = positions.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
        (lo.min(t), hi.max(t))
    });
    let overlap = high.min(length) - low.max(0.0);
    Some(if median > MAX_ERROR_PX {
        Verdict::Off
    } else if overlap > 0.0 {
        Verdict::Correct
    } else {
        Verdict::Disjoint
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn rig() -> StereoRig {
        StereoRig {
            focal_px: 400.0,
            cx_px: 160.0,
            cy_px: 120.0,
            baseline_m: 0.1,
            width_px: 320,
            height_px: 240,
        }
    }

    fn segment_of(rig: &StereoRig, a: Point3<f64>, b: Point3<f64>) -> Segment {
        let (Some(a), Some(b)) = (rig.project_left(&a), rig.project_left(&b)) else {
            panic!("behind the camera");
        };
        Segment::new(a, b)
    }

    /// Shifted by `px` across its own direction.
    fn shifted(s: &Segment, px: f64) -> Segment {
        let d = (s.end - s.start).normalize();
        let normal = nalgebra::Vector2::new(-d.y, d.x) * px;
        Segment::new(s.start + normal, s.end + normal)
    }

    #[test]
    fn the_judge_passes_the_true_match_and_fails_shifted_and_disjoint_ones() {
        // A slanted edge on a fronto-parallel wall 3 m ahead (exact depth everywhere but in
        // a hole), seen again after the camera moved 20 cm forward, 5 cm right and turned.
        let rig = rig();
        let depth = DepthMap {
            width: 320,
            height: 240,
            metres: vec![3.0; 320 * 240],
        };
        let ends = [Point3::new(-0.4, -0.3, 3.0), Point3::new(0.2, 0.35, 3.0)];
        let previous = segment_of(&rig, ends[0], ends[1]);
        let current_from_previous = Isometry3::from_parts(
            Translation3::new(-0.05, 0.0, -0.2),
            UnitQuaternion::from_euler_angles(0.01, -0.03, 0.02),
        );
        let samples = samples_from_depth(&rig, &depth, &previous).expect("depth along it");
        let truth = segment_of(
            &rig,
            current_from_previous * ends[0],
            current_from_previous * ends[1],
        );
        assert_eq!(
            judge(&rig, &samples, &current_from_previous, &truth),
            Some(Verdict::Correct)
        );
        // A detector's fragment of it (its middle third), and 1.5 px off: still correct.
        let fragment = Segment::new(
            truth.start + (truth.end - truth.start) / 3.0,
            truth.start + (truth.end - truth.start) * (2.0 / 3.0),
        );
        assert_eq!(
            judge(&rig, &samples, &current_from_previous, &fragment),
            Some(Verdict::Correct)
        );
        assert_eq!(
            judge(
                &rig,
                &samples,
                &current_from_previous,
                &shifted(&truth, 1.5)
            ),
            Some(Verdict::Correct)
        );
        // A parallel edge 3 px away: wrong.
        assert_eq!(
            judge(
                &rig,
                &samples,
                &current_from_previous,
                &shifted(&truth, 3.0)
            ),
            Some(Verdict::Off)
        );
        // The same line beyond the segment's end: on the line, but not the same segment.
        let beyond = Segment::new(
            truth.end + (truth.end - truth.start) * 0.1,
            truth.end + (truth.end - truth.start) * 0.5,
        );
        assert_eq!(
            judge(&rig, &samples, &current_from_previous, &beyond),
            Some(Verdict::Disjoint)
        );
        // Judged against the previous position (no motion), the true match is wrong.
        assert_eq!(
            judge(&rig, &samples, &Isometry3::identity(), &truth),
            Some(Verdict::Off)
        );
        // A degenerate match, or too few samples in front of the camera: not judged.
        let point = Segment::new(truth.start, truth.start);
        assert_eq!(judge(&rig, &samples, &current_from_previous, &point), None);
        let behind = Isometry3::translation(0.0, 0.0, -5.0);
        assert_eq!(judge(&rig, &samples, &behind, &truth), None);
    }

    #[test]
    fn depth_samples_take_the_near_surface_and_need_depth() {
        let rig = rig();
        // Left half of the image a box face at 2 m, right half a wall at 6 m; a vertical
        // segment on the box's contour at x = 160.
        let mut depth = DepthMap {
            width: 320,
            height: 240,
            metres: vec![6.0; 320 * 240],
        };
        for v in 0..240 {
            for u in 0..160 {
                depth.metres[v * 320 + u] = 2.0;
            }
        }
        let contour = Segment::new(Point::new(160.0, 40.0), Point::new(160.0, 200.0));
        let samples = samples_from_depth(&rig, &depth, &contour).expect("depth along it");
        assert!(
            samples.iter().all(|p| (p.z - 2.0).abs() < 1e-6),
            "{samples:?}"
        );
        // Beyond the depth maps' range (0 = unknown) over most of it: not judged.
        depth
            .metres
            .iter_mut()
            .skip(320 * 80)
            .for_each(|d| *d = 0.0);
        assert_eq!(samples_from_depth(&rig, &depth, &contour), None);
        // Off the image: no depth, no panic.
        let outside = Segment::new(Point::new(-50.0, -50.0), Point::new(-10.0, -90.0));
        assert_eq!(samples_from_depth(&rig, &depth, &outside), None);
        let nan = Segment::new(Point::new(f64::NAN, 3.0), Point::new(10.0, 3.0));
        assert_eq!(samples_from_depth(&rig, &depth, &nan), None);
    }

    #[test]
    fn stereo_samples_lie_on_the_triangulated_line() {
        let rig = rig();
        let ends = [Point3::new(-0.3, -0.4, 4.0), Point3::new(0.1, 0.3, 5.0)];
        let left = segment_of(&rig, ends[0], ends[1]);
        let to_right = Isometry3::translation(-rig.baseline_m, 0.0, 0.0);
        let right = segment_of(&rig, to_right * ends[0], to_right * ends[1]);
        let limits = TriangulationLimits::default();
        let samples = samples_from_stereo(&rig, &left, &right, &limits).expect("triangulated");
        assert!((samples[0] - ends[0]).norm() < 1e-6, "{:?}", samples[0]);
        assert!((samples[STEREO_SAMPLES - 1] - ends[1]).norm() < 1e-6);
        // A horizontal partner: no depth along it.
        let flat = Segment::new(Point::new(100.0, 50.0), Point::new(200.0, 52.0));
        assert_eq!(samples_from_stereo(&rig, &flat, &flat, &limits), None);
    }
}
