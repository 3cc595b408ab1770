//! Frame-to-frame motion by Gauss–Newton on SE(3) (PL-StVO): point reprojection errors and
//! the distances of projected 3-D segment endpoints to the observed 2-D lines, with
//! pseudo-Huber weights and per-observation uncertainty weights, in two passes
//! (optimise → drop outliers → refine).
//!
//! The unknown is `T`, mapping points of the previous left camera frame into the current
//! one (`p_curr = T · p_prev`). Updates are applied on the left: `T ← exp(δ) · T`,
//! δ = (ρ, φ) ∈ ℝ⁶, for which the Jacobian of a transformed point `p' = T·X` is
//! `[I₃ | −[p']×]`.

use crate::observation::{
    LineObservation, PointObservation, apply_update, line_residual, line_right_residual,
    point_residual, point_right_residual,
};
use crate::robust::robust_start;
use linetrack_geometry::StereoRig;
use nalgebra::{Isometry3, Matrix6, Point3, SMatrix, SVector, Vector3, Vector4, Vector6};
use serde::{Deserialize, Serialize};
use std::ops::AddAssign;

/// Gauss–Newton settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MotionConfig {
    /// Iterations per pass at most.
    pub max_iterations: usize,
    /// Stop when the update's norm falls below this.
    pub min_step: f64,
    /// Scale of the pseudo-Huber loss, pixels.
    pub huber_px: f64,
    /// After the first pass, observations with a residual above this are outliers, pixels.
    pub outlier_px: f64,
    /// Fewer inlier observations (points + lines) than this: the frame is lost. Six lines
    /// (two equations each) already fix the six degrees of freedom, and the motion prior
    /// holds what they leave weak: on the generated `lights-switching` sequence (seed 1, LBD,
    /// lines only) 8 lost 4 frames that had 6–7 good lines (ATE 4.4 cm), 6 lost none
    /// (3.3 cm).
    pub min_inliers: usize,
    /// The same when the estimate has a constant-velocity prior ([`estimate_motion_near`]):
    /// the prior holds the directions a few observations leave open, and the estimate must
    /// still stay near the prediction to be believed. At most `min_inliers`.
    pub min_inliers_with_prior: usize,
    /// Smallest eigenvalue of the normal matrix relative to the largest below this,
    /// without a prior (the first frame, or the one after a loss): the motion is not
    /// constrained (degenerate), the frame is lost. Translations are
    /// measured in units of the depth that balances the translation's information with the
    /// rotation's for this, so the figure does not depend on the scene's scale.
    pub min_relative_eigenvalue: f64,
    /// Robust start: minimal sets drawn at most (0: start Gauss–Newton from the prediction
    /// on every observation, as PL-StVO does).
    pub ransac_draws: usize,
    /// Robust start: an observation whose residual norm under a hypothesis is within this
    /// is one of its inliers, pixels.
    pub ransac_threshold_px: f64,
    /// Constant-velocity prior ([`estimate_motion_near`]): how far the motion may depart
    /// from the prediction, one standard deviation, metres (0: no prior). Observations
    /// outweigh it wherever they constrain the motion; where they do not (a wall of
    /// parallel segments) the prediction fills in instead of noise.
    pub prior_translation_m: f64,
    /// The same for the rotation, degrees (0: no prior).
    pub prior_rotation_deg: f64,
    /// Reproject points and segment endpoints into the current right image too, where
    /// their stereo partner is known ([`PointObservation::right_x`],
    /// [`LineObservation::right_line`]): a landmark whose previous depth disagrees with its
    /// current disparity then has a residual of its own and is weighed down or dropped as
    /// an outlier, instead of stretching or shrinking the step to fit the left image
    /// alone.
    pub stereo_reprojection: bool,
    /// The share of the constant-velocity prior's translation information that the
    /// disparity offset's evidence ([`disparity_offset_evidence`]) keeps, 0 to 1. The
    /// prediction is the last step, measured through the same disparities: under an offset
    /// it is stretched (or shrunk) as this one is, so the prior pulls the evidence towards
    /// the offset already applied. Where near features fix the step that pull is small;
    /// where every feature is far, the prior holds the step's length and the evidence reads
    /// a fraction of the offset (the generated `highway`, seed 3, its rig a pixel off:
    /// −0.2 to −0.3 px until frame 40). 1 keeps the whole prior (the default); 0 leaves
    /// the length to the points alone, which finds a far-field offset in a few frames but
    /// wanders further where the offset is nil (docs/odometry.md, "Far-field scenes").
    pub offset_evidence_prior: f64,
}

