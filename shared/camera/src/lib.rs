//! A live stereo camera as a source of rectified frames, for the pipeline's frame source.
//!
//! - [`calibration`]: the rig from a calibration file (Kalibr `camchain.yaml`, or EuRoC
//!   `sensor.yaml` pairs through the data set reader);
//! - [`capture`]: a V4L2 device, two devices, a side-by-side device, a GStreamer pipeline
//!   or numbered images through OpenCV `videoio`, read as grey, size-checked and rectified
//!   with maps computed once ([`StereoCamera`]);
//! - [`timing`]: capture timestamps (the driver's, else the monotonic read time), frames
//!   lost in gaps of the driver's timestamps, and late frames (the reconnection backoff is the
//!   stage runtime's `Backoff`).
//!
//! The frame source (`services/frame-source`) runs the capture on its own thread, counts
//! the frames it could not take, and reports a camera that disappears; this crate knows
//! nothing of the pipeline's transport.
#![warn(missing_docs)]

pub mod calibration;
pub mod capture;
pub mod timing;

pub use calibration::{StereoCalibration, read_calibration};
pub use capture::{
    Device, DeviceKind, StereoCamera, StereoImages, rectify_calibration, split_side_by_side,
};
pub use timing::{FrameClock, Stamp};

use std::path::PathBuf;

/// What can go wrong with a camera or its calibration; each names the device or file.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    /// A capture string names nothing this crate can open.
    #[error("capture {spec:?}: {message}")]
    Spec {
        /// The string.
        spec: String,
        /// Why.
        message: String,
    },
    /// A capture could not be opened.
    #[error("cannot open {device}: {reason}")]
    Open {
        /// The device, described.
        device: String,
        /// Why.
        reason: String,
    },
    /// A read failed: the device is gone or the stream ended.
    #[error("{device}: read failed: {reason}")]
    Read {
        /// The device, described.
        device: String,
        /// Why.
        reason: String,
    },
    /// A frame is not the size the calibration is for.
    #[error(
        "{device} delivers {got_width}×{got_height} frames but the calibration needs {expected_width}×{expected_height}{layout}"
    )]
    Size {
        /// The device, described.
        device: String,
        /// The frame's width.
        got_width: i32,
        /// The frame's height.
        got_height: i32,
        /// The width the calibration needs.
        expected_width: i32,
        /// The height the calibration needs.
        expected_height: i32,
        /// How the needed size comes from the calibration (side by side), or empty.
        layout: String,
    },
    /// A frame cannot be split or wrapped.
    #[error("{0}")]
    Layout(String),
    /// A frame cannot be used as an image.
    #[error("frame: {0}")]
    Frame(String),
    /// A calibration file cannot be read.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// A calibration file is malformed or unusable.
    #[error("calibration {}: {message}", path.display())]
    Calibration {
        /// The file or folder.
        path: PathBuf,
        /// What is wrong, naming the key.
        message: String,
    },
    /// The data set reader refused the calibration or an image (EuRoC files, rectification).
    #[error(transparent)]
    Dataset(#[from] linetrack_datasets::DatasetError),
    /// An OpenCV call failed.
    #[error("OpenCV {context}: {reason}")]
    OpenCv {
        /// What was being done.
        context: &'static str,
        /// OpenCV's error.
        reason: opencv::Error,
    },
}
