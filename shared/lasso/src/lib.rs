//! Homotopy (LARS-lasso) solver for
//!
//! ```text
//! min_ω  λ‖ω‖₁ + ½‖Aω − b‖₂²
//! ```
//!
//! where `A` has a small, fixed number of rows `R` (the ℓ1 line matcher uses `R = 4`: one
//! row per geometric term) and any number of columns (one per candidate segment).
//!
//! The solver follows the solution path from ω = 0 at λ_max = ‖Aᵀb‖∞ down to the requested
//! λ, one breakpoint at a time (Efron et al.'s LARS with the lasso modification; the
//! homotopy of Osborne et al., Donoho & Tsaig 2008, Asif & Romberg 2008). At each breakpoint
//! one column joins or leaves the active set. Between breakpoints the active weights move
//! along the direction `d = (A_Sᵀ A_S)⁻¹ sign(c_S)` that keeps every active correlation
//! `c_j = A_jᵀ(b − Aω)` at exactly ±λ. With `R` rows at most `R` columns are ever active, so
//! each step costs one `R × R` solve plus one pass over the columns: `O(R·n)`.
//!
//! The solver owns its scratch buffers and does not allocate once they have grown to the
//! largest problem it has seen; the caller owns the output weights.
#![warn(missing_docs)]

/// Relative pivot below which a joining column is treated as linearly dependent on the
/// active ones (its correlation then moves with theirs, so leaving it out keeps the
/// optimality conditions).
const DEPENDENCE_TOLERANCE: f64 = 1e-10;

/// Breakpoints at most, per solve, before giving up (a path over `R` rows normally has
/// well under `4·R` breakpoints; this bound only guards against cycling on ties).
const STEPS_PER_ROW: usize = 16;

/// What went wrong in a solve.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LassoError {
    /// λ must be finite and non-negative.
    #[error("lambda must be finite and >= 0, got {0}")]
    InvalidLambda(f64),
    /// The output slice must have one entry per column.
    #[error("weights buffer has {weights} entries for {columns} columns")]
    LengthMismatch {
        /// Number of columns of A.
        columns: usize,
        /// Length of the weights buffer given.
        weights: usize,
    },
    /// A or b holds NaN or an infinity.
    #[error("non-finite entry in {}", column.map_or("b".to_string(), |c| format!("column {c} of A")))]
    NonFinite {
        /// Index of the offending column, `None` for b.
        column: Option<usize>,
    },
    /// The path did not reach λ within the step limit (cycling on exact ties).
    #[error("homotopy stopped after {steps} steps at lambda {reached} before reaching {target}")]
    StepLimit {
        /// Steps taken.
        steps: usize,
        /// The λ the path had reached (the weights are optimal for it).
        reached: f64,
        /// The λ asked for.
        target: f64,
    },
}

/// How a solve went.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SolveStats {
    /// Breakpoints crossed on the way from λ_max to λ.
    pub steps: usize,
    /// Columns active (non-zero weight) at the end.
    pub active: usize,
}

/// Reusable homotopy solver for problems with `R` rows.
#[derive(Debug, Clone, Default)]
pub struct Homotopy<const R: usize> {
    /// Correlations `c_j = A_jᵀ (b − Aω)`, updated along the path.
    correlation: Vec<f64>,
    /// `a_j = A_jᵀ A_S d`: how fast each correlation falls per unit of λ, this step.
    rate: Vec<f64>,
    /// Columns found linearly dependent on the active set during this solve.
    dependent: Vec<usize>,
}

/// The active set: at most `R` column indices with their current sign.
#[derive(Debug, Clone, Copy)]
struct ActiveSet<const R: usize> {
    index: [usize; R],
    sign: [f64; R],
    len: usize,
}

impl<const R: usize> ActiveSet<R> {
    fn contains(&self, j: usize) -> bool {
        self.index[..self.len].contains(&j)
    }

    fn push(&mut self, j: usize, sign: f64) {
        self.index[self.len] = j;
        self.sign[self.len] = sign;
        self.len += 1;
    }

    fn remove(&mut self, slot: usize) {
        self.index.copy_within(slot + 1..self.len, slot);
        self.sign.copy_within(slot + 1..self.len, slot);
        self.len -= 1;
    }
}

/// Where the path meets its next breakpoint.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Event {
    /// λ reaches the target.
    Target,
    /// The active column in this slot reaches zero weight and leaves.
    Leave(usize),
    /// This inactive column's correlation reaches ±λ and it joins.
    Join(usize),
}

