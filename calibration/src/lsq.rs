//! Bounded non-linear least squares: a trust-region reflective method (the solver family the
//! paper used, SciPy's `least_squares(method = "trf")`), with parameter uncertainties.
//!
//! Minimises `0.5 |f(x)|^2` subject to `lower <= x <= upper`. The algorithm follows Branch,
//! Coleman and Li (SIAM J. Sci. Comput. 21(1), 1999) and Moré (1978):
//!
//! - Coleman-Li scaling: near an active bound the variable is scaled by the square root of its
//!   distance to that bound, so the iteration stays strictly feasible and approaches the bound
//!   smoothly; the scaled problem gets the extra diagonal term `g dv`.
//! - In the scaled variables the trust-region subproblem is solved exactly from an SVD of the
//!   augmented Jacobian (Moré's iteration for the Levenberg-Marquardt parameter).
//! - A step that would leave the box is replaced by the best of three 1-D minimisations of the
//!   quadratic model: the step cut back to the bound (times `theta` < 1), its reflection off the
//!   bound, and the scaled steepest-descent direction.
//! - Variables are scaled by the Jacobian's column norms (`x_scale = "jac"`), so parameters of
//!   very different magnitude (a length in mm, a tendon-map coefficient of 1e-3 1/mm^2) are
//!   treated alike.
//!
//! After convergence [`Fit::covariance`] is `s^2 (J^T J)^-1` with `s^2 = 2 cost / (m - n)`, from
//! which the standard errors and the correlation matrix come.
//!
//! [`solve`] reads as the outline of the iteration; its pieces are one file each: `solver.rs`
//! (the iteration's state: start, step search, acceptance, convergence test), `step.rs` (the
//! trust-region subproblem and its step inside the box) and `bounds.rs` (the box and the
//! Coleman-Li scaling).

mod bounds;
mod solver;
mod step;

use nalgebra::DMatrix;
use solver::Solver;

/// Why a least-squares problem could not be solved.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LsqError {
    /// The starting point, bounds or sizes are inconsistent.
    #[error("least squares set-up: {0}")]
    Setup(String),
    /// The residuals could not be evaluated at the starting point.
    #[error("the model cannot be evaluated at the starting point: {0}")]
    StartUndefined(String),
    /// The residuals or the Jacobian hold a NaN or an infinity at an accepted point.
    #[error("the model returned a non-finite value at an accepted point")]
    NonFinite,
}

/// Why the iteration stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// The scaled gradient is below `gtol`.
    Gradient,
    /// The relative cost reduction is below `ftol`.
    Cost,
    /// The relative step is below `xtol`.
    Step,
    /// Both `ftol` and `xtol` were met.
    CostAndStep,
    /// The cost fell by less than `stall_ftol` of itself over the last `stall_window` steps
    /// taken ([`Options::stall_window`]).
    Stalled,
    /// The evaluation budget ran out.
    MaxEvaluations,
}

impl Status {
    /// Whether the status is a convergence (not a budget exhaustion).
    pub fn converged(self) -> bool {
        self != Status::MaxEvaluations
    }
}

