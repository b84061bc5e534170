//! The trust-region step in the scaled variables: the subproblem (the Jacobian scaled by the
//! Coleman-Li and column scales, augmented by the `g dv` diagonal, and its SVD), its exact
//! solution (Moré 1978), the step kept inside the box (cut back to the bound, reflected off it,
//! or along the scaled steepest descent), and the radius update.

use super::bounds::Bounds;
use super::LsqError;
use nalgebra::{DMatrix, DVector};

/// The trust-region subproblem at one point, in the scaled variables p_h (a step of x is
/// `d .* p_h`).
pub(super) struct Subproblem {
    /// Scale of each variable: sqrt(v) over the column scale (units of x per scaled unit).
    d: DVector<f64>,
    /// The Coleman-Li diagonal term g dv in the scaled variables.
    diag_h: DVector<f64>,
    /// Gradient in the scaled variables.
    g_h: DVector<f64>,
    /// Jacobian in the scaled variables (m x n), or, for a tall one, its triangle R of a QR
    /// (n x n): the quadratic model reads only |J_h s|^2 and (J_h s0) . (J_h s), which R gives
    /// as well.
    j_h: DMatrix<f64>,
    /// Rows of the augmented Jacobian, m + n.
    rows: usize,
    /// U^T of the augmented Jacobian's SVD times the augmented residuals (f, 0).
    uf: DVector<f64>,
    /// Singular values of the augmented Jacobian.
    s: DVector<f64>,
    /// V^T of the augmented Jacobian's SVD.
    vt: DMatrix<f64>,
    /// Fraction of the way to a bound that a step cut back to it goes (0.995 or more).
    theta: f64,
}

/// A step that stays inside the box.
pub(super) struct Step {
    /// The step of x (units of x).
    pub(super) full: DVector<f64>,
    /// The same step in the scaled variables.
    pub(super) scaled: DVector<f64>,
    /// The cost reduction the quadratic model predicts for it.
    pub(super) predicted: f64,
}

impl Step {
    fn new(full: DVector<f64>, scaled: DVector<f64>, predicted: f64) -> Self {
        Step {
            full,
            scaled,
            predicted,
        }
    }
}

impl Subproblem {
    /// The subproblem at a point with Jacobian `jac`, residuals `f` and gradient `g`, from the
    /// Coleman-Li vector `v` (already multiplied by the column scale where `dv` is not 0), its
    /// derivative `dv`, the inverse column scale `scale_inv` and the scaled gradient's infinity
    /// norm `g_norm`. `Err` when the SVD does not converge.
    pub(super) fn new(
        jac: &DMatrix<f64>,
        f: &DVector<f64>,
        g: &DVector<f64>,
        v: &DVector<f64>,
        dv: &DVector<f64>,
        scale_inv: &DVector<f64>,
        g_norm: f64,
    ) -> Result<Self, LsqError> {
        let (m, n) = jac.shape();
        // d = sqrt(v) * scale (scale = 1 / scale_inv)
        let d = DVector::from_fn(n, |k, _| v[k].sqrt() / scale_inv[k]);
        let diag_h = DVector::from_fn(n, |k, _| g[k] * dv[k] / scale_inv[k]);
        let g_h = d.component_mul(g);
        let (j_h, (uf, s, vt)) = if is_tall(m + n, n) {
            reduced_svd(jac, &d, &diag_h, f)?
        } else {
            let j_h = scaled_columns(jac, &d);
            let parts = svd_solve(augmented_jacobian(&j_h, &diag_h), augmented_residuals(f, n))?;
            (j_h, parts)
        };
        Ok(Subproblem {
            d,
            diag_h,
            g_h,
            j_h,
            rows: m + n,
            uf,
            s,
            vt,
            theta: (1.0 - g_norm).max(0.995),
        })
    }

