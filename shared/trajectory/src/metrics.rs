//! Trajectory error metrics, defined as in the TUM RGB-D benchmark tools so they can be
//! checked with other tools:
//!
//! - **RPE** (relative pose error), translational RMSE over pose pairs `step` frames apart:
//!   `E_i = (Q_i⁻¹ Q_{i+step})⁻¹ (P_i⁻¹ P_{i+step})`, RMSE of ‖trans(E_i)‖, metres.
//! - **ATE** (absolute trajectory error) after aligning both trajectories at their first
//!   pose (no scale, no least-squares alignment: odometry starts where the truth starts):
//!   RMSE of ‖trans(Q₀⁻¹ Q_i) − trans(P₀⁻¹ P_i)‖, metres.
//! - **ATE, SE(3)-aligned** (evo's `-a`): the estimate's positions rigidly moved (rotation
//!   and translation, no scale) to fit the truth's in least squares (Horn / Umeyama), then
//!   the RMSE of the position differences.
//! - **Drift per metre**: final position error (first-pose aligned) over the length of the
//!   true path, percent; not given for a path under 1 m, where it means nothing.
//! - [`Summary`] gathers them with the zero-motion baseline (the ATE of a trajectory that
//!   never moves), which a parked-vehicle excerpt needs: there, "no motion" can beat any
//!   estimator.
//!
//! `P` is the estimate, `Q` the ground truth, both camera poses in their worlds. Two
//! trajectories with timestamps are paired pose by pose with [`Summary::of_stamped`].
//!
//! [`Summary`]'s field names ([`METRIC_NAMES`]) are what `metrics.json` (`linetrack-vo`) and
//! `summary.json` (`linetrack run`, under `metrics`) call the metrics.

use crate::tum::StampedPose;
use nalgebra::{Isometry3, Matrix3, Vector3};

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

/// Paths shorter than this get no drift figure, metres.
pub const MIN_DRIFT_PATH_M: f64 = 1.0;

/// ATE RMSE after the best rigid alignment (rotation and translation, no scale) of the
/// estimate's positions to the truth's; `None` with fewer than 3 poses.
pub fn ate_rmse_aligned(estimate: &[Isometry3<f64>], truth: &[Isometry3<f64>]) -> Option<f64> {
    let n = estimate.len().min(truth.len());
    if n < 3 {
        return None;
    }
    let p: Vec<Vector3<f64>> = estimate[..n].iter().map(|x| x.translation.vector).collect();
    let q: Vec<Vector3<f64>> = truth[..n].iter().map(|x| x.translation.vector).collect();
    let mean = |v: &[Vector3<f64>]| v.iter().sum::<Vector3<f64>>() / n as f64;
    let (p_mean, q_mean) = (mean(&p), mean(&q));
    let cross: Matrix3<f64> = p
        .iter()
        .zip(&q)
        .map(|(a, b)| (b - q_mean) * (a - p_mean).transpose())
        .sum();
    let svd = cross.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut flip = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        flip[(2, 2)] = -1.0;
    }
    let rotation = u * flip * v_t;
    let sum: f64 = p
        .iter()
        .zip(&q)
        .map(|(a, b)| (rotation * (a - p_mean) + q_mean - b).norm_squared())
        .sum();
    Some((sum / n as f64).sqrt())
}

/// Length of the true path, metres.
pub fn path_length(truth: &[Isometry3<f64>]) -> f64 {
    truth
        .windows(2)
        .map(|w| (w[1].translation.vector - w[0].translation.vector).norm())
        .sum()
}

/// The names of [`Summary`]'s fields as written to JSON, in order.
pub const METRIC_NAMES: [&str; 7] = [
    "poses",
    "path_m",
    "rpe_m",
    "ate_m",
    "ate_aligned_m",
    "drift_percent",
    "zero_motion_ate_m",
];