/// Solver settings (the defaults are SciPy's).
#[derive(Debug, Clone, Copy)]
pub struct Options {
    /// Relative cost-reduction tolerance.
    pub ftol: f64,
    /// Relative step tolerance.
    pub xtol: f64,
    /// Tolerance on the scaled gradient's infinity norm.
    pub gtol: f64,
    /// Largest number of residual evaluations (Jacobian evaluations not counted).
    pub max_evaluations: usize,
    /// Whether the Jacobian is evaluated at the point the solver ends on (SciPy's way, and the
    /// default: [`Fit::jacobian`] is the optimum's, as an error estimate needs). Off, a step
    /// that meets the convergence test is taken without one, and [`Fit::jacobian`] is the
    /// Jacobian at the point before that step: a caller that reads only the optimum saves an
    /// evaluation of the Jacobian (the joint refinements of `pcr_residuals`, where it costs
    /// several evaluations of the model). The optimum is the same either way.
    pub jacobian_at_end: bool,
    /// The initial trust-region radius as a multiple of the starting point's length in the
    /// scaled variables (MINPACK's `factor`; 1 is SciPy's `trf`, MINPACK's default is 100).
    pub initial_radius_factor: f64,
    /// Steps taken over which the cost must fall by at least `stall_ftol` of itself, or the
    /// iteration ends ([`Status::Stalled`]); 0 (the default): no such test. Where the residuals
    /// are not smooth at the level of the last steps' gains (a model solved iteratively, each
    /// evaluation from the last one's solution), the solver otherwise crawls along a flat
    /// valley with steps that each gain just more than `ftol`, some of them refused.
    pub stall_window: usize,
    /// See [`Options::stall_window`].
    pub stall_ftol: f64,
    /// Whether a step that does not lower the cost also ends the iteration when both its
    /// actual and its predicted reduction are within `ftol` of the cost (MINPACK's `lmdif` test,
    /// `|actred| <= ftol` and `prered <= ftol`, which it makes whether or not the step is taken;
    /// SciPy's `trf`, the default, tests taken steps alone and shrinks the radius instead).
    /// Where the residuals carry noise above the quadratic model's gain at the optimum (a model
    /// solved iteratively), SciPy's test refuses step after step, each a quarter of the last,
    /// until one gains by chance.
    pub ftol_refused: bool,
    /// Steps taken in a row after an evaluated Jacobian whose Jacobian is Broyden's rank-one
    /// update of the last one instead ([`Problem::secant_column`]: the columns it may
    /// change; the others are the problem's own, constant); 0 (the default): every step
    /// taken evaluates the Jacobian. The Jacobian at the end ([`Options::jacobian_at_end`])
    /// is evaluated, never a secant one; without it, [`Fit::jacobian`] (the point's before the
    /// last step) may be. Where a Jacobian costs more than an evaluation of the
    /// residuals (a model solved iteratively, with its responses at every row), the steps
    /// after the first few move along directions the last Jacobian nearly has.
    pub secant_steps: usize,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            ftol: 1e-8,
            xtol: 1e-8,
            gtol: 1e-8,
            max_evaluations: 1000,
            jacobian_at_end: true,
            initial_radius_factor: 1.0,
            stall_window: 0,
            stall_ftol: 0.0,
            ftol_refused: false,
            secant_steps: 0,
        }
    }
}

/// A least-squares problem: residuals and (optionally) their Jacobian.
pub trait Problem {
    /// Number of residuals m.
    fn residual_count(&self) -> usize;

    /// Writes the residuals at `x` into `r` (length m). `Err` with a reason where the model is
    /// undefined (the solver then shrinks its step).
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), String>;

    /// Writes the m x n Jacobian at `x` (residuals `r` already evaluated there) into `j`.
    /// The default is a forward difference that steps away from a nearby upper bound.
    fn jacobian(
        &mut self,
        x: &[f64],
        r: &[f64],
        upper: &[f64],
        j: &mut DMatrix<f64>,
    ) -> Result<(), String> {
        forward_difference(self, x, r, upper, j)
    }

    /// Whether a secant step may change column `c` of the Jacobian ([`Options::secant_steps`];
    /// the default: every column). Where the residuals are linear in some parameters (their
    /// columns constant), Broyden's update of the others alone keeps those exact and still
    /// meets the secant condition.
    fn secant_column(&self, _c: usize) -> bool {
        true
    }
}

/// Forward-difference Jacobian (relative step sqrt(eps), at least sqrt(eps) absolute), stepping
/// backwards where the forward step would cross `upper`.
pub fn forward_difference<P: Problem + ?Sized>(
    p: &mut P,
    x: &[f64],
    r: &[f64],
    upper: &[f64],
    j: &mut DMatrix<f64>,
) -> Result<(), String> {
    let mut xp = x.to_vec();
    let mut rp = vec![0.0; r.len()];
    for k in 0..x.len() {
        xp[k] = x[k] + difference_step(x, upper, k);
        let h = xp[k] - x[k];
        p.residuals(&xp, &mut rp)?;
        for i in 0..r.len() {
            j[(i, k)] = (rp[i] - r[i]) / h;
        }
        xp[k] = x[k];
    }
    Ok(())
}

/// Residuals at `x` written into `r` through a shared reference
/// ([`forward_difference_parallel`]).
pub type SharedResiduals<'a> = dyn Fn(&[f64], &mut [f64]) -> Result<(), String> + Sync + 'a;