impl Default for MotionConfig {
    fn default() -> Self {
        Self {
            max_iterations: 20,
            min_step: 1e-9,
            huber_px: 1.0,
            outlier_px: 3.0,
            min_inliers: 6,
            min_inliers_with_prior: 6,
            min_relative_eigenvalue: 1e-5,
            ransac_draws: 200,
            ransac_threshold_px: 2.0,
            // Weak on purpose. Measured on the KITTI raw drive (ℓ1): a 2 cm translation prior
            // raised the ATE from 0.19 m to 0.59 m (forward motion is weakly observed from
            // far features, so the prior held the car at constant speed); 10 cm gives 0.17 m
            // (LBD 0.29 m) and still fills the directions a wall of parallel segments leaves
            // open: generated sequences, lines only, frames lost 2 → 0 (normal, LBD; hand-held
            // gain jumps, ℓ1).
            prior_translation_m: 0.1,
            prior_rotation_deg: 1.0,
            stereo_reprojection: false,
            offset_evidence_prior: 1.0,
        }
    }
}

/// A successful estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionEstimate {
    /// `p_curr = motion · p_prev`.
    pub motion: Isometry3<f64>,
    /// Point observations kept as inliers.
    pub inlier_points: usize,
    /// Line observations kept as inliers.
    pub inlier_lines: usize,
    /// Gauss–Newton iterations, both passes.
    pub iterations: usize,
    /// RMS residual of the inliers at the end, pixels.
    pub rms_px: f64,
    /// Conditioning of the final normal matrix (translations in units of the observations'
    /// depth): its smallest eigenvalue over its largest.
    pub relative_eigenvalue: f64,
    /// Covariance of the estimate, from the final inliers' residuals (the IRLS sandwich
    /// `σ̂² · H⁻¹ (Σ v w² JᵀJ) H⁻¹`, see `motion_covariance` in the source): of the
    /// left-multiplied error `δ = (ρ, φ)` (metres, radians) with
    /// `true motion = exp(δ) · motion`, in the current left camera frame; `None` when the
    /// inliers leave no degree of freedom for the residual variance.
    pub covariance: Option<Matrix6<f64>>,
    /// What this frame says of a constant error in the disparities the previous frame's
    /// features were triangulated from ([`disparity_offset_evidence`]); `None` with
    /// `stereo_reprojection`, with fewer than 20 inlying points, or when the inliers leave
    /// it undetermined.
    pub disparity_offset: Option<OffsetEvidence>,
}

/// Why no motion could be estimated (the frame is reported as lost).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MotionError {
    /// Not enough inliers to trust an estimate.
    #[error("too few inliers: {inliers} (need {needed})")]
    TooFewInliers {
        /// Inliers found.
        inliers: usize,
        /// The minimum.
        needed: usize,
    },
    /// The observations do not constrain all six degrees of freedom.
    #[error("degenerate geometry: relative eigenvalue {relative_eigenvalue:e}")]
    Degenerate {
        /// Smallest over largest eigenvalue of the normal matrix.
        relative_eigenvalue: f64,
    },
}

