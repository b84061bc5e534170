//! Linearised least squares over the rows of a context: the design columns of each row (the
//! change of the weighted pose residual per unit parameter), the calibration parameters as
//! nuisance columns, normal equations, covariance.

use crate::context::Context;
use nalgebra::{DMatrix, DVector};
use pcr_kinematics::{Leg, TendonMap};
use pcr_robot::{geometry as g, Vec2};
use rayon::prelude::*;

/// Design columns of one row: `cols[j]` is d(predicted, weighted pose)/d(param j).
pub type Columns = Vec<[f64; 3]>;

/// A linear least-squares solution.
#[derive(Debug, Clone)]
pub struct LinearFit {
    /// Parameters.
    pub x: Vec<f64>,
    /// Standard errors (sigma^2 (A^T A)^+).
    pub std: Vec<f64>,
    /// Training SSE after the fit.
    pub sse: f64,
}

/// Solves min sum_rows |r - A x|^2 over the rows `idx`, where `cols(i)` gives A's columns for
/// row i (each a weighted pose vector), through the normal equations with a truncated SVD.
pub fn solve(
    ctx: &Context,
    idx: &[usize],
    n: usize,
    cols: &dyn Fn(usize, &mut Columns),
) -> Option<LinearFit> {
    solve_with_prior(ctx, idx, n, cols, None)
}

/// [`solve`] with a zero-mean Gaussian prior on the parameters: `prior[j]` = 1 / sigma_j^2
/// (0 = free), added to the normal equations (a ridge; each Gauss-Newton step stays where the
/// linearisation holds).
pub fn solve_with_prior(
    ctx: &Context,
    idx: &[usize],
    n: usize,
    cols: &dyn Fn(usize, &mut Columns),
    prior: Option<&[f64]>,
) -> Option<LinearFit> {
    if n == 0 || idx.is_empty() {
        return None;
    }
    let mut ata = DMatrix::<f64>::zeros(n, n);
    let mut atr = DVector::<f64>::zeros(n);
    let mut c: Columns = vec![[0.0; 3]; n];
    let mut rr = 0.0;
    for &i in idx {
        cols(i, &mut c);
        let r = ctx.rows[i].r;
        rr += r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
        for a in 0..n {
            atr[a] += c[a][0] * r[0] + c[a][1] * r[1] + c[a][2] * r[2];
            for b in a..n {
                ata[(a, b)] += c[a][0] * c[b][0] + c[a][1] * c[b][1] + c[a][2] * c[b][2];
            }
        }
    }
    for a in 0..n {
        for b in 0..a {
            ata[(a, b)] = ata[(b, a)];
        }
    }
    if let Some(p) = prior {
        for (a, w) in p.iter().enumerate().take(n) {
            ata[(a, a)] += w;
        }
    }
    // Scale columns for conditioning.
    let s: Vec<f64> = (0..n).map(|a| ata[(a, a)].sqrt().max(1e-300)).collect();
    let mut sa = ata.clone();
    for a in 0..n {
        for b in 0..n {
            sa[(a, b)] /= s[a] * s[b];
        }
    }
    let sr = DVector::from_fn(n, |a, _| atr[a] / s[a]);
    let svd = sa.clone().svd(true, true);
    let smax = svd.singular_values.max();
    let tol = smax * 1e-10;
    let pinv = svd.pseudo_inverse(tol).ok()?;
    let xs = &pinv * &sr;
    let x: Vec<f64> = (0..n).map(|a| xs[a] / s[a]).collect();
    // SSE = r.r - 2 x.A^T r + x.A^T A x
    let xv = DVector::from_column_slice(&x);
    let sse = (rr - 2.0 * xv.dot(&atr) + (xv.transpose() * &ata * &xv)[(0, 0)]).max(0.0);
    let dof = (3 * idx.len()).saturating_sub(n).max(1) as f64;
    let s2 = sse / dof;
    let std = (0..n)
        .map(|a| (s2 * pinv[(a, a)]).max(0.0).sqrt() / s[a])
        .collect();
    x.iter()
        .all(|v| v.is_finite())
        .then_some(LinearFit { x, std, sse })
}