    /// The step from `x` for the radius `delta`, starting Moré's iteration from the
    /// Levenberg-Marquardt parameter `alpha`: the step kept inside `bounds`, and the new
    /// parameter.
    pub(super) fn step(
        &self,
        x: &DVector<f64>,
        bounds: &Bounds,
        delta: f64,
        alpha: f64,
    ) -> (Step, f64) {
        let (p_h, alpha) = trust_region_step(self.rows, &self.uf, &self.s, &self.vt, delta, alpha);
        let p_full = self.d.component_mul(&p_h);
        (select_step(x, self, p_full, p_h, delta, bounds), alpha)
    }
}

/// `U^T b`, the singular values and `V^T` of an SVD ([`svd_solve`]).
type SvdParts = (DVector<f64>, DVector<f64>, DMatrix<f64>);

/// Rows of the augmented Jacobian from which the subproblem reduces it by QR first
/// ([`reduced_svd`]): the residual analysis's refinements (thousands); a calibration on static
/// poses (a few hundred) keeps the direct SVD and its results to the last digit.
const QR_FIRST_ROWS: usize = 1024;

/// Rows of a block of [`tall_qr`]: a block's reflections stay in the cache (2048 rows of 30
/// columns are half a megabyte), and the blocks are reduced in parallel.
const QR_BLOCK_ROWS: usize = 2048;

/// Whether an augmented Jacobian of `rows` x `n` is reduced by QR before its SVD
/// ([`reduced_svd`]): from [`QR_FIRST_ROWS`] rows and four per column.
fn is_tall(rows: usize, n: usize) -> bool {
    rows >= QR_FIRST_ROWS && rows >= 4 * n
}

/// What the trust-region step needs of the SVD `a = U S V^T` (m x n) of a small matrix: `U^T
/// b`, the singular values and `V^T` (a calibration on static poses: a few hundred rows).
fn svd_solve(a: DMatrix<f64>, b: DVector<f64>) -> Result<SvdParts, LsqError> {
    let svd = a.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return Err(LsqError::NonFinite);
    };
    Ok((u.tr_mul(&b), svd.singular_values, vt))
}

/// The subproblem's parts for a tall Jacobian (the refinements' thousands of rows for a few
/// dozen parameters): the scaled Jacobian `J_h = jac diag(d)` is reduced to its triangle,
/// `J_h = Q R` ([`tall_qr`]), without forming it or the augmented matrix (each was the size
/// of the Jacobian: 16 MB a step on the final estimate's 66k residuals, allocated, zeroed and
/// copied on one core); the augmented `[R; diag(sqrt(diag_h))]` (2n x n) is reduced again and
/// its SVD taken. The augmented matrix `[Q 0; 0 I] [R; D]` has the same singular values and V,
/// and `U^T (f, 0) = U_2^T (Q^T f, 0)`, the same steps to rounding (5 % off a
/// refinement-heavy analysis, drift with creep at 3x, when it was first reduced by QR). Returns
/// R (what the quadratic model reads of `J_h`) and the parts.
fn reduced_svd(
    jac: &DMatrix<f64>,
    d: &DVector<f64>,
    diag_h: &DVector<f64>,
    f: &DVector<f64>,
) -> Result<(DMatrix<f64>, SvdParts), LsqError> {
    let n = jac.ncols();
    let (r, qtf) = tall_qr(jac, d, f);
    let mut aug = DMatrix::zeros(2 * n, n);
    aug.view_mut((0, 0), (n, n)).copy_from(&r);
    for k in 0..n {
        aug[(n + k, k)] = diag_h[k].max(0.0).sqrt();
    }
    let mut rhs = DVector::zeros(2 * n);
    rhs.rows_mut(0, n).copy_from(&qtf);
    let (r2, qtb) = qr_reduce(aug, rhs);
    let parts = svd_solve(r2, qtb)?;
    Ok((r, parts))
}