/// [`forward_difference`] of residuals that a shared reference evaluates (`residuals(x, r)`),
/// the columns in parallel: the same steps and the same numbers, to the bit. For problems whose
/// evaluation holds no state of its own (the calibration's), where a Jacobian's columns are
/// most of a fit's time.
pub fn forward_difference_parallel(
    residuals: &SharedResiduals,
    x: &[f64],
    r: &[f64],
    upper: &[f64],
    j: &mut DMatrix<f64>,
) -> Result<(), String> {
    use rayon::prelude::*;
    let columns: Vec<Vec<f64>> = (0..x.len())
        .into_par_iter()
        .map(|k| {
            let mut xp = x.to_vec();
            xp[k] = x[k] + difference_step(x, upper, k);
            let h = xp[k] - x[k];
            let mut rp = vec![0.0; r.len()];
            residuals(&xp, &mut rp)?;
            Ok(rp.iter().zip(r).map(|(a, b)| (a - b) / h).collect())
        })
        .collect::<Result<_, String>>()?;
    for (k, c) in columns.iter().enumerate() {
        j.column_mut(k).copy_from_slice(c);
    }
    Ok(())
}

/// A least-squares problem whose residuals a shared reference evaluates (it keeps no state
/// between evaluations): solved as [`InParallel`], its Jacobian's columns are evaluated in
/// parallel.
pub trait SharedProblem: Sync {
    /// Number of residuals m.
    fn residual_count(&self) -> usize;

    /// Writes the residuals at `x` into `r` ([`Problem::residuals`]).
    fn residuals_at(&self, x: &[f64], r: &mut [f64]) -> Result<(), String>;
}

/// A [`SharedProblem`] as a [`Problem`] whose forward-difference Jacobian's columns are
/// evaluated in parallel ([`forward_difference_parallel`]): the same fit, to the bit.
pub struct InParallel<P>(pub P);

impl<P: SharedProblem> Problem for InParallel<P> {
    fn residual_count(&self) -> usize {
        self.0.residual_count()
    }

    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), String> {
        self.0.residuals_at(x, r)
    }

    fn jacobian(
        &mut self,
        x: &[f64],
        r: &[f64],
        upper: &[f64],
        j: &mut DMatrix<f64>,
    ) -> Result<(), String> {
        forward_difference_parallel(&|x, r| self.0.residuals_at(x, r), x, r, upper, j)
    }
}

/// The forward-difference step of parameter `k` at `x` ([`forward_difference`]).
fn difference_step(x: &[f64], upper: &[f64], k: usize) -> f64 {
    let h = f64::EPSILON.sqrt() * x[k].abs().max(1.0);
    if x[k] + h > upper[k] {
        -h
    } else {
        h
    }
}

/// The result of a fit.
#[derive(Debug, Clone)]
pub struct Fit {
    /// The optimum.
    pub x: Vec<f64>,
    /// Residuals at the optimum.
    pub residuals: Vec<f64>,
    /// 0.5 |f|^2 at the optimum.
    pub cost: f64,
    /// Jacobian at the optimum (m x n); with [`Options::jacobian_at_end`] off, where the last
    /// step (the one that met the convergence test) started.
    pub jacobian: DMatrix<f64>,
    /// Why it stopped.
    pub status: Status,
    /// Residual evaluations.
    pub evaluations: usize,
    /// Jacobian evaluations (accepted steps + 1).
    pub jacobians: usize,
    /// Which parameters ended on a bound (within 1e-10 relative).
    pub at_bound: Vec<bool>,
}

impl Fit {
    /// Root mean square of the residuals.
    pub fn rms(&self) -> f64 {
        (2.0 * self.cost / self.residuals.len().max(1) as f64).sqrt()
    }

    /// Residual variance estimate s^2 = |f|^2 / (m - n) (`None` when m <= n).
    pub fn residual_variance(&self) -> Option<f64> {
        let (m, n) = (self.residuals.len(), self.x.len());
        (m > n).then(|| 2.0 * self.cost / (m - n) as f64)
    }