/// A point observation's residual rows under `t`: the left image's two, and the right
/// image's column when `stereo` and the observation has one (else 0 with a zero row).
fn point_rows(
    rig: &StereoRig,
    t: &Isometry3<f64>,
    obs: &PointObservation,
    stereo: bool,
) -> Option<(Vector3<f64>, SMatrix<f64, 3, 6>)> {
    let (left, j_left) = point_residual(rig, t, obs)?;
    let (right, j_right) = if stereo {
        point_right_residual(rig, t, obs).unwrap_or((0.0, SMatrix::zeros()))
    } else {
        (0.0, SMatrix::zeros())
    };
    let mut j = SMatrix::<f64, 3, 6>::zeros();
    j.fixed_view_mut::<2, 6>(0, 0).copy_from(&j_left);
    j.set_row(2, &j_right);
    Some((Vector3::new(left.x, left.y, right), j))
}

/// A line observation's residual rows under `t`: the left image's two endpoint distances,
/// then the right image's two when `stereo` and the observation has a right line (else 0
/// with zero rows).
fn line_rows(
    rig: &StereoRig,
    t: &Isometry3<f64>,
    obs: &LineObservation,
    stereo: bool,
) -> Option<(Vector4<f64>, SMatrix<f64, 4, 6>)> {
    let (left, j_left) = line_residual(rig, t, obs)?;
    let (right, j_right) = if stereo {
        line_right_residual(rig, t, obs).unwrap_or_default()
    } else {
        Default::default()
    };
    let mut j = SMatrix::<f64, 4, 6>::zeros();
    j.fixed_view_mut::<2, 6>(0, 0).copy_from(&j_left);
    j.fixed_view_mut::<2, 6>(2, 0).copy_from(&j_right);
    Some((Vector4::new(left.x, left.y, right.x, right.y), j))
}

/// Information on how far the motion departs from a prediction (a diagonal prior in the
/// tangent space, in the units of the pixel residuals).
#[derive(Debug, Clone, Copy)]
struct Prior {
    prediction: Isometry3<f64>,
    information: Vector6<f64>,
}

impl Prior {
    fn new(prediction: &Isometry3<f64>, config: &MotionConfig) -> Option<Self> {
        let inverse_square = |sigma: f64| {
            if sigma > 0.0 && sigma.is_finite() {
                1.0 / (sigma * sigma)
            } else {
                0.0
            }
        };
        let t = inverse_square(config.prior_translation_m);
        let r = inverse_square(config.prior_rotation_deg.to_radians());
        (t > 0.0 || r > 0.0).then(|| Self {
            prediction: *prediction,
            information: Vector6::new(t, t, t, r, r, r),
        })
    }

    /// Adds the prior's term at `t` to the normal equations (its Jacobian is close to the
    /// identity under the left-multiplied update).
    fn accumulate(&self, t: &Isometry3<f64>, h: &mut Matrix6<f64>, g: &mut Vector6<f64>) {
        self.accumulate_share(t, 1.0, h, g);
    }

    /// The same with the translation's information scaled by `translation_share`.
    fn accumulate_share(
        &self,
        t: &Isometry3<f64>,
        translation_share: f64,
        h: &mut Matrix6<f64>,
        g: &mut Vector6<f64>,
    ) {
        let mut information = self.information;
        information
            .fixed_rows_mut::<3>(0)
            .scale_mut(translation_share);
        let departure = t * self.prediction.inverse();
        let (p, phi) = (
            departure.translation.vector,
            departure.rotation.scaled_axis(),
        );
        let e = Vector6::new(p.x, p.y, p.z, phi.x, phi.y, phi.z);
        *h += Matrix6::from_diagonal(&information);
        *g += information.component_mul(&e);
    }
}

/// Which observations take part in a pass.
struct Active<'a> {
    points: &'a [bool],
    lines: &'a [bool],
}

/// What stays the same over the passes of one estimate.
struct Settings<'a> {
    rig: &'a StereoRig,
    prior: Option<&'a Prior>,
    config: &'a MotionConfig,
}