/// The triangle R (n x n) of a Householder QR `a diag(d) = Q R` of a tall `a` (m x n, m >= 4 n)
/// with its columns scaled by `d`, and the first n entries of `Q^T b`, reduced by blocks
/// (Demmel et al., "Communication-optimal parallel and sequential QR", 2012: the tall-skinny
/// QR): the row blocks of about [`QR_BLOCK_ROWS`], scaled as they are copied, are reduced to
/// their triangles in parallel, and the triangles stacked are reduced once more. `Q` is
/// orthogonal either way, so R is a QR's triangle (up to the signs of its rows, which the SVD
/// absorbs) and the pair gives the same least-squares problem to rounding. The blocks do not
/// depend on the thread count.
fn tall_qr(a: &DMatrix<f64>, d: &DVector<f64>, b: &DVector<f64>) -> (DMatrix<f64>, DVector<f64>) {
    use rayon::prelude::*;
    let (m, n) = a.shape();
    let block = |r0: usize, r1: usize| {
        let mut x = a.rows(r0, r1 - r0).into_owned();
        for k in 0..n {
            x.column_mut(k).scale_mut(d[k]);
        }
        qr_reduce(x, b.rows(r0, r1 - r0).into_owned())
    };
    let blocks = m.div_ceil(QR_BLOCK_ROWS.max(4 * n));
    if blocks <= 1 {
        return block(0, m);
    }
    // Balanced: every block has at least half the block rows, more than 2 n.
    let parts: Vec<(DMatrix<f64>, DVector<f64>)> = (0..blocks)
        .into_par_iter()
        .map(|k| block(k * m / blocks, (k + 1) * m / blocks))
        .collect();
    let mut stacked = DMatrix::zeros(blocks * n, n);
    let mut rhs = DVector::zeros(blocks * n);
    for (k, (r, c)) in parts.iter().enumerate() {
        stacked.view_mut((k * n, 0), (n, n)).copy_from(r);
        rhs.rows_mut(k * n, n).copy_from(c);
    }
    qr_reduce(stacked, rhs)
}

/// The triangle R (n x n) of a Householder QR `a = Q R` (m x n, m >= n) and the first n
/// entries of `Q^T b`.
fn qr_reduce(a: DMatrix<f64>, mut b: DVector<f64>) -> (DMatrix<f64>, DVector<f64>) {
    let n = a.ncols();
    let qr = a.qr();
    qr.q_tr_mul(&mut b);
    (qr.r(), b.rows(0, n).into_owned())
}

/// `jac` with column k multiplied by `d[k]`.
fn scaled_columns(jac: &DMatrix<f64>, d: &DVector<f64>) -> DMatrix<f64> {
    let mut j_h = jac.clone();
    for k in 0..d.len() {
        j_h.column_mut(k).scale_mut(d[k]);
    }
    j_h
}

/// The (m + n) x n Jacobian of the scaled problem: `j_h` above the diagonal sqrt(diag_h)
/// (negative terms taken as 0).
fn augmented_jacobian(j_h: &DMatrix<f64>, diag_h: &DVector<f64>) -> DMatrix<f64> {
    let (m, n) = j_h.shape();
    let mut j_aug = DMatrix::zeros(m + n, n);
    j_aug.view_mut((0, 0), (m, n)).copy_from(j_h);
    for k in 0..n {
        j_aug[(m + k, k)] = diag_h[k].max(0.0).sqrt();
    }
    j_aug
}

/// The residuals `f` followed by `n` zeros.
fn augmented_residuals(f: &DVector<f64>, n: usize) -> DVector<f64> {
    let m = f.len();
    let mut f_aug = DVector::zeros(m + n);
    f_aug.rows_mut(0, m).copy_from(f);
    f_aug
}

