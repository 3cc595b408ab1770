//! The covariance of the camera's pose in the world, carried from frame to frame.
//!
//! The pose error is `(δp, θ)`: the position's error in world axes, metres, and the
//! orientation's as a rotation vector in world axes, radians (`R_true = exp(θ)·R`) — the
//! order and axes of a ROS pose covariance (x, y, z, rotation about x, y, z of the parent
//! frame). A step `pose_k = pose_{k−1} · motion⁻¹` with the motion's covariance `Σ`
//! (left-multiplied error `(ρ, φ)` in the current camera frame, see
//! `linetrack_stereo_vo::MotionEstimate::covariance`) moves it to first order as
//!
//! ```text
//! δp_k = δp_{k−1} − [R_{k−1}·s]× θ_{k−1} − R_k ρ        (s: the step's translation,
//! θ_k  = θ_{k−1} − R_k φ                                   motion⁻¹'s, in frame k−1)
//! ```
//!
//! so `C_k = F C_{k−1} Fᵀ + G Σ Gᵀ` with `F = [[I, −[R_{k−1}s]×], [0, I]]` and
//! `G = −diag(R_k, R_k)`. The first frame's pose is the world's origin: exact.

use nalgebra::{Isometry3, Matrix3, Matrix6};

/// The pose covariance so far.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseCovariance {
    covariance: Matrix6<f64>,
    /// The last measured step's covariance: what a predicted step (a lost frame) adds.
    last_step: Matrix6<f64>,
}

impl Default for PoseCovariance {
    fn default() -> Self {
        Self {
            covariance: Matrix6::zeros(),
            last_step: Matrix6::zeros(),
        }
    }
}

impl PoseCovariance {
    /// The covariance of the current pose, `(x, y, z, rx, ry, rz)` in world axes.
    pub fn covariance(&self) -> Matrix6<f64> {
        self.covariance
    }

    /// Moves on from `before` to `after` (`after = before · motion⁻¹`). `step` is the
    /// motion's covariance when it was measured; a predicted step (`None`) adds the last
    /// measured one's, at least as uncertain as a measurement would have been.
    pub fn advance(
        &mut self,
        before: &Isometry3<f64>,
        after: &Isometry3<f64>,
        step: Option<&Matrix6<f64>>,
    ) {
        if let Some(step) = step {
            self.last_step = *step;
        }
        let step = self.last_step;
        let moved = after.translation.vector - before.translation.vector;
        let mut f = Matrix6::identity();
        f.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(-moved.cross_matrix()));
        let r: Matrix3<f64> = after.rotation.to_rotation_matrix().into_inner();
        let mut g = Matrix6::zeros();
        g.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-r));
        g.fixed_view_mut::<3, 3>(3, 3).copy_from(&(-r));
        let next = f * self.covariance * f.transpose() + g * step * g.transpose();
        self.covariance = (next + next.transpose()) * 0.5;
    }

    /// Starts over at `covariance` (a resumed run's pose is taken as exact: zeros).
    pub fn reset(&mut self, covariance: Matrix6<f64>) {
        self.covariance = covariance;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3, Vector6};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The propagated covariance matches the spread of poses chained from sampled noisy
    /// steps (first order: small steps' errors).
    #[test]
    fn the_propagated_covariance_matches_chained_noisy_steps() {
        let motion = Isometry3::from_parts(
            Translation3::new(0.02, -0.01, -0.1),
            UnitQuaternion::from_euler_angles(0.01, 0.03, -0.02),
        );
        let sigma = Vector6::new(2e-3, 1e-3, 3e-3, 1e-3, 2e-3, 5e-4);
        let step = Matrix6::from_diagonal(&sigma.component_mul(&sigma));
        let steps = 10;
        let mut propagated = PoseCovariance::default();
        let mut pose = Isometry3::identity();
        for _ in 0..steps {
            let after = pose * motion.inverse();
            propagated.advance(&pose, &after, Some(&step));
            pose = after;
        }
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut normal = |s: f64| {
            let (u, v): (f64, f64) = (rng.random_range(f64::EPSILON..1.0), rng.random());
            s * (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        };
        let samples = 4000;
        let mut sampled = Matrix6::zeros();
        for _ in 0..samples {
            let mut chained = Isometry3::identity();
            for _ in 0..steps {
                let d: Vec<f64> = (0..6).map(|i| normal(sigma[i])).collect();
                let error = Isometry3::from_parts(
                    Translation3::new(d[0], d[1], d[2]),
                    UnitQuaternion::from_scaled_axis(Vector3::new(d[3], d[4], d[5])),
                );
                chained *= (error * motion).inverse();
            }
            let dp = chained.translation.vector - pose.translation.vector;
            let theta = (chained.rotation * pose.rotation.inverse()).scaled_axis();
            let e = Vector6::new(dp.x, dp.y, dp.z, theta.x, theta.y, theta.z);
            sampled += e * e.transpose() / samples as f64;
        }
        let c = propagated.covariance();
        for i in 0..6 {
            let ratio = sampled[(i, i)] / c[(i, i)];
            assert!(
                (0.85..=1.15).contains(&ratio),
                "axis {i}: {ratio}\n{c}\n{sampled}"
            );
        }
        // The position–orientation coupling is there and has the sampled sign.
        assert!(c[(0, 4)].signum() == sampled[(0, 4)].signum() && c[(0, 4)].abs() > 0.0);
    }

    #[test]
    fn a_predicted_step_adds_the_last_measured_one() {
        let step = Matrix6::identity() * 1e-4;
        let mut c = PoseCovariance::default();
        let (a, b) = (Isometry3::identity(), Isometry3::translation(0.0, 0.0, 0.1));
        c.advance(&a, &b, Some(&step));
        let one = c.covariance();
        c.advance(&b, &Isometry3::translation(0.0, 0.0, 0.2), None);
        let block = |m: Matrix6<f64>, at: usize| m.fixed_view::<3, 3>(at, at).trace();
        // The orientation's doubles; the position's more (the first step's turn moves the
        // second's 10 cm).
        assert!((block(c.covariance(), 3) - 2.0 * block(one, 3)).abs() < 1e-15);
        assert!(block(c.covariance(), 0) > 2.0 * block(one, 0));
        c.reset(Matrix6::zeros());
        assert_eq!(c.covariance(), Matrix6::zeros());
    }
}