    /// Covariance of the parameters, s^2 (J^T J)^+ (pseudo-inverse through an SVD; directions
    /// the data do not determine get no variance and are reported by [`Fit::rank`]).
    pub fn covariance(&self) -> Option<DMatrix<f64>> {
        let s2 = self.residual_variance()?;
        let svd = self.jacobian.clone().svd(false, true);
        let vt = svd.v_t?;
        let smax = svd.singular_values.max();
        let n = self.x.len();
        let tol = smax * f64::EPSILON * (self.residuals.len().max(n) as f64);
        let mut cov = DMatrix::zeros(n, n);
        for (k, &s) in svd.singular_values.iter().enumerate() {
            if s > tol {
                let v = vt.row(k).transpose();
                cov += (&v * v.transpose()) * (s2 / (s * s));
            }
        }
        Some(cov)
    }

    /// Numerical rank of the Jacobian at the optimum.
    pub fn rank(&self) -> usize {
        let sv = self.jacobian.clone().singular_values();
        let smax = sv.max();
        let tol = smax * f64::EPSILON * (self.residuals.len().max(self.x.len()) as f64);
        sv.iter().filter(|s| **s > tol).count()
    }

    /// Standard errors of the parameters (square roots of the covariance diagonal).
    pub fn standard_errors(&self) -> Option<Vec<f64>> {
        let c = self.covariance()?;
        Some(
            (0..self.x.len())
                .map(|k| c[(k, k)].max(0.0).sqrt())
                .collect(),
        )
    }

    /// Correlation matrix of the parameters.
    pub fn correlation(&self) -> Option<DMatrix<f64>> {
        let c = self.covariance()?;
        let n = self.x.len();
        Some(DMatrix::from_fn(n, n, |i, j| {
            let d = (c[(i, i)] * c[(j, j)]).sqrt();
            if d > 0.0 {
                c[(i, j)] / d
            } else if i == j {
                1.0
            } else {
                0.0
            }
        }))
    }
}

/// Solves the bounded problem from `x0`. Infinite bounds are allowed; `x0` is moved strictly
/// inside the box first.
pub fn solve<P: Problem + ?Sized>(
    p: &mut P,
    x0: &[f64],
    lower: &[f64],
    upper: &[f64],
    opt: &Options,
) -> Result<Fit, LsqError> {
    let m = p.residual_count();
    check_setup(x0, lower, upper, m)?;
    let mut solver = Solver::start(p, x0, lower, upper, m, opt)?;
    // The cost after each step taken, the start's first (the stall test).
    let mut costs = vec![solver.cost()];
    let status = loop {
        let (v, dv) = solver.coleman_li_scaling();
        let g_norm = solver.scaled_gradient_norm(&v);
        if g_norm < opt.gtol {
            break Status::Gradient;
        }
        if solver.budget_spent() {
            break Status::MaxEvaluations;
        }
        let sub = solver.subproblem(v, &dv, g_norm)?;
        let mut search = solver.search_step(&sub);
        if search.lowered_cost() && search.status.is_none() && opt.stall_window > 0 {
            let now = solver.cost() - search.actual_reduction;
            costs.push(now);
            let (n, w) = (costs.len(), opt.stall_window);
            if n > w && costs[n - 1 - w] - now < opt.stall_ftol * now {
                search.status = Some(Status::Stalled);
            }
        }
        if search.lowered_cost() && search.status.is_some() && !opt.jacobian_at_end {
            solver.take_trial();
        } else if search.lowered_cost() {
            // The optimum's Jacobian is evaluated, never a secant one.
            solver.accept_trial(search.status.is_some())?;
        } else if search.status.is_none() && solver.budget_spent() {
            break Status::MaxEvaluations;
        }
        if let Some(status) = search.status {
            break status;
        }
    };
    Ok(solver.into_fit(status))
}