/// One Gauss–Newton pass from `t`; returns the final pose, the iterations and the
/// conditioning of the last normal matrix (smallest over largest eigenvalue). `Err` only
/// when that matrix cannot be factorised.
fn optimise(
    settings: &Settings<'_>,
    points: &[PointObservation],
    lines: &[LineObservation],
    active: &Active<'_>,
    mut t: Isometry3<f64>,
) -> Result<(Isometry3<f64>, usize, f64), MotionError> {
    let Settings { rig, prior, config } = *settings;
    let robust = |r: f64| robust_weight(r, config.huber_px);
    for iteration in 1..=config.max_iterations {
        let mut h = Matrix6::zeros();
        let mut g = Vector6::zeros();
        for (obs, _) in points.iter().zip(active.points).filter(|(_, on)| **on) {
            if let Some((r, j)) = point_rows(rig, &t, obs, config.stereo_reprojection) {
                let w = obs.weight * robust(r.norm());
                h += w * j.transpose() * j;
                g += w * j.transpose() * r;
            }
        }
        for (obs, _) in lines.iter().zip(active.lines).filter(|(_, on)| **on) {
            if let Some((r, j)) = line_rows(rig, &t, obs, config.stereo_reprojection) {
                let w = obs.weight * robust(r.norm());
                h += w * j.transpose() * j;
                g += w * j.transpose() * r;
            }
        }
        let depth_m = information_depth(&h);
        if let Some(prior) = prior {
            prior.accumulate(&t, &mut h, &mut g);
        }
        // Conditioning is judged with translations in units of the observations' depth, so
        // that it does not depend on the scene's scale (a metre matters less at 30 m than
        // at 2 m).
        let scale = Matrix6::from_diagonal(&Vector6::new(depth_m, depth_m, depth_m, 1.0, 1.0, 1.0));
        let relative = || {
            let eigen = (scale * h * scale).symmetric_eigenvalues();
            let (low, high) = (eigen.min(), eigen.max());
            if high > 0.0 { low / high } else { 0.0 }
        };
        let Some(step) = h.cholesky().map(|c| -c.solve(&g)) else {
            return Err(MotionError::Degenerate {
                relative_eigenvalue: relative(),
            });
        };
        t = apply_update(&step, t);
        if step.norm() < config.min_step || iteration == config.max_iterations {
            return Ok((t, iteration, relative()));
        }
    }
    Ok((t, 0, 1.0))
}

/// The depth, metres, at which a translation moves the observations as much as a rotation
/// of one radian does: the square root of the rotation block's trace of the normal matrix
/// `h` over the translation block's (1 when either is empty). For points at one depth it is
/// that depth (a translation `t` moves a point at depth `z` by about `f·t/z` pixels, a
/// rotation `ω` by about `f·ω`); for a mixed scene it is the depth of the observations that
/// pin the translation, the near ones, however many far ones there are. The median depth
/// served before: on the generated `highway` preset (median 110–170 m, the translation
/// pinned by points at 5–20 m) it inflated the translation's eigenvalues ~10⁴-fold and frames
/// with 250–330 well-fitted points were lost as "degenerate".
fn information_depth(h: &Matrix6<f64>) -> f64 {
    let translation = h[(0, 0)] + h[(1, 1)] + h[(2, 2)];
    let rotation = h[(3, 3)] + h[(4, 4)] + h[(5, 5)];
    if translation > 0.0 && rotation > 0.0 && translation.is_finite() && rotation.is_finite() {
        (rotation / translation).sqrt()
    } else {
        1.0
    }
}

/// Estimates the motion from `initial` (e.g. identity, or the previous motion), from the
/// observations alone.
pub fn estimate_motion(
    rig: &StereoRig,
    points: &[PointObservation],
    lines: &[LineObservation],
    initial: &Isometry3<f64>,
    config: &MotionConfig,
) -> Result<MotionEstimate, MotionError> {
    estimate(rig, points, lines, initial, None, config)
}

