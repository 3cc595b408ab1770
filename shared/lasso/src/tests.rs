//! The solver is checked against the lasso's optimality (KKT) conditions and against an
//! independent coordinate-descent reference on random problems.

use super::*;
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const KKT_TOL: f64 = 1e-9;

/// `c = Aᵀ(b − Aω)`.
fn correlations<const R: usize>(columns: &[[f64; R]], b: &[f64; R], w: &[f64]) -> Vec<f64> {
    let mut residual = *b;
    for (column, wj) in columns.iter().zip(w) {
        axpy(-wj, column, &mut residual);
    }
    columns.iter().map(|c| dot(c, &residual)).collect()
}

/// Largest violation of the KKT conditions: |c_j| ≤ λ for all j, c_j = λ·sign(ω_j) where
/// ω_j ≠ 0.
fn kkt_violation<const R: usize>(
    columns: &[[f64; R]],
    b: &[f64; R],
    lambda: f64,
    w: &[f64],
) -> f64 {
    correlations(columns, b, w)
        .iter()
        .zip(w)
        .map(|(c, wj)| {
            if *wj == 0.0 {
                (c.abs() - lambda).max(0.0)
            } else {
                (c - lambda * wj.signum()).abs()
            }
        })
        .fold(0.0, f64::max)
}

fn objective<const R: usize>(columns: &[[f64; R]], b: &[f64; R], lambda: f64, w: &[f64]) -> f64 {
    let mut residual = *b;
    for (column, wj) in columns.iter().zip(w) {
        axpy(-wj, column, &mut residual);
    }
    lambda * w.iter().map(|v| v.abs()).sum::<f64>() + 0.5 * dot(&residual, &residual)
}

/// Cyclic coordinate descent with soft thresholding, run until no weight moves: a
/// reference that shares no code with the homotopy.
fn coordinate_descent<const R: usize>(columns: &[[f64; R]], b: &[f64; R], lambda: f64) -> Vec<f64> {
    let mut w = vec![0.0; columns.len()];
    let mut residual = *b;
    for _sweep in 0..200_000 {
        let mut largest_move: f64 = 0.0;
        for (j, column) in columns.iter().enumerate() {
            let norm2 = dot(column, column);
            if norm2 == 0.0 {
                continue;
            }
            let rho = dot(column, &residual) + norm2 * w[j];
            let updated = rho.signum() * (rho.abs() - lambda).max(0.0) / norm2;
            let delta = updated - w[j];
            if delta != 0.0 {
                axpy(-delta, column, &mut residual);
                w[j] = updated;
                largest_move = largest_move.max(delta.abs());
            }
        }
        if largest_move < 1e-15 {
            break;
        }
    }
    w
}

fn random_problem(seed: u64, n: usize, nonnegative: bool) -> (Vec<[f64; 4]>, [f64; 4]) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let low = if nonnegative { 0.0 } else { -2.0 };
    let columns = (0..n)
        .map(|_| std::array::from_fn(|_| rng.random_range(low..2.0)))
        .collect();
    let b = std::array::from_fn(|_| rng.random_range(low..2.0));
    (columns, b)
}

fn solve4(columns: &[[f64; 4]], b: &[f64; 4], lambda: f64) -> (Vec<f64>, SolveStats) {
    let mut w = vec![f64::NAN; columns.len()];
    let stats = Homotopy::<4>::new()
        .solve(columns, b, lambda, &mut w)
        .unwrap();
    (w, stats)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(5_000))]

    #[test]
    fn solution_satisfies_kkt(seed in any::<u64>(), n in 1usize..80, lambda in 0.001f64..3.0, nonneg in any::<bool>()) {
        let (columns, b) = random_problem(seed, n, nonneg);
        let (w, stats) = solve4(&columns, &b, lambda);
        prop_assert!(stats.active <= 4);
        let violation = kkt_violation(&columns, &b, lambda, &w);
        prop_assert!(violation <= KKT_TOL, "KKT violated by {violation:e}");
    }

    #[test]
    fn agrees_with_coordinate_descent(seed in any::<u64>(), n in 1usize..40, lambda in 0.01f64..2.0) {
        let (columns, b) = random_problem(seed, n, false);
        let (w, _) = solve4(&columns, &b, lambda);
        let reference = coordinate_descent(&columns, &b, lambda);
        let (f_h, f_cd) = (objective(&columns, &b, lambda, &w), objective(&columns, &b, lambda, &reference));
        // The homotopy is exact up to rounding: never worse than the iterative reference.
        prop_assert!(f_h <= f_cd + 1e-12 * (1.0 + f_cd.abs()), "objective {f_h} vs {f_cd}");
        // Where the reference has converged too, both find the same (unique) minimiser.
        if kkt_violation(&columns, &b, lambda, &reference) <= 1e-10 {
            prop_assert!((f_h - f_cd).abs() <= 1e-9 * (1.0 + f_cd.abs()), "objective {f_h} vs {f_cd}");
            for (x, y) in w.iter().zip(&reference) {
                prop_assert!((x - y).abs() <= 1e-6, "homotopy {w:?}\nreference {reference:?}");
            }
        }
    }
}

