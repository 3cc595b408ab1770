//! Features followed from frame to frame as landmarks: a world position fused from every
//! stereo sighting that agreed with it.
//!
//! PL-StVO re-triangulates every feature in every frame and chains the frame-to-frame
//! motions, so each frame's stereo noise enters the trajectory once and the errors add up
//! as a random walk. A landmark instead keeps one world position while it is tracked:
//! the motion into the current frame is measured against a position averaged over all its
//! earlier sightings (expressed in the previous camera frame through the previous pose),
//! which both lowers the noise of each estimate and ties successive estimates to the same
//! structure. A new sighting whose disparity disagrees with the landmark's prediction by
//! more than the gate starts a new landmark instead (a stereo mismatch, or a track that
//! jumped to a look-alike).

use linetrack_geometry::StereoRig;
use nalgebra::{Isometry3, Point3};

/// A tracked feature's world position (`P`: a point, or a segment's two endpoints).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Landmark<P> {
    /// World position (the first camera's frame), metres.
    pub world: P,
    /// Sum of the weights of the sightings fused into it.
    pub weight: f64,
    /// How many stereo sightings were fused into it.
    pub sightings: u32,
}

/// The landmark of a fresh stereo triangulation `local` (camera frame of `pose`).
pub(crate) fn sighted<P: Geometry>(pose: &Isometry3<f64>, local: &P, weight: f64) -> Landmark<P> {
    Landmark {
        world: local.transformed(pose),
        weight,
        sightings: 1,
    }
}

/// What a landmark is made of: a point or a segment's endpoints.
pub(crate) trait Geometry: Copy {
    /// The same geometry under `pose`.
    fn transformed(&self, pose: &Isometry3<f64>) -> Self;
    /// The largest disparity difference between `self` and `other`, both in the current
    /// camera frame, pixels (for segments: of each of `self`'s endpoints and the closest
    /// point of `other`'s line).
    fn disparity_gap(&self, other: &Self, rig: &StereoRig) -> f64;
    /// The weighted mean of `self` (weight `w`) and `other` (weight `w_other`), both in the
    /// same frame (for segments: `self`'s endpoints moved towards `other`'s line, so the
    /// extent stays that of the first sighting).
    fn fused(&self, w: f64, other: &Self, w_other: f64) -> Self;
    /// The same geometry (camera frame) as triangulated from disparities `more_px` larger
    /// (each point moved along its ray from the camera); `None` when a disparity would
    /// no longer be positive.
    fn with_disparities_grown(&self, more_px: f64, rig: &StereoRig) -> Option<Self>;
}

/// `p` (camera frame) as triangulated from a disparity `more_px` larger.
fn point_with_disparity_grown(
    p: &Point3<f64>,
    more_px: f64,
    rig: &StereoRig,
) -> Option<Point3<f64>> {
    let before = disparity(rig, p);
    let after = before + more_px;
    (before.is_finite() && after > 0.0).then(|| Point3::from(p.coords * (before / after)))
}

/// Disparity of `p`, pixels (infinite at or behind the camera).
fn disparity(rig: &StereoRig, p: &Point3<f64>) -> f64 {
    if p.z > 0.0 {
        rig.disparity_px(p.z)
    } else {
        f64::INFINITY
    }
}

impl Geometry for Point3<f64> {
    fn transformed(&self, pose: &Isometry3<f64>) -> Self {
        pose * self
    }

    fn disparity_gap(&self, other: &Self, rig: &StereoRig) -> f64 {
        (disparity(rig, self) - disparity(rig, other)).abs()
    }

    fn fused(&self, w: f64, other: &Self, w_other: f64) -> Self {
        Point3::from((self.coords * w + other.coords * w_other) / (w + w_other))
    }

    fn with_disparities_grown(&self, more_px: f64, rig: &StereoRig) -> Option<Self> {
        point_with_disparity_grown(self, more_px, rig)
    }
}