/// Estimates the motion from the observations and a constant-velocity prior: `prediction`
/// (the last motion) with the spread of `config.prior_translation_m` and
/// `prior_rotation_deg`; it also starts the search.
pub fn estimate_motion_near(
    rig: &StereoRig,
    points: &[PointObservation],
    lines: &[LineObservation],
    prediction: &Isometry3<f64>,
    config: &MotionConfig,
) -> Result<MotionEstimate, MotionError> {
    let prior = Prior::new(prediction, config);
    estimate(rig, points, lines, prediction, prior.as_ref(), config)
}

fn estimate(
    rig: &StereoRig,
    points: &[PointObservation],
    lines: &[LineObservation],
    initial: &Isometry3<f64>,
    prior: Option<&Prior>,
    config: &MotionConfig,
) -> Result<MotionEstimate, MotionError> {
    let min_inliers = if prior.is_some() {
        config.min_inliers_with_prior.min(config.min_inliers)
    } else {
        config.min_inliers
    };
    let total = points.len() + lines.len();
    if total < min_inliers {
        return Err(MotionError::TooFewInliers {
            inliers: total,
            needed: min_inliers,
        });
    }
    // Where the first pass starts, and on which observations.
    let (start, start_points, start_lines) = if config.ransac_draws > 0 {
        let found = robust_start(
            rig,
            points,
            lines,
            initial,
            config.ransac_draws,
            config.ransac_threshold_px,
        );
        let inliers = found.inliers.iter().filter(|b| **b).count();
        if inliers < min_inliers {
            return Err(MotionError::TooFewInliers {
                inliers,
                needed: min_inliers,
            });
        }
        let (p, l) = found.inliers.split_at(points.len());
        (found.motion, p.to_vec(), l.to_vec())
    } else {
        (*initial, vec![true; points.len()], vec![true; lines.len()])
    };
    let settings = Settings { rig, prior, config };
    let (first, iterations_1, _) = optimise(
        &settings,
        points,
        lines,
        &Active {
            points: &start_points,
            lines: &start_lines,
        },
        start,
    )?;
    let stereo = config.stereo_reprojection;
    let within = |amax: Option<f64>, weight: f64| {
        amax.is_some_and(|amax| amax * weight.sqrt() <= config.outlier_px)
    };
    let inlier_points: Vec<bool> = points
        .iter()
        .map(|o| {
            let rows = point_rows(rig, &first, o, stereo);
            within(rows.map(|(r, _)| r.amax()), o.weight)
        })
        .collect();
    let inlier_lines: Vec<bool> = lines
        .iter()
        .map(|o| {
            let rows = line_rows(rig, &first, o, stereo);
            within(rows.map(|(r, _)| r.amax()), o.weight)
        })
        .collect();
    let count = |v: &[bool]| v.iter().filter(|b| **b).count();
    let (n_points, n_lines) = (count(&inlier_points), count(&inlier_lines));
    if n_points + n_lines < min_inliers {
        return Err(MotionError::TooFewInliers {
            inliers: n_points + n_lines,
            needed: min_inliers,
        });
    }
    let active = Active {
        points: &inlier_points,
        lines: &inlier_lines,
    };
    let (motion, iterations_2, relative_eigenvalue) =
        optimise(&settings, points, lines, &active, first)?;
    // Judged on the final inliers at the solution only: the first pass's set still holds
    // the outliers, and on the way to a solution (from a prediction far from the truth)
    // the normal matrix may be worse conditioned than at it (KITTI raw drive, LBD, lines
    // only: frames 1 and 2 ended their first pass at 5e-6 and the second at 1.8e-5, with
    // the right motion). With a prior nothing is left unconstrained: what the observations
    // leave open takes the prediction.
    if prior.is_none() && !(relative_eigenvalue >= config.min_relative_eigenvalue) {
        return Err(MotionError::Degenerate {
            relative_eigenvalue,
        });
    }
    let mut sum = 0.0;
    let mut n = 0usize;
    for (obs, _) in points.iter().zip(&inlier_points).filter(|(_, on)| **on) {
        if let Some((r, _)) = point_rows(rig, &motion, obs, stereo) {
            sum += r.norm_squared();
            n += if stereo && obs.right_x.is_some() {
                3
            } else {
                2
            };
        }
    }
    for (obs, _) in lines.iter().zip(&inlier_lines).filter(|(_, on)| **on) {
        if let Some((r, _)) = line_rows(rig, &motion, obs, stereo) {
            sum += r.norm_squared();
            n += if stereo && obs.right_line.is_some() {
                4
            } else {
                2
            };
        }
    }
    Ok(MotionEstimate {
        motion,
        inlier_points: n_points,
        inlier_lines: n_lines,
        iterations: iterations_1 + iterations_2,
        rms_px: if n > 0 { (sum / n as f64).sqrt() } else { 0.0 },
        relative_eigenvalue,
        covariance: motion_covariance(&settings, points, lines, &active, &motion),
        disparity_offset: (!stereo)
            .then(|| disparity_offset_evidence(&settings, points, &active, &motion))
            .flatten(),
    })
}

