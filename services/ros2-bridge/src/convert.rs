//! From the pipeline's poses to ROS messages: axes, stamp, and the path window.

use crate::ros_msgs::{Header, Path, Point, Pose, PoseStamped, Quaternion, Time};
use linetrack_msgs::{FrameHeader, PoseRecord};
use linetrack_pipeline_config::{Convention, StampSource};
use nalgebra::{
    Isometry3, Matrix3, Quaternion as NaQuaternion, Rotation3, Translation3, UnitQuaternion,
};
use std::collections::VecDeque;

/// REP-103 body axes from the left camera's optical axes: x forward (the camera's z),
/// y left (its −x), z up (its −y).
pub(crate) fn optical_to_rep103() -> UnitQuaternion<f64> {
    let m = Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m))
}

/// The pose of a record (the left camera in the first frame's camera frame); `None` when it
/// is not a finite rotation and position.
pub fn camera_pose(record: &PoseRecord) -> Option<Isometry3<f64>> {
    let [x, y, z] = record.translation;
    let [qx, qy, qz, qw] = record.rotation_xyzw;
    let q = NaQuaternion::new(qw, qx, qy, qz);
    let finite = [x, y, z, qx, qy, qz, qw].iter().all(|v| v.is_finite());
    (finite && q.norm() >= f64::EPSILON).then(|| {
        Isometry3::from_parts(
            Translation3::new(x, y, z),
            UnitQuaternion::from_quaternion(q),
        )
    })
}

/// A pose as a ROS message.
pub fn pose_message(pose: &Isometry3<f64>) -> Pose {
    let (t, q) = (pose.translation.vector, pose.rotation);
    Pose {
        position: Point {
            x: t.x,
            y: t.y,
            z: t.z,
        },
        orientation: Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        },
    }
}

/// The pose of `record` (the left camera in the first frame's camera frame) in
/// `convention`'s axes; `None` when it is not a finite rotation and position.
///
/// With [`Convention::Rep103`] both the world frame (the first camera frame) and the body
/// frame are turned to x forward, y left, z up: position `M·t`, orientation `M·R·Mᵀ`.
pub fn ros_pose(record: &PoseRecord, convention: Convention) -> Option<Pose> {
    let pose = camera_pose(record)?;
    Some(pose_message(&match convention {
        Convention::Camera => pose,
        Convention::Rep103 => {
            let m = Isometry3::from_parts(Translation3::identity(), optical_to_rep103());
            m * pose * m.inverse()
        }
    }))
}

/// The stamp of a frame's messages.
pub fn stamp(header: &FrameHeader, source: StampSource) -> Time {
    Time::from_ns(stamp_ns(header, source))
}

/// The stamp of a frame's messages, nanoseconds.
pub fn stamp_ns(header: &FrameHeader, source: StampSource) -> u64 {
    match source {
        StampSource::Capture => header.capture_ns,
        StampSource::Sequence => header.sequence_ns,
    }
}

/// The newest poses, at most a fixed number: the published path.
#[derive(Debug, Clone)]
pub struct PathWindow {
    poses: VecDeque<PoseStamped>,
    capacity: usize,
}

impl PathWindow {
    /// An empty window of at most `capacity` poses (at least 1).
    pub fn new(capacity: usize) -> Self {
        let capacity = capacity.max(1);
        Self {
            poses: VecDeque::with_capacity(capacity),
            capacity,
        }
    }

    /// Adds the newest pose, forgetting the oldest when full.
    pub fn push(&mut self, pose: PoseStamped) {
        if self.poses.len() == self.capacity {
            self.poses.pop_front();
        }
        self.poses.push_back(pose);
    }

    /// The path message: the window's poses, oldest first, stamped with the newest's time.
    pub fn message(&self, frame_id: &str) -> Path {
        Path {
            header: Header {
                stamp: self
                    .poses
                    .back()
                    .map(|p| p.header.stamp)
                    .unwrap_or_default(),
                frame_id: frame_id.to_string(),
            },
            poses: self.poses.iter().cloned().collect(),
        }
    }

