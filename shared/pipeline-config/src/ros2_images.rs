//! `[camera.ros2_images]`: frames from two ROS 2 image topics (the `linetrack-ros2-source`
//! process of `linetrack-ros2-bridge`, cargo feature `ros2`) in place of a sequence or a
//! camera. The DDS domain and the loopback-only setting are `[ros2]`'s `domain_id` and
//! `localhost_only`.

use serde::{Deserialize, Serialize};

/// The widest stamp tolerance, milliseconds: a second (more pairs images of other frames).
pub const MAX_STAMP_TOLERANCE_MS: f64 = 1000.0;
/// The longest image queue of one side.
const MAX_QUEUE: usize = 100;

/// Two `sensor_msgs/Image` topics and their `sensor_msgs/CameraInfo`: off while `left` is
/// empty.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Ros2ImagesConfig {
    /// The left camera's rectified image topic (`/stereo/left/image_rect`); empty: off.
    pub left: String,
    /// The right camera's rectified image topic.
    pub right: String,
    /// The left `CameraInfo` topic; empty: `camera_info` beside the image topic
    /// (`/stereo/left/camera_info`), as ROS camera drivers name it.
    pub left_info: String,
    /// The right `CameraInfo` topic; empty: beside the right image topic.
    pub right_info: String,
    /// A left and a right image are one frame when their header stamps are this close
    /// (the nearest within it); 0 = only equal stamps.
    pub stamp_tolerance_ms: f64,
    /// Images of one side kept waiting for their partner (or for the `CameraInfo`); an
    /// older one is then counted `capture-dropped`.
    pub queue: usize,
    /// Subscribe best effort (ROS's sensor-data profile, which also receives reliable
    /// publishers); false: reliable, keep-last `queue` (rclcpp's default profile).
    pub best_effort: bool,
}

impl Default for Ros2ImagesConfig {
    fn default() -> Self {
        Self {
            left: String::new(),
            right: String::new(),
            left_info: String::new(),
            right_info: String::new(),
            stamp_tolerance_ms: 0.0,
            queue: 10,
            best_effort: false,
        }
    }
}

/// `camera_info` beside `image_topic`: `/a/b/image_rect` → `/a/b/camera_info`.
fn info_beside(image_topic: &str) -> String {
    match image_topic.trim().rsplit_once('/') {
        Some((namespace, _)) => format!("{namespace}/camera_info"),
        None => "camera_info".to_string(),
    }
}

impl Ros2ImagesConfig {
    /// Whether frames come from ROS 2 topics.
    pub fn enabled(&self) -> bool {
        !self.left.trim().is_empty()
    }

    /// The left `CameraInfo` topic.
    pub fn left_info_topic(&self) -> String {
        if self.left_info.trim().is_empty() {
            info_beside(&self.left)
        } else {
            self.left_info.trim().to_string()
        }
    }

    /// The right `CameraInfo` topic.
    pub fn right_info_topic(&self) -> String {
        if self.right_info.trim().is_empty() {
            info_beside(&self.right)
        } else {
            self.right_info.trim().to_string()
        }
    }

    /// The tolerance in nanoseconds.
    pub fn tolerance_ns(&self) -> u64 {
        (self.stamp_tolerance_ms * 1e6).round() as u64
    }

    /// The first bad value, named (`camera.ros2_images.…`) with why.
    pub fn validate(&self) -> Result<(), String> {
        let key = "camera.ros2_images";
        let right_set = !self.right.trim().is_empty();
        if self.enabled() != right_set {
            return Err(format!(
                "{key}: left = {:?} and right = {:?}: set both image topics or neither",
                self.left, self.right
            ));
        }
        let info_set = !self.left_info.trim().is_empty() || !self.right_info.trim().is_empty();
        if !self.enabled() && info_set {
            return Err(format!(
                "{key}.left_info / right_info are set but no image topics are"
            ));
        }
        if self.enabled() && self.left.trim() == self.right.trim() {
            return Err(format!(
                "{key}: left and right are the same topic {:?}",
                self.left
            ));
        }
        if !(0.0..=MAX_STAMP_TOLERANCE_MS).contains(&self.stamp_tolerance_ms) {
            return Err(format!(
                "{key}.stamp_tolerance_ms = {:?} is out of range: allowed 0.0 ..= {MAX_STAMP_TOLERANCE_MS:?}",
                self.stamp_tolerance_ms
            ));
        }
        if !(1..=MAX_QUEUE).contains(&self.queue) {
            return Err(format!(
                "{key}.queue = {} is out of range: allowed 1 ..= {MAX_QUEUE}",
                self.queue
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn info_topics_default_to_camera_info_beside_the_images() {
        let c = Ros2ImagesConfig {
            left: "/stereo/left/image_rect".into(),
            right: "/stereo/right/image_rect".into(),
            right_info: "/calib/right".into(),
            ..Default::default()
        };
        assert!(c.enabled());
        assert_eq!(c.left_info_topic(), "/stereo/left/camera_info");
        assert_eq!(c.right_info_topic(), "/calib/right");
        assert_eq!(c.validate(), Ok(()));
        assert!(!Ros2ImagesConfig::default().enabled());
    }

    #[test]
    fn the_pipeline_config_reads_it_and_refuses_a_second_source() {
        let read = |text: &str| crate::PipelineConfig::from_toml_str(text, "x.toml");
        let config = read(
            "[camera.ros2_images]\nleft = \"/l/image\"\nright = \"/r/image\"\nstamp_tolerance_ms = 5.0\n",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert!(config.camera.ros2_images.enabled() && !config.camera.enabled());
        assert_eq!(
            config.camera.ros2_images.right_info_topic(),
            "/r/camera_info"
        );
        for (text, says) in [
            (
                "[camera]\ncapture = \"0\"\ncalibration = \"c.yaml\"\n[camera.ros2_images]\nleft = \"/l\"\nright = \"/r\"\n",
                "frames come from one of them",
            ),
            (
                "[source]\nreplay = \"r.mcap\"\n[camera.ros2_images]\nleft = \"/l\"\nright = \"/r\"\n",
                "frames come from one of them",
            ),
            ("[camera.ros2_images]\nleft = \"/l\"\n", "set both"),
            ("[camera.ros2_images]\nleft_topic = \"/l\"\n", "left_topic"),
        ] {
            let err = match read(text) {
                Ok(_) => panic!("accepted {text}"),
                Err(e) => e.to_string(),
            };
            assert!(err.contains(says), "{text}: {err}");
        }
    }

    #[test]
    fn bad_values_are_named() {
        let both = |left: &str, right: &str| Ros2ImagesConfig {
            left: left.into(),
            right: right.into(),
            ..Default::default()
        };
        let err = both("/l", "").validate().unwrap_err();
        assert!(err.contains("set both"), "{err}");
        let err = both("/l", "/l").validate().unwrap_err();
        assert!(err.contains("same topic"), "{err}");
        let err = Ros2ImagesConfig {
            stamp_tolerance_ms: -1.0,
            ..both("/l", "/r")
        }
        .validate()
        .unwrap_err();
        assert!(err.contains("stamp_tolerance_ms"), "{err}");
        let err = Ros2ImagesConfig {
            queue: 0,
            ..both("/l", "/r")
        }
        .validate()
        .unwrap_err();
        assert!(err.contains("queue"), "{err}");
        assert_eq!(
            Ros2ImagesConfig {
                stamp_tolerance_ms: 2.5,
                ..Default::default()
            }
            .tolerance_ns(),
            2_500_000
        );
    }
}