/// The IRLS weight of a residual of norm `r` under the pseudo-Huber loss of scale
/// `huber_px`.
fn robust_weight(r: f64, huber_px: f64) -> f64 {
    1.0 / (1.0 + (r / huber_px).powi(2)).sqrt()
}

/// The sums of [`motion_covariance`]: the normal matrix `Σ v w JᵀJ`, the weighted
/// information `Σ v w² JᵀJ`, the residuals' `Σ v ‖r‖²` and how many rows.
#[derive(Default)]
struct Sandwich {
    normal: Matrix6<f64>,
    information: Matrix6<f64>,
    squares: f64,
    rows: usize,
}

impl Sandwich {
    /// Adds an observation of uncertainty weight `weight` with residual rows `r` and their
    /// Jacobian `j`.
    fn add<const R: usize>(
        &mut self,
        weight: f64,
        huber_px: f64,
        r: &SMatrix<f64, R, 1>,
        j: &SMatrix<f64, R, 6>,
    ) {
        let w = robust_weight(r.norm(), huber_px);
        self.normal += weight * w * j.transpose() * j;
        self.information += weight * w * w * j.transpose() * j;
        self.squares += weight * r.norm_squared();
        // A missing stereo partner's row is all zeros: no residual.
        self.rows += j
            .row_iter()
            .filter(|row| row.iter().any(|v| *v != 0.0))
            .count();
    }
}