#[test]
fn kkt_holds_on_two_thousand_matcher_like_columns() {
    // Columns shaped like the matcher's: two angles in [0, π/2], overlap in [0, 1],
    // length ratio ≥ 1; b = [0, 0, 1, 1].
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let columns: Vec<[f64; 4]> = (0..2000)
        .map(|_| {
            [
                rng.random_range(0.0..1.57),
                rng.random_range(0.0..1.57),
                rng.random_range(0.0..1.0),
                rng.random_range(1.0..5.0),
            ]
        })
        .collect();
    let b = [0.0, 0.0, 1.0, 1.0];
    for lambda in [0.01, 0.1, 1.0] {
        let (w, _) = solve4(&columns, &b, lambda);
        assert!(kkt_violation(&columns, &b, lambda, &w) <= KKT_TOL);
    }
}

#[test]
fn lambda_above_the_largest_correlation_gives_zero() {
    let columns = [[1.0, 0.0, 0.0, 0.0], [0.0, 2.0, 0.0, 0.0]];
    let b = [1.0, 1.0, 0.0, 0.0];
    // λ_max = max |Aᵀb| = 2.
    let (w, stats) = solve4(&columns, &b, 2.0);
    assert_eq!(w, vec![0.0, 0.0]);
    assert_eq!(stats.active, 0);
    let (w, _) = solve4(&columns, &b, 1.5);
    assert!(
        w[1] > 0.0 && w[0] == 0.0,
        "only the most correlated column is active: {w:?}"
    );
}

#[test]
fn orthonormal_columns_give_soft_thresholded_weights() {
    // With orthonormal columns the lasso is separable: ω_j = soft(c_j, λ).
    let columns = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
    ];
    let b = [3.0, -0.5, 1.0, 7.0];
    let (w, _) = solve4(&columns, &b, 0.8);
    let expected = [2.2, 0.0, 0.2];
    for (x, y) in w.iter().zip(expected) {
        assert!((x - y).abs() < 1e-12, "{w:?}");
    }
}

#[test]
fn duplicate_columns_stay_optimal() {
    let column = [0.1, 0.2, 1.0, 1.0];
    let columns = [column, column, [0.9, 0.3, 0.2, 3.0], column];
    let b = [0.0, 0.0, 1.0, 1.0];
    let (w, _) = solve4(&columns, &b, 0.1);
    assert!(kkt_violation(&columns, &b, 0.1, &w) <= KKT_TOL);
    let total: f64 = [w[0], w[1], w[3]].iter().sum();
    assert!(total > 0.5, "the duplicated atom carries the fit: {w:?}");
}

#[test]
fn empty_problem_and_zero_target_give_zero() {
    let (w, stats) = solve4(&[], &[0.0, 0.0, 1.0, 1.0], 0.1);
    assert!(w.is_empty());
    assert_eq!(stats, SolveStats::default());
    let (w, _) = solve4(&[[1.0, 2.0, 3.0, 4.0]], &[0.0; 4], 0.1);
    assert_eq!(w, vec![0.0]);
}

#[test]
fn bad_input_is_refused_with_the_culprit() {
    let mut solver = Homotopy::<4>::new();
    let good = [[1.0, 0.0, 0.0, 0.0]];
    let b = [1.0, 0.0, 0.0, 0.0];
    let mut w = [0.0];
    assert!(
        matches!(solver.solve(&good, &b, f64::NAN, &mut w), Err(LassoError::InvalidLambda(v)) if v.is_nan())
    );
    assert!(matches!(
        solver.solve(&good, &b, -1.0, &mut w),
        Err(LassoError::InvalidLambda(_))
    ));
    assert_eq!(
        solver.solve(&good, &b, 0.1, &mut [0.0, 0.0]),
        Err(LassoError::LengthMismatch {
            columns: 1,
            weights: 2
        })
    );
    let bad = [[1.0, 0.0, 0.0, 0.0], [0.0, f64::INFINITY, 0.0, 0.0]];
    assert_eq!(
        solver.solve(&bad, &b, 0.1, &mut [0.0, 0.0]),
        Err(LassoError::NonFinite { column: Some(1) })
    );
    assert_eq!(
        solver.solve(&good, &[f64::NAN, 0.0, 0.0, 0.0], 0.1, &mut w),
        Err(LassoError::NonFinite { column: None })
    );
}

#[test]
fn solver_is_reusable_across_problem_sizes() {
    let mut solver = Homotopy::<4>::new();
    for (seed, n) in [(1, 50), (2, 3), (3, 120), (4, 1)] {
        let (columns, b) = random_problem(seed, n, false);
        let mut w = vec![0.0; n];
        solver.solve(&columns, &b, 0.05, &mut w).unwrap();
        assert!(kkt_violation(&columns, &b, 0.05, &w) <= KKT_TOL);
    }
}

#[test]
fn a_column_that_left_can_rejoin_with_the_opposite_sign() {
    // Found by `agrees_with_coordinate_descent`: column 1 leaves the active set at
    // λ ≈ 1.84 and its correlation then crosses to the opposite boundary before λ = 0.01.
    // Keeping it out for the whole next step left the KKT conditions violated by 0.62.
    let (columns, b) = random_problem(16945050632794242499, 4, false);
    let (w, _) = solve4(&columns, &b, 0.01);
    assert!(kkt_violation(&columns, &b, 0.01, &w) <= KKT_TOL);
    let reference = coordinate_descent(&columns, &b, 0.01);
    for (x, y) in w.iter().zip(&reference) {
        assert!((x - y).abs() <= 1e-6, "{w:?} vs {reference:?}");
    }
}
