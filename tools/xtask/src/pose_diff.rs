//! How far apart two runs' trajectories are, pose by pose: the check behind `cargo xtask
//! cross`, which runs the same commands as native x86 and as emulated aarch64 binaries.
//!
//! Both trajectories must hold the same frames (timestamps equal to the microsecond, in the
//! same order): a frame one run estimated and the other dropped or lost is a difference in
//! itself, reported as such. For the frames both have, the largest distance between the
//! camera positions (metres) and the largest rotation between the orientations (degrees,
//! the angle of `R_a⁻¹ R_b`) are what the tolerance is checked against.

use anyhow::{Context, bail};
use linetrack_trajectory::tum::{self, StampedPose};
use nalgebra::UnitQuaternion;
use std::path::Path;

/// Timestamps closer than this are the same frame, seconds (TUM files carry them printed).
const SAME_FRAME_S: f64 = 1e-6;

/// The largest differences between two trajectories of the same frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseDifference {
    /// Poses compared.
    pub poses: usize,
    /// The largest distance between the two positions, metres.
    pub max_position_m: f64,
    /// The timestamp of the frame with that distance, seconds.
    pub max_position_at_s: f64,
    /// The largest rotation between the two orientations, degrees.
    pub max_rotation_deg: f64,
    /// The timestamp of the frame with that rotation, seconds.
    pub max_rotation_at_s: f64,
}

impl PoseDifference {
    /// Whether both largest differences are within the tolerance.
    pub fn within(&self, tolerance: &Tolerance) -> bool {
        self.max_position_m <= tolerance.position_m
            && self.max_rotation_deg <= tolerance.rotation_deg
    }
}

impl std::fmt::Display for PoseDifference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} poses, max position difference {:.3e} m (t = {:.6} s), max rotation difference {:.3e}° (t = {:.6} s)",
            self.poses,
            self.max_position_m,
            self.max_position_at_s,
            self.max_rotation_deg,
            self.max_rotation_at_s
        )
    }
}

/// How far two trajectories of the same frames may lie apart.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerance {
    /// Largest allowed distance between positions, metres.
    pub position_m: f64,
    /// Largest allowed rotation between orientations, degrees.
    pub rotation_deg: f64,
}

/// Compares two TUM trajectory files (see [`compare`]); errors name the files.
pub fn compare_files(reference: &Path, other: &Path) -> anyhow::Result<PoseDifference> {
    let a = tum::read(reference).with_context(|| format!("reading {}", reference.display()))?;
    let b = tum::read(other).with_context(|| format!("reading {}", other.display()))?;
    compare(&a, &b).with_context(|| format!("{} against {}", other.display(), reference.display()))
}

/// The largest position and rotation differences between two trajectories of the same
/// frames. Errors when they hold different frames (naming the first that differs) or no
/// frame at all.
pub fn compare(reference: &[StampedPose], other: &[StampedPose]) -> anyhow::Result<PoseDifference> {
    if reference.is_empty() {
        bail!("the reference trajectory is empty");
    }
    for (k, (a, b)) in reference.iter().zip(other).enumerate() {
        if (a.timestamp_s - b.timestamp_s).abs() > SAME_FRAME_S {
            bail!(
                "pose {} is of frame t = {:.6} s here and t = {:.6} s in the reference: the runs estimated different frames",
                k + 1,
                b.timestamp_s,
                a.timestamp_s
            );
        }
    }
    if reference.len() != other.len() {
        bail!(
            "{} poses against {} in the reference: the runs estimated different frames",
            other.len(),
            reference.len()
        );
    }
    let mut difference = PoseDifference {
        poses: reference.len(),
        max_position_m: 0.0,
        max_position_at_s: reference[0].timestamp_s,
        max_rotation_deg: 0.0,
        max_rotation_at_s: reference[0].timestamp_s,
    };
    for (a, b) in reference.iter().zip(other) {
        let position_m = (a.pose.translation.vector - b.pose.translation.vector).norm();
        let rotation_deg = rotation_between_rad(&a.pose.rotation, &b.pose.rotation).to_degrees();
        // `!(x <= max)` also takes a NaN, which then fails any tolerance.
        if !(position_m <= difference.max_position_m) {
            difference.max_position_m = position_m;
            difference.max_position_at_s = a.timestamp_s;
        }
        if !(rotation_deg <= difference.max_rotation_deg) {
            difference.max_rotation_deg = rotation_deg;
            difference.max_rotation_at_s = a.timestamp_s;
        }
    }
    Ok(difference)
}

