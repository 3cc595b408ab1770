//! Before a camera run starts: the calibration must be readable and rectifiable, the
//! capture strings must name something, and a camera that opens must deliver frames of the
//! calibration's size (refused before any stage starts, naming both sizes). A camera that
//! does not open now is only warned about: the frame source keeps reopening it, so a rig
//! whose camera appears after the pipeline (boot order, a replugged cable) still runs.

use anyhow::Context;
use linetrack_camera::{CameraError, Device, StereoCamera};
use linetrack_pipeline_config::CameraConfig;
use std::sync::Arc;

/// The camera's capture(s), described for events and messages.
pub fn describe(camera: &CameraConfig) -> String {
    let one = |spec: &str| {
        Device::parse(spec).map_or_else(|_| format!("{spec:?}"), |kind| kind.describe())
    };
    match camera.right() {
        None => format!("camera {} (side by side)", one(&camera.capture)),
        Some(right) => format!("cameras {} and {}", one(&camera.capture), one(right)),
    }
}

/// Checks the calibration and, when the camera opens, one frame's size.
pub fn preflight(camera: &CameraConfig) -> anyhow::Result<()> {
    let calibration = linetrack_camera::read_calibration(&camera.calibration)
        .with_context(|| "camera.calibration (--calibration)".to_string())?;
    let (rectifier, rig) = linetrack_camera::rectify_calibration(&calibration)
        .with_context(|| format!("camera.calibration {}", camera.calibration.display()))?;
    Device::parse(&camera.capture).context("camera.capture (--camera)")?;
    if let Some(right) = camera.right() {
        Device::parse(right).context("camera.capture_right (--camera-right)")?;
    }
    let checked = StereoCamera::open(&camera.capture, camera.right(), Arc::new(rectifier))
        .and_then(|mut c| c.read().map(|_| ()));
    match checked {
        Ok(()) => {
            tracing::info!(
                "{}: {}×{} frames, rig focal {:.1} px, baseline {:.4} m",
                describe(camera),
                rig.width_px,
                rig.height_px,
                rig.focal_px,
                rig.baseline_m
            );
            Ok(())
        }
        Err(e @ (CameraError::Size { .. } | CameraError::Layout(_))) => {
            Err(anyhow::anyhow!("{e} ({})", camera.calibration.display()))
        }
        Err(e) => {
            tracing::warn!("{e}: the frame source will keep trying to open it");
            Ok(())
        }
    }
}
