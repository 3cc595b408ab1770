//! Stereo visual odometry with points and line segments (PL-StVO, Gomez-Ojeda et al.): the
//! geometry half. Stereo matches are triangulated in the rectified rig ([`triangulate`]);
//! the motion between consecutive frames is estimated by Gauss–Newton on SE(3) from
//! point reprojection errors and endpoint-to-line distances ([`motion`]), started from the
//! best of RANSAC's minimal-set hypotheses ([`robust`]), with the covariance of the estimate
//! ([`MotionEstimate::covariance`], checked against the truth with [`nees`]).
//!
//! Feature detection and matching live in `linetrack-vision`; this crate only sees 2-D
//! observations and 3-D positions, so it runs (and is tested) without OpenCV.
#![warn(missing_docs)]

pub mod motion;
pub mod nees;
pub mod observation;
pub mod robust;
pub mod triangulate;

pub use motion::{
    MotionConfig, MotionError, MotionEstimate, OffsetEvidence, estimate_motion,
    estimate_motion_near,
};
pub use observation::{LineObservation, PointObservation};
pub use triangulate::{Triangulated, TriangulationLimits, triangulate_point, triangulate_segment};

/// Weight of an observation triangulated from disparity `d` pixels: `d² / (d² + d_ref²)`
/// with `d_ref` = 4 px. Depth uncertainty grows as 1/d², so far points (small disparity)
/// count less; near ones count fully.
pub fn disparity_weight(disparity_px: f64) -> f64 {
    const REFERENCE_DISPARITY_PX: f64 = 4.0;
    let d2 = disparity_px * disparity_px;
    d2 / (d2 + REFERENCE_DISPARITY_PX * REFERENCE_DISPARITY_PX)
}

#[cfg(test)]
mod tests;
