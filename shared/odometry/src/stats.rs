//! What tracking a frame gives back: its pose, whether it was lost, and its
//! [`FrameStats`] (feature counts, the estimate's figures, the milliseconds of each step).

use nalgebra::{Isometry3, Matrix6};
use serde::Serialize;
use std::time::Instant;

/// What happened in one frame.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct FrameStats {
    /// Points detected left / right.
    pub points: [usize; 2],
    /// Segments detected left / right.
    pub segments: [usize; 2],
    /// Stereo matches triangulated: points, segments.
    pub triangulated: [usize; 2],
    /// Frame-to-frame observations used: points, segments.
    pub observations: [usize; 2],
    /// Inliers after the second pass: points, segments.
    pub inliers: [usize; 2],
    /// Gauss–Newton iterations.
    pub iterations: usize,
    /// Final RMS residual of the inliers, pixels.
    pub rms_px: f64,
    /// Conditioning of the final normal matrix (smallest over largest eigenvalue).
    pub conditioning: f64,
    /// How far the estimate departs from the prediction (the last motion): translation,
    /// metres, and rotation, degrees.
    pub departure: [f64; 2],
    /// Whether the frame would have been lost and `lost.rescue_window_px` or
    /// `lost.rescue_min_inliers` rescued it (lines only).
    pub rescued: bool,
    /// The disparity offset subtracted before this frame's features were triangulated,
    /// pixels (`[disparity_offset]`: given, or estimated over the frames so far).
    pub disparity_offset_px: f64,
    /// The offset's running estimate after this frame, applied or not, pixels.
    pub disparity_offset_estimate_px: f64,
    /// Milliseconds detecting: the images stretched, their corners found (less the point
    /// work done ahead, counted in `stereo_ms` and `frame_to_frame_ms`) and, by
    /// [`Odometry`](crate::Odometry), their segments.
    pub detect_ms: f64,
    /// Milliseconds describing the segments, by [`Odometry`](crate::Odometry) (segments
    /// matched elsewhere: what the caller's stats held).
    pub describe_ms: f64,
    /// Milliseconds of stereo matching and triangulation, points and segments.
    pub stereo_ms: f64,
    /// Milliseconds of frame-to-frame matching (points and segments) and observing the
    /// previous frame's landmarks.
    pub frame_to_frame_ms: f64,
    /// Milliseconds estimating the motion.
    pub motion_ms: f64,
}

/// The result of one frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameResult {
    /// Pose of the left camera in the world of the first frame.
    #[serde(skip)]
    pub pose: Isometry3<f64>,
    /// Whether tracking was lost in this frame (the pose is then a prediction).
    pub lost: bool,
    /// Why, when lost.
    pub reason: Option<String>,
    /// Which kind of reason, when lost.
    #[serde(skip)]
    pub lost_kind: Option<LostKind>,
    /// Counts and timings.
    pub stats: FrameStats,
    /// Covariance of this frame's motion estimate (see
    /// `linetrack_stereo_vo::MotionEstimate::covariance`: the left-multiplied error of
    /// `p_curr = motion · p_prev`, translation metres then rotation radians, in the current
    /// left camera frame); `None` when the frame was lost or not tracked against a previous
    /// one.
    #[serde(skip)]
    pub step_covariance: Option<Matrix6<f64>>,
}

/// Why a frame was lost.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LostKind {
    /// Too few observations agreed with the estimate.
    TooFewInliers,
    /// The observations left the motion undetermined (ill-conditioned).
    Degenerate,
    /// The estimate departed from the prediction by more than `[lost]` allows.
    Departed,
}

impl LostKind {
    /// Every kind.
    pub const ALL: [Self; 3] = [Self::TooFewInliers, Self::Degenerate, Self::Departed];

    /// Its name in records: `too-few-inliers`, `degenerate`, `departed`.
    pub fn name(self) -> &'static str {
        match self {
            Self::TooFewInliers => "too-few-inliers",
            Self::Degenerate => "degenerate",
            Self::Departed => "departed",
        }
    }
}

/// Milliseconds since `start`.
pub(crate) fn since(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}
