//! PL-StVO over a stream of rectified stereo frames.
//!
//! [`Odometry`] per frame: dark images are stretched to the full grey range (a bounded
//! gain), ORB points and line segments (LSD, FLD or edgelines) are detected in both images and matched
//! stereo (segments with LBD or the ℓ1 matcher) and triangulated — point matches refined to
//! a fraction of a pixel, segments with look-alike partners (repetitive structure) left
//! out; the left image's features are matched to the previous frame's (points around where
//! the last motion puts them, segments kept only near the line it predicts). A tracked
//! feature is a landmark whose world position is fused over its stereo sightings (a
//! sighting whose disparity disagrees starts it over); each landmark seen again becomes an
//! observation, and the motion is estimated by `linetrack-stereo-vo` (a RANSAC start, then
//! Gauss–Newton on SE(3) in two passes). A frame with too few inliers, an ill-conditioned
//! problem or an estimate far from the prediction is reported as lost: its pose repeats
//! the last good motion, and its own triangulations start the landmarks afresh.
//!
//! The back end alone, [`MotionTracker`], takes segments matched elsewhere (the pipeline's
//! matcher stage) and does the rest. [`metrics`] (from `linetrack-trajectory`) scores
//! trajectories. Each tracked frame's result carries the covariance of its motion
//! ([`FrameResult::step_covariance`]); [`PoseCovariance`] chains them into the pose's.
#![warn(missing_docs)]

mod disparity_offset;
mod front_end;
mod landmarks;
mod pose_covariance;
mod stats;
mod tracker;

pub use front_end::{Odometry, SegmentTracking, rescue_matcher};
// The settings, OpenCV-free in their own crate, re-exported where they are run.
pub use linetrack_odometry_config::{
    Features, LinePrediction, LostLimits, OdometryConfig, PredictedNarrowing, StereoPhotometric,
};
pub use linetrack_stereo_vo::nees;
pub use linetrack_trajectory::metrics;
pub use pose_covariance::PoseCovariance;
pub use stats::{FrameResult, FrameStats, LostKind};
pub use tracker::{
    MatchedLines, MotionTracker, Preparation, PreparedImages, SightingKind, StereoSighting,
};

use linetrack_vision::VisionError;

/// Errors that stop the odometry (bad configuration; per-frame problems are `lost`).
#[derive(Debug, thiserror::Error)]
pub enum OdometryError {
    /// The front end could not be built or failed on an image.
    #[error(transparent)]
    Vision(#[from] VisionError),
}
