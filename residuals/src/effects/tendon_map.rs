//! `tendon_map`: the remaining tendon-map nonlinearity. A richer function of the tendon
//! displacement per leg, written back into the legs as the Table I function that reproduces
//! the map and the correction best. A recalibration: it absorbs, it does not explain.

use super::joint_fit::{fit_joint, nuisance_change};
use super::{lerp, Effect, Role};
use crate::context::Context;
use crate::extension::Extension;
use crate::fitted::{Estimate, Fitted};
use crate::linear::Columns;
use pcr_kinematics::TendonMap as Map;
use pcr_robot::{RobotConfig, TendonMapKind, TendonMapSpec};

/// The `tendon_map` candidate.
#[derive(Debug)]
pub struct TendonMap;

/// Written into the legs: no part of the prediction beyond the constant-curvature model's.
impl Extension for TendonMap {}

impl Effect for TendonMap {
    fn name(&self) -> &'static str {
        "tendon_map"
    }

    fn description(&self) -> &'static str {
        "remaining tendon-map nonlinearity: a richer function of the tendon displacement"
    }

    fn role(&self) -> Role {
        Role::Recalibration
    }

    /// A richer function of the tendon displacement per leg: the current map plus a correction
    /// in the basis of the richest Table I family (root series to dl^(1/6)) and dl|dl|, dl^3;
    /// written back as the Table I function that reproduces it best over the data's range.
    fn fit(&self, ctx: &Context, train: &[usize]) -> Option<Fitted> {
        // Extra basis per leg: dl|dl|, dl^3, s|dl|^(1/2), s|dl|^(1/3).
        const NB: usize = 4;
        let basis = |dl: f64| -> [f64; NB] {
            let a = dl.abs();
            let s = dl.signum();
            [dl * a, dl * dl * dl, s * a.sqrt(), s * a.cbrt()]
        };
        let effect = |i: usize, c: &mut Columns| {
            let p = ctx.pred(&ctx.rows[i]);
            for leg in 0..3 {
                let b = basis(p.dl_eff[leg]);
                for (j, bj) in b.iter().enumerate() {
                    c[leg * NB + j] = [
                        p.j_kappa[(0, leg)] * bj,
                        p.j_kappa[(1, leg)] * bj,
                        p.j_kappa[(2, leg)] * bj * ctx.w_phi,
                    ];
                }
            }
        };
        let nui = ctx.nuisance().nui.clone();
        let (fit, delta, alone) = fit_joint(ctx, &nui, train, 3 * NB, &effect, None)?;
        // The displacement range of the data, per leg.
        let mut range = [[f64::INFINITY, f64::NEG_INFINITY]; 3];
        for row in &ctx.rows {
            let p = ctx.pred(row);
            for leg in 0..3 {
                range[leg][0] = range[leg][0].min(p.dl_eff[leg]);
                range[leg][1] = range[leg][1].max(p.dl_eff[leg]);
            }
        }
        let x = fit.x.clone();
        let nuis = nuisance_change(nui, fit.x.clone(), 3 * NB);
        let params = (0..3)
            .flat_map(|leg| {
                let names = ["dl|dl|", "dl^3", "dl^(1/2)", "dl^(1/3)"];
                let fit = &fit;
                names.into_iter().enumerate().map(move |(j, n)| {
                    Estimate::new(
                        &format!("leg {} {n}", leg + 1),
                        fit.x[leg * NB + j],
                        Some(fit.std[leg * NB + j]),
                        "1/mm per unit",
                    )
                })
            })
            .collect();
        Some(Fitted {
            name: self.name(),
            params,
            k: 3 * NB,
            delta,
            alone,
            train_sse: fit.sse,
            change: Box::new(move |c| {
                nuis(c);
                for leg in 0..3 {
                    let corr = |dl: f64| -> f64 {
                        let b = basis(dl);
                        (0..NB).map(|j| x[leg * NB + j] * b[j]).sum::<f64>()
                    };
                    let lo = range[leg][0];
                    let hi = range[leg][1].max(lo + 1e-6);
                    let current = Map::from_leg(&c.legs[leg]);
                    let target: Vec<(f64, f64)> = (0..=200)
                        .map(|k| {
                            let dl = lo + (hi - lo) * k as f64 / 200.0;
                            (dl, current.kappa(dl) + corr(dl))
                        })
                        .collect();
                    // The new map must stay invertible over the data's range and up to the robot's
                    // bending limit (the chain must reach every pose it could before), or it is
                    // not used.
                    let bending_max = c.limits.bending_max_deg;
                    let l_c = c.legs[leg].l_c_mm;
                    if let Some(spec) = best_family(&target).filter(|spec| {
                        let m = Map::from_spec(spec);
                        pcr_calibration::step1::is_monotonic(&m, lo, hi)
                            && pcr_calibration::step1::reaches_bending_limit(&m, l_c, bending_max)
                    }) {
                        c.legs[leg].tendon_map = spec;
                    }
                }
            }),
        })
    }

    fn file_position(&self) -> u8 {
        0
    }

    /// The map coefficients, when the family is the same.
    fn blend(&self, old: &RobotConfig, new: &mut RobotConfig, s: f64) {
        for (o, a) in new.legs.iter_mut().zip(&old.legs) {
            if a.tendon_map.model == o.tendon_map.model
                && a.tendon_map.coeffs.len() == o.tendon_map.coeffs.len()
            {
                for (c, x) in o.tendon_map.coeffs.iter_mut().zip(&a.tendon_map.coeffs) {
                    *c = lerp(*x, *c, s);
                }
            }
        }
    }
}

