//! The state of the trust-region reflective iteration that [`super::solve`] drives: the current
//! point with its residuals, cost, Jacobian and gradient, the trial point, the variable scale,
//! the trust region, the evaluation counts, and the convergence test.

use super::bounds::Bounds;
use super::step::{update_radius, Step, Subproblem};
use super::{Fit, LsqError, Options, Problem, Status};
use nalgebra::{DMatrix, DVector};

/// The iteration between its start and its [`Fit`].
pub(super) struct Solver<'a, P: Problem + ?Sized> {
    problem: &'a mut P,
    /// The upper bounds as given (the Jacobian steps away from them).
    upper: &'a [f64],
    opt: &'a Options,
    bounds: Bounds,
    /// The current point, strictly inside the box.
    x: DVector<f64>,
    /// Residuals at `x`.
    f: DVector<f64>,
    /// 0.5 |f|^2.
    cost: f64,
    /// Jacobian at `x` (m x n).
    jac: DMatrix<f64>,
    /// Gradient J^T f.
    g: DVector<f64>,
    /// The trial point (a buffer, swapped with `x` when the step is taken).
    x_new: DVector<f64>,
    /// Residuals at the trial point (a buffer, swapped with `f`).
    f_new: DVector<f64>,
    /// Inverse scale of the variables: the Jacobian's column norms, never decreasing.
    scale_inv: DVector<f64>,
    /// Trust-region radius in the scaled variables.
    delta: f64,
    /// Levenberg-Marquardt parameter of the last step.
    alpha: f64,
    /// Residual evaluations.
    evaluations: usize,
    /// Jacobian evaluations.
    jacobians: usize,
    /// Secant steps left before the next Jacobian is evaluated ([`Options::secant_steps`]).
    secants_left: usize,
}

/// How a search for a step ended.
pub(super) struct Search {
    /// Cost reduction of the last step evaluated (-1 when none could be).
    pub(super) actual_reduction: f64,
    /// Set when the last step met the convergence test.
    pub(super) status: Option<Status>,
}

impl Search {
    /// Whether the last step lowered the cost (and is to be taken).
    pub(super) fn lowered_cost(&self) -> bool {
        self.actual_reduction > 0.0
    }
}

impl<'a, P: Problem + ?Sized> Solver<'a, P> {
    /// Evaluates the `m` residuals and the Jacobian at `x0` moved strictly inside the box, and
    /// sets the variable scale and the initial radius. The set-up is assumed checked.
    pub(super) fn start(
        problem: &'a mut P,
        x0: &[f64],
        lower: &[f64],
        upper: &'a [f64],
        m: usize,
        opt: &'a Options,
    ) -> Result<Self, LsqError> {
        let n = x0.len();
        let bounds = Bounds::new(lower, upper);
        let x = bounds.strictly_feasible(&DVector::from_column_slice(x0));
        let f = residuals_at_start(problem, &x, m)?;
        let jac = jacobian_at_start(problem, &x, &f, upper)?;
        let cost = 0.5 * f.norm_squared();
        let g = jac.tr_mul(&f);
        let scale_inv = column_scale(&jac);
        let (v, dv) = bounds.coleman_li_scaling(&x, &g);
        let delta = opt.initial_radius_factor
            * initial_radius(&x, &scaled_by_columns(v, &dv, &scale_inv), &scale_inv);
        Ok(Solver {
            problem,
            upper,
            opt,
            bounds,
            x,
            f,
            cost,
            jac,
            g,
            x_new: DVector::zeros(n),
            f_new: DVector::zeros(m),
            scale_inv,
            delta,
            alpha: 0.0,
            evaluations: 1,
            jacobians: 1,
            secants_left: opt.secant_steps,
        })
    }

    /// The Coleman-Li scaling vector v and its derivative dv at the current point.
    pub(super) fn coleman_li_scaling(&self) -> (DVector<f64>, DVector<f64>) {
        self.bounds.coleman_li_scaling(&self.x, &self.g)
    }

    /// Infinity norm of the gradient scaled by the Coleman-Li vector `v`.
    pub(super) fn scaled_gradient_norm(&self, v: &DVector<f64>) -> f64 {
        self.g
            .iter()
            .zip(v.iter())
            .map(|(a, b)| (a * b).abs())
            .fold(0.0, f64::max)
    }

    /// 0.5 |f|^2 at the current point.
    pub(super) fn cost(&self) -> f64 {
        self.cost
    }

    /// Whether the residual evaluations have reached the budget.
    pub(super) fn budget_spent(&self) -> bool {
        self.evaluations >= self.opt.max_evaluations
    }

