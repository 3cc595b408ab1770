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
}

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
        }
    }
}

impl Ros2Config {
    /// The first bad key, named with why.
    pub fn validate(&self) -> Result<(), String> {
        if let Some(id) = self.domain_id {
            crate::in_range("ros2.domain_id", id, 0..=MAX_DOMAIN_ID)?;
        }
        crate::in_range(
            "ros2.path_max_poses",
            self.path_max_poses,
            1..=MAX_PATH_POSES,
        )?;
        ros_name("ros2.node_name", &self.node_name, false)?;
        ros_name("ros2.pose_topic", &self.pose_topic, true)?;
        if !self.path_topic.is_empty() {
            ros_name("ros2.path_topic", &self.path_topic, true)?;
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
