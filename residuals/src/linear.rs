//! Linearised least squares over the rows of a context: the design columns of each row (the
//! change of the weighted pose residual per unit parameter), normal equations, covariance.

use crate::context::Context;
use nalgebra::{DMatrix, DVector};
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
    cols: &(dyn Fn(usize, &mut Columns) + Sync),
) -> Option<LinearFit> {
    solve_with_prior(ctx, idx, n, cols, None, None)
}

/// Row `i`'s residual less `offset[i]` (a fixed change of the residual: an effect's part that
/// has no free linear parameter), read where a fit reads the residual, instead of a copy of the
/// context with its residuals shifted (every row's prediction copied: 15 MB on the sweep's
/// recordings, for every value a profile tries).
#[inline]
fn residual(ctx: &Context, i: usize, offset: Option<&[[f64; 3]]>) -> [f64; 3] {
    let mut r = ctx.rows[i].r;
    if let Some(o) = offset {
        for k in 0..3 {
            r[k] -= o[i][k];
        }
    }
    r
}

/// [`solve`] with a zero-mean Gaussian prior on the parameters: `prior[j]` = 1 / sigma_j^2
/// (0 = free), added to the normal equations (a ridge; each Gauss-Newton step stays where the
/// linearisation holds), of the residuals less `offset` (one per row of `ctx`, if any).
pub fn solve_with_prior(
    ctx: &Context,
    idx: &[usize],
    n: usize,
    cols: &(dyn Fn(usize, &mut Columns) + Sync),
    prior: Option<&[f64]>,
    offset: Option<&[[f64; 3]]>,
) -> Option<LinearFit> {
    if n == 0 || idx.is_empty() {
        return None;
    }
    // Per time block (the clusters of the standard errors below), then summed.
    let nb = idx
        .iter()
        .map(|&i| ctx.rows[i].block + 1)
        .max()
        .unwrap_or(1);
    let mut per_block: Vec<Option<(DMatrix<f64>, DVector<f64>)>> = vec![None; nb];
    let mut c: Columns = vec![[0.0; 3]; n];
    let mut rr = 0.0;
    for &i in idx {
        cols(i, &mut c);
        let r = residual(ctx, i, offset);
        rr += r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
        let (ata, atr) = per_block[ctx.rows[i].block]
            .get_or_insert_with(|| (DMatrix::zeros(n, n), DVector::zeros(n)));
        for a in 0..n {
            atr[a] += c[a][0] * r[0] + c[a][1] * r[1] + c[a][2] * r[2];
            for b in a..n {
                ata[(a, b)] += c[a][0] * c[b][0] + c[a][1] * c[b][1] + c[a][2] * c[b][2];
            }
        }
    }
    let mut blocks: Vec<(DMatrix<f64>, DVector<f64>)> = per_block.into_iter().flatten().collect();
    for (m, _) in blocks.iter_mut() {
        for a in 0..n {
            for b in 0..a {
                m[(a, b)] = m[(b, a)];
            }
        }
    }
    finish(blocks, rr, n, idx.len(), prior)
}

