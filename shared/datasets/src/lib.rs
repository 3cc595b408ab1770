//! Stereo datasets in their native layouts, rectified, as a stream of frames.
//!
//! - [`StereoSequence::open_euroc`]: EuRoC MAV, ASL layout (`mav0/cam0|cam1/data.csv`,
//!   `data/<ns>.png`, `sensor.yaml`; ground truth from `state_groundtruth_estimate0`).
//! - [`StereoSequence::open_kitti`]: KITTI odometry (`image_0|image_1/`, `calib.txt`,
//!   `times.txt`, `poses/NN.txt`).
//! - [`StereoSequence::open_kitti_raw`]: KITTI raw, one synchronised drive
//!   (`<date>/<drive>_sync/image_00|image_01/`, `timestamps.txt`, calibration files in
//!   `<date>/`; ground truth converted from the OXTS GPS/IMU fixes in `oxts/`).
//! - [`list_middlebury`]: Middlebury stereo pairs with ground-truth disparity (single
//!   rectified pairs, no sequence), for scoring stereo matching on real images.
//!
//! Unrectified rigs are rectified once from the calibration ([`Rectifier`]); every frame is
//! then remapped with precomputed maps. Ground truth is given as the pose of the
//! *rectified left camera* in the dataset's world frame, so it matches what the rest of
//! the system measures. [`StereoSequence::into_stream`] reads frames ahead on a thread so
//! loading stays off the critical path; a frame that cannot be loaded comes out as a
//! [`FrameError`] and the stream goes on.
//!
//! Malformed files are refused with the file and line at fault.
#![warn(missing_docs)]

mod calib;
pub mod depth;
mod euroc;
mod kitti;
mod kitti_raw;
mod middlebury;
mod sequence;
mod writer;

pub use calib::{PinholeCamera, Rectifier};
pub use euroc::read_euroc_camera;
pub use kitti::read_kitti_poses;
pub use middlebury::{
    DisparityMap, LoadedPair, MiddleburyPair, list_middlebury, select_middlebury,
};
pub use sequence::{
    FrameEntry, FrameError, Next, StereoFrame, StereoSequence, StereoStream,
    opencv_on_calling_threads,
};
pub use writer::EurocWriter;

use std::path::PathBuf;

/// What can be wrong with a dataset, naming the file (and line) at fault.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// A file or folder cannot be read.
    #[error("{path}: {reason}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The operating system's reason.
        reason: std::io::Error,
    },
    /// A line of a text file is malformed.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number (0: the file as a whole).
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// The calibration cannot be used.
    #[error("calibration: {0}")]
    Calibration(String),
    /// An image cannot be used.
    #[error(transparent)]
    Image(#[from] linetrack_vision::VisionError),
    /// An OpenCV call failed.
    #[error("OpenCV {context}: {reason}")]
    OpenCv {
        /// What was being done.
        context: &'static str,
        /// OpenCV's error.
        reason: opencv::Error,
    },
}

pub(crate) fn read_text(path: &std::path::Path) -> Result<String, DatasetError> {
    std::fs::read_to_string(path).map_err(|reason| DatasetError::Io {
        path: path.to_path_buf(),
        reason,
    })
}

pub(crate) fn parse_error(
    path: &std::path::Path,
    line: usize,
    message: impl Into<String>,
) -> DatasetError {
    DatasetError::Parse {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}
