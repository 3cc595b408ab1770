//! The ROS 2 messages the image source reads, field for field as their `.msg` files define
//! them (CDR deserialises the fields in this order), and their ROS type names.

use crate::ros_msgs::Header;
use serde::{Deserialize, Serialize};

/// `sensor_msgs/msg/Image`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Image {
    /// Capture stamp and camera frame.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding (`mono8`, `rgb8`, `bgr8`, `mono16`, …).
    pub encoding: String,
    /// Whether multi-byte samples are big-endian.
    pub is_bigendian: u8,
    /// Bytes of one row.
    pub step: u32,
    /// `step × height` bytes.
    pub data: Vec<u8>,
}

/// `sensor_msgs/msg/RegionOfInterest`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct RegionOfInterest {
    /// Leftmost pixel.
    pub x_offset: u32,
    /// Topmost pixel.
    pub y_offset: u32,
    /// Rows (0: the whole image).
    pub height: u32,
    /// Columns (0: the whole image).
    pub width: u32,
    /// Whether the region is to be rectified.
    pub do_rectify: bool,
}

/// `sensor_msgs/msg/CameraInfo`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct CameraInfo {
    /// Stamp and camera frame.
    pub header: Header,
    /// Rows of the calibrated images.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// The raw images' distortion model.
    pub distortion_model: String,
    /// Its coefficients.
    pub d: Vec<f64>,
    /// The raw camera's intrinsics, row-major 3×3.
    pub k: [f64; 9],
    /// The rectifying rotation, row-major 3×3.
    pub r: [f64; 9],
    /// The rectified images' projection, row-major 3×4: `[fx' 0 cx' Tx; 0 fy' cy' Ty; 0 0 1 0]`,
    /// `Tx = −fx'·B` for the right camera of a stereo pair.
    pub p: [f64; 12],
    /// Horizontal binning.
    pub binning_x: u32,
    /// Vertical binning.
    pub binning_y: u32,
    /// The region of interest.
    pub roi: RegionOfInterest,
}

/// `sensor_msgs/msg/Image`'s package and name.
pub const IMAGE_TYPE: (&str, &str) = ("sensor_msgs", "Image");
/// `sensor_msgs/msg/CameraInfo`'s package and name.
pub const CAMERA_INFO_TYPE: (&str, &str) = ("sensor_msgs", "CameraInfo");

#[cfg(feature = "ros2")]
mod message_impls {
    use ros2_client::Message;
    impl Message for super::Image {}
    impl Message for super::CameraInfo {}
}