    /// Poses held.
    pub fn len(&self) -> usize {
        self.poses.len()
    }

    /// Whether it holds none.
    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn record(t: [f64; 3], q: UnitQuaternion<f64>) -> PoseRecord {
        PoseRecord {
            translation: t,
            rotation_xyzw: [q.i, q.j, q.k, q.w],
            ..PoseRecord::default()
        }
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn camera_convention_is_the_pose_as_recorded() {
        let q = UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3);
        let p = ros_pose(&record([1.0, 2.0, 3.0], q), Convention::Camera).unwrap_or_default();
        assert_eq!((p.position.x, p.position.y, p.position.z), (1.0, 2.0, 3.0));
        assert!(close(p.orientation.w, q.w) && close(p.orientation.z, q.k));
    }

    #[test]
    fn rep103_puts_forward_on_x_left_on_y_up_on_z() {
        let identity = UnitQuaternion::identity();
        // A camera 1 m forward (its z), 2 m right (its x), 3 m down (its y).
        let p =
            ros_pose(&record([2.0, 3.0, 1.0], identity), Convention::Rep103).unwrap_or_default();
        assert!(close(p.position.x, 1.0) && close(p.position.y, -2.0) && close(p.position.z, -3.0));
        // The start pose stays the identity.
        assert!(close(p.orientation.w.abs(), 1.0));
        // Turning left is about the camera's −y (up); in REP-103 it is about +z.
        let left = UnitQuaternion::from_axis_angle(&-Vector3::y_axis(), 0.5);
        let p = ros_pose(&record([0.0; 3], left), Convention::Rep103).unwrap_or_default();
        let q = UnitQuaternion::from_quaternion(NaQuaternion::new(
            p.orientation.w,
            p.orientation.x,
            p.orientation.y,
            p.orientation.z,
        ));
        let (roll, pitch, yaw) = q.euler_angles();
        assert!(
            close(roll, 0.0) && close(pitch, 0.0) && close(yaw, 0.5),
            "{roll} {pitch} {yaw}"
        );
    }

    #[test]
    fn a_pose_that_is_no_rotation_is_refused() {
        let mut r = record([0.0; 3], UnitQuaternion::identity());
        r.rotation_xyzw = [0.0; 4];
        assert_eq!(ros_pose(&r, Convention::Rep103), None);
        r.rotation_xyzw = [0.0, 0.0, 0.0, 1.0];
        r.translation[1] = f64::NAN;
        assert_eq!(ros_pose(&r, Convention::Camera), None);
    }

    #[test]
    fn stamps_come_from_the_chosen_clock() {
        let header = FrameHeader::new(3, 1_403_715_273_262_142_976, 1_700_000_000_500_000_000);
        assert_eq!(
            stamp(&header, StampSource::Sequence),
            Time {
                sec: 1_403_715_273,
                nanosec: 262_142_976
            }
        );
        assert_eq!(
            stamp(&header, StampSource::Capture),
            Time {
                sec: 1_700_000_000,
                nanosec: 500_000_000
            }
        );
    }

    #[test]
    fn the_path_keeps_the_newest_poses_in_order() {
        let mut window = PathWindow::new(3);
        for i in 0..5u64 {
            window.push(PoseStamped {
                header: Header {
                    stamp: Time::from_ns(i),
                    frame_id: "odom".into(),
                },
                pose: Pose::default(),
            });
        }
        let path = window.message("map");
        let stamps: Vec<u32> = path.poses.iter().map(|p| p.header.stamp.nanosec).collect();
        assert_eq!(stamps, [2, 3, 4]);
        assert_eq!(
            (path.header.stamp.nanosec, path.header.frame_id.as_str()),
            (4, "map")
        );
    }
}
