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
//! - **Step ratio** ([`StepRatio`]): a scale bias made visible. For each pair of
//!   consecutive poses both trajectories have, the estimated step length over the true one,
//!   ‖trans(P_i⁻¹ P_{i+1})‖ / ‖trans(Q_i⁻¹ Q_{i+1})‖ (the distance between consecutive
//!   positions, so world frames and rotations do not enter). Steps over which the truth moves
//!   less than [`MIN_RATIO_STEP_M`] (1 cm) are left out and counted: over so short a step,
//!   millimetres of noise in either position make the ratio anything (a parked vehicle's
//!   steps are nothing but noise; the KITTI car steps about 1 m a frame, the generated
//!   handheld camera 1.5–3.2 cm, 10th to 90th percentile of its motion model at 20 Hz).
//!   A pose pair of [`Summary::of_stamped`] that spans a dropped frame is one step of both
//!   trajectories over the same interval. Reported as the overall ratio (sum
//!   of estimated over sum of true step lengths, so long steps weigh more), the median, and
//!   the 10th and 90th percentiles (nearest rank) of the per-step ratios; none with fewer
//!   than [`MIN_RATIO_STEPS`] steps kept. 1 is unbiased; 1.1 means the estimate moves 10 %
//!   too far.
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

/// The distance between each pose's position and the next one's, metres.
fn step_lengths(poses: &[Isometry3<f64>]) -> impl Iterator<Item = f64> + '_ {
    poses
        .windows(2)
        .map(|w| (w[1].translation.vector - w[0].translation.vector).norm())
}

/// Length of the true path, metres.
pub fn path_length(truth: &[Isometry3<f64>]) -> f64 {
    step_lengths(truth).sum()
}

/// Steps over which the truth moves less than this are left out of the step ratio, metres.
pub const MIN_RATIO_STEP_M: f64 = 0.01;

/// The step ratio needs at least this many steps kept: a single step has no spread to
/// take percentiles of.
pub const MIN_RATIO_STEPS: usize = 2;

/// Estimated over true step length, frame to frame: a scale bias shows as a ratio away
/// from 1 (the module documentation defines it).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepRatio {
    /// Steps compared: consecutive pose pairs over which the truth moves at least
    /// [`MIN_RATIO_STEP_M`].
    pub steps: usize,
    /// Steps left out because the truth moves less than [`MIN_RATIO_STEP_M`] over them.
    pub skipped: usize,
    /// Sum of the estimated step lengths over the sum of the true ones (steps compared).
    pub overall: f64,
    /// Median of the per-step ratios.
    pub median: f64,
    /// 10th percentile of the per-step ratios (nearest rank).
    pub p10: f64,
    /// 90th percentile of the per-step ratios (nearest rank).
    pub p90: f64,
}

/// The `percent`th percentile of increasingly sorted values by nearest rank: the smallest
/// value with at least `percent` % of them at or below it; `None` for no values.
fn nearest_rank(sorted: &[f64], percent: f64) -> Option<f64> {
    // Multiplied before dividing, so whole percentages of whole counts stay exact.
    let rank = (percent * sorted.len() as f64 / 100.0).ceil() as usize;
    sorted.get(rank.clamp(1, sorted.len().max(1)) - 1).copied()
}

impl StepRatio {
    /// The step ratio of `estimate` against `truth` over the poses both have; `None` with
    /// fewer than [`MIN_RATIO_STEPS`] steps of at least [`MIN_RATIO_STEP_M`] in the truth.
    pub fn new(estimate: &[Isometry3<f64>], truth: &[Isometry3<f64>]) -> Option<Self> {
        let n = estimate.len().min(truth.len());
        let pairs: Vec<(f64, f64)> = step_lengths(&estimate[..n])
            .zip(step_lengths(&truth[..n]))
            .collect();
        let kept: Vec<(f64, f64)> = pairs
            .iter()
            .copied()
            .filter(|&(_, true_m)| true_m >= MIN_RATIO_STEP_M)
            .collect();
        if kept.len() < MIN_RATIO_STEPS {
            return None;
        }
        let (estimated_m, true_m) = kept.iter().fold((0.0, 0.0), |(e, t), &(step_e, step_t)| {
            (e + step_e, t + step_t)
        });
        let mut ratios: Vec<f64> = kept.iter().map(|&(e, t)| e / t).collect();
        ratios.sort_by(f64::total_cmp);
        Some(Self {
            steps: kept.len(),
            skipped: pairs.len() - kept.len(),
            overall: estimated_m / true_m,
            median: nearest_rank(&ratios, 50.0)?,
            p10: nearest_rank(&ratios, 10.0)?,
            p90: nearest_rank(&ratios, 90.0)?,
        })
    }
}

