//! The OpenCV front end of linetrack: everything that looks at pixels.
//!
//! - [`GrayImage`]: an 8-bit single-channel image that has been checked (decodable, not
//!   empty, one channel, 8 bits); loading names the file in every error.
//! - [`perturb`]: the paper's photometric perturbation `I' = clamp(α·I + β)`.
//! - [`LineDetector`]: LSD (imgproc), FLD (ximgproc) and our own edge-drawing detector
//!   (`linetrack-edge-lines`, no OpenCV) behind one trait, chosen by name at runtime
//!   ([`DetectorKind`]); all keep the N longest segments above a length.
//! - [`SegmentMatcher`]: the appearance baseline LBD (line_descriptor descriptors, mutual
//!   best + ratio test) and the geometric ℓ1 matcher behind one trait ([`MatcherKind`]).
//! - [`PointExtractor`]: the points' extractor chosen by name ([`PointExtractorKind`]):
//!   OpenCV's ORB ([`OrbExtractor`]) or our own oriented FAST corners with a steered binary
//!   descriptor ([`FastBriefExtractor`], `linetrack-corners`, no OpenCV); the same 32-byte
//!   descriptors either way.
//! - [`OrbExtractor`] and [`PointMatcher`]: ORB points matched mutual-best with a
//!   second-best distance ratio ([`HammingMatcher`]), stereo and frame to frame, among the
//!   candidates a grid over the second image's points gives; [`OrbWorker`] finds one
//!   image's points on a thread of its own while the caller works on the other.
//! - [`SideWorker`]: a thread kept for its owner's life, for the right image's side of a
//!   stereo step.
//!
//! The algorithms of `linetrack-l1-matcher` stay free of OpenCV; this crate is where the
//! two meet. Images are not rectified here (the datasets crate does that).
#![warn(missing_docs)]

mod cpu;
mod detect;
mod hamming;
mod image;
mod lbd;
mod matchers;
mod orb;
mod pair;
mod png_gray;
mod worker;

pub use detect::{
    EdgeLinesDetector, FldDetector, LineDetector, LsdDetector, MIN_IMAGE_SIDE_PX, create_detector,
    keep_longest,
};
pub use hamming::{BinaryDescriptors, FeatureMatch, HammingMatcher};
pub use image::{
    BorrowedGray, ChannelOrder, ContrastStretch, GrayImage, MAX_FILE_BYTES, MAX_PIXELS, perturb,
    stretch_contrast, stretch_contrast_into, to_gray8_ordered,
};
pub use lbd::LbdExtractor;
pub use matchers::{
    L1SegmentMatcher, LbdSegmentMatcher, LineFeatures, SegmentMatcher, create_segment_matcher,
};
pub use orb::{
    FastBriefExtractor, MIN_TRACK_CORRELATION, OrbExtractor, OrbWorker, PointExtractor,
    PointFeatures, PointMatcher, RowSearch, RowSearchSettings, points_may_match,
    refine_stereo_column, refine_track,
};
pub use pair::{LinePairMatcher, PairResult, PairTimings};
pub use worker::{SideWorker, copy_image_into};

// The settings, OpenCV-free in their own crate (so that what only reads a configuration
// builds without OpenCV), re-exported where they are run.
pub use linetrack_vision_config::{
    AppearanceGates, DetectorKind, EdgeLinesOptions, FldOptions, FrontendConfig,
    FrontendConfigError, LbdOptions, LineOptions, LsdOptions, LsdRefine, MatcherKind, OrbOptions,
    PointExtractorKind, PointStereo,
};

use std::path::PathBuf;

/// Everything that can go wrong in the front end, each naming its culprit.
#[derive(Debug, thiserror::Error)]
pub enum VisionError {
    /// The image file cannot be read.
    #[error("{path}: cannot read image file: {reason}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        reason: std::io::Error,
    },
    /// The bytes are not an image OpenCV can decode.
    #[error("{origin}: not a decodable image (corrupt, truncated or unsupported format)")]
    Decode {
        /// The file or other origin of the bytes.
        origin: String,
    },
    /// The file or image is too large to read.
    #[error("{origin}: too large to read ({what})")]
    TooLarge {
        /// The file or other origin.
        origin: String,
        /// What is too large.
        what: String,
    },
    /// The image has no pixels.
    #[error("{origin}: image is empty (0 pixels)")]
    Empty {
        /// The file or other origin.
        origin: String,
    },
    /// Not an 8-bit single-channel image.
    #[error(
        "{origin}: expected an 8-bit single-channel (grayscale) image, found {channels} channel(s) of {depth}"
    )]
    Format {
        /// The file or other origin.
        origin: String,
        /// Channels found.
        channels: i32,
        /// Pixel depth found, as OpenCV names it.
        depth: String,
    },
    /// Two images that must have the same size do not.
    #[error(
        "{first} is {first_size:?} (w×h) but {second} is {second_size:?}: the two images must have the same size"
    )]
    SizeMismatch {
        /// The first image.
        first: String,
        /// Its width and height.
        first_size: (i32, i32),
        /// The second image.
        second: String,
        /// Its width and height.
        second_size: (i32, i32),
    },
    /// Raw pixel data does not fit the stated size.
    #[error("{origin}: {len} bytes of pixels for a {width}×{height} image")]
    RawSize {
        /// Origin of the data.
        origin: String,
        /// Bytes given.
        len: usize,
        /// Stated width.
        width: usize,
        /// Stated height.
        height: usize,
    },
    /// The image's pixels could not be handed to the `edgelines` detector.
    #[error("{origin}: edgelines detection")]
    EdgeLines {
        /// The image's origin.
        origin: String,
        /// Why.
        #[source]
        source: linetrack_edge_lines::EdgeLinesError,
    },
    /// The `fast-brief` point extractor's settings are out of range.
    #[error("{origin}: fast-brief points")]
    Corners {
        /// The settings.
        origin: String,
        /// Why.
        #[source]
        source: linetrack_corners::CornersError,
    },
    /// The image's pixels could not be handed to the `fast-brief` point extractor.
    #[error("{origin}: fast-brief points")]
    PointImage {
        /// The image's origin.
        origin: String,
        /// Why.
        #[source]
        source: linetrack_edge_lines::EdgeLinesError,
    },
    /// A gain or bias that is not a finite, usable number.
    #[error("photometric perturbation: {0}")]
    Perturbation(String),
    /// A configuration value or file is unusable.
    #[error("front-end config {origin}: {message}")]
    Config {
        /// The file or "<string>".
        origin: String,
        /// What is wrong, naming the field.
        message: String,
    },
    /// An OpenCV call failed.
    #[error("OpenCV {context}: {reason}")]
    OpenCv {
        /// What was being done.
        context: &'static str,
        /// OpenCV's error.
        reason: opencv::Error,
    },
    /// A worker thread could not start or has stopped.
    #[error("{what}: {reason}")]
    Worker {
        /// Which worker.
        what: &'static str,
        /// Why.
        reason: String,
    },
}

/// Attaches a context to OpenCV errors.
pub(crate) trait OpenCvContext<T> {
    fn context(self, context: &'static str) -> Result<T, VisionError>;
}

impl<T> OpenCvContext<T> for opencv::Result<T> {
    fn context(self, context: &'static str) -> Result<T, VisionError> {
        self.map_err(|reason| VisionError::OpenCv { context, reason })
    }
}
