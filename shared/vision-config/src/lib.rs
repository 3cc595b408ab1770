//! What the front end is told, without OpenCV: the line detector and segment matcher by
//! name ([`DetectorKind`], [`MatcherKind`]), each detector's and descriptor's options
//! ([`FrontendConfig`], read from `configs/frontend.toml`), the ORB points' options and
//! extractor, and the gates of appearance matching.
//!
//! `linetrack-vision` runs these settings (and re-exports every type here); this crate
//! holds them apart so that what only reads a configuration (`linetrack-pipeline-config`,
//! and through it the link and the ROS 2 bridge) builds without OpenCV.
#![warn(missing_docs)]

mod frontend;
mod kinds;

pub use frontend::{
    AppearanceGates, FldOptions, FrontendConfig, LbdOptions, LsdOptions, LsdRefine, OrbOptions,
    PointExtractorKind, PointStereo,
};
pub use kinds::{DetectorKind, MatcherKind};
pub use linetrack_frontend_core::{EdgeLinesOptions, LineOptions};

/// A front-end configuration that cannot be used: unreadable, malformed or out of range.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("front-end config {origin}: {message}")]
pub struct FrontendConfigError {
    /// The file or "<string>".
    pub origin: String,
    /// What is wrong, naming the field.
    pub message: String,
}