/// The exact trust-region step in the scaled variables from the SVD of the augmented Jacobian
/// (Moré 1978): the Gauss-Newton step if it fits, else the Levenberg-Marquardt step of length
/// `delta`. Returns the step and the LM parameter.
///
/// Where the Jacobian is rank-deficient (a parameter at a bound whose gradient points out of
/// the box: its scaled column is zero), the Gauss-Newton step is the least-norm one, the
/// singular values below the rank's tolerance left out. When it fits, no Levenberg-Marquardt
/// step reaches the radius: Moré's iteration then drove the parameter below zero (-5e-4),
/// and the step stretched to the radius raised the model's cost. A refinement of the supports'
/// friction with the joints' couple held at zero took 15 evaluations for 4, every other step
/// refused (SciPy's `solve_lsq_trust_region` iterates the same way).
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
    let rank_tol = f64::EPSILON * rows as f64 * smax;
    let full_rank = rows >= n && smin > rank_tol;
    // The (least-norm) Gauss-Newton step, when it fits.
    let gauss_newton = DVector::from_fn(n, |k, _| if s[k] > rank_tol { uf[k] / s[k] } else { 0.0 });
    let p = -vt.tr_mul(&gauss_newton);
    if p.norm() <= delta {
        return (p, 0.0);
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
fn step_to_bound(x: &DVector<f64>, s: &DVector<f64>, bounds: &Bounds) -> (f64, DVector<f64>) {
    let (lb, ub) = (&bounds.lower, &bounds.upper);
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

/// Keeps the step `p` (scaled: `p_h`) from `x` inside the box: the full step if it stays
/// inside, else the best of the step cut back to the bound, its reflection, and the scaled
/// gradient direction, by the reduction the quadratic model of `sub` predicts.
fn select_step(
    x: &DVector<f64>,
    sub: &Subproblem,
    mut p: DVector<f64>,
    mut p_h: DVector<f64>,
    delta: f64,
    bounds: &Bounds,
) -> Step {
    let Subproblem {
        d,
        diag_h,
        g_h,
        j_h,
        theta,
        ..
    } = sub;
    let theta = *theta;
    let xp = x + &p;
    if bounds.contains(&xp) {
        let v = quadratic(j_h, g_h, &p_h, diag_h);
        return Step::new(p, p_h, -v);
    }
    let (p_stride, hits) = step_to_bound(x, &p, bounds);
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
    let (to_bound, _) = step_to_bound(&x_on_bound, &r, bounds);
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
    let (to_bound, _) = step_to_bound(x, &ag, bounds);
    let ag_max = if to_bound < to_tr {
        theta * to_bound
    } else {
        to_tr
    };
    let (a, b, _) = quadratic_1d(j_h, g_h, &ag_h, diag_h, None);
    let (t, ag_value) = minimize_1d(a, b, 0.0, 0.0, ag_max);
    if p_value < r_value && p_value < ag_value {
        Step::new(p, p_h, -p_value)
    } else if r_value < ag_value {
        Step::new(r_step, r_step_h, -r_value)
    } else {
        Step::new(ag * t, ag_h * t, -ag_value)
    }
}

/// Trust-region radius update from the ratio of actual to predicted reduction: a quarter of
/// the step's (scaled) length after a poor step, twice the radius after a good step that
/// reached the region's edge (`bound_hit`). Returns (radius, ratio).
pub(super) fn update_radius(
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A tall, badly scaled matrix and a right-hand side (a fixed pseudo-random sequence).
    fn tall(m: usize, n: usize) -> (DMatrix<f64>, DVector<f64>) {
        let mut x = 0.5_f64;
        let mut next = move || {
            x = (x * 3.9 * (1.0 - x)).clamp(1e-6, 1.0 - 1e-6);
            x - 0.5
        };
        let a = DMatrix::from_fn(m, n, |_, k| next() * 10f64.powi(k as i32 % 5 - 2));
        let b = DVector::from_fn(m, |_, _| next());
        (a, b)
    }

    /// A Jacobian with a zero column (a parameter at its bound whose scaled column vanishes):
    /// where the least-norm Gauss-Newton step fits in the radius it is the step, with no
    /// Levenberg-Marquardt parameter, and lowers the model; where it does not, the step has
    /// the radius's length, a parameter not below zero, and lowers the model too.
    #[test]
    fn a_rank_deficient_jacobian_takes_its_least_norm_gauss_newton_step() {
        let (m, n) = (200, 5);
        let (mut a, f) = tall(m, n);
        a.column_mut(2).fill(0.0);
        let svd = a.clone().svd(true, true);
        let (uf, s, vt) = (
            svd.u.unwrap().tr_mul(&f),
            svd.singular_values,
            svd.v_t.unwrap(),
        );
        let g = a.tr_mul(&f);
        let zero = DVector::zeros(n);
        let least = a.clone().pseudo_inverse(1e-12).unwrap() * &f;
        for delta in [10.0 * least.norm(), 0.5 * least.norm()] {
            let (p, alpha) = trust_region_step(m, &uf, &s, &vt, delta, 0.0);
            assert!(alpha >= 0.0, "{alpha}");
            assert!(p[2].abs() < 1e-12 * p.norm(), "{p}");
            assert!(quadratic(&a, &g, &p, &zero) < 0.0);
            if delta > least.norm() {
                assert_eq!(alpha, 0.0);
                assert!((&p + &least).norm() <= 1e-10 * least.norm(), "{p} {least}");
            } else {
                assert!((p.norm() - delta).abs() <= 1e-12 * delta);
            }
        }
    }

    #[test]
    fn the_qr_reduced_svd_gives_the_steps_of_the_full_svd() {
        // One block, and three reduced in parallel.
        for m in [1500, 5000] {
            qr_reduced_against_full(m);
        }
    }

    /// The tall subproblem's parts ([`reduced_svd`]: the scaled Jacobian reduced by blocks,
    /// then the augmented triangle) against the SVD of the augmented matrix formed in full, and
    /// its triangle against the scaled Jacobian in the quadratic model.
    fn qr_reduced_against_full(m: usize) {
        let n = 12;
        let (a, f) = tall(m, n);
        let d = DVector::from_fn(n, |k, _| 0.5 + 0.25 * k as f64);
        // One negative term: the augmented matrix takes it as 0, the quadratic model as it is.
        let diag = DVector::from_fn(n, |k, _| if k == 3 { -0.2 } else { 0.1 * k as f64 });
        let j_h = scaled_columns(&a, &d);
        let full = augmented_jacobian(&j_h, &diag).svd(true, true);
        let u = full.u.unwrap();
        let (uf_full, s_full, vt_full) = (
            u.tr_mul(&augmented_residuals(&f, n)),
            full.singular_values,
            full.v_t.unwrap(),
        );
        let (r, (uf, s, vt)) = reduced_svd(&a, &d, &diag, &f).unwrap();
        assert_eq!(r.shape(), (n, n));
        // The same singular values; the singular vectors up to sign, so compare what the
        // trust-region step is made of: the Gauss-Newton step and a Levenberg-Marquardt one.
        let mut order_a: Vec<f64> = s.iter().copied().collect();
        let mut order_b: Vec<f64> = s_full.iter().copied().collect();
        order_a.sort_by(f64::total_cmp);
        order_b.sort_by(f64::total_cmp);
        for (x, y) in order_a.iter().zip(&order_b) {
            assert!(
                (x - y).abs() <= 1e-12 * order_b[order_b.len() - 1],
                "{x} {y}"
            );
        }
        for delta in [1e3, 1e-2] {
            let (p, alpha) = trust_region_step(m + n, &uf, &s, &vt, delta, 0.0);
            let (q, beta) = trust_region_step(m + n, &uf_full, &s_full, &vt_full, delta, 0.0);
            assert!((&p - &q).norm() <= 1e-10 * q.norm().max(1e-300), "{p} {q}");
            assert!(
                (alpha - beta).abs() <= 1e-8 * beta.abs().max(1e-12),
                "{alpha} {beta}"
            );
        }
        let g = j_h.tr_mul(&f);
        let (s0, s1) = (
            DVector::from_fn(n, |k, _| (k as f64 - 5.0) * 0.1),
            DVector::from_fn(n, |k, _| 1.0 / (1.0 + k as f64)),
        );
        let close = |x: f64, y: f64| (x - y).abs() <= 1e-11 * y.abs().max(1.0);
        let (v, w) = (
            quadratic(&r, &g, &s1, &diag),
            quadratic(&j_h, &g, &s1, &diag),
        );
        assert!(close(v, w), "{v} {w}");
        let (x, y) = (
            quadratic_1d(&r, &g, &s1, &diag, Some(&s0)),
            quadratic_1d(&j_h, &g, &s1, &diag, Some(&s0)),
        );
        assert!(
            close(x.0, y.0) && close(x.1, y.1) && close(x.2, y.2),
            "{x:?} {y:?}"
        );
    }
}