/// The point of the line through `line` closest to `p`.
fn closest_on_line(line: &[Point3<f64>; 2], p: &Point3<f64>) -> Point3<f64> {
    let direction = line[1] - line[0];
    let length2 = direction.norm_squared();
    if length2 < 1e-18 {
        return line[0];
    }
    line[0] + direction * ((p - line[0]).dot(&direction) / length2)
}

impl Geometry for [Point3<f64>; 2] {
    fn transformed(&self, pose: &Isometry3<f64>) -> Self {
        [pose * self[0], pose * self[1]]
    }

    fn disparity_gap(&self, other: &Self, rig: &StereoRig) -> f64 {
        self.iter()
            .map(|p| (disparity(rig, p) - disparity(rig, &closest_on_line(other, p))).abs())
            .fold(0.0, f64::max)
    }

    fn fused(&self, w: f64, other: &Self, w_other: f64) -> Self {
        self.map(|p| p.fused(w, &closest_on_line(other, &p), w_other))
    }

    fn with_disparities_grown(&self, more_px: f64, rig: &StereoRig) -> Option<Self> {
        Some([
            point_with_disparity_grown(&self[0], more_px, rig)?,
            point_with_disparity_grown(&self[1], more_px, rig)?,
        ])
    }
}

impl<P: Geometry> Landmark<P> {
    /// The landmark in the camera frame of `pose` (camera to world).
    pub fn local(&self, pose: &Isometry3<f64>) -> P {
        self.world.transformed(&pose.inverse())
    }

    /// The landmark after it was seen again from `pose`: fused with the fresh stereo
    /// triangulation `fresh` (camera frame, weight `weight`) when their disparities agree
    /// within `gate_px`, else replaced by it; carried on unchanged when the feature was
    /// seen without a stereo partner.
    pub fn seen_again(
        &self,
        pose: &Isometry3<f64>,
        fresh: Option<(&P, f64)>,
        rig: &StereoRig,
        gate_px: f64,
    ) -> Self {
        let Some((fresh, weight)) = fresh else {
            return *self;
        };
        let local = self.local(pose);
        if local.disparity_gap(fresh, rig) > gate_px {
            return sighted(pose, fresh, weight);
        }
        Landmark {
            world: local.fused(self.weight, fresh, weight).transformed(pose),
            weight: self.weight + weight,
            sightings: self.sightings + 1,
        }
    }

    /// The landmark as triangulated from disparities `more_px` larger, seen from `pose`
    /// (camera to world): a disparity offset applied anew moves what was fused before it.
    pub fn with_disparities_grown(
        &self,
        pose: &Isometry3<f64>,
        more_px: f64,
        rig: &StereoRig,
    ) -> Option<Self> {
        let local = self.local(pose).with_disparities_grown(more_px, rig)?;
        Some(Landmark {
            world: local.transformed(pose),
            ..*self
        })
    }

    /// The weight of an observation of this landmark: its best single sighting's share of
    /// the fused weight, grown with the square root of the sightings (their noise is not
    /// independent: the poses they were placed with share errors), at most 1.
    pub fn observation_weight(&self) -> f64 {
        let per_sighting = self.weight / f64::from(self.sightings.max(1));
        (per_sighting * f64::from(self.sightings.max(1)).sqrt()).min(1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn rig() -> StereoRig {
        StereoRig {
            focal_px: 400.0,
            baseline_m: 0.1,
            ..StereoRig::default()
        }
    }

    fn pose() -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(0.3, -0.1, 1.0),
            UnitQuaternion::from_euler_angles(0.02, -0.1, 0.05),
        )
    }

