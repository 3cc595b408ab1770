//! `nav_msgs/Odometry` and `/tf` from the pipeline's poses: the camera's pose turned into the
//! robot base's in the published axes, with the pose's and the step's covariances carried
//! along.
//!
//! `C` is the camera's optical frame seen from the base: the convention's axes (REP-103:
//! x forward, y left, z up) then [`CameraMount`]. The odom frame is the base at the first
//! frame, so a camera pose `P` (first camera → camera) becomes `C·P·C⁻¹`. Its covariance,
//! `(δp, θ)` in the world's axes (`linetrack_msgs::PoseRecord::covariance`), goes through
//! the Jacobian of that map: `θ' = R_C θ`, `δp' = R_C δp + [R'·t_C]× θ'` (`R'` the base's
//! orientation, `t_C` the camera's position in the base). The twist is the last step
//! (from the previous pose the bridge saw, over the stamps' difference) in the base frame;
//! its covariance is the step's (`PoseRecord::step_covariance`, an error of the new pose
//! in the camera's own frame) through the adjoint of `C`, over the time step squared.

use crate::convert;
use crate::ros_msgs::{
    Covariance, Header, Odometry, PoseWithCovariance, TfMessage, Transform, TransformStamped,
    Twist, TwistWithCovariance, Vector3 as RosVector3,
};
use linetrack_msgs::PoseRecord;
use linetrack_pipeline_config::{CameraMount, Convention};
use nalgebra::{
    Isometry3, Matrix3, Matrix6, Quaternion as NaQuaternion, Translation3, UnitQuaternion, Vector3,
};

/// The symmetric 6×6 matrix of a covariance of a [`PoseRecord`].
fn unpacked(values: &[f64; 21]) -> Matrix6<f64> {
    Matrix6::from(PoseRecord::unpack_covariance(values))
}

/// The camera's optical frame in the base frame (`C`).
pub fn camera_in_base(convention: Convention, mount: &CameraMount) -> Isometry3<f64> {
    let [x, y, z] = mount.translation_m;
    let [qx, qy, qz, qw] = mount.rotation_xyzw;
    let mount = Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_quaternion(NaQuaternion::new(qw, qx, qy, qz)),
    );
    match convention {
        Convention::Camera => mount,
        Convention::Rep103 => {
            let optical = convert::optical_to_rep103();
            mount * Isometry3::from_parts(Translation3::identity(), optical)
        }
    }
}