/// The deltas (weighted pose changes) of every row for parameters `x`.
pub fn deltas(
    ctx: &Context,
    n: usize,
    x: &[f64],
    cols: &dyn Fn(usize, &mut Columns),
) -> Vec<[f64; 3]> {
    let mut c: Columns = vec![[0.0; 3]; n];
    (0..ctx.rows.len())
        .map(|i| {
            cols(i, &mut c);
            let mut d = [0.0; 3];
            for (a, col) in c.iter().enumerate() {
                for k in 0..3 {
                    d[k] += col[k] * x[a];
                }
            }
            d
        })
        .collect()
}

/// Weighted pose change of a row for a change of the effective motor positions, steps.
pub fn motor_delta(ctx: &Context, i: usize, dq: [f64; 3]) -> [f64; 3] {
    let j = &ctx.pred(&ctx.rows[i]).j_q;
    let mut d = [0.0; 3];
    for a in 0..3 {
        d[a] = j[(a, 0)] * dq[0] + j[(a, 1)] * dq[1] + j[(a, 2)] * dq[2];
    }
    d[2] *= ctx.w_phi;
    d
}

/// The calibration parameters (the paper's step-1 and step-2 sets) as nuisance columns:
/// per leg psi (deg), l_C (mm), the map coefficients, r_p (mm), theta_p (deg).
#[derive(Debug, Clone)]
pub struct Nuisance {
    cfg: Vec<pcr_robot::LegConfig>,
    /// Per leg: the leg as it is and perturbed in each geometric parameter, with P_i^E.
    legs: Vec<[(Leg, Vec2); 1 + GEO.len()]>,
    n_map: [usize; 3],
    /// Number of columns.
    pub n: usize,
    names: Vec<String>,
}

const GEO: [&str; 4] = ["psi_deg", "l_c_mm", "r_p_mm", "theta_p_deg"];
/// Finite-difference step of the geometric parameters (deg or mm).
const GEO_STEP: f64 = 1e-4;

impl Nuisance {
    /// The nuisance set of the context's model.
    pub fn of(ctx: &Context) -> Nuisance {
        let cfg = ctx.model.config.legs.clone();
        let n_map: [usize; 3] = std::array::from_fn(|i| cfg[i].tendon_map.form().n_coeffs());
        let legs = cfg
            .iter()
            .map(|c| {
                std::array::from_fn(|k| {
                    let mut p = c.clone();
                    match k {
                        1 => p.psi_deg += GEO_STEP,
                        2 => p.l_c_mm += GEO_STEP,
                        3 => p.r_p_mm += GEO_STEP,
                        4 => p.theta_p_deg += GEO_STEP,
                        _ => {}
                    }
                    (Leg::from_config(&p), p.platform_point())
                })
            })
            .collect();
        let mut names = Vec::new();
        for i in 0..3 {
            for gname in GEO {
                names.push(format!("{gname}[{}]", i + 1));
            }
            let form = cfg[i].tendon_map.form();
            for j in 0..n_map[i] {
                names.push(format!("{}[{}]", form.coeff_name(j), i + 1));
            }
        }
        Nuisance {
            legs,
            n: names.len(),
            names,
            cfg,
            n_map,
        }
    }

    /// Column names.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Offset of leg i's columns.
    fn offset(&self, i: usize) -> usize {
        (0..i).map(|l| GEO.len() + self.n_map[l]).sum()
    }