/// The angle of the rotation from `a` to `b`, radians: `2 atan2(|v|, |w|)` of the quaternion
/// `a⁻¹ b`, exact near zero (where an arc cosine of `w` loses half the digits).
fn rotation_between_rad(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> f64 {
    let q = (a.inverse() * b).into_inner();
    2.0 * q.imag().norm().atan2(q.w.abs())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, Translation3, Vector3};

    fn pose(t: f64, x: f64, yaw_deg: f64) -> StampedPose {
        StampedPose {
            timestamp_s: t,
            pose: Isometry3::from_parts(
                Translation3::new(x, 0.5, -1.0),
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw_deg.to_radians()),
            ),
        }
    }

    const TIGHT: Tolerance = Tolerance {
        position_m: 1e-3,
        rotation_deg: 0.05,
    };

    #[test]
    fn identical_trajectories_do_not_differ() {
        let a = vec![pose(0.0, 0.0, 0.0), pose(0.05, 0.1, 3.0)];
        let d = compare(&a, &a).unwrap();
        assert_eq!(d.poses, 2);
        assert_eq!(d.max_position_m, 0.0);
        assert!(d.max_rotation_deg < 1e-6, "{d}");
        assert!(d.within(&TIGHT));
    }

    #[test]
    fn the_largest_differences_and_their_frames_are_reported() {
        let a = vec![
            pose(0.0, 0.0, 0.0),
            pose(0.05, 0.1, 3.0),
            pose(0.1, 0.2, 6.0),
        ];
        let b = vec![
            pose(0.0, 0.0, 0.5),
            pose(0.05, 0.1004, 3.0),
            pose(0.1, 0.2001, 6.0),
        ];
        let d = compare(&a, &b).unwrap();
        assert!((d.max_position_m - 4e-4).abs() < 1e-9, "{d}");
        assert_eq!(d.max_position_at_s, 0.05);
        assert!((d.max_rotation_deg - 0.5).abs() < 1e-6, "{d}");
        assert_eq!(d.max_rotation_at_s, 0.0);
        assert!(!d.within(&TIGHT), "0.5° is over 0.05°");
        assert!(d.within(&Tolerance {
            position_m: 1e-3,
            rotation_deg: 1.0
        }));
    }

    #[test]
    fn a_frame_missing_from_one_run_is_a_difference() {
        let a = vec![
            pose(0.0, 0.0, 0.0),
            pose(0.05, 0.1, 3.0),
            pose(0.1, 0.2, 6.0),
        ];
        let skipped = vec![pose(0.0, 0.0, 0.0), pose(0.1, 0.2, 6.0)];
        let error = compare(&a, &skipped).unwrap_err().to_string();
        assert!(
            error.contains("pose 2") && error.contains("different frames"),
            "{error}"
        );
        let short = vec![pose(0.0, 0.0, 0.0), pose(0.05, 0.1, 3.0)];
        let error = compare(&a, &short).unwrap_err().to_string();
        assert!(error.contains("2 poses against 3"), "{error}");
        assert!(compare(&[], &a).is_err());
    }

    #[test]
    fn a_nan_pose_fails_any_tolerance() {
        let a = vec![pose(0.0, 0.0, 0.0)];
        let b = vec![pose(0.0, f64::NAN, 0.0)];
        let d = compare(&a, &b).unwrap();
        assert!(!d.within(&Tolerance {
            position_m: 1e9,
            rotation_deg: 1e9
        }));
    }

    #[test]
    fn files_are_read_and_named_in_errors() {
        let dir = linetrack_test_data::Scratch::new("xtask", "pose-diff");
        let (ra, rb) = (dir.join("a.tum"), dir.join("b.tum"));
        tum::write(&ra, &[pose(0.0, 0.0, 0.0), pose(0.05, 0.1, 3.0)]).unwrap();
        tum::write(&rb, &[pose(0.0, 0.0, 0.0), pose(0.05, 0.1, 3.0)]).unwrap();
        let d = compare_files(&ra, &rb).unwrap();
        assert_eq!(d.poses, 2);
        assert!(d.max_position_m < 1e-6, "{d}");
        let missing = dir.join("missing.tum");
        let error = format!("{:#}", compare_files(&ra, &missing).unwrap_err());
        assert!(error.contains("missing.tum"), "{error}");
    }
}