impl<const R: usize> Homotopy<R> {
    /// A solver with empty scratch buffers.
    pub fn new() -> Self {
        Self {
            correlation: Vec::new(),
            rate: Vec::new(),
            dependent: Vec::new(),
        }
    }

    /// Solves `min λ‖ω‖₁ + ½‖Aω − b‖²` for `A = [columns…]`, writing ω into `weights`
    /// (one entry per column; entries of inactive columns are exactly 0).
    pub fn solve(
        &mut self,
        columns: &[[f64; R]],
        b: &[f64; R],
        lambda: f64,
        weights: &mut [f64],
    ) -> Result<SolveStats, LassoError> {
        if !(lambda.is_finite() && lambda >= 0.0) {
            return Err(LassoError::InvalidLambda(lambda));
        }
        if weights.len() != columns.len() {
            return Err(LassoError::LengthMismatch {
                columns: columns.len(),
                weights: weights.len(),
            });
        }
        if !b.iter().all(|v| v.is_finite()) {
            return Err(LassoError::NonFinite { column: None });
        }
        if let Some(bad) = columns
            .iter()
            .position(|c| !c.iter().all(|v| v.is_finite()))
        {
            return Err(LassoError::NonFinite { column: Some(bad) });
        }
        weights.fill(0.0);
        self.dependent.clear();
        self.correlation.clear();
        self.correlation.extend(columns.iter().map(|c| dot(c, b)));

        let Some((first, level)) = arg_max_abs(&self.correlation) else {
            return Ok(SolveStats::default());
        };
        // `level` is the current λ on the path: every active correlation equals ±level.
        let mut level = level;
        if level <= lambda {
            return Ok(SolveStats::default());
        }
        let mut active = ActiveSet::<R> {
            index: [0; R],
            sign: [0.0; R],
            len: 0,
        };
        active.push(first, self.correlation[first].signum());
        let mut just_left: Option<usize> = None;
        let max_steps = STEPS_PER_ROW * R.max(1);

        for step in 1..=max_steps {
            let direction = active_direction(columns, &active);
            // u = A_S d: how the fit moves per unit of λ decrease.
            let mut fit_rate = [0.0; R];
            for slot in 0..active.len {
                axpy(direction[slot], &columns[active.index[slot]], &mut fit_rate);
            }

            let mut gamma = level - lambda;
            let mut event = Event::Target;
            for slot in 0..active.len {
                let w = weights[active.index[slot]];
                let d = direction[slot];
                if w * d < 0.0 {
                    let to_zero = -w / d;
                    if to_zero < gamma {
                        gamma = to_zero;
                        event = Event::Leave(slot);
                    }
                }
            }
            self.rate.clear();
            self.rate
                .extend(columns.iter().map(|column| dot(column, &fit_rate)));
            for (j, (&a, &c)) in self.rate.iter().zip(&self.correlation).enumerate() {
                if active.contains(j) || self.dependent.contains(&j) {
                    continue;
                }
                // c_j − γ a_j = ±(level − γ); numerators are ≥ 0 because |c_j| ≤ level.
                // A column that has just left sits on the boundary of its old sign: it may
                // only come back through the opposite one (else it would rejoin at γ = 0).
                let boundaries = [(level - c, 1.0 - a, 1.0), (level + c, 1.0 + a, -1.0)];
                for (numerator, denominator, side) in boundaries {
                    if just_left == Some(j) && side == c.signum() {
                        continue;
                    }
                    // `numerator / denominator < gamma`, compared without dividing: most
                    // columns are not the next to join, and a division costs more.
                    if denominator > 0.0 && numerator.max(0.0) < gamma * denominator {
                        gamma = numerator.max(0.0) / denominator;
                        event = Event::Join(j);
                    }
                }
            }

            // Move to the breakpoint.
            for slot in 0..active.len {
                weights[active.index[slot]] += gamma * direction[slot];
            }
            for (c, a) in self.correlation.iter_mut().zip(&self.rate) {
                *c -= gamma * a;
            }
            level -= gamma;
            for slot in 0..active.len {
                self.correlation[active.index[slot]] = active.sign[slot] * level;
            }
            just_left = None;

            match event {
                Event::Target => {
                    return Ok(SolveStats {
                        steps: step,
                        active: active.len,
                    });
                }
                Event::Leave(slot) => {
                    let j = active.index[slot];
                    weights[j] = 0.0;
                    active.remove(slot);
                    just_left = Some(j);
                }
                Event::Join(j) => {
                    if active.len < R && !makes_singular(columns, &active, j) {
                        active.push(j, self.correlation[j].signum());
                    } else {
                        self.dependent.push(j);
                    }
                }
            }
            if active.len == 0 {
                // Every weight left: restart from the largest correlation at this level.
                match arg_max_abs(&self.correlation) {
                    Some((j, c)) if c > lambda => {
                        level = c;
                        active.push(j, self.correlation[j].signum());
                    }
                    _ => {
                        return Ok(SolveStats {
                            steps: step,
                            active: 0,
                        });
                    }
                }
            }
        }
        Err(LassoError::StepLimit {
            steps: max_steps,
            reached: level,
            target: lambda,
        })
    }
}