/// An estimated pose is compared with the true pose stamped within this of it, seconds
/// (well under any camera's frame period; TUM files keep the stamps to the nanosecond, the
/// f64 seconds of a Unix-epoch stamp to about a quarter of a microsecond).
pub const PAIRING_TOLERANCE_S: f64 = 1e-3;

/// Every metric of one run against its ground truth.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Summary {
    /// Poses compared.
    pub poses: usize,
    /// Length of the true path, metres.
    pub path_m: f64,
    /// Translational RPE RMSE over consecutive frames, metres.
    pub rpe_m: Option<f64>,
    /// ATE RMSE, first-pose aligned, metres.
    pub ate_m: Option<f64>,
    /// ATE RMSE, SE(3)-aligned, metres.
    pub ate_aligned_m: Option<f64>,
    /// Final error over path length, percent (none under [`MIN_DRIFT_PATH_M`]).
    pub drift_percent: Option<f64>,
    /// ATE RMSE of a trajectory that stays at the first pose, metres.
    pub zero_motion_ate_m: Option<f64>,
}

impl Summary {
    /// The metrics of `estimate` against `truth`.
    pub fn new(estimate: &[Isometry3<f64>], truth: &[Isometry3<f64>]) -> Self {
        let n = estimate.len().min(truth.len());
        let still = vec![truth.first().copied().unwrap_or_else(Isometry3::identity); n];
        Self {
            poses: n,
            path_m: path_length(&truth[..n]),
            rpe_m: rpe_translation_rmse(estimate, truth, 1),
            ate_m: ate_rmse(estimate, truth),
            ate_aligned_m: ate_rmse_aligned(estimate, truth),
            drift_percent: drift_percent(estimate, truth),
            zero_motion_ate_m: ate_rmse(&still, truth),
        }
    }

    /// The metrics of the estimated poses that have a true pose stamped within
    /// [`PAIRING_TOLERANCE_S`] (the nearest one), in time order; `None` when no pose
    /// pairs up. Both lists must be in increasing time (as [`crate::tum::read`] gives them).
    pub fn of_stamped(estimate: &[StampedPose], truth: &[StampedPose]) -> Option<Self> {
        let (mut paired_estimate, mut paired_truth) = (Vec::new(), Vec::new());
        for e in estimate {
            let after = truth.partition_point(|t| t.timestamp_s < e.timestamp_s);
            let nearest = [after.checked_sub(1), Some(after)]
                .into_iter()
                .flatten()
                .filter_map(|k| truth.get(k))
                .min_by(|a, b| {
                    (a.timestamp_s - e.timestamp_s)
                        .abs()
                        .total_cmp(&(b.timestamp_s - e.timestamp_s).abs())
                });
            if let Some(t) = nearest
                && (t.timestamp_s - e.timestamp_s).abs() <= PAIRING_TOLERANCE_S
            {
                paired_estimate.push(e.pose);
                paired_truth.push(t.pose);
            }
        }
        (!paired_estimate.is_empty()).then(|| Self::new(&paired_estimate, &paired_truth))
    }
}