    /// The columns of row `i` (written from `start` on in `out`).
    pub fn columns(&self, ctx: &Context, i: usize, out: &mut Columns, start: usize) {
        for c in out.iter_mut().skip(start).take(self.n) {
            *c = [0.0; 3];
        }
        let row = &ctx.rows[i];
        let p = ctx.pred(row);
        let Some(pose) = p.pose else {
            return;
        };
        let x = pcr_kinematics::Pose::new(pose[0], pose[1], pose[2]);
        let a = ctx.model.robot.jacobian_a(&x, &p.kappa);
        let Some(ainv) = a.try_inverse() else {
            return;
        };
        let mut basis = [0.0; 13];
        for leg in 0..3 {
            let off = start + self.offset(leg);
            // dh_leg/d param by finite differences of the constraint alone.
            let h = |k: usize| {
                let (l, pe) = &self.legs[leg][k];
                let m = l.joint_m(p.kappa[leg]);
                let pe = g::rot(x.phi, *pe);
                let d = g::sub(g::add([x.x, x.y], pe), m);
                g::dot(d, d) - l.l_st * l.l_st
            };
            let h0 = h(0);
            for gk in 0..GEO.len() {
                // l_C changes the segment at a fixed curvature (theta = kappa l_C).
                let dh = (h(gk + 1) - h0) / GEO_STEP;
                out[off + gk] = [
                    -ainv[(0, leg)] * dh,
                    -ainv[(1, leg)] * dh,
                    -ainv[(2, leg)] * dh * ctx.w_phi,
                ];
            }
            // Map coefficients: d pose / d kappa_leg * basis_j(dl).
            let form = self.cfg[leg].tendon_map.form();
            TendonMap::flat_basis(form, p.dl_eff[leg], &mut basis);
            for j in 0..self.n_map[leg] {
                let b = basis[j];
                out[off + GEO.len() + j] = [
                    p.j_kappa[(0, leg)] * b,
                    p.j_kappa[(1, leg)] * b,
                    p.j_kappa[(2, leg)] * b * ctx.w_phi,
                ];
            }
        }
    }

    /// The prior of the nuisance parameters (1 / sigma^2, column order): the calibration has
    /// placed them, so one step moves the geometry by about a millimetre or a degree and a map
    /// coefficient by about 5 % of its value.
    pub fn prior(&self) -> Vec<f64> {
        let mut p = Vec::with_capacity(self.n);
        for leg in 0..3 {
            p.extend([1.0; GEO.len()]);
            let coeffs = self.cfg[leg].tendon_map.flat_coeffs();
            for j in 0..self.n_map[leg] {
                let c = coeffs.get(j).copied().unwrap_or(1e-3).abs().max(1e-6);
                p.push(1.0 / (0.05 * c).powi(2));
            }
        }
        p
    }

    /// The columns of every row of a context, computed once.
    pub fn table(&self, ctx: &Context) -> Vec<Columns> {
        (0..ctx.rows.len())
            .into_par_iter()
            .map(|i| {
                let mut c = vec![[0.0; 3]; self.n];
                self.columns(ctx, i, &mut c, 0);
                c
            })
            .collect()
    }

    /// Applies parameter changes `dx` (in column order) to a robot configuration's legs.
    pub fn apply(&self, dx: &[f64], cfg: &mut pcr_robot::RobotConfig) {
        for leg in 0..3 {
            let off = self.offset(leg);
            let l = &mut cfg.legs[leg];
            l.psi_deg += dx[off];
            l.l_c_mm += dx[off + 1];
            l.r_p_mm += dx[off + 2];
            l.theta_p_deg += dx[off + 3];
            if l.tendon_map.coeffs.is_empty() {
                // The nominal linear map written out: k0 = 1 / (a l_C) of the old length.
                l.tendon_map.coeffs =
                    vec![1.0 / (l.actuation.tendon_offset_mm * self.cfg[leg].l_c_mm)];
            }
            let mut flat = l.tendon_map.flat_coeffs();
            for j in 0..self.n_map[leg] {
                flat[j] += dx[off + GEO.len() + j];
            }
            l.tendon_map = pcr_robot::TendonMapSpec::from_flat(l.tendon_map.form(), &flat);
        }
    }
}
