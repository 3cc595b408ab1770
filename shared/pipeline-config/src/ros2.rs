//! `[ros2]`: the optional ROS 2 output process (`linetrack-ros2`, cargo feature `ros2`).

use serde::{Deserialize, Serialize};

/// The highest ROS domain id: RTPS ports of higher ones overflow on Linux (ROS 2's limit).
pub const MAX_DOMAIN_ID: u16 = 232;
/// The longest path window, poses.
const MAX_PATH_POSES: usize = 100_000;

/// Which axes the published poses are in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Convention {
    /// ROS REP-103 body axes: x forward, y left, z up, in the first frame's body frame.
    #[default]
    Rep103,
    /// The pipeline's own (as in `poses.tum`): the left camera's optical axes, x right,
    /// y down, z forward, in the first frame's camera frame (REP-103's `_optical` frames).
    Camera,
}

/// Where a message's header stamp comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StampSource {
    /// When the frame source started reading the frame (UNIX time): what a live robot wants.
    #[default]
    Capture,
    /// The sequence's own timestamp of the frame: the one `poses.tum` is written with.
    Sequence,
}

/// Where the camera sits on the robot: the left camera's pose in the base frame, in the
/// published convention's axes (with `rep103`, of the camera's x-forward, y-left, z-up
/// body frame; with `camera`, of its optical frame). The identity: the base is the camera.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraMount {
    /// Position of the camera in the base frame, metres.
    pub translation_m: [f64; 3],
    /// Orientation of the camera in the base frame, unit quaternion x, y, z, w.
    pub rotation_xyzw: [f64; 4],
}

impl Default for CameraMount {
    fn default() -> Self {
        Self {
            translation_m: [0.0; 3],
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
        }
    }
}

impl CameraMount {
    /// How far a unit quaternion's norm may be from 1 (rounding of hand-written values).
    pub const UNIT_TOLERANCE: f64 = 1e-3;

    /// The first bad value, named with why.
    pub fn validate(&self) -> Result<(), String> {
        if !self.translation_m.iter().all(|v| v.is_finite()) {
            return Err(format!(
                "ros2.camera_in_base.translation_m = {:?}: not finite",
                self.translation_m
            ));
        }
        let norm = self.rotation_xyzw.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !((norm - 1.0).abs() <= Self::UNIT_TOLERANCE) {
            return Err(format!(
                "ros2.camera_in_base.rotation_xyzw = {:?}: not a unit quaternion (norm {norm})",
                self.rotation_xyzw
            ));
        }
        Ok(())
    }
}

/// The ROS 2 output: poses and the path of the run over DDS.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Ros2Config {
    /// Start `linetrack-ros2` with the run.
    pub enabled: bool,
    /// The ROS domain id; unset: `ROS_DOMAIN_ID` from the environment, else 0.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub domain_id: Option<u16>,
    /// Discovery and traffic on the loopback interface only (also with
    /// `ROS_LOCALHOST_ONLY=1` in the environment).
    pub localhost_only: bool,
    /// The ROS node's name.
    pub node_name: String,
    /// The `geometry_msgs/msg/PoseStamped` topic, one message per tracked frame.
    pub pose_topic: String,
    /// The `nav_msgs/msg/Path` topic: the last `path_max_poses` poses; empty = none.
    pub path_topic: String,
    /// The frame the poses are in (`header.frame_id`).
    pub frame_id: String,
    /// Axes of the published poses.
    pub convention: Convention,
    /// Where header stamps come from.
    pub stamp: StampSource,
    /// The path holds at most this many poses (the newest).
    pub path_max_poses: usize,
    /// Publish the predicted poses of frames where tracking was lost (otherwise only
    /// tracked poses go out).
    pub publish_lost: bool,
    /// The `nav_msgs/msg/Odometry` topic (pose and twist of `child_frame_id` in `frame_id`,
    /// with covariances), one message per published pose; empty = none.
    pub odom_topic: String,
    /// The robot's frame: the odometry's `child_frame_id` and the `/tf` child.
    pub child_frame_id: String,
    /// Also publish `frame_id → child_frame_id` on `/tf` (`tf2_msgs/msg/TFMessage`) at
    /// each published pose.
    pub tf: bool,
    /// The camera's pose in `child_frame_id`.
    pub camera_in_base: CameraMount,
    /// The `diagnostic_msgs/msg/DiagnosticArray` topic: the pipeline's health once a
    /// second (stage latencies and budget misses, drops, matcher mode, tracking); empty =
    /// none.
    pub diagnostics_topic: String,
    /// Before the bridge says it is ready (and the run's frames start), it waits up to this
    /// long for a subscriber on each of the pose, odometry and `/tf` topics it publishes
    /// (they are volatile: a subscriber matched late misses the first poses), then goes
    /// on, warning of the topics without one; 0 = no wait. Keep it under
    /// `supervisor.startup_timeout_ms`.
    pub wait_for_subscribers_ms: u64,
}

/// The longest `wait_for_subscribers_ms` accepted (the supervisor's longest start-up).
const MAX_WAIT_FOR_SUBSCRIBERS_MS: u64 = 600_000;