/// The covariance of the final estimate `motion` from the `active` (final inlier)
/// observations: `σ̂² · H⁻¹ (Σ vᵢwᵢ²JᵢᵀJᵢ) H⁻¹`, with `H = Σ vᵢwᵢJᵢᵀJᵢ` the final normal
/// matrix (pseudo-Huber weights `w(‖r‖)`, uncertainty weights `v`; the prior's information
/// added when there is one) and `σ̂² = Σ vᵢ‖rᵢ‖² / (m − 6)` the residual variance per unit
/// `v` over the `m` residual rows. It is the covariance of the weighted fit when each row's
/// error has variance `σ²/v`, independently, the weights `w` taken as given (the IRLS
/// sandwich).
///
/// Why not `σ̂_w² · H⁻¹` (the normal matrix scaled by the *weighted* residual variance
/// `Σ vw‖r‖²/(m − 6)`): that is a least-squares fit's covariance, exact only when the weights
/// are the inverse variances. The IRLS weights come from the residuals themselves and shrink
/// the residuals the variance is measured from. Under Gaussian pixel noise of 0.6 px (the
/// 1 px pseudo-Huber scale, 40 points, 300 trials) `σ̂_w²·H⁻¹` gave a mean NEES of 7.6
/// instead of 6; this form is within [5.2, 6.8] at 0.2 and 0.6 px
/// (`the_covariance_is_honest_under_the_noise_it_assumes`). Tried and dropped: the Hessian
/// with the weights' derivative in place of `H` (4.6 at 0.6 px: too cautious), and the
/// observations' own gradient spread `H⁻¹ Σgᵢgᵢᵀ H⁻¹` (8.4 at 0.2 px: the small-sample
/// optimism of that estimator).
///
/// The parameterisation is the optimiser's: the left-multiplied update `δ = (ρ, φ)`
/// (translation metres, then rotation vector radians) with `true = exp(δ) · motion`, so the
/// covariance is in the current left camera frame. For the camera's pose
/// (`pose_k = pose_{k−1} · motion⁻¹`) that is, to first order, the covariance of the
/// right-multiplied error of the new pose in its own body frame. `None` when `m ≤ 6` or the
/// normal matrix is not positive definite.
fn motion_covariance(
    settings: &Settings<'_>,
    points: &[PointObservation],
    lines: &[LineObservation],
    active: &Active<'_>,
    motion: &Isometry3<f64>,
) -> Option<Matrix6<f64>> {
    let Settings { rig, prior, config } = *settings;
    let stereo = config.stereo_reprojection;
    let mut sums = Sandwich::default();
    for (obs, _) in points.iter().zip(active.points).filter(|(_, on)| **on) {
        if let Some((r, j)) = point_rows(rig, motion, obs, stereo) {
            sums.add(obs.weight, config.huber_px, &r, &j);
        }
    }
    for (obs, _) in lines.iter().zip(active.lines).filter(|(_, on)| **on) {
        if let Some((r, j)) = line_rows(rig, motion, obs, stereo) {
            sums.add(obs.weight, config.huber_px, &r, &j);
        }
    }
    let Sandwich {
        mut normal,
        information,
        squares,
        rows,
    } = sums;
    let dof = rows.checked_sub(6).filter(|d| *d > 0)?;
    if let Some(prior) = prior {
        normal += Matrix6::from_diagonal(&prior.information);
    }
    let inverse = normal.cholesky()?.inverse();
    let variance = squares / dof as f64;
    let covariance = inverse * information * inverse * variance;
    let symmetric = (covariance + covariance.transpose()) * 0.5;
    symmetric.iter().all(|v| v.is_finite()).then_some(symmetric)
}

/// Fewer inlying points than this: a frame gives no evidence on the disparity offset
/// ([`disparity_offset_evidence`]).
const MIN_OFFSET_POINTS: usize = 20;

/// A frame's evidence on the disparity offset: the correction ε, pixels, that the
/// disparities the previous frame's features were triangulated from still need (the true
/// disparity is the one used minus ε), and its variance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OffsetEvidence {
    /// The correction, pixels.
    pub correction_px: f64,
    /// Its variance, px².
    pub variance_px2: f64,
}

/// How a feature of the previous frame at `p` moves per pixel of disparity offset: its
/// depth came from disparity `d = f·b / z`; with `d − ε` it lies at `p · d / (d − ε)`, so
/// `∂p/∂ε = p / d = p · z / (f·b)` at ε = 0.
fn offset_direction(rig: &StereoRig, p: &Point3<f64>) -> Vector3<f64> {
    p.coords * (p.z / (rig.focal_px * rig.baseline_m))
}

/// The Jacobian's columns of the update's translation: under `p' = exp(δ)·T·X` they are the
/// residual's derivative by the transformed point `p'` itself (`∂p'/∂ρ = I`), so a move of
/// the previous point by `v` changes the residual by these times `R·v`.
fn translation_columns(j: &SMatrix<f64, 2, 6>) -> SMatrix<f64, 2, 3> {
    j.fixed_columns::<3>(0).into_owned()
}

