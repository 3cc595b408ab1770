//! `[camera]`: a live stereo camera in place of the sequence.

use crate::Ros2ImagesConfig;
use crate::limits::{BUDGET_MS, MAX_DURATION_S, MAX_WAIT_MS, RATE_HZ, in_range};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// A live stereo camera in place of the sequence (`[camera]`): off while `capture` is empty.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraConfig {
    /// The capture: a V4L2 device (`0`, `/dev/video0`), a GStreamer pipeline ending in
    /// `appsink`, or a numbered image pattern (`dir/%06d.png`). Side by side (left half,
    /// right half) unless `capture_right` is set, then the left camera. Empty: no camera.
    pub capture: String,
    /// The right camera's capture when the two are separate devices; empty: side by side.
    pub capture_right: String,
    /// Kalibr `camchain.yaml`, or a folder with EuRoC `cam0/sensor.yaml` and `cam1/sensor.yaml`.
    pub calibration: PathBuf,
    /// Frames per second the camera delivers, to count frames lost in gaps of the driver's
    /// timestamps; 0 = the rate the driver announces (no count when it announces none).
    pub fps: f64,
    /// A frame read more than this long after it could have been (it waited in a buffer)
    /// is late: with `budget.drop_late` it is dropped as `capture-late`.
    pub late_ms: f64,
    /// Stop after this many seconds; 0 = until stopped (Ctrl-C, `source.max_frames`).
    pub duration_s: f64,
    /// A camera that fails is reopened after this long, doubling per failure ...
    pub retry_ms: u64,
    /// ... up to this.
    pub retry_max_ms: u64,
    /// Frames from two ROS 2 image topics instead (`[camera.ros2_images]`, needs the
    /// `linetrack-ros2-source` binary: cargo feature `linetrack-ros2-bridge/ros2`); off
    /// while its `left` is empty. `duration_s` applies to it too.
    pub ros2_images: Ros2ImagesConfig,
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            capture: String::new(),
            capture_right: String::new(),
            calibration: PathBuf::new(),
            fps: 0.0,
            late_ms: 100.0,
            duration_s: 0.0,
            retry_ms: 500,
            retry_max_ms: 5000,
            ros2_images: Ros2ImagesConfig::default(),
        }
    }
}

impl CameraConfig {
    /// Whether a camera replaces the sequence.
    pub fn enabled(&self) -> bool {
        !self.capture.trim().is_empty()
    }

    /// The right camera's capture, when separate.
    pub fn right(&self) -> Option<&str> {
        let right = self.capture_right.trim();
        (!right.is_empty()).then_some(right)
    }
}

impl CameraConfig {
    /// The first out-of-range key of `[camera]`, or a capture without its calibration.
    pub fn validate(&self) -> Result<(), String> {
        if self.fps != 0.0 {
            in_range("camera.fps", self.fps, RATE_HZ)
                .map_err(|e| format!("{e} (or 0 = the driver's rate)"))?;
        }
        in_range("camera.late_ms", self.late_ms, BUDGET_MS)?;
        in_range("camera.duration_s", self.duration_s, 0.0..=MAX_DURATION_S)?;
        in_range("camera.retry_ms", self.retry_ms, 1..=MAX_WAIT_MS)?;
        in_range(
            "camera.retry_max_ms",
            self.retry_max_ms,
            self.retry_ms..=MAX_WAIT_MS,
        )
        .map_err(|e| format!("{e}: at least retry_ms"))?;
        if self.enabled() && self.calibration.as_os_str().is_empty() {
            return Err(
                "camera.capture is set but camera.calibration is empty: the rig comes from a calibration file (Kalibr camchain.yaml or a folder of EuRoC sensor.yaml)"
                    .to_string(),
            );
        }
        if !self.enabled() && self.right().is_some() {
            return Err("camera.capture_right is set but camera.capture is empty".to_string());
        }
        self.ros2_images.validate()?;
        if self.ros2_images.enabled() && self.enabled() {
            return Err(
                "camera.ros2_images is set with camera.capture: frames come from one of them"
                    .to_string(),
            );
        }
        Ok(())
    }
}
