//! A robust start for Gauss–Newton: RANSAC over minimal sets of observations.
//!
//! Gauss–Newton with a pseudo-Huber loss copes with scattered outliers but not with a
//! *consistent* group of them — mismatches one stripe off on a repetitive texture all agree
//! with each other and pull the estimate to a wrong motion with small residuals. Here a
//! hypothesis is fitted to three observations (points or lines alike: two residual rows
//! each, six for the six unknowns) by a few Gauss–Newton steps from the prediction, and
//! scored on every observation with the MSAC cost `Σ min(‖r‖², τ²)`; the prediction itself is
//! a hypothesis too. The best one and its inliers (`‖r‖ ≤ τ`) start the refinement. The
//! number of draws adapts to the inlier ratio found so far (99 % confidence of one clean
//! draw), up to a cap; draws come from a seeded generator, so a run is reproducible.

use crate::observation::{
    LineObservation, PointObservation, apply_update, line_residual, point_residual,
};
use linetrack_geometry::StereoRig;
use nalgebra::{Isometry3, Matrix6, SMatrix, Vector2, Vector6};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Residual rows and Jacobian of observation `k`: points first, then lines.
pub(crate) fn residual(
    rig: &StereoRig,
    t: &Isometry3<f64>,
    points: &[PointObservation],
    lines: &[LineObservation],
    k: usize,
) -> Option<(Vector2<f64>, SMatrix<f64, 2, 6>)> {
    match points.get(k) {
        Some(p) => point_residual(rig, t, p),
        None => line_residual(rig, t, lines.get(k - points.len())?),
    }
}

/// Squared residual norm of observation `k` scaled by its weight (residuals in units of
/// their expected noise); infinite when it cannot be projected.
pub(crate) fn weighted_error2(
    rig: &StereoRig,
    t: &Isometry3<f64>,
    points: &[PointObservation],
    lines: &[LineObservation],
    k: usize,
) -> f64 {
    let weight = match points.get(k) {
        Some(p) => p.weight,
        None => lines.get(k - points.len()).map_or(0.0, |l| l.weight),
    };
    residual(rig, t, points, lines, k).map_or(f64::INFINITY, |(r, _)| weight * r.norm_squared())
}

/// Gauss–Newton on exactly the observations `set`, unweighted, from `t`; `None` when they
/// do not constrain the motion or a point falls behind the camera.
fn fit_minimal(
    rig: &StereoRig,
    points: &[PointObservation],
    lines: &[LineObservation],
    set: &[usize],
    mut t: Isometry3<f64>,
) -> Option<Isometry3<f64>> {
    const ITERATIONS: usize = 8;
    for _ in 0..ITERATIONS {
        let mut h = Matrix6::zeros();
        let mut g = Vector6::zeros();
        for &k in set {
            let (r, j) = residual(rig, &t, points, lines, k)?;
            h += j.transpose() * j;
            g += j.transpose() * r;
        }
        // A touch of damping keeps a nearly singular set from producing a huge step.
        let damping = 1e-6 * h.diagonal().max();
        let step = (h + Matrix6::identity() * damping).cholesky()?.solve(&g) * -1.0;
        if !step.iter().all(|v| v.is_finite()) {
            return None;
        }
        t = apply_update(&step, t);
        if step.norm() < 1e-7 {
            break;
        }
    }
    Some(t)
}

/// The MSAC cost of `t` over all observations and the number of inliers.
fn score(
    rig: &StereoRig,
    points: &[PointObservation],
    lines: &[LineObservation],
    t: &Isometry3<f64>,
    threshold_px: f64,
) -> (f64, usize) {
    let tau2 = threshold_px * threshold_px;
    let mut cost = 0.0;
    let mut inliers = 0;
    for k in 0..points.len() + lines.len() {
        let e2 = weighted_error2(rig, t, points, lines, k);
        if e2 <= tau2 {
            inliers += 1;
            cost += e2;
        } else {
            cost += tau2;
        }
    }
    (cost, inliers)
}

/// Observations in a minimal set.
const SET: usize = 3;

/// Draws needed for a 99 % chance that one minimal set is all inliers, at the inlier ratio
/// `inliers / n`; at most `max_draws`.
fn draws_needed(inliers: usize, n: usize, max_draws: usize) -> usize {
    const CONFIDENCE: f64 = 0.99;
    let clean = (inliers as f64 / n.max(1) as f64).powi(SET as i32);
    if clean >= 1.0 - 1e-12 {
        1
    } else if clean <= 1e-12 {
        max_draws
    } else {
        (((1.0 - CONFIDENCE).ln() / (1.0 - clean).ln()).ceil() as usize).min(max_draws)
    }
}

/// What the robust start found.
#[derive(Debug, Clone, PartialEq)]
pub struct RobustStart {
    /// The best hypothesis.
    pub motion: Isometry3<f64>,
    /// Inlier flags, points first then lines.
    pub inliers: Vec<bool>,
    /// Minimal sets drawn.
    pub draws: usize,
}

/// The best motion hypothesis for the observations, starting each minimal fit from
/// `prediction`; at most `max_draws` minimal sets, inliers within `threshold_px`.
pub fn robust_start(
    rig: &StereoRig,
    points: &[PointObservation],
    lines: &[LineObservation],
    prediction: &Isometry3<f64>,
    max_draws: usize,
    threshold_px: f64,
) -> RobustStart {
    let n = points.len() + lines.len();
    let mut rng = ChaCha8Rng::seed_from_u64(0x005e_ed0f_1a7e);
    let (mut best_cost, inliers) = score(rig, points, lines, prediction, threshold_px);
    let mut best = *prediction;
    let mut needed = draws_needed(inliers, n, max_draws);
    let mut draws = 0;
    while n >= SET && draws < needed.min(max_draws) {
        draws += 1;
        let mut set = [0usize; SET];
        for i in 0..SET {
            set[i] = loop {
                let k = rng.random_range(0..n);
                if !set[..i].contains(&k) {
                    break k;
                }
            };
        }
        let Some(hypothesis) = fit_minimal(rig, points, lines, &set, *prediction) else {
            continue;
        };
        let (cost, inliers) = score(rig, points, lines, &hypothesis, threshold_px);
        if cost < best_cost {
            (best_cost, best) = (cost, hypothesis);
            needed = draws_needed(inliers, n, max_draws);
        }
    }
    let tau2 = threshold_px * threshold_px;
    let inliers = (0..n)
        .map(|k| weighted_error2(rig, &best, points, lines, k) <= tau2)
        .collect();
    RobustStart {
        motion: best,
        inliers,
        draws,
    }
}