/// `[[A, B], [0, A]]` blocks.
fn blocks(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Matrix6<f64> {
    let mut j = Matrix6::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(a);
    j.fixed_view_mut::<3, 3>(0, 3).copy_from(b);
    j.fixed_view_mut::<3, 3>(3, 3).copy_from(a);
    j
}

/// A ROS covariance from a 6×6 matrix (symmetrised).
fn ros_covariance(m: &Matrix6<f64>) -> Covariance {
    let mut out = [0.0; 36];
    for i in 0..6 {
        for j in 0..6 {
            out[i * 6 + j] = 0.5 * (m[(i, j)] + m[(j, i)]);
        }
    }
    Covariance(out)
}

fn ros_vector(v: &Vector3<f64>) -> RosVector3 {
    RosVector3 {
        x: v.x,
        y: v.y,
        z: v.z,
    }
}

/// The base's pose in odom and its covariance, from the camera's pose and its covariance.
pub fn base_pose(
    camera: &Isometry3<f64>,
    covariance: &Matrix6<f64>,
    mount: &Isometry3<f64>,
) -> (Isometry3<f64>, Matrix6<f64>) {
    let base = mount * camera * mount.inverse();
    let r_c: Matrix3<f64> = mount.rotation.to_rotation_matrix().into_inner();
    let lever = base.rotation * mount.translation.vector;
    let j = blocks(&r_c, &(lever.cross_matrix() * r_c));
    (base, j * covariance * j.transpose())
}

/// The base's velocity over the step `previous → current` (camera poses) of `dt_s` seconds
/// in the base frame, and its covariance from the step's (`step`, in the current camera
/// frame).
pub fn base_twist(
    previous: &Isometry3<f64>,
    current: &Isometry3<f64>,
    step: &Matrix6<f64>,
    dt_s: f64,
    mount: &Isometry3<f64>,
) -> (Twist, Matrix6<f64>) {
    let displacement = mount * (previous.inverse() * current) * mount.inverse();
    let linear = displacement.translation.vector / dt_s;
    let angular = displacement.rotation.scaled_axis() / dt_s;
    let r_c: Matrix3<f64> = mount.rotation.to_rotation_matrix().into_inner();
    let adjoint = blocks(&r_c, &(mount.translation.vector.cross_matrix() * r_c));
    (
        Twist {
            linear: ros_vector(&linear),
            angular: ros_vector(&angular),
        },
        adjoint * step * adjoint.transpose() / (dt_s * dt_s),
    )
}

/// The odometry message of `record` stamped `header` (its frame the odom frame), with the
/// twist over the step from `previous` (the last pose seen and its stamp, nanoseconds)
/// when there is one; `None` when the pose is no finite rotation and position.
pub fn odometry(
    record: &PoseRecord,
    header: Header,
    stamp_ns: u64,
    previous: Option<(&PoseRecord, u64)>,
    child_frame_id: &str,
    mount: &Isometry3<f64>,
) -> Option<Odometry> {
    let camera = convert::camera_pose(record)?;
    let (base, pose_covariance) = base_pose(&camera, &unpacked(&record.covariance), mount);
    let twist = previous
        .and_then(|(p, ns)| Some((convert::camera_pose(p)?, stamp_ns.checked_sub(ns)?)))
        .filter(|(_, dt)| *dt > 0)
        .map(|(before, dt_ns)| {
            let step = unpacked(&record.step_covariance);
            let (twist, covariance) =
                base_twist(&before, &camera, &step, dt_ns as f64 * 1e-9, mount);
            TwistWithCovariance {
                twist,
                covariance: ros_covariance(&covariance),
            }
        })
        .unwrap_or_default();
    Some(Odometry {
        header,
        child_frame_id: child_frame_id.to_string(),
        pose: PoseWithCovariance {
            pose: convert::pose_message(&base),
            covariance: ros_covariance(&pose_covariance),
        },
        twist,
    })
}

/// The `/tf` message of an odometry message: its parent → child at its pose.
pub fn transform(odometry: &Odometry) -> TfMessage {
    let pose = odometry.pose.pose;
    TfMessage {
        transforms: vec![TransformStamped {
            header: odometry.header.clone(),
            child_frame_id: odometry.child_frame_id.clone(),
            transform: Transform {
                translation: RosVector3 {
                    x: pose.position.x,
                    y: pose.position.y,
                    z: pose.position.z,
                },
                rotation: pose.orientation,
            },
        }],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector6;

    fn record(pose: &Isometry3<f64>, covariance: &Matrix6<f64>) -> PoseRecord {
        let (t, q) = (pose.translation.vector, pose.rotation);
        let packed = PoseRecord::pack_covariance(&(*covariance).into());
        PoseRecord {
            translation: [t.x, t.y, t.z],
            rotation_xyzw: [q.i, q.j, q.k, q.w],
            covariance: packed,
            step_covariance: packed,
            ..PoseRecord::default()
        }
    }

    fn camera() -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(0.3, -0.1, 2.0),
            UnitQuaternion::from_euler_angles(0.05, -0.4, 0.1),
        )
    }

    /// With the camera as the base, the odometry's pose is the PoseStamped's.
    #[test]
    fn the_pose_is_the_pose_stamped_one_when_the_camera_is_the_base() {
        let cov = Matrix6::identity() * 1e-4;
        let r = record(&camera(), &cov);
        for convention in [Convention::Rep103, Convention::Camera] {
            let mount = camera_in_base(convention, &CameraMount::default());
            let odom = odometry(&r, Header::default(), 0, None, "base_link", &mount)
                .unwrap_or_else(|| panic!("no odometry"));
            let stamped = convert::ros_pose(&r, convention).unwrap_or_default();
            let (a, b) = (odom.pose.pose, stamped);
            for (x, y) in [
                (a.position.x, b.position.x),
                (a.position.y, b.position.y),
                (a.position.z, b.position.z),
                (a.orientation.w.abs(), b.orientation.w.abs()),
            ] {
                assert!((x - y).abs() < 1e-12, "{convention:?}: {a:?} vs {b:?}");
            }
            // An isotropic covariance stays isotropic under a rotation.
            let c = odom.pose.covariance.0;
            assert!((c[0] - 1e-4).abs() < 1e-15 && c[1].abs() < 1e-15, "{c:?}");
        }
    }

    /// The published covariance is the spread of the published poses when the camera pose
    /// is perturbed as its covariance says (first order: small errors), with a lever arm.
    #[test]
    fn the_covariance_follows_the_axes_and_the_lever_arm() {
        let mount = camera_in_base(
            Convention::Rep103,
            &CameraMount {
                translation_m: [0.5, 0.1, 0.3],
                rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
            },
        );
        let sigma = Vector6::new(1e-3, 2e-3, 3e-3, 1e-3, 5e-4, 2e-3);
        let cov = Matrix6::from_diagonal(&sigma.component_mul(&sigma));
        let (base, published) = base_pose(&camera(), &cov, &mount);
        // Each axis of the camera error alone, ±1σ: its image in the base pose error.
        let mut sampled = Matrix6::zeros();
        for axis in 0..6 {
            for sign in [-1.0, 1.0] {
                let mut d = Vector6::zeros();
                d[axis] = sign * sigma[axis];
                let c = camera();
                let perturbed = Isometry3::from_parts(
                    Translation3::from(c.translation.vector + d.fixed_rows::<3>(0)),
                    UnitQuaternion::from_scaled_axis(d.fixed_rows::<3>(3).into_owned())
                        * c.rotation,
                );
                let b = mount * perturbed * mount.inverse();
                let dp = b.translation.vector - base.translation.vector;
                let th = (b.rotation * base.rotation.inverse()).scaled_axis();
                let e = Vector6::new(dp.x, dp.y, dp.z, th.x, th.y, th.z);
                sampled += e * e.transpose() / 2.0;
            }
        }
        let scale = published.amax();
        assert!(
            (sampled - published).amax() < 1e-3 * scale,
            "{published}\n{sampled}"
        );
        // It is symmetric and positive semi-definite as published.
        let out = ros_covariance(&published).0;
        let m = Matrix6::from_row_slice(&out);
        assert_eq!(m, m.transpose());
        assert!(m.symmetric_eigenvalues().min() >= -1e-18);
    }

    #[test]
    fn the_twist_is_the_step_over_the_time_in_the_base_frame() {
        let mount = camera_in_base(Convention::Rep103, &CameraMount::default());
        let before = camera();
        // 5 cm along the camera's z (forward) in 0.05 s: 1 m/s along the base's x.
        let after = before * Isometry3::translation(0.0, 0.0, 0.05);
        let cov = Matrix6::identity() * 1e-6;
        let (twist, covariance) = base_twist(&before, &after, &cov, 0.05, &mount);
        assert!((twist.linear.x - 1.0).abs() < 1e-9, "{twist:?}");
        assert!(twist.linear.y.abs() < 1e-9 && twist.angular.z.abs() < 1e-9);
        assert!((covariance[(0, 0)] - 1e-6 / 0.0025).abs() < 1e-12);
        // Through the message: no previous pose, no twist.
        let r = record(&after, &cov);
        let odom = odometry(&r, Header::default(), 50_000_000, None, "base_link", &mount)
            .unwrap_or_else(|| panic!("no odometry"));
        assert_eq!(odom.twist, TwistWithCovariance::default());
        let p = record(&before, &cov);
        let odom = odometry(
            &r,
            Header::default(),
            50_000_000,
            Some((&p, 0)),
            "base_link",
            &mount,
        )
        .unwrap_or_else(|| panic!("no odometry"));
        assert!((odom.twist.twist.linear.x - 1.0).abs() < 1e-9);
        let tf = transform(&odom);
        assert_eq!(tf.transforms.len(), 1);
        assert_eq!(tf.transforms[0].child_frame_id, "base_link");
        assert_eq!(
            tf.transforms[0].transform.rotation,
            odom.pose.pose.orientation
        );
    }
}