/// The names of [`Summary`]'s fields as written to JSON, in order.
pub const METRIC_NAMES: [&str; 8] = [
    "poses",
    "path_m",
    "rpe_m",
    "ate_m",
    "ate_aligned_m",
    "drift_percent",
    "step_ratio",
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
    /// Estimated over true step length (none with too few steps that move, see
    /// [`StepRatio::new`]).
    pub step_ratio: Option<StepRatio>,
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
            step_ratio: StepRatio::new(estimate, truth),
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
        // Every step 10 % too long.
        let ratio = StepRatio::new(&estimate, &truth).unwrap();
        assert_eq!((ratio.steps, ratio.skipped), (20, 0));
        for value in statistics(&ratio) {
            assert!((value - 1.1).abs() < 1e-12, "{ratio:?}");
        }
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

    /// Every statistic of `ratio`, in the order overall, median, p10, p90.
    fn statistics(ratio: &StepRatio) -> [f64; 4] {
        [ratio.overall, ratio.median, ratio.p10, ratio.p90]
    }

    #[test]
    fn a_trajectory_scaled_by_1_1_has_a_step_ratio_of_1_1_in_every_world_frame() {
        // Turning, climbing, with steps of changing length (10 to 29 cm).
        let truth: Vec<Isometry3<f64>> = walk([0.1, 0.02, 0.05], 0.05, 40)
            .iter()
            .enumerate()
            .map(|(k, p)| {
                let stretch = 1.0 + 0.05 * (k % 20) as f64;
                Isometry3::from_parts((p.translation.vector * stretch).into(), p.rotation)
            })
            .collect();
        let scaled: Vec<_> = truth
            .iter()
            .map(|p| Isometry3::from_parts((p.translation.vector * 1.1).into(), p.rotation))
            .collect();
        let offset = Isometry3::from_parts(
            Translation3::new(5.0, -2.0, 1.0),
            UnitQuaternion::from_euler_angles(0.3, 0.1, -0.7),
        );
        let moved: Vec<_> = scaled.iter().map(|p| offset * p).collect();
        for estimate in [&scaled, &moved] {
            let ratio = StepRatio::new(estimate, &truth).unwrap();
            assert_eq!((ratio.steps, ratio.skipped), (39, 0));
            for value in statistics(&ratio) {
                assert!((value - 1.1).abs() < 1e-12, "{ratio:?}");
            }
        }
        // The same trajectory rigidly moved, or shifted by a constant: no bias.
        let shifted: Vec<_> = truth
            .iter()
            .map(|p| Translation3::new(3.0, 0.5, -7.0) * p)
            .collect();
        let unmoved: Vec<_> = truth.iter().map(|p| offset * p).collect();
        for estimate in [&shifted, &unmoved] {
            let ratio = StepRatio::new(estimate, &truth).unwrap();
            for value in statistics(&ratio) {
                assert!((value - 1.0).abs() < 1e-12, "{ratio:?}");
            }
        }
    }

    #[test]
    fn step_ratio_percentiles_are_nearest_rank_and_overall_weighs_by_length() {
        // 20 true steps of 10 cm along x; the estimate's k-th smallest ratio is 0.5 + 0.05 k,
        // in a shuffled order.
        let truth = walk([0.1, 0.0, 0.0], 0.0, 21);
        let ratios: Vec<f64> = (0..20)
            .map(|k| 0.5 + 0.05 * ((7 * k) % 20) as f64)
            .collect();
        let estimate: Vec<Isometry3<f64>> = std::iter::once(0.0)
            .chain(ratios.iter().scan(0.0, |x, r| {
                *x += 0.1 * r;
                Some(*x)
            }))
            .map(|x| Isometry3::translation(x, 0.0, 0.0))
            .collect();
        let ratio = StepRatio::new(&estimate, &truth).unwrap();
        // Nearest rank of 20 sorted values: p10 the 2nd, median the 10th, p90 the 18th.
        let expected = [0.975, 0.95, 0.55, 1.35];
        for (value, want) in statistics(&ratio).into_iter().zip(expected) {
            assert!((value - want).abs() < 1e-9, "{ratio:?}");
        }
        // One long step 1.5 times too long among short exact ones: the overall ratio weighs
        // it by its length, the median does not see it.
        let truth: Vec<_> = [0.0, 0.1, 0.2, 0.3, 1.3]
            .map(|x| Isometry3::translation(x, 0.0, 0.0))
            .into();
        let estimate: Vec<_> = [0.0, 0.1, 0.2, 0.3, 1.8]
            .map(|x| Isometry3::translation(x, 0.0, 0.0))
            .into();
        let ratio = StepRatio::new(&estimate, &truth).unwrap();
        assert!((ratio.overall - 1.8 / 1.3).abs() < 1e-12, "{ratio:?}");
        assert!((ratio.median - 1.0).abs() < 1e-12 && (ratio.p90 - 1.5).abs() < 1e-12);
    }

    #[test]
    fn steps_where_the_truth_stands_still_are_left_out_and_too_few_give_none() {
        // 10 steps of 10 cm, then 10 parked steps of 5 mm over which the estimate jumps 1 m.
        let along_x = |moving_m: f64, parked_m: f64| -> Vec<Isometry3<f64>> {
            (0..21usize)
                .map(|k| {
                    let x = moving_m * k.min(10) as f64 + parked_m * k.saturating_sub(10) as f64;
                    Isometry3::translation(x, 0.0, 0.0)
                })
                .collect()
        };
        let (truth, estimate) = (along_x(0.1, 0.005), along_x(0.1, 1.0));
        let ratio = StepRatio::new(&estimate, &truth).unwrap();
        assert_eq!((ratio.steps, ratio.skipped), (10, 10));
        for value in statistics(&ratio) {
            assert!((value - 1.0).abs() < 1e-12, "{ratio:?}");
        }
        // Parked all along, a single step, a single pose, nothing: no ratio (not NaN).
        let parked = &truth[10..];
        assert_eq!(StepRatio::new(&estimate[10..], parked), None);
        assert_eq!(StepRatio::new(&estimate[..2], &truth[..2]), None);
        assert_eq!(StepRatio::new(&estimate[..1], &truth[..1]), None);
        assert_eq!(StepRatio::new(&[], &truth), None);
        assert_eq!(
            StepRatio::new(&estimate[..3], &truth[..3]).map(|r| r.steps),
            Some(2)
        );
        let summary = Summary::new(&estimate[10..], parked);
        assert_eq!(summary.step_ratio, None);
        let json = serde_json::to_value(summary).unwrap();
        assert!(json["step_ratio"].is_null(), "{json}");
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
