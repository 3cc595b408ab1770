//! Trajectory error metrics, defined as in the TUM RGB-D benchmark tools so they can be
//! checked with other tools:
//!
//! - **RPE** (relative pose error), translational RMSE over pose pairs `step` frames apart:
//!   `E_i = (Q_i⁻¹ Q_{i+step})⁻¹ (P_i⁻¹ P_{i+step})`, RMSE of ‖trans(E_i)‖, metres.
//! - **ATE** (absolute trajectory error) after aligning both trajectories at their first
//!   pose (no scale, no least-squares alignment: odometry starts where the truth starts):
//!   RMSE of ‖trans(Q₀⁻¹ Q_i) − trans(P₀⁻¹ P_i)‖, metres.
//! - **Drift per metre**: final position error (first-pose aligned) over the length of the
//!   true path, percent.
//!
//! `P` is the estimate, `Q` the ground truth, both camera poses in their worlds.

use nalgebra::Isometry3;

/// Translational RPE RMSE over pairs `step` frames apart; `None` without such pairs.
pub fn rpe_translation_rmse(
    estimate: &[Isometry3<f64>],
    truth: &[Isometry3<f64>],
    step: usize,
) -> Option<f64> {
    let n = estimate.len().min(truth.len());
    if step == 0 || n <= step {
        return None;
    }
    let sum: f64 = (0..n - step)
        .map(|i| {
            let q = truth[i].inverse() * truth[i + step];
            let p = estimate[i].inverse() * estimate[i + step];
            (q.inverse() * p).translation.vector.norm_squared()
        })
        .sum();
    Some((sum / (n - step) as f64).sqrt())
}

/// ATE RMSE with both trajectories aligned at their first pose.
pub fn ate_rmse(estimate: &[Isometry3<f64>], truth: &[Isometry3<f64>]) -> Option<f64> {
    let n = estimate.len().min(truth.len());
    if n == 0 {
        return None;
    }
    let sum: f64 = (0..n)
        .map(|i| {
            let q = (truth[0].inverse() * truth[i]).translation.vector;
            let p = (estimate[0].inverse() * estimate[i]).translation.vector;
            (q - p).norm_squared()
        })
        .sum();
    Some((sum / n as f64).sqrt())
}

/// Final position error over true path length, percent; `None` for a path under 1 cm.
pub fn drift_percent(estimate: &[Isometry3<f64>], truth: &[Isometry3<f64>]) -> Option<f64> {
    let n = estimate.len().min(truth.len());
    let path: f64 = truth[..n]
        .windows(2)
        .map(|w| (w[1].translation.vector - w[0].translation.vector).norm())
        .sum();
    if n < 2 || path < 0.01 {
        return None;
    }
    let q = (truth[0].inverse() * truth[n - 1]).translation.vector;
    let p = (estimate[0].inverse() * estimate[n - 1]).translation.vector;
    Some(100.0 * (q - p).norm() / path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn walk(step: [f64; 3], turn: f64, n: usize) -> Vec<Isometry3<f64>> {
        let delta = Isometry3::from_parts(
            Translation3::new(step[0], step[1], step[2]),
            UnitQuaternion::from_euler_angles(0.0, turn, 0.0),
        );
        (0..n)
            .scan(Isometry3::identity(), |pose, _| {
                let current = *pose;
                *pose *= delta;
                Some(current)
            })
            .collect()
    }

    #[test]
    fn identical_trajectories_have_no_error_in_any_world_frame() {
        let truth = walk([0.1, 0.0, 0.05], 0.02, 30);
        let offset = Isometry3::from_parts(
            Translation3::new(5.0, -2.0, 1.0),
            UnitQuaternion::from_euler_angles(0.3, 0.1, -0.7),
        );
        let estimate: Vec<_> = truth.iter().map(|p| offset * p).collect();
        assert!(rpe_translation_rmse(&estimate, &truth, 1).unwrap() < 1e-12);
        assert!(ate_rmse(&estimate, &truth).unwrap() < 1e-12);
        assert!(drift_percent(&estimate, &truth).unwrap() < 1e-9);
    }

    #[test]
    fn a_constant_step_error_shows_in_each_metric() {
        // Truth moves 10 cm a frame, the estimate 11 cm: RPE 1 cm, drift 10 %.
        let truth = walk([0.1, 0.0, 0.0], 0.0, 11);
        let estimate = walk([0.11, 0.0, 0.0], 0.0, 11);
        assert!((rpe_translation_rmse(&estimate, &truth, 1).unwrap() - 0.01).abs() < 1e-12);
        assert!((drift_percent(&estimate, &truth).unwrap() - 10.0).abs() < 1e-9);
        // ATE: errors 0, 1, …, 10 cm → RMSE sqrt(Σk²/11) cm.
        let expected = ((0..11).map(|k| (0.01 * k as f64).powi(2)).sum::<f64>() / 11.0).sqrt();
        assert!((ate_rmse(&estimate, &truth).unwrap() - expected).abs() < 1e-12);
        assert!(rpe_translation_rmse(&estimate, &truth, 20).is_none());
    }
}