/// [`solve_with_prior`] of a joint fit: `n_e` columns of the effect (`effect`), then the
/// nuisance's columns of `table`, whose products with themselves come from the table's cache.
/// The same solution and errors, for a third of the arithmetic per row when the effect has a
/// few parameters and the calibration thirty.
pub fn solve_joint(
    ctx: &Context,
    idx: &[usize],
    n_e: usize,
    effect: &(dyn Fn(usize, &mut Columns) + Sync),
    table: &crate::nuisance::NuisanceTable,
    prior: Option<&[f64]>,
    offset: Option<&[[f64; 3]]>,
) -> Option<LinearFit> {
    let n_g = table.nui.n;
    let n = n_e + n_g;
    if n == 0 || idx.is_empty() {
        return None;
    }
    let gram = table.gram(&|i| ctx.rows[i].block, idx);
    let nb = idx
        .iter()
        .map(|&i| ctx.rows[i].block + 1)
        .max()
        .unwrap_or(1);
    // Per block: E^T E, E^T G, E^T r, G^T r.
    struct Acc {
        ee: DMatrix<f64>,
        /// Row by row (effect column a, nuisance column b at a n_g + b).
        eg: Vec<f64>,
        er: DVector<f64>,
        gr: DVector<f64>,
    }
    let mut per_block: Vec<Option<Acc>> = (0..nb).map(|_| None).collect();
    let mut c: Columns = vec![[0.0; 3]; n_e];
    let mut rr = 0.0;
    for &i in idx {
        effect(i, &mut c);
        let g = &table.cols[i];
        let r = residual(ctx, i, offset);
        rr += r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
        let acc = per_block[ctx.rows[i].block].get_or_insert_with(|| Acc {
            ee: DMatrix::zeros(n_e, n_e),
            eg: vec![0.0; n_e * n_g],
            er: DVector::zeros(n_e),
            gr: DVector::zeros(n_g),
        });
        for (b, gb) in g.iter().enumerate() {
            acc.gr[b] += gb[0] * r[0] + gb[1] * r[1] + gb[2] * r[2];
        }
        for a in 0..n_e {
            let ca = c[a];
            acc.er[a] += ca[0] * r[0] + ca[1] * r[1] + ca[2] * r[2];
            for b in a..n_e {
                acc.ee[(a, b)] += ca[0] * c[b][0] + ca[1] * c[b][1] + ca[2] * c[b][2];
            }
            for (v, gb) in acc.eg[a * n_g..(a + 1) * n_g].iter_mut().zip(g) {
                *v += ca[0] * gb[0] + ca[1] * gb[1] + ca[2] * gb[2];
            }
        }
    }
    let mut blocks = Vec::with_capacity(gram.len());
    for (blk, gg) in gram.iter() {
        let Some(acc) = per_block[*blk].take() else {
            continue;
        };
        let mut m = DMatrix::<f64>::zeros(n, n);
        let mut v = DVector::<f64>::zeros(n);
        for a in 0..n_e {
            v[a] = acc.er[a];
            for b in a..n_e {
                m[(a, b)] = acc.ee[(a, b)];
                m[(b, a)] = acc.ee[(a, b)];
            }
            for b in 0..n_g {
                m[(a, n_e + b)] = acc.eg[a * n_g + b];
                m[(n_e + b, a)] = acc.eg[a * n_g + b];
            }
        }
        for a in 0..n_g {
            v[n_e + a] = acc.gr[a];
            for b in 0..n_g {
                m[(n_e + a, n_e + b)] = gg[(a, b)];
            }
        }
        blocks.push((m, v));
    }
    finish(blocks, rr, n, idx.len(), prior)
}

/// Weight of the prior in the standard errors of a fit with one ([`finish`]). The prior steadies
/// the estimate where the data hardly tell a parameter from the calibration's (a frame shift
/// against the legs' base angles and lengths, a small load against the maps), and its 1 mm /
/// 1 deg / 5 % are a choice, not a measurement: with it at full weight the stated errors were
/// the prior's in those directions (a 2.4 mm frame stated +- 0.06 mm, 7 errors off its truth;
/// a 0.4 N load +- 0.008 N, 3 errors off). Weighed 1e-4 the errors are the data's (+- 0.5 mm,
/// +- 0.017 N), and a direction the data do not see at all keeps a finite error a hundred
/// times the prior's instead of none.
pub(crate) const PRIOR_IN_ERRORS: f64 = 1e-4;

/// The pseudo-inverse of the symmetric matrix `m` scaled to a unit diagonal, with the scales
/// (singular values below 1e-10 of the largest dropped); `None` when `m` is not finite (the
/// decomposition would not end).
pub(crate) fn scaled_pinv(m: &DMatrix<f64>) -> Option<(DMatrix<f64>, Vec<f64>)> {
    if m.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let n = m.nrows();
    // A column the data do not see at all (a zero diagonal) keeps the scale 1: its row and
    // column are zero and the pseudo-inverse drops them (a tiny scale would square to zero
    // and make 0 / 0 of them, on which the decomposition never ends).
    let s: Vec<f64> = (0..n)
        .map(|a| {
            let d = m[(a, a)];
            if d > 1e-200 {
                d.sqrt()
            } else {
                1.0
            }
        })
        .collect();
    let sa = DMatrix::from_fn(n, n, |a, b| m[(a, b)] / (s[a] * s[b]));
    if sa.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let svd = sa.svd(true, true);
    let tol = svd.singular_values.max() * 1e-10;
    Some((svd.pseudo_inverse(tol).ok()?, s))
}