fn dot<const R: usize>(a: &[f64; R], b: &[f64; R]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn axpy<const R: usize>(alpha: f64, x: &[f64; R], y: &mut [f64; R]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += alpha * xi;
    }
}

fn arg_max_abs(values: &[f64]) -> Option<(usize, f64)> {
    values
        .iter()
        .map(|v| v.abs())
        .enumerate()
        .fold(None, |best, (j, v)| match best {
            Some((_, b)) if b >= v => best,
            _ => Some((j, v)),
        })
}

/// Gram matrix of the active columns (top-left `len × len` block used).
fn active_gram<const R: usize>(columns: &[[f64; R]], active: &ActiveSet<R>) -> [[f64; R]; R] {
    let mut gram = [[0.0; R]; R];
    for p in 0..active.len {
        for q in 0..=p {
            let g = dot(&columns[active.index[p]], &columns[active.index[q]]);
            gram[p][q] = g;
            gram[q][p] = g;
        }
    }
    gram
}

/// Solves `(A_Sᵀ A_S) d = sign_S`. The active set is kept linearly independent, so the
/// Cholesky factorisation succeeds.
fn active_direction<const R: usize>(columns: &[[f64; R]], active: &ActiveSet<R>) -> [f64; R] {
    let mut factor = active_gram(columns, active);
    // Independence was checked when each column joined; a failure here can only come from
    // rounding, and the tiny pivot is then clamped rather than dividing by zero.
    let _ = cholesky_in_place(&mut factor, active.len);
    let mut x = active.sign;
    cholesky_solve(&factor, active.len, &mut x);
    x
}

/// Whether adding column `j` to the active set would make its Gram matrix singular.
fn makes_singular<const R: usize>(columns: &[[f64; R]], active: &ActiveSet<R>, j: usize) -> bool {
    let mut grown = *active;
    grown.push(j, 1.0);
    let mut gram = active_gram(columns, &grown);
    !cholesky_in_place(&mut gram, grown.len)
}

#[allow(clippy::needless_range_loop)] // index-based triangular algebra reads clearer
/// Lower Cholesky factor of the leading `n × n` block, in place. Returns false when a
/// pivot is not clearly positive (the block is singular or nearly so).
fn cholesky_in_place<const R: usize>(m: &mut [[f64; R]; R], n: usize) -> bool {
    let mut ok = true;
    for k in 0..n {
        let scale = m[k][k].abs().max(f64::MIN_POSITIVE);
        let mut pivot = m[k][k];
        for p in 0..k {
            pivot -= m[k][p] * m[k][p];
        }
        if !(pivot > DEPENDENCE_TOLERANCE * scale) {
            ok = false;
            pivot = DEPENDENCE_TOLERANCE * scale;
        }
        let root = pivot.sqrt();
        m[k][k] = root;
        for i in k + 1..n {
            let mut v = m[i][k];
            for p in 0..k {
                v -= m[i][p] * m[k][p];
            }
            m[i][k] = v / root;
        }
    }
    ok
}

/// Solves `L Lᵀ x = x` for the factor left by [`cholesky_in_place`].
fn cholesky_solve<const R: usize>(l: &[[f64; R]; R], n: usize, x: &mut [f64; R]) {
    for i in 0..n {
        let mut v = x[i];
        for p in 0..i {
            v -= l[i][p] * x[p];
        }
        x[i] = v / l[i][i];
    }
    for i in (0..n).rev() {
        let mut v = x[i];
        for p in i + 1..n {
            v -= l[p][i] * x[p];
        }
        x[i] = v / l[i][i];
    }
}

#[cfg(test)]
mod tests;
