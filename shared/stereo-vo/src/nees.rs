//! How honest a motion's covariance is: the normalised estimation error squared (NEES) of
//! an estimate against the truth, `δᵀ Σ⁻¹ δ`, with `δ` the error in the parameterisation of
//! [`MotionEstimate::covariance`](crate::MotionEstimate::covariance) (left-multiplied,
//! `truth = exp(δ) · estimate`, translation then rotation vector). For a consistent
//! covariance it follows a χ² distribution with 6 degrees of freedom: its mean over many
//! estimates is 6; above it the covariance is too small (overconfident), below it too
//! large.

use nalgebra::{Isometry3, Matrix6, Vector6};

/// The degrees of freedom of a motion's NEES: its mean for a consistent covariance.
pub const MOTION_DOF: f64 = 6.0;

/// The error `δ = (ρ, φ)` with `truth = exp(δ) · estimate` (the optimiser's update:
/// translation `ρ`, metres, after rotation `φ`, radians).
pub fn left_error(estimate: &Isometry3<f64>, truth: &Isometry3<f64>) -> Vector6<f64> {
    let e = truth * estimate.inverse();
    let (rho, phi) = (e.translation.vector, e.rotation.scaled_axis());
    Vector6::new(rho.x, rho.y, rho.z, phi.x, phi.y, phi.z)
}

/// `δᵀ Σ⁻¹ δ` for `estimate` against `truth` with covariance `covariance`; `None` when the
/// covariance is not positive definite or the result is not finite.
pub fn nees(
    estimate: &Isometry3<f64>,
    truth: &Isometry3<f64>,
    covariance: &Matrix6<f64>,
) -> Option<f64> {
    let delta = left_error(estimate, truth);
    let value = covariance.cholesky()?.solve(&delta).dot(&delta);
    value.is_finite().then_some(value)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    #[test]
    fn nees_is_the_squared_error_in_units_of_the_spread() {
        let estimate = Isometry3::from_parts(
            Translation3::new(0.1, -0.2, 0.3),
            UnitQuaternion::from_euler_angles(0.1, 0.0, -0.2),
        );
        // 2 cm off along x (left-multiplied: in the current frame), and 0.01 rad about z.
        let truth = Isometry3::translation(0.02, 0.0, 0.0)
            * Isometry3::rotation(Vector3::new(0.0, 0.0, 0.01))
            * estimate;
        let delta = left_error(&estimate, &truth);
        assert!((delta[5] - 0.01).abs() < 1e-12, "{delta}");
        assert!((delta[0] - 0.02).abs() < 1e-12, "{delta}");
        // σ = 1 cm in translation, 0.01 rad in rotation: 2² + 1² = 5.
        let sigma = Vector6::new(0.01, 0.01, 0.01, 0.01, 0.01, 0.01);
        let cov = Matrix6::from_diagonal(&sigma.component_mul(&sigma));
        let value = nees(&estimate, &truth, &cov).unwrap_or(f64::NAN);
        assert!((value - 5.0).abs() < 1e-9, "{value}");
        // Correlation counts: with translation x and rotation z correlated at 0.99, an error
        // of 2σ and 1σ along them is (2² − 2·0.99·2·1 + 1²) / (1 − 0.99²), not 5.
        let mut correlated = cov;
        correlated[(0, 5)] = 0.99e-4;
        correlated[(5, 0)] = 0.99e-4;
        let expected = (5.0 - 2.0 * 0.99 * 2.0) / (1.0 - 0.99 * 0.99);
        let value = nees(&estimate, &truth, &correlated).unwrap_or(f64::NAN);
        assert!(
            (value - expected).abs() < 1e-6 * expected,
            "{value} vs {expected}"
        );
        // The truth itself has no error.
        assert!(nees(&estimate, &estimate, &cov).is_some_and(|v| v < 1e-20));
        // A covariance that is not positive definite gives no figure.
        assert_eq!(nees(&estimate, &truth, &Matrix6::zeros()), None);
        assert_eq!(nees(&estimate, &truth, &-cov), None);
    }
}