/// The Table I function that reproduces (dl, kappa) samples best (least squares, smallest
/// maximum error), with its coefficients.
pub fn best_family(target: &[(f64, f64)]) -> Option<TendonMapSpec> {
    let mut best: Option<(f64, TendonMapSpec)> = None;
    for kind in TendonMapKind::ALL {
        let Some(c) = linear_fit(kind, target) else {
            continue;
        };
        let m = Map::new(kind, &c);
        if m.dl_for_kappa(m.kappa(0.0)).is_err() {
            continue;
        }
        let err = target
            .iter()
            .map(|(d, k)| (m.kappa(*d) - k).abs())
            .fold(0.0, f64::max);
        if best.as_ref().is_none_or(|b| err < b.0 * 0.999) {
            best = Some((
                err,
                TendonMapSpec {
                    model: kind,
                    coeffs: c,
                },
            ));
        }
    }
    best.map(|b| b.1)
}

/// The coefficients of the family `kind` fitted to (dl, kappa) samples by least squares (on
/// equilibrated columns); `None` when a coefficient is not finite.
fn linear_fit(kind: TendonMapKind, pts: &[(f64, f64)]) -> Option<Vec<f64>> {
    let off = usize::from(!kind.has_offset());
    let nc = kind.n_coeffs();
    let mut a = nalgebra::DMatrix::zeros(pts.len(), nc);
    let mut b = nalgebra::DVector::zeros(pts.len());
    let mut basis = [0.0; 7];
    for (r, (dl, k)) in pts.iter().enumerate() {
        Map::basis(kind, *dl, &mut basis);
        for c in 0..nc {
            a[(r, c)] = basis[c + off];
        }
        b[r] = *k;
    }
    let s: Vec<f64> = (0..nc).map(|c| a.column(c).norm().max(1e-300)).collect();
    for (c, sc) in s.iter().enumerate() {
        a.column_mut(c).unscale_mut(*sc);
    }
    let x = a.svd(true, true).solve(&b, 1e-12).ok()?;
    let out: Vec<f64> = (0..nc).map(|c| x[c] / s[c]).collect();
    out.iter().all(|v| v.is_finite()).then_some(out)
}