/// Final position error over true path length, percent; `None` for a path under
/// [`MIN_DRIFT_PATH_M`].
pub fn drift_percent(estimate: &[Isometry3<f64>], truth: &[Isometry3<f64>]) -> Option<f64> {
    let n = estimate.len().min(truth.len());
    let path = path_length(&truth[..n]);
    if n < 2 || path < MIN_DRIFT_PATH_M {
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
        // Truth moves 10 cm a frame (2 m in all), the estimate 11 cm: RPE 1 cm, drift 10 %.
        let truth = walk([0.1, 0.0, 0.0], 0.0, 21);
        let estimate = walk([0.11, 0.0, 0.0], 0.0, 21);
        assert!((rpe_translation_rmse(&estimate, &truth, 1).unwrap() - 0.01).abs() < 1e-12);
        assert!((drift_percent(&estimate, &truth).unwrap() - 10.0).abs() < 1e-9);
        // ATE: errors 0, 1, …, 20 cm → RMSE sqrt(Σk²/21) cm.
        let expected = ((0..21).map(|k| (0.01 * k as f64).powi(2)).sum::<f64>() / 21.0).sqrt();
        assert!((ate_rmse(&estimate, &truth).unwrap() - expected).abs() < 1e-12);
        assert!(rpe_translation_rmse(&estimate, &truth, 30).is_none());
    }

    #[test]
    fn aligned_ate_removes_a_rigid_offset_but_not_a_shape_error() {
        let truth = walk([0.1, 0.0, 0.05], 0.05, 40);
        let offset = Isometry3::from_parts(
            Translation3::new(0.3, -0.2, 0.1),
            UnitQuaternion::from_euler_angles(0.0, 0.2, 0.0),
        );
        // A rigidly moved copy: the origin-aligned ATE sees the offset, the aligned one not.
        let moved: Vec<_> = truth.iter().map(|p| offset * p).collect();
        assert!(ate_rmse_aligned(&moved, &truth).unwrap() < 1e-9);
        // A copy 10 % too long keeps an error after alignment.
        let stretched = walk([0.11, 0.0, 0.055], 0.05, 40);
        let aligned = ate_rmse_aligned(&stretched, &truth).unwrap();
        assert!(aligned > 0.01 && aligned < ate_rmse(&stretched, &truth).unwrap());
    }

    #[test]
    fn stamped_trajectories_pair_by_nearest_time_and_serialise_under_the_metric_names() {
        let truth = walk([0.1, 0.0, 0.0], 0.0, 21);
        let estimate = walk([0.11, 0.0, 0.0], 0.0, 21);
        let stamp = |poses: &[Isometry3<f64>], offset_s: f64| -> Vec<StampedPose> {
            poses
                .iter()
                .enumerate()
                .map(|(k, p)| StampedPose {
                    timestamp_s: 1.4e9 + 0.05 * k as f64 + offset_s,
                    pose: *p,
                })
                .collect()
        };
        // The estimate lacks frames 3 and 4 (dropped) and is stamped 0.2 ms off: the rest
        // pair with their own true poses.
        let mut stamped = stamp(&estimate, 2e-4);
        stamped.drain(3..5);
        let summary = Summary::of_stamped(&stamped, &stamp(&truth, 0.0)).unwrap();
        let kept: Vec<usize> = (0..21).filter(|k| !(3..5).contains(k)).collect();
        let pick = |poses: &[Isometry3<f64>]| kept.iter().map(|&k| poses[k]).collect::<Vec<_>>();
        assert_eq!(summary, Summary::new(&pick(&estimate), &pick(&truth)));
        assert_eq!(summary.poses, 19);
        assert!((summary.drift_percent.unwrap() - 10.0).abs() < 1e-6);
        // Nothing within a millisecond: no metrics.
        assert!(Summary::of_stamped(&stamp(&estimate, 0.01), &stamp(&truth, 0.0)).is_none());
        assert!(Summary::of_stamped(&[], &stamp(&truth, 0.0)).is_none());

        let json = serde_json::to_value(summary).unwrap();
        let names: Vec<&str> = json
            .as_object()
            .unwrap()
            .keys()
            .map(String::as_str)
            .collect();
        let mut expected = METRIC_NAMES.to_vec();
        expected.sort_unstable();
        assert_eq!(names, expected);
    }

    #[test]
    fn summary_gives_no_drift_under_a_metre_and_a_zero_motion_baseline() {
        let parked = walk([0.001, 0.0, 0.0], 0.0, 50);
        let summary = Summary::new(&parked, &parked);
        assert!(summary.drift_percent.is_none() && (summary.path_m - 0.049).abs() < 1e-9);
        // Staying put is off by the distance travelled so far: RMS of 0…49 mm.
        let expected = ((0..50).map(|k| (0.001 * k as f64).powi(2)).sum::<f64>() / 50.0).sqrt();
        assert!((summary.zero_motion_ate_m.unwrap() - expected).abs() < 1e-12);
        assert_eq!(summary.ate_m, Some(0.0));
    }
}