impl Default for Ros2Config {
    fn default() -> Self {
        Self {
            enabled: false,
            domain_id: None,
            localhost_only: false,
            node_name: "linetrack".to_string(),
            pose_topic: "/linetrack/pose".to_string(),
            path_topic: "/linetrack/path".to_string(),
            frame_id: "odom".to_string(),
            convention: Convention::default(),
            stamp: StampSource::default(),
            path_max_poses: 1000,
            publish_lost: false,
            odom_topic: "/linetrack/odom".to_string(),
            child_frame_id: "base_link".to_string(),
            tf: false,
            camera_in_base: CameraMount::default(),
            diagnostics_topic: "/diagnostics".to_string(),
            wait_for_subscribers_ms: 0,
        }
    }
}

impl Ros2Config {
    /// The first bad key, named with why.
    pub fn validate(&self) -> Result<(), String> {
        if let Some(id) = self.domain_id {
            crate::limits::in_range("ros2.domain_id", id, 0..=MAX_DOMAIN_ID)?;
        }
        crate::limits::in_range(
            "ros2.path_max_poses",
            self.path_max_poses,
            1..=MAX_PATH_POSES,
        )?;
        crate::limits::in_range(
            "ros2.wait_for_subscribers_ms",
            self.wait_for_subscribers_ms,
            0..=MAX_WAIT_FOR_SUBSCRIBERS_MS,
        )?;
        ros_name("ros2.node_name", &self.node_name, false)?;
        ros_name("ros2.pose_topic", &self.pose_topic, true)?;
        if !self.path_topic.is_empty() {
            ros_name("ros2.path_topic", &self.path_topic, true)?;
        }
        if !self.odom_topic.is_empty() {
            ros_name("ros2.odom_topic", &self.odom_topic, true)?;
        }
        if self.child_frame_id.is_empty() || self.child_frame_id == self.frame_id {
            return Err(format!(
                "ros2.child_frame_id = {:?}: name the robot's frame, other than frame_id {:?} \
                 (e.g. \"base_link\")",
                self.child_frame_id, self.frame_id
            ));
        }
        self.camera_in_base.validate()?;
        if !self.diagnostics_topic.is_empty() {
            ros_name("ros2.diagnostics_topic", &self.diagnostics_topic, true)?;
        }
        if self.frame_id.is_empty() {
            return Err(
                "ros2.frame_id is empty: name the frame the poses are in (e.g. \"odom\")"
                    .to_string(),
            );
        }
        Ok(())
    }
}

/// A ROS name: letters, digits and `_`, not starting with a digit; a topic may have `/`
/// between such tokens and one in front.
fn ros_name(key: &str, name: &str, topic: bool) -> Result<(), String> {
    let tokens: Vec<&str> = if topic {
        name.strip_prefix('/').unwrap_or(name).split('/').collect()
    } else {
        vec![name]
    };
    let token_ok = |t: &str| {
        t.chars()
            .next()
            .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
            && t.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
    };
    if tokens.iter().all(|t| token_ok(t)) {
        Ok(())
    } else {
        Err(format!(
            "{key} = {name:?} is not a ROS name: letters, digits and '_', not starting with a digit{}",
            if topic {
                ", tokens separated by '/'"
            } else {
                ""
            }
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_defaults_are_valid_and_bad_names_and_ids_are_refused_by_key() {
        assert_eq!(Ros2Config::default().validate(), Ok(()));
        let bad = |c: Ros2Config| c.validate().err().unwrap_or_default();
        assert!(
            bad(Ros2Config {
                domain_id: Some(233),
                ..Default::default()
            })
            .starts_with("ros2.domain_id = 233")
        );
        assert!(
            bad(Ros2Config {
                pose_topic: "/a//b".into(),
                ..Default::default()
            })
            .starts_with("ros2.pose_topic")
        );
        assert!(
            bad(Ros2Config {
                path_topic: "/1path".into(),
                ..Default::default()
            })
            .starts_with("ros2.path_topic")
        );
        assert!(
            bad(Ros2Config {
                node_name: "a/b".into(),
                ..Default::default()
            })
            .starts_with("ros2.node_name")
        );
        assert!(
            bad(Ros2Config {
                frame_id: String::new(),
                ..Default::default()
            })
            .starts_with("ros2.frame_id")
        );
        assert!(
            bad(Ros2Config {
                path_max_poses: 0,
                ..Default::default()
            })
            .starts_with("ros2.path_max_poses")
        );
        assert!(
            bad(Ros2Config {
                child_frame_id: "odom".into(),
                ..Default::default()
            })
            .starts_with("ros2.child_frame_id")
        );
        assert!(
            bad(Ros2Config {
                odom_topic: "/odom/".into(),
                ..Default::default()
            })
            .starts_with("ros2.odom_topic")
        );
        let mount = |translation_m, rotation_xyzw| Ros2Config {
            camera_in_base: CameraMount {
                translation_m,
                rotation_xyzw,
            },
            ..Default::default()
        };
        assert!(
            bad(mount([0.0; 3], [0.0, 0.0, 0.0, 2.0]))
                .starts_with("ros2.camera_in_base.rotation_xyzw")
        );
        assert!(
            bad(mount([f64::NAN, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]))
                .starts_with("ros2.camera_in_base.translation_m")
        );
        assert_eq!(
            mount([0.1, 0.0, 0.3], [0.0, 0.0, 0.6, 0.8]).validate(),
            Ok(())
        );
        assert_eq!(
            Ros2Config {
                path_topic: String::new(),
                pose_topic: "pose".into(),
                ..Default::default()
            }
            .validate(),
            Ok(())
        );
    }
}