/// Solves the summed per-block normal equations (`rr`: the residual's sum of squares over the
/// `rows` rows) with the prior; the errors clustered by block ([`standard_errors`]).
fn finish(
    blocks: Vec<(DMatrix<f64>, DVector<f64>)>,
    rr: f64,
    n: usize,
    rows: usize,
    prior: Option<&[f64]>,
) -> Option<LinearFit> {
    let mut ata = DMatrix::<f64>::zeros(n, n);
    let mut atr = DVector::<f64>::zeros(n);
    for (m, v) in &blocks {
        ata += m;
        atr += v;
    }
    if let Some(p) = prior {
        for (a, w) in p.iter().enumerate().take(n) {
            ata[(a, a)] += w;
        }
    }
    // Columns scaled for conditioning.
    let (pinv, s) = scaled_pinv(&ata)?;
    let sr = DVector::from_fn(n, |a, _| atr[a] / s[a]);
    let xs = &pinv * &sr;
    let x: Vec<f64> = (0..n).map(|a| xs[a] / s[a]).collect();
    // SSE = r.r - 2 x.A^T r + x.A^T A x
    let xv = DVector::from_column_slice(&x);
    let sse = (rr - 2.0 * xv.dot(&atr) + (xv.transpose() * &ata * &xv)[(0, 0)]).max(0.0);
    let dof = (3 * rows).saturating_sub(n).max(1) as f64;
    let s2 = sse / dof;
    let std = match prior {
        Some(p) => {
            // The errors of the data: the prior weighed PRIOR_IN_ERRORS.
            let mut weak = ata.clone();
            for (a, w) in p.iter().enumerate().take(n) {
                weak[(a, a)] -= w * (1.0 - PRIOR_IN_ERRORS);
            }
            match scaled_pinv(&weak) {
                Some((pw, sw)) => standard_errors(&blocks, &pw, &sw, &xv, s2),
                None => vec![f64::NAN; n],
            }
        }
        None => standard_errors(&blocks, &pinv, &s, &xv, s2),
    };
    x.iter()
        .all(|v| v.is_finite())
        .then_some(LinearFit { x, std, sse })
}

/// The standard errors of a fit: the larger of the classical `sigma^2 (A^T A)^-1` and the
/// cluster-robust (sandwich) one with the time blocks as clusters,
/// `(A^T A)^-1 (G/(G-1) sum_b u_b u_b^T) (A^T A)^-1` with `u_b = A_b^T (r_b - A_b x)`.
///
/// The rows of one block are not independent draws: a residual the model cannot follow lasts
/// for the whole move, and the capture noise is the smaller part of most residuals. The
/// classical errors count 40,000 rows as 40,000 independent ones and come out several times too
/// small (a periodic amplitude 3.014 +- 0.0037 steps for a truth of 3). Clusters of whole blocks
/// keep what is correlated inside a block together. `pinv` is the inverse of the normal matrix
/// scaled by `s` (`A^T A = S (pinv)^-1 S`).
pub(crate) fn standard_errors(
    blocks: &[(DMatrix<f64>, DVector<f64>)],
    pinv: &DMatrix<f64>,
    s: &[f64],
    x: &DVector<f64>,
    s2: f64,
) -> Vec<f64> {
    let n = s.len();
    let classical = |a: usize| (s2 * pinv[(a, a)]).max(0.0).sqrt() / s[a];
    let g = blocks.len();
    if g < 3 {
        return (0..n).map(classical).collect();
    }
    // Meat in the scaled coordinates: u_b / s.
    let mut meat = DMatrix::<f64>::zeros(n, n);
    for (m, v) in blocks {
        let u = v - m * x;
        let us = DVector::from_fn(n, |a, _| u[a] / s[a]);
        meat += &us * us.transpose();
    }
    meat *= g as f64 / (g - 1) as f64;
    let cov = pinv * meat * pinv;
    (0..n)
        .map(|a| classical(a).max(cov[(a, a)].max(0.0).sqrt() / s[a]))
        .collect()
}

/// The deltas (weighted pose changes) of every row for parameters `x`: the `n` columns of
/// `cols`, then, with `table` (a joint fit, [`solve_joint`]), the nuisance's columns read in
/// place, in that order.
pub fn deltas(
    ctx: &Context,
    n: usize,
    x: &[f64],
    cols: &(dyn Fn(usize, &mut Columns) + Sync),
    table: Option<&crate::nuisance::NuisanceTable>,
) -> Vec<[f64; 3]> {
    // The effect's columns, then the nuisance's, each with its share of `x` (the sums in the
    // order of the columns); the rows in parallel.
    let (xe, xg) = x.split_at(n.min(x.len()));
    (0..ctx.rows.len())
        .into_par_iter()
        .map_init(
            || vec![[0.0; 3]; n],
            |c, i| {
                cols(i, c);
                let mut d = [0.0; 3];
                let mut add = |col: &[f64; 3], xa: f64| {
                    for k in 0..3 {
                        d[k] += col[k] * xa;
                    }
                };
                for (col, &xa) in c.iter().zip(xe) {
                    add(col, xa);
                }
                if let Some(t) = table {
                    for (col, &xa) in t.cols[i].iter().zip(xg) {
                        add(col, xa);
                    }
                }
                d
            },
        )
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
