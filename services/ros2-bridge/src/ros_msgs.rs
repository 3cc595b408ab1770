//! The ROS 2 messages the bridge publishes, field for field as their `.msg` files define
//! them (CDR serialises the fields in this order), and their ROS type names.

use serde::{Deserialize, Serialize};

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Time {
    /// Seconds since the UNIX epoch (or the sequence's zero).
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

impl Time {
    /// The time `ns` nanoseconds after the epoch (seconds saturate at `i32::MAX`, 2038).
    pub fn from_ns(ns: u64) -> Self {
        const NS_PER_S: u64 = 1_000_000_000;
        Self {
            sec: i32::try_from(ns / NS_PER_S).unwrap_or(i32::MAX),
            nanosec: (ns % NS_PER_S) as u32,
        }
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Header {
    /// When the data was taken.
    pub stamp: Time,
    /// The frame the data is in.
    pub frame_id: String,
}

/// `geometry_msgs/msg/Point`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Point {
    /// Metres.
    pub x: f64,
    /// Metres.
    pub y: f64,
    /// Metres.
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// Imaginary i.
    pub x: f64,
    /// Imaginary j.
    pub y: f64,
    /// Imaginary k.
    pub z: f64,
    /// Real part.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Self {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

/// `geometry_msgs/msg/Pose`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose {
    /// Position.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/PoseStamped`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PoseStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The pose.
    pub pose: Pose,
}

/// `nav_msgs/msg/Path`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Path {
    /// Stamp (the newest pose's) and frame.
    pub header: Header,
    /// The poses, oldest first.
    pub poses: Vec<PoseStamped>,
}

/// ROS package and type name of `PoseStamped` (DDS: `geometry_msgs::msg::dds_::PoseStamped_`).
pub const POSE_STAMPED_TYPE: (&str, &str) = ("geometry_msgs", "PoseStamped");
/// ROS package and type name of `Path` (DDS: `nav_msgs::msg::dds_::Path_`).
pub const PATH_TYPE: (&str, &str) = ("nav_msgs", "Path");

#[cfg(feature = "ros2")]
mod message_impls {
    use ros2_client::Message;
    impl Message for super::PoseStamped {}
    impl Message for super::Path {}
}
