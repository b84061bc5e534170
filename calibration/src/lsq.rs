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

use nalgebra::{DMatrix, DVector};

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
}

impl Default for Options {
    fn default() -> Self {
        Options {
            ftol: 1e-8,
            xtol: 1e-8,
            gtol: 1e-8,
            max_evaluations: 1000,
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
    let eps = f64::EPSILON.sqrt();
    let mut xp = x.to_vec();
    let mut rp = vec![0.0; r.len()];
    for k in 0..x.len() {
        let mut h = eps * x[k].abs().max(1.0);
        if x[k] + h > upper[k] {
            h = -h;
        }
        xp[k] = x[k] + h;
        let h = xp[k] - x[k];
        p.residuals(&xp, &mut rp)?;
        for i in 0..r.len() {
            j[(i, k)] = (rp[i] - r[i]) / h;
        }
        xp[k] = x[k];
    }
    Ok(())
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
    /// Jacobian at the optimum (m x n).
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
    let n = x0.len();
    let m = p.residual_count();
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
    let lb = DVector::from_column_slice(lower);
    let ub = DVector::from_column_slice(upper);
    let mut x = strictly_feasible(&DVector::from_column_slice(x0), &lb, &ub);

    let mut f = DVector::zeros(m);
    p.residuals(x.as_slice(), f.as_mut_slice())
        .map_err(LsqError::StartUndefined)?;
    if f.iter().any(|v| !v.is_finite()) {
        return Err(LsqError::StartUndefined(
            "non-finite residual at the start".into(),
        ));
    }
    let mut nfev = 1usize;
    let mut njev = 1usize;
    let mut jac = DMatrix::zeros(m, n);
    p.jacobian(x.as_slice(), f.as_slice(), upper, &mut jac)
        .map_err(LsqError::StartUndefined)?;
    if jac.iter().any(|v| !v.is_finite()) {
        return Err(LsqError::NonFinite);
    }
    let mut cost = 0.5 * f.norm_squared();
    let mut g = jac.tr_mul(&f);

    // Jacobian scaling: scale_inv = column norms, never decreasing.
    let mut scale_inv = DVector::from_fn(n, |k, _| col_norm(&jac, k));
    for s in scale_inv.iter_mut() {
        if *s == 0.0 {
            *s = 1.0;
        }
    }

    let (mut v, dv) = cl_scaling(&x, &g, &lb, &ub);
    for k in 0..n {
        if dv[k] != 0.0 {
            v[k] *= scale_inv[k];
        }
    }
    let mut delta = x
        .iter()
        .zip(scale_inv.iter())
        .zip(v.iter())
        .map(|((xi, si), vi)| (xi * si / vi.sqrt()).powi(2))
        .sum::<f64>()
        .sqrt();
    if delta == 0.0 || !delta.is_finite() {
        delta = 1.0;
    }
    let mut alpha = 0.0;
    let mut status: Option<Status> = None;

    let mut x_new = DVector::zeros(n);
    let mut f_new = DVector::zeros(m);
    loop {
        let (mut v, dv) = cl_scaling(&x, &g, &lb, &ub);
        let g_norm = g
            .iter()
            .zip(v.iter())
            .map(|(a, b)| (a * b).abs())
            .fold(0.0, f64::max);
        if g_norm < opt.gtol {
            status = Some(Status::Gradient);
        }
        if status.is_some() {
            break;
        }
        if nfev >= opt.max_evaluations {
            status = Some(Status::MaxEvaluations);
            break;
        }
        for k in 0..n {
            if dv[k] != 0.0 {
                v[k] *= scale_inv[k];
            }
        }
        // d = sqrt(v) * scale (scale = 1 / scale_inv)
        let d = DVector::from_fn(n, |k, _| v[k].sqrt() / scale_inv[k]);
        let diag_h = DVector::from_fn(n, |k, _| g[k] * dv[k] / scale_inv[k]);
        let g_h = d.component_mul(&g);
        let mut j_h = jac.clone();
        for k in 0..n {
            j_h.column_mut(k).scale_mut(d[k]);
        }
        let mut j_aug = DMatrix::zeros(m + n, n);
        j_aug.view_mut((0, 0), (m, n)).copy_from(&j_h);
        for k in 0..n {
            j_aug[(m + k, k)] = diag_h[k].max(0.0).sqrt();
        }
        let mut f_aug = DVector::zeros(m + n);
        f_aug.rows_mut(0, m).copy_from(&f);
        let svd = j_aug.svd(true, true);
        let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
            return Err(LsqError::NonFinite);
        };
        let s = svd.singular_values;
        let uf = u.tr_mul(&f_aug);
        let theta = (1.0 - g_norm).max(0.995);

        let mut actual_reduction = -1.0;
        while actual_reduction <= 0.0 && nfev < opt.max_evaluations {
            let (p_h, a) = trust_region_step(m + n, &uf, &s, &vt, delta, alpha);
            alpha = a;
            let p_full = d.component_mul(&p_h);
            let (step, step_h, predicted) = select_step(
                &x, &j_h, &diag_h, &g_h, p_full, p_h, &d, delta, &lb, &ub, theta,
            );
            x_new.copy_from(&strictly_feasible(&(&x + &step), &lb, &ub));
            nfev += 1;
            let step_h_norm = step_h.norm();
            let ok = p.residuals(x_new.as_slice(), f_new.as_mut_slice()).is_ok()
                && f_new.iter().all(|v| v.is_finite());
            if !ok {
                delta = 0.25 * step_h_norm;
                continue;
            }
            let cost_new = 0.5 * f_new.norm_squared();
            actual_reduction = cost - cost_new;
            let (delta_new, ratio) = update_radius(
                delta,
                actual_reduction,
                predicted,
                step_h_norm,
                step_h_norm > 0.95 * delta,
            );
            let step_norm = step.norm();
            status = termination(
                actual_reduction,
                cost,
                step_norm,
                x.norm(),
                ratio,
                opt.ftol,
                opt.xtol,
            );
            if status.is_some() {
                break;
            }
            if delta_new > 0.0 {
                alpha *= delta / delta_new;
            }
            delta = delta_new;
        }
        if actual_reduction > 0.0 {
            std::mem::swap(&mut x, &mut x_new);
            std::mem::swap(&mut f, &mut f_new);
            cost = 0.5 * f.norm_squared();
            p.jacobian(x.as_slice(), f.as_slice(), upper, &mut jac)
                .map_err(|_| LsqError::NonFinite)?;
            njev += 1;
            if jac.iter().any(|v| !v.is_finite()) {
                return Err(LsqError::NonFinite);
            }
            g = jac.tr_mul(&f);
            for k in 0..n {
                scale_inv[k] = scale_inv[k].max(col_norm(&jac, k));
            }
        } else if status.is_none() && nfev >= opt.max_evaluations {
            status = Some(Status::MaxEvaluations);
        }
        if status.is_some() {
            break;
        }
    }
    let at_bound = (0..n)
        .map(|k| {
            let tol = 1e-10 * x[k].abs().max(1.0);
            (x[k] - lb[k]).abs() <= tol || (ub[k] - x[k]).abs() <= tol
        })
        .collect();
    Ok(Fit {
        x: x.as_slice().to_vec(),
        residuals: f.as_slice().to_vec(),
        cost,
        jacobian: jac,
        status: status.unwrap_or(Status::MaxEvaluations),
        evaluations: nfev,
        jacobians: njev,
        at_bound,
    })
}

fn col_norm(j: &DMatrix<f64>, k: usize) -> f64 {
    j.column(k).norm()
}

/// Moves `x` strictly inside [lb, ub] (one ulp inwards where it sits on or beyond a bound).
fn strictly_feasible(x: &DVector<f64>, lb: &DVector<f64>, ub: &DVector<f64>) -> DVector<f64> {
    DVector::from_fn(x.len(), |k, _| {
        if x[k] <= lb[k] {
            next_towards(lb[k], ub[k])
        } else if x[k] >= ub[k] {
            next_towards(ub[k], lb[k])
        } else {
            x[k]
        }
    })
}

/// The next representable number after `a` in the direction of `b`.
fn next_towards(a: f64, b: f64) -> f64 {
    if !a.is_finite() || a == b {
        return a;
    }
    let bits = a.to_bits();
    let up = b > a;
    let next = if a == 0.0 {
        if up {
            f64::from_bits(1)
        } else {
            -f64::from_bits(1)
        }
    } else if (a > 0.0) == up {
        f64::from_bits(bits + 1)
    } else {
        f64::from_bits(bits - 1)
    };
    // Keep a relative margin so that sqrt(v) of the Coleman-Li scaling is not denormal.
    let margin = 1e-10 * a.abs().max(1e-10);
    if up {
        next.max(a + margin).min(b)
    } else {
        next.min(a - margin).max(b)
    }
}

/// Coleman-Li scaling vector v and its derivative dv.
fn cl_scaling(
    x: &DVector<f64>,
    g: &DVector<f64>,
    lb: &DVector<f64>,
    ub: &DVector<f64>,
) -> (DVector<f64>, DVector<f64>) {
    let n = x.len();
    let mut v = DVector::from_element(n, 1.0);
    let mut dv = DVector::zeros(n);
    for k in 0..n {
        if g[k] < 0.0 && ub[k].is_finite() {
            v[k] = ub[k] - x[k];
            dv[k] = -1.0;
        } else if g[k] > 0.0 && lb[k].is_finite() {
            v[k] = x[k] - lb[k];
            dv[k] = 1.0;
        }
    }
    (v, dv)
}

/// The exact trust-region step in the scaled variables from the SVD of the augmented Jacobian
/// (Moré 1978): the Gauss-Newton step if it fits, else the Levenberg-Marquardt step of length
/// `delta`. Returns the step and the LM parameter.
fn trust_region_step(
    rows: usize,
    uf: &DVector<f64>,
    s: &DVector<f64>,
    vt: &DMatrix<f64>,
    delta: f64,
    alpha0: f64,
) -> (DVector<f64>, f64) {
    let n = s.len();
    let suf = s.component_mul(uf);
    let smax = s.max();
    let smin = s.min();
    let full_rank = rows >= n && smin > f64::EPSILON * rows as f64 * smax;
    if full_rank {
        let p = -vt.tr_mul(&uf.component_div(s));
        if p.norm() <= delta {
            return (p, 0.0);
        }
    }
    let phi = |a: f64| -> (f64, f64) {
        let mut pn2 = 0.0;
        let mut d3 = 0.0;
        for k in 0..n {
            let den = s[k] * s[k] + a;
            pn2 += (suf[k] / den).powi(2);
            d3 += suf[k] * suf[k] / (den * den * den);
        }
        let pn = pn2.sqrt();
        (pn - delta, -d3 / pn)
    };
    let mut upper = suf.norm() / delta;
    let mut lower = if full_rank {
        let (f0, d0) = phi(0.0);
        -f0 / d0
    } else {
        0.0
    };
    let mut a = if alpha0 == 0.0 && !full_rank || alpha0 <= 0.0 {
        (0.001 * upper).max((lower * upper).sqrt())
    } else {
        alpha0
    };
    for _ in 0..10 {
        if a < lower || a > upper {
            a = (0.001 * upper).max((lower * upper).sqrt());
        }
        let (f, df) = phi(a);
        if f < 0.0 {
            upper = a;
        }
        let r = f / df;
        lower = lower.max(a - r);
        a -= (f + delta) * r / delta;
        if f.abs() < 0.01 * delta {
            break;
        }
    }
    let coef = DVector::from_fn(n, |k, _| suf[k] / (s[k] * s[k] + a));
    let mut p = -vt.tr_mul(&coef);
    let pn = p.norm();
    if pn > 0.0 {
        p *= delta / pn;
    }
    (p, a)
}

/// Value of the quadratic model 0.5 s^T (J^T J + diag) s + g^T s.
fn quadratic(j: &DMatrix<f64>, g: &DVector<f64>, s: &DVector<f64>, diag: &DVector<f64>) -> f64 {
    let js = j * s;
    0.5 * (js.norm_squared() + diag.component_mul(s).dot(s)) + g.dot(s)
}

/// Coefficients (a, b, c) of the model along s0 + t s: a t^2 + b t + c.
fn quadratic_1d(
    j: &DMatrix<f64>,
    g: &DVector<f64>,
    s: &DVector<f64>,
    diag: &DVector<f64>,
    s0: Option<&DVector<f64>>,
) -> (f64, f64, f64) {
    let v = j * s;
    let a = 0.5 * (v.norm_squared() + diag.component_mul(s).dot(s));
    let mut b = g.dot(s);
    let mut c = 0.0;
    if let Some(s0) = s0 {
        let u = j * s0;
        b += u.dot(&v) + diag.component_mul(s0).dot(s);
        c = 0.5 * (u.norm_squared() + diag.component_mul(s0).dot(s0)) + g.dot(s0);
    }
    (a, b, c)
}

/// Minimum of a t^2 + b t + c on [lo, hi]: (t, value).
fn minimize_1d(a: f64, b: f64, c: f64, lo: f64, hi: f64) -> (f64, f64) {
    let f = |t: f64| a * t * t + b * t + c;
    let mut best = (lo, f(lo));
    let fh = f(hi);
    if fh < best.1 {
        best = (hi, fh);
    }
    if a != 0.0 {
        let t = -0.5 * b / a;
        if t > lo && t < hi {
            let ft = f(t);
            if ft < best.1 {
                best = (t, ft);
            }
        }
    }
    best
}

/// Largest t >= 0 with x + t s inside the box, and which components hit (sign of s there).
fn step_to_bound(
    x: &DVector<f64>,
    s: &DVector<f64>,
    lb: &DVector<f64>,
    ub: &DVector<f64>,
) -> (f64, DVector<f64>) {
    let n = x.len();
    let steps = DVector::from_fn(n, |k, _| {
        if s[k] == 0.0 {
            f64::INFINITY
        } else {
            ((lb[k] - x[k]) / s[k]).max((ub[k] - x[k]) / s[k])
        }
    });
    let t = steps.min();
    let hits = DVector::from_fn(n, |k, _| {
        if steps[k] == t && s[k] != 0.0 {
            s[k].signum()
        } else {
            0.0
        }
    });
    (t, hits)
}

/// The positive t with |x + t s| = delta.
fn to_trust_region(x: &DVector<f64>, s: &DVector<f64>, delta: f64) -> f64 {
    let a = s.dot(s);
    if a == 0.0 {
        return f64::INFINITY;
    }
    let b = x.dot(s);
    let c = x.dot(x) - delta * delta;
    let disc = (b * b - a * c).max(0.0).sqrt();
    let q = -(b + disc.copysign(b));
    let (t1, t2) = (q / a, c / q);
    t1.max(t2)
}

/// Keeps the step inside the box: the full step if it stays inside, else the best of the step
/// cut back to the bound, its reflection, and the scaled gradient direction.
/// Returns (step, scaled step, predicted reduction).
#[allow(clippy::too_many_arguments)]
fn select_step(
    x: &DVector<f64>,
    j_h: &DMatrix<f64>,
    diag_h: &DVector<f64>,
    g_h: &DVector<f64>,
    mut p: DVector<f64>,
    mut p_h: DVector<f64>,
    d: &DVector<f64>,
    delta: f64,
    lb: &DVector<f64>,
    ub: &DVector<f64>,
    theta: f64,
) -> (DVector<f64>, DVector<f64>, f64) {
    let xp = x + &p;
    if (0..x.len()).all(|k| xp[k] >= lb[k] && xp[k] <= ub[k]) {
        let v = quadratic(j_h, g_h, &p_h, diag_h);
        return (p, p_h, -v);
    }
    let (p_stride, hits) = step_to_bound(x, &p, lb, ub);
    // Reflection off the bound that was hit.
    let mut r_h = p_h.clone();
    for k in 0..x.len() {
        if hits[k] != 0.0 {
            r_h[k] = -r_h[k];
        }
    }
    let r = d.component_mul(&r_h);
    p *= p_stride;
    p_h *= p_stride;
    let x_on_bound = x + &p;
    let to_tr = to_trust_region(&p_h, &r_h, delta);
    let (to_bound, _) = step_to_bound(&x_on_bound, &r, lb, ub);
    let r_stride = to_bound.min(to_tr);
    let (r_lo, r_hi) = if r_stride > 0.0 {
        let lo = (1.0 - theta) * p_stride / r_stride;
        let hi = if r_stride == to_bound {
            theta * to_bound
        } else {
            to_tr
        };
        (lo, hi)
    } else {
        (0.0, -1.0)
    };
    let (r_step, r_step_h, r_value) = if r_lo <= r_hi {
        let (a, b, c) = quadratic_1d(j_h, g_h, &r_h, diag_h, Some(&p_h));
        let (t, val) = minimize_1d(a, b, c, r_lo, r_hi);
        let rh = &p_h + &r_h * t;
        (d.component_mul(&rh), rh, val)
    } else {
        (p.clone(), p_h.clone(), f64::INFINITY)
    };
    // The step cut back to (theta times) the bound.
    p *= theta;
    p_h *= theta;
    let p_value = quadratic(j_h, g_h, &p_h, diag_h);
    // Scaled steepest descent, kept inside the box and the region.
    let ag_h = -g_h;
    let ag = d.component_mul(&ag_h);
    let ag_norm = ag_h.norm();
    let to_tr = if ag_norm > 0.0 { delta / ag_norm } else { 0.0 };
    let (to_bound, _) = step_to_bound(x, &ag, lb, ub);
    let ag_max = if to_bound < to_tr {
        theta * to_bound
    } else {
        to_tr
    };
    let (a, b, _) = quadratic_1d(j_h, g_h, &ag_h, diag_h, None);
    let (t, ag_value) = minimize_1d(a, b, 0.0, 0.0, ag_max);
    if p_value < r_value && p_value < ag_value {
        (p, p_h, -p_value)
    } else if r_value < ag_value {
        (r_step, r_step_h, -r_value)
    } else {
        (ag * t, ag_h * t, -ag_value)
    }
}

/// Trust-region radius update from the ratio of actual to predicted reduction.
fn update_radius(
    delta: f64,
    actual: f64,
    predicted: f64,
    step_norm: f64,
    bound_hit: bool,
) -> (f64, f64) {
    let ratio = if predicted > 0.0 {
        actual / predicted
    } else if predicted == actual {
        1.0
    } else {
        0.0
    };
    let delta = if ratio < 0.25 {
        0.25 * step_norm
    } else if ratio > 0.75 && bound_hit {
        2.0 * delta
    } else {
        delta
    };
    (delta, ratio)
}

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
