//! Camera trajectories and how far an estimate is from the truth.
//!
//! - [`tum`]: TUM-format trajectory files (`t tx ty tz qx qy qz qw`), read and written.
//! - [`metrics`]: RPE, ATE (first-pose and SE(3)-aligned), drift, the step ratio (scale
//!   bias) and the zero-motion baseline, gathered in [`metrics::Summary`]: the one set of metric names that
//!   `linetrack-vo` writes to `metrics.json` and `linetrack run` to `summary.json`.
//!
//! No image or dataset code here, so the run records (`linetrack-run-record`) can score a
//! run without pulling in OpenCV.
#![warn(missing_docs)]

pub mod metrics;
pub mod tum;

use std::path::PathBuf;

/// A trajectory file that cannot be read or written, naming the file (and line).
#[derive(Debug, thiserror::Error)]
pub enum TrajectoryError {
    /// The file cannot be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// A line is malformed.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
}