    #[test]
    fn agreeing_sightings_average_and_disagreeing_ones_start_over() {
        let (rig, pose) = (rig(), pose());
        let local = Point3::new(0.5, 0.2, 4.0);
        let landmark = sighted(&pose, &local, 0.8);
        // 4 m at f·b = 40 px·m: disparity 10 px; 4.05 m is 0.12 px away, 5 m is 2 px away.
        let near = Point3::new(0.5, 0.2, 4.05);
        let fused = landmark.seen_again(&pose, Some((&near, 0.8)), &rig, 1.0);
        assert_eq!(fused.sightings, 2);
        assert!((fused.local(&pose) - Point3::new(0.5, 0.2, 4.025)).norm() < 1e-9);
        let far = Point3::new(0.5, 0.2, 5.0);
        let restarted = fused.seen_again(&pose, Some((&far, 0.5)), &rig, 1.0);
        assert_eq!(restarted.sightings, 1);
        assert!((restarted.local(&pose) - far).norm() < 1e-9);
        let carried = fused.seen_again(&pose, None, &rig, 1.0);
        assert_eq!(carried, fused);
    }

    #[test]
    fn a_segment_keeps_its_extent_and_moves_towards_the_new_line() {
        let (rig, pose) = (rig(), Isometry3::identity());
        let first = [Point3::new(0.0, -1.0, 4.0), Point3::new(0.0, 1.0, 4.0)];
        let landmark = sighted(&pose, &first, 1.0);
        // The same wall edge seen shorter and 4 cm deeper.
        let again = [Point3::new(0.0, -0.5, 4.04), Point3::new(0.0, 0.5, 4.04)];
        let fused = landmark.seen_again(&pose, Some((&again, 1.0)), &rig, 1.0);
        let [a, b] = fused.local(&pose);
        assert!((a - Point3::new(0.0, -1.0, 4.02)).norm() < 1e-9);
        assert!((b - Point3::new(0.0, 1.0, 4.02)).norm() < 1e-9);
    }

    /// A disparity offset applied anew moves a landmark along its ray from the camera it
    /// is expressed for, to the depth of its disparity so grown.
    #[test]
    fn a_landmark_moves_along_its_ray_to_its_grown_disparity() {
        let (rig, pose) = (rig(), pose());
        let local = Point3::new(2.0, -1.0, 20.0);
        let point = sighted(&pose, &local, 1.0);
        let d = rig.disparity_px(20.0);
        let moved = point
            .with_disparities_grown(&pose, 1.0, &rig)
            .unwrap_or_else(|| panic!("a positive disparity"))
            .local(&pose);
        assert!((moved.z - rig.focal_px * rig.baseline_m / (d + 1.0)).abs() < 1e-9);
        assert!(
            (moved.x / moved.z - 0.1).abs() < 1e-12 && (moved.y / moved.z + 0.05).abs() < 1e-12
        );
        assert_eq!(
            point
                .with_disparities_grown(&pose, 1.0, &rig)
                .map(|l| l.sightings),
            Some(1)
        );
        // Shrunk to nothing or below: no depth.
        assert!(point.with_disparities_grown(&pose, -d, &rig).is_none());
        // A segment's endpoints move each along its own ray.
        let segment = sighted(&pose, &[local, Point3::new(-1.0, 0.5, 10.0)], 1.0);
        let [a, b] = segment
            .with_disparities_grown(&pose, -0.5, &rig)
            .unwrap_or_else(|| panic!("positive disparities"))
            .local(&pose);
        assert!((rig.disparity_px(a.z) - (d - 0.5)).abs() < 1e-9);
        assert!((rig.disparity_px(b.z) - (rig.disparity_px(10.0) - 0.5)).abs() < 1e-9);
    }

    #[test]
    fn observation_weight_grows_slower_than_the_sightings() {
        let one = Landmark {
            world: Point3::origin(),
            weight: 0.25,
            sightings: 1,
        };
        let four = Landmark {
            weight: 1.0,
            sightings: 4,
            ..one
        };
        assert_eq!(one.observation_weight(), 0.25);
        assert_eq!(four.observation_weight(), 0.5);
    }
}