    /// The trust-region subproblem at the current point, from its Coleman-Li scaling (`v`,
    /// `dv`) and scaled gradient norm.
    pub(super) fn subproblem(
        &self,
        v: DVector<f64>,
        dv: &DVector<f64>,
        g_norm: f64,
    ) -> Result<Subproblem, LsqError> {
        let v = scaled_by_columns(v, dv, &self.scale_inv);
        Subproblem::new(&self.jac, &self.f, &self.g, &v, dv, &self.scale_inv, g_norm)
    }

    /// Tries steps of `sub` until one lowers the cost, meets the convergence test or the budget
    /// is spent; the region shrinks after a step where the model is undefined and is updated
    /// after each step evaluated.
    pub(super) fn search_step(&mut self, sub: &Subproblem) -> Search {
        let mut search = Search {
            actual_reduction: -1.0,
            status: None,
        };
        while search.actual_reduction <= 0.0 && !self.budget_spent() {
            let step = self.propose_step(sub);
            if !self.evaluate_trial(&step) {
                self.delta = 0.25 * step.scaled.norm();
                continue;
            }
            search.actual_reduction = self.cost - 0.5 * self.f_new.norm_squared();
            search.status = self.rate_step(&step, search.actual_reduction);
            if search.status.is_some() {
                break;
            }
        }
        search
    }

    /// Takes the trial point and its residuals and cost, not its Jacobian (the last step of a
    /// solve that needs none at its end: [`super::Options::jacobian_at_end`]).
    pub(super) fn take_trial(&mut self) {
        std::mem::swap(&mut self.x, &mut self.x_new);
        std::mem::swap(&mut self.f, &mut self.f_new);
        self.cost = 0.5 * self.f.norm_squared();
    }

    /// Takes the trial point: its residuals, cost, Jacobian, gradient and the grown variable
    /// scale; the Jacobian evaluated where `exact` (the optimum's, for its errors) or no
    /// secant step is left ([`Options::secant_steps`]). `Err` when the Jacobian cannot be
    /// evaluated there or is not finite.
    pub(super) fn accept_trial(&mut self, exact: bool) -> Result<(), LsqError> {
        if self.secants_left > 0 && !exact {
            self.secants_left -= 1;
            self.secant_update();
        } else {
            self.take_trial();
            self.problem
                .jacobian(
                    self.x.as_slice(),
                    self.f.as_slice(),
                    self.upper,
                    &mut self.jac,
                )
                .map_err(|_| LsqError::NonFinite)?;
            self.jacobians += 1;
            self.secants_left = self.opt.secant_steps;
        }
        if self.jac.iter().any(|v| !v.is_finite()) {
            return Err(LsqError::NonFinite);
        }
        self.g = self.jac.tr_mul(&self.f);
        for k in 0..self.scale_inv.len() {
            self.scale_inv[k] = self.scale_inv[k].max(col_norm(&self.jac, k));
        }
        Ok(())
    }

    /// Takes the trial point with Broyden's update of the Jacobian's secant columns
    /// ([`Problem::secant_column`]): `J += (df - J dx) dx_s^T / |dx_s|^2`, `dx_s` the step in
    /// those columns' variables (zero in the others'), so that the updated Jacobian maps the
    /// step to the residuals' change.
    fn secant_update(&mut self) {
        let mut dx = &self.x_new - &self.x;
        let mut r = &self.f_new - &self.f;
        r.gemv(-1.0, &self.jac, &dx, 1.0);
        for (c, d) in dx.iter_mut().enumerate() {
            if !self.problem.secant_column(c) {
                *d = 0.0;
            }
        }
        let n2 = dx.norm_squared();
        if n2 > 0.0 {
            for (c, d) in dx.iter().enumerate() {
                if *d != 0.0 {
                    self.jac.column_mut(c).axpy(d / n2, &r, 1.0);
                }
            }
        }
        self.take_trial();
    }

    /// The result at the current point.
    pub(super) fn into_fit(self, status: Status) -> Fit {
        Fit {
            at_bound: self.bounds.at_bound(&self.x),
            x: self.x.as_slice().to_vec(),
            residuals: self.f.as_slice().to_vec(),
            cost: self.cost,
            jacobian: self.jac,
            status,
            evaluations: self.evaluations,
            jacobians: self.jacobians,
        }
    }

    /// The subproblem's step for the current radius; keeps its Levenberg-Marquardt parameter.
    fn propose_step(&mut self, sub: &Subproblem) -> Step {
        let (step, alpha) = sub.step(&self.x, &self.bounds, self.delta, self.alpha);
        self.alpha = alpha;
        step
    }

    /// Evaluates the residuals at the current point plus `step` (moved strictly inside the
    /// box): whether they are defined and finite.
    fn evaluate_trial(&mut self, step: &Step) -> bool {
        self.x_new
            .copy_from(&self.bounds.strictly_feasible(&(&self.x + &step.full)));
        self.evaluations += 1;
        self.problem
            .residuals(self.x_new.as_slice(), self.f_new.as_mut_slice())
            .is_ok()
            && self.f_new.iter().all(|v| v.is_finite())
    }