/// Checks that `x0` and the bounds have the same non-zero length, that each start is finite
/// with `lower < upper`, and that the `m` residuals are at least as many as the parameters.
fn check_setup(x0: &[f64], lower: &[f64], upper: &[f64], m: usize) -> Result<(), LsqError> {
    let n = x0.len();
    if n == 0 || lower.len() != n || upper.len() != n {
        return Err(LsqError::Setup(format!(
            "{n} parameters, {} lower and {} upper bounds",
            lower.len(),
            upper.len()
        )));
    }
    for k in 0..n {
        if lower[k] >= upper[k] || lower[k].is_nan() || upper[k].is_nan() || !x0[k].is_finite() {
            return Err(LsqError::Setup(format!(
                "parameter {k}: start {} and bounds [{}, {}] are not a valid box",
                x0[k], lower[k], upper[k]
            )));
        }
    }
    if m < n {
        return Err(LsqError::Setup(format!(
            "{m} residuals cannot determine {n} parameters"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rosenbrock as least squares: f = (10 (x1 - x0^2), 1 - x0).
    struct Rosen;
    impl Problem for Rosen {
        fn residual_count(&self) -> usize {
            2
        }
        fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), String> {
            r[0] = 10.0 * (x[1] - x[0] * x[0]);
            r[1] = 1.0 - x[0];
            Ok(())
        }
    }

    const INF: f64 = f64::INFINITY;

    #[test]
    fn rosenbrock_unbounded_reaches_the_minimum() {
        let fit = solve(
            &mut Rosen,
            &[-1.2, 1.0],
            &[-INF; 2],
            &[INF; 2],
            &Options::default(),
        )
        .unwrap();
        assert!(fit.status.converged());
        assert!((fit.x[0] - 1.0).abs() < 1e-6 && (fit.x[1] - 1.0).abs() < 1e-6);
        assert!(fit.cost < 1e-12);
    }

    #[test]
    fn rosenbrock_with_an_active_bound() {
        // x1 <= 0.5 cuts off the minimum (1, 1); the constrained optimum has x1 = 0.5 and
        // x0 minimising 100 (0.5 - x0^2)^2 + (1 - x0)^2 (computed by hand: stationary point of
        // a quartic, x0 = 0.70597...).
        let fit = solve(
            &mut Rosen,
            &[-1.2, 0.0],
            &[-INF, -INF],
            &[INF, 0.5],
            &Options::default(),
        )
        .unwrap();
        assert!((fit.x[1] - 0.5).abs() < 1e-6, "{:?}", fit.x);
        assert!(fit.evaluations < 50, "{} evaluations", fit.evaluations);
        // d/dx0: -400 x0 (0.5 - x0^2) - 2 (1 - x0) = 0
        let x0 = fit.x[0];
        let grad = -400.0 * x0 * (0.5 - x0 * x0) - 2.0 * (1.0 - x0);
        assert!(grad.abs() < 1e-4, "x0 {x0} grad {grad}");
        assert!(fit.at_bound[1] || (fit.x[1] - 0.5).abs() < 1e-9);
        assert!(fit.x[1] <= 0.5);
    }

    /// Straight-line fit y = a + b t with known answer and standard errors.
    struct Line {
        t: Vec<f64>,
        y: Vec<f64>,
    }
    impl Problem for Line {
        fn residual_count(&self) -> usize {
            self.t.len()
        }
        fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), String> {
            for i in 0..self.t.len() {
                r[i] = x[0] + x[1] * self.t[i] - self.y[i];
            }
            Ok(())
        }
    }

    #[test]
    fn linear_fit_uncertainties_match_the_textbook_formula() {
        // t = 0..4, y = 1 + 2 t + e, e = (0.1, -0.2, 0.05, 0.15, -0.1)
        let t: Vec<f64> = (0..5).map(|k| k as f64).collect();
        let e = [0.1, -0.2, 0.05, 0.15, -0.1];
        let y: Vec<f64> = t.iter().zip(e).map(|(t, e)| 1.0 + 2.0 * t + e).collect();
        let mut p = Line { t, y };
        let fit = solve(
            &mut p,
            &[0.0, 0.0],
            &[-INF; 2],
            &[INF; 2],
            &Options::default(),
        )
        .unwrap();
        // Ordinary least squares by hand: tbar = 2, Stt = 10, ebar = 0
        // b = 2 + sum (t - 2) e / 10 = 2 + (-0.2 + 0.2 + 0 + 0.15 - 0.2) / 10 = 1.995
        // a = ybar - b tbar = 5 - 3.99 = 1.01
        assert!((fit.x[1] - 1.995).abs() < 1e-9, "{:?}", fit.x);
        assert!((fit.x[0] - 1.01).abs() < 1e-9);
        // Residuals and s^2 = SSR / 3; se(b) = s / sqrt(Stt), se(a) = s sqrt(1/5 + 4/10)
        let ssr: f64 = fit.residuals.iter().map(|r| r * r).sum();
        let s = (ssr / 3.0).sqrt();
        let se = fit.standard_errors().unwrap();
        assert!((se[1] - s / 10f64.sqrt()).abs() < 1e-9);
        assert!((se[0] - s * (0.2f64 + 0.4).sqrt()).abs() < 1e-9);
        // corr(a, b) = -tbar / sqrt(tbar^2 + Stt/n) = -2 / sqrt(4 + 2)
        let c = fit.correlation().unwrap();
        assert!((c[(0, 1)] + 2.0 / 6f64.sqrt()).abs() < 1e-7, "{c}");
    }

    /// A problem that counts its Jacobians (forward differences underneath).
    struct Counted<P>(P, usize);
    impl<P: Problem> Problem for Counted<P> {
        fn residual_count(&self) -> usize {
            self.0.residual_count()
        }
        fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), String> {
            self.0.residuals(x, r)
        }
        fn jacobian(
            &mut self,
            x: &[f64],
            r: &[f64],
            upper: &[f64],
            j: &mut DMatrix<f64>,
        ) -> Result<(), String> {
            self.1 += 1;
            forward_difference(&mut self.0, x, r, upper, j)
        }
    }

    /// y = a exp(b t) on 20 points, with a residual that no (a, b) takes away (the fits stop
    /// on the cost's change, not a zero gradient).
    struct Exp;
    impl Problem for Exp {
        fn residual_count(&self) -> usize {
            20
        }
        fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), String> {
            for (k, r) in r.iter_mut().enumerate() {
                let t = k as f64 / 10.0;
                *r = x[0] * (x[1] * t).exp() - 30.0 * (0.2 * t).exp() - 0.1 * (k as f64).sin();
            }
            Ok(())
        }
    }

    #[test]
    fn the_parallel_forward_difference_is_the_serial_one_to_the_bit() {
        // At a point and beside an upper bound (the step then goes backwards), and with a
        // residual that fails (the error comes back).
        let x = [1.3, 0.17];
        let mut r = vec![0.0; 20];
        Exp.residuals(&x, &mut r).unwrap();
        for upper in [[INF, INF], [INF, 0.17 + 1e-12]] {
            let mut serial = DMatrix::zeros(20, 2);
            forward_difference(&mut Exp, &x, &r, &upper, &mut serial).unwrap();
            let mut parallel = DMatrix::zeros(20, 2);
            let shared = |x: &[f64], r: &mut [f64]| Exp.residuals(x, r);
            forward_difference_parallel(&shared, &x, &r, &upper, &mut parallel).unwrap();
            assert_eq!(serial, parallel, "upper {upper:?}");
        }
        let failing = |_: &[f64], _: &mut [f64]| Err("undefined".to_string());
        let mut j = DMatrix::zeros(20, 2);
        let e = forward_difference_parallel(&failing, &x, &r, &[INF; 2], &mut j).unwrap_err();
        assert_eq!(e, "undefined");
    }

    /// [`Exp`] from (1, 0.1) with `opt`: the fit and the Jacobians it evaluated.
    fn exp_counted(opt: &Options) -> (Fit, usize) {
        let mut p = Counted(Exp, 0);
        let fit = solve(&mut p, &[1.0, 0.1], &[-INF; 2], &[INF; 2], opt).unwrap();
        (fit, p.1)
    }

    #[test]
    fn without_the_jacobian_at_the_end_the_optimum_is_the_same_for_one_jacobian_less() {
        let run = |jacobian_at_end| {
            exp_counted(&Options {
                jacobian_at_end,
                ..Options::default()
            })
        };
        let (with, n_with) = run(true);
        let (without, n_without) = run(false);
        assert!(matches!(with.status, Status::Cost | Status::CostAndStep));
        assert_eq!(with.x, without.x);
        assert_eq!(with.cost, without.cost);
        assert_eq!(with.evaluations, without.evaluations);
        assert_eq!(n_without + 1, n_with);
        assert_eq!(without.jacobians, n_without);
    }

    /// [`Exp`]'s analytic Jacobian into the first two columns of `j`.
    fn exp_jacobian(x: &[f64], j: &mut DMatrix<f64>) {
        for k in 0..20 {
            let t = k as f64 / 10.0;
            j[(k, 0)] = (x[1] * t).exp();
            j[(k, 1)] = x[0] * t * (x[1] * t).exp();
        }
    }

    /// [`Exp`] with a third parameter the residuals are linear in (an offset along a fixed
    /// column, as the joint refinement's calibration parameters), its analytic Jacobian
    /// counted; the secant steps may change the first two columns.
    struct ExpOffset(usize);
    impl ExpOffset {
        fn column(k: usize) -> f64 {
            (k as f64 * 0.7).cos()
        }
    }
    impl Problem for ExpOffset {
        fn residual_count(&self) -> usize {
            20
        }
        fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), String> {
            Exp.residuals(x, r)?;
            for (k, r) in r.iter_mut().enumerate() {
                *r += x[2] * Self::column(k) - 0.5 * (k as f64 * 0.7).cos().powi(2);
            }
            Ok(())
        }
        fn jacobian(
            &mut self,
            x: &[f64],
            _r: &[f64],
            _upper: &[f64],
            j: &mut DMatrix<f64>,
        ) -> Result<(), String> {
            self.0 += 1;
            exp_jacobian(x, j);
            for k in 0..20 {
                j[(k, 2)] = Self::column(k);
            }
            Ok(())
        }
        fn secant_column(&self, c: usize) -> bool {
            c < 2
        }
    }

    #[test]
    fn secant_steps_reach_the_optimum_with_fewer_jacobians_and_leave_the_linear_columns_exact() {
        let run = |secant_steps| {
            let mut p = ExpOffset(0);
            let opt = Options {
                secant_steps,
                ..Options::default()
            };
            let fit = solve(&mut p, &[1.0, 0.1, 0.0], &[-INF; 3], &[INF; 3], &opt).unwrap();
            (fit, p.0)
        };
        let (exact, n_exact) = run(0);
        let (secant, n_secant) = run(1);
        assert!(exact.status.converged() && secant.status.converged());
        for k in 0..3 {
            assert!(
                (exact.x[k] - secant.x[k]).abs() < 1e-5 * exact.x[k].abs().max(1.0),
                "{k}: {} against {}",
                secant.x[k],
                exact.x[k]
            );
        }
        assert!((secant.cost - exact.cost).abs() <= 1e-8 * exact.cost);
        assert!(n_secant < n_exact, "{n_secant} Jacobians against {n_exact}");
        assert_eq!(secant.jacobians, n_secant);
        // The offset's column is the problem's own after every update.
        for k in 0..20 {
            assert_eq!(secant.jacobian[(k, 2)], ExpOffset::column(k));
        }
    }

    /// [`Exp`] whose residuals carry a jitter (`amplitude` each, turning over as fast as
    /// `rate` says in each parameter) that the Jacobian (analytic) does not see: a model solved
    /// iteratively, each evaluation from the last one's solution.
    struct Jittered {
        amplitude: f64,
        rate: [f64; 2],
    }
    impl Problem for Jittered {
        fn residual_count(&self) -> usize {
            20
        }
        fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), String> {
            Exp.residuals(x, r)?;
            for (k, r) in r.iter_mut().enumerate() {
                *r += self.amplitude * (self.rate[0] * x[0] + self.rate[1] * x[1] + k as f64).sin();
            }
            Ok(())
        }
        fn jacobian(
            &mut self,
            x: &[f64],
            _r: &[f64],
            _upper: &[f64],
            j: &mut DMatrix<f64>,
        ) -> Result<(), String> {
            exp_jacobian(x, j);
            Ok(())
        }
    }

    #[test]
    fn a_stalled_cost_ends_the_iteration_near_the_optimum_in_fewer_evaluations() {
        let run = |stall_window, stall_ftol| {
            let opt = Options {
                stall_window,
                stall_ftol,
                initial_radius_factor: 100.0,
                ..Options::default()
            };
            let mut p = Jittered {
                amplitude: 3e-4,
                rate: [1e7, 1e6],
            };
            solve(&mut p, &[1.0, 0.1], &[-INF; 2], &[INF; 2], &opt).unwrap()
        };
        let full = run(0, 0.0);
        // Over two steps the cost must fall by 1 % of itself: the jitter's steps take less.
        let stalled = run(2, 1e-2);
        assert_eq!(stalled.status, Status::Stalled);
        assert!(stalled.status.converged());
        assert!(
            stalled.evaluations < full.evaluations,
            "{} against {} evaluations",
            stalled.evaluations,
            full.evaluations
        );
        assert!(
            stalled.cost < 1.02 * full.cost,
            "{} against {}",
            stalled.cost,
            full.cost
        );
    }

    /// [`Jittered`] by 1e-7 each: the jitter moves the cost (0.045) by about the tolerance of a
    /// relative 1e-6, so that near the optimum SciPy's test refuses step after step, each a
    /// quarter of the last, until one gains by chance or the step itself is below `xtol`;
    /// MINPACK's ends at the first refused step whose actual and predicted gains are within
    /// the tolerance (16 evaluations against 22).
    #[test]
    fn a_refused_step_within_the_tolerance_ends_the_iteration_at_the_optimum() {
        let run = |ftol_refused| {
            let opt = Options {
                ftol: 1e-6,
                xtol: 1e-14,
                ftol_refused,
                initial_radius_factor: 100.0,
                ..Options::default()
            };
            let mut p = Jittered {
                amplitude: 1e-7,
                rate: [1e9, 1e8],
            };
            solve(&mut p, &[1.0, 0.1], &[-INF; 2], &[INF; 2], &opt).unwrap()
        };
        let scipy = run(false);
        let minpack = run(true);
        assert!(minpack.status.converged() && scipy.status.converged());
        assert!(
            minpack.evaluations < scipy.evaluations,
            "{} against {} evaluations",
            minpack.evaluations,
            scipy.evaluations
        );
        // The same optimum to the tolerance.
        assert!(
            (minpack.cost - scipy.cost).abs() <= 1e-6 * scipy.cost,
            "{} against {}",
            minpack.cost,
            scipy.cost
        );
        for (a, b) in minpack.x.iter().zip(&scipy.x) {
            assert!(
                (a - b).abs() < 1e-4 * b.abs(),
                "{:?} {:?}",
                minpack.x,
                scipy.x
            );
        }
    }

    #[test]
    fn a_larger_first_radius_reaches_the_same_optimum_in_fewer_jacobians() {
        // Far from the optimum, SciPy's first radius (the start's length) makes the steps
        // grow by doubling; MINPACK's factor of 100 takes the Gauss-Newton steps at once.
        let run = |initial_radius_factor| {
            exp_counted(&Options {
                initial_radius_factor,
                ..Options::default()
            })
        };
        let (scipy, n_scipy) = run(1.0);
        let (minpack, n_minpack) = run(100.0);
        for (a, b) in scipy.x.iter().zip(&minpack.x) {
            assert!((a - b).abs() < 1e-6, "{:?} {:?}", scipy.x, minpack.x);
        }
        assert!((minpack.x[0] - 30.0).abs() < 0.1 && (minpack.x[1] - 0.2).abs() < 1e-2);
        assert!(
            n_minpack < n_scipy,
            "{n_minpack} against {n_scipy} Jacobians"
        );
    }

    #[test]
    fn bad_set_ups_are_errors() {
        let mut p = Line {
            t: vec![0.0],
            y: vec![1.0],
        };
        assert!(matches!(
            solve(
                &mut p,
                &[0.0, 0.0],
                &[-INF; 2],
                &[INF; 2],
                &Options::default()
            ),
            Err(LsqError::Setup(_))
        ));
        let mut p = Line {
            t: vec![0.0, 1.0, 2.0],
            y: vec![1.0, 2.0, 3.0],
        };
        assert!(matches!(
            solve(
                &mut p,
                &[0.0, 0.0],
                &[1.0, -INF],
                &[0.0, INF],
                &Options::default()
            ),
            Err(LsqError::Setup(_))
        ));
    }

    #[test]
    fn undefined_regions_shrink_the_step() {
        // sqrt model undefined for x < 0; the optimum x = 4 is approached from 0.5 through
        // steps that may overshoot into the undefined region.
        struct Sqrt;
        impl Problem for Sqrt {
            fn residual_count(&self) -> usize {
                2
            }
            fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), String> {
                if x[0] < 0.0 {
                    return Err("negative".into());
                }
                r[0] = x[0].sqrt() - 2.0;
                r[1] = 0.0;
                Ok(())
            }
        }
        let fit = solve(&mut Sqrt, &[0.5], &[-INF], &[INF], &Options::default()).unwrap();
        assert!((fit.x[0] - 4.0).abs() < 1e-6);
    }
}