/// The disparity offset seen from the final inlying points at the solution `motion`: one
/// Gauss–Newton step over the motion and the offset together (the points' rows in the left
/// image, the weights of the last pass, the prior when there is one, its translation's
/// share `offset_evidence_prior`), whose offset component is the correction; its variance
/// from the normal matrix and the residual variance. Without enough points there is no
/// evidence. Without the prior in it, the KITTI raw drive's evidence (LBD) swung far enough
/// to be applied where the truth is nil (measured before `min_px`: the drive's ATE went
/// from 0.160 to 0.209 m); since `min_px`, nothing is applied there without it, but the
/// generated `highway`'s nil offset wanders to 0.38 px (0.21 at most with it).
///
/// Segments take no part. An endpoint's disparity is read off the right segment's line at
/// the endpoint's row, so the lines' angles and the detector's cuts weigh in, and their
/// evidence was not of one offset: lines only, on the KITTI raw drive as it is, it said
/// −0.26 to −0.34 px, and beside the points it carried the generated presets' nil offset
/// as far as 0.48 px (points alone: 0.31 px at most, 0.21 but for one sequence).
///
/// Why this is observable: a constant error in disparity changes a feature's depth by a
/// fraction `ε / d`, which is small for near features and large for far ones. Near
/// features fix the step's length, so far features whose depth is off by a common
/// fraction no longer fit the same step. A scene at one depth gives no evidence (every
/// depth scales alike, and so does the step): the offset's information is then nil.
fn disparity_offset_evidence(
    settings: &Settings<'_>,
    points: &[PointObservation],
    active: &Active<'_>,
    motion: &Isometry3<f64>,
) -> Option<OffsetEvidence> {
    let Settings { rig, prior, config } = *settings;
    if active.points.iter().filter(|on| **on).count() < MIN_OFFSET_POINTS {
        return None;
    }
    let rotation = motion.rotation.to_rotation_matrix();
    let mut h = SMatrix::<f64, 7, 7>::zeros();
    let mut g = SVector::<f64, 7>::zeros();
    let (mut squares, mut rows) = (0.0, 0usize);
    let mut add = |weight: f64, r: f64, j: SMatrix<f64, 1, 6>, j_offset: f64| {
        let mut row = SMatrix::<f64, 1, 7>::zeros();
        row.fixed_view_mut::<1, 6>(0, 0).copy_from(&j);
        row[6] = j_offset;
        (h, g) = (
            h + weight * row.transpose() * row,
            g + weight * row.transpose() * r,
        );
        squares += weight * r * r;
        rows += 1;
    };
    for (obs, _) in points.iter().zip(active.points).filter(|(_, on)| **on) {
        let Some((r, j)) = point_residual(rig, motion, obs) else {
            continue;
        };
        let w = obs.weight * robust_weight(r.norm(), config.huber_px);
        let j_offset = translation_columns(&j) * (rotation * offset_direction(rig, &obs.position));
        for k in 0..2 {
            add(w, r[k], j.fixed_rows::<1>(k).into_owned(), j_offset[k]);
        }
    }
    if let Some(prior) = prior {
        let mut h6 = Matrix6::zeros();
        let mut g6 = Vector6::zeros();
        prior.accumulate_share(motion, config.offset_evidence_prior, &mut h6, &mut g6);
        h.fixed_view_mut::<6, 6>(0, 0).add_assign(&h6);
        g.fixed_rows_mut::<6>(0).add_assign(&g6);
    }
    let dof = rows.checked_sub(7).filter(|d| *d > 0)?;
    let inverse = h.cholesky()?.inverse();
    let step = -(inverse * g);
    let variance_px2 = inverse[(6, 6)] * squares / dof as f64;
    (step[6].is_finite() && variance_px2.is_finite() && variance_px2 > 0.0).then_some(
        OffsetEvidence {
            correction_px: step[6],
            variance_px2,
        },
    )
}