    /// Rates an evaluated `step` by its `actual` against its predicted reduction: the
    /// convergence status if it meets the test, else `None` with the radius and the
    /// Levenberg-Marquardt parameter updated.
    fn rate_step(&mut self, step: &Step, actual: f64) -> Option<Status> {
        let step_h_norm = step.scaled.norm();
        let (delta_new, ratio) = update_radius(
            self.delta,
            actual,
            step.predicted,
            step_h_norm,
            step_h_norm > 0.95 * self.delta,
        );
        let status = termination(
            actual,
            self.cost,
            step.full.norm(),
            self.x.norm(),
            ratio,
            self.opt.ftol,
            self.opt.xtol,
        )
        .or_else(|| {
            let tol = self.opt.ftol * self.cost;
            let within = actual <= 0.0 && -actual <= tol && step.predicted <= tol;
            (self.opt.ftol_refused && within).then_some(Status::Cost)
        });
        if status.is_none() {
            if delta_new > 0.0 {
                self.alpha *= self.delta / delta_new;
            }
            self.delta = delta_new;
        }
        status
    }
}

/// The residuals at the start; `Err` where they are undefined or not finite.
fn residuals_at_start<P: Problem + ?Sized>(
    problem: &mut P,
    x: &DVector<f64>,
    m: usize,
) -> Result<DVector<f64>, LsqError> {
    let mut f = DVector::zeros(m);
    problem
        .residuals(x.as_slice(), f.as_mut_slice())
        .map_err(LsqError::StartUndefined)?;
    if f.iter().any(|v| !v.is_finite()) {
        return Err(LsqError::StartUndefined(
            "non-finite residual at the start".into(),
        ));
    }
    Ok(f)
}

/// The Jacobian at the start (residuals `f` there); `Err` where it is undefined or not finite.
fn jacobian_at_start<P: Problem + ?Sized>(
    problem: &mut P,
    x: &DVector<f64>,
    f: &DVector<f64>,
    upper: &[f64],
) -> Result<DMatrix<f64>, LsqError> {
    let mut jac = DMatrix::zeros(f.len(), x.len());
    problem
        .jacobian(x.as_slice(), f.as_slice(), upper, &mut jac)
        .map_err(LsqError::StartUndefined)?;
    if jac.iter().any(|v| !v.is_finite()) {
        return Err(LsqError::NonFinite);
    }
    Ok(jac)
}

/// The inverse variable scale (`x_scale = "jac"`): the Jacobian's column norms, 1 where a
/// column is zero.
fn column_scale(jac: &DMatrix<f64>) -> DVector<f64> {
    let mut scale_inv = DVector::from_fn(jac.ncols(), |k, _| col_norm(jac, k));
    for s in scale_inv.iter_mut() {
        if *s == 0.0 {
            *s = 1.0;
        }
    }
    scale_inv
}

fn col_norm(j: &DMatrix<f64>, k: usize) -> f64 {
    j.column(k).norm()
}

/// The Coleman-Li vector `v` multiplied by the inverse column scale where `dv` is not 0 (the
/// bound-distance entries).
fn scaled_by_columns(
    mut v: DVector<f64>,
    dv: &DVector<f64>,
    scale_inv: &DVector<f64>,
) -> DVector<f64> {
    for k in 0..v.len() {
        if dv[k] != 0.0 {
            v[k] *= scale_inv[k];
        }
    }
    v
}

/// The starting radius: the length of `x` in the scaled variables, |x scale_inv / sqrt(v)|
/// (1 where that is 0 or not finite).
fn initial_radius(x: &DVector<f64>, v: &DVector<f64>, scale_inv: &DVector<f64>) -> f64 {
    let delta = x
        .iter()
        .zip(scale_inv.iter())
        .zip(v.iter())
        .map(|((xi, si), vi)| (xi * si / vi.sqrt()).powi(2))
        .sum::<f64>()
        .sqrt();
    if delta == 0.0 || !delta.is_finite() {
        1.0
    } else {
        delta
    }
}

/// The convergence test after a step: the cost reduction `d_cost` below `ftol` times the cost
/// (with a good model `ratio`), and the step below `xtol` relative to |x|.
fn termination(
    d_cost: f64,
    cost: f64,
    step_norm: f64,
    x_norm: f64,
    ratio: f64,
    ftol: f64,
    xtol: f64,
) -> Option<Status> {
    let f_ok = d_cost < ftol * cost && ratio > 0.25;
    let x_ok = step_norm < xtol * (xtol + x_norm);
    match (f_ok, x_ok) {
        (true, true) => Some(Status::CostAndStep),
        (true, false) => Some(Status::Cost),
        (false, true) => Some(Status::Step),
        _ => None,
    }
}
