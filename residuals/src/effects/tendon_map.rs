//! `tendon_map`: the remaining tendon-map nonlinearity. A richer function of the tendon
//! displacement per leg, written back into the legs as the Table I function that reproduces
//! the map and the correction best. A recalibration: it absorbs, it does not explain.

use super::joint_fit::{fit_joint, nuisance_change};
use super::{lerp, Effect, Role};
use crate::context::Context;
use crate::extension::Extension;
use crate::fitted::{Estimate, Fitted};
use crate::linear::Columns;
use pcr_calibration::step1::{linear_coefficients, map_coverage};
use pcr_kinematics::TendonMap as Map;
use pcr_robot::{MapForm, MapReading, RobotConfig, TendonMapKind, TendonMapSpec};

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
    /// with odd terms (dl|dl|, dl^3, s|dl|^(1/2), s|dl|^(1/3)) and even ones (dl^2, |dl|: the
    /// two bending directions may differ); written back as the Table I function, in either
    /// reading, that reproduces it best over the data's range.
    fn fit(&self, ctx: &Context, train: &[usize]) -> Option<Fitted> {
        const NB: usize = 6;
        let basis = |dl: f64| -> [f64; NB] {
            let a = dl.abs();
            let s = dl.signum();
            [dl * a, dl * dl * dl, s * a.sqrt(), s * a.cbrt(), dl * dl, a]
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
        let phis = orientations(ctx);
        let nuis = nuisance_change(nui, fit.x.clone(), 3 * NB);
        let params = (0..3)
            .flat_map(|leg| {
                let names = ["dl|dl|", "dl^3", "dl^(1/2)", "dl^(1/3)", "dl^2", "|dl|"];
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
            change: std::sync::Arc::new(move |c| {
                nuis(c);
                let travel = pcr_kinematics::Robot::new(c)
                    .ok()
                    .and_then(|r| pcr_kinematics::workspace::leg_travel(&r, &phis, 4.0));
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
                    // The new map must stay invertible over the data's range and the leg's
                    // travel over the workspace (the chain must reach every pose it could
                    // before), as the calibration's, or it is not used.
                    let l_c = c.legs[leg].l_c_mm;
                    let Some(travel) = travel else {
                        continue;
                    };
                    if let Some(spec) = best_family(&target, |spec| {
                        map_coverage(&Map::from_spec(spec), l_c, travel[leg], lo, hi).is_ok()
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

    /// The map coefficients, when the family and reading are the same.
    fn blend(&self, old: &RobotConfig, new: &mut RobotConfig, s: f64) {
        for (o, a) in new.legs.iter_mut().zip(&old.legs) {
            let (fa, fo) = (a.tendon_map.flat_coeffs(), o.tendon_map.flat_coeffs());
            if a.tendon_map.form() == o.tendon_map.form() && fa.len() == fo.len() {
                let flat: Vec<f64> = fa.iter().zip(&fo).map(|(x, c)| lerp(*x, *c, s)).collect();
                o.tendon_map = TendonMapSpec::from_flat(o.tendon_map.form(), &flat);
            }
        }
    }
}

/// The orientations (rad) of the rows' measured poses for the legs' travel: the smallest, zero
/// and the largest, to the degree.
fn orientations(ctx: &Context) -> Vec<f64> {
    let (lo, hi) = ctx
        .series
        .iter()
        .flat_map(|s| &s.samples)
        .filter_map(|x| x.pose.map(|m| m[2].to_degrees().round()))
        .fold((0.0f64, 0.0f64), |a, p| (a.0.min(p), a.1.max(p)));
    let mut v = vec![lo.to_radians(), 0.0, hi.to_radians()];
    v.dedup();
    v
}

/// The Table I function that reproduces (dl, kappa) samples best (least squares, smallest
/// maximum error) among those `admissible` accepts, with its coefficients: the symmetric reading
/// unless the asymmetric one of some function halves the best symmetric error (a map written
/// per direction only where the two directions really differ).
pub fn best_family(
    target: &[(f64, f64)],
    admissible: impl Fn(&TendonMapSpec) -> bool,
) -> Option<TendonMapSpec> {
    let best_of = |reading: MapReading| {
        let mut best: Option<(f64, TendonMapSpec)> = None;
        for kind in TendonMapKind::ALL {
            let form = MapForm { kind, reading };
            let Some(c) = linear_coefficients(form, target) else {
                continue;
            };
            let spec = TendonMapSpec::from_flat(form, &c);
            let m = Map::from_spec(&spec);
            if m.dl_for_kappa(m.kappa(0.0)).is_err() || !admissible(&spec) {
                continue;
            }
            let err = target
                .iter()
                .map(|(d, k)| (m.kappa(*d) - k).abs())
                .fold(0.0, f64::max);
            if best.as_ref().is_none_or(|b| err < b.0 * 0.999) {
                best = Some((err, spec));
            }
        }
        best
    };
    match (
        best_of(MapReading::Symmetric),
        best_of(MapReading::Asymmetric),
    ) {
        (Some(s), Some(a)) if a.0 < 0.5 * s.0 => Some(a.1),
        (Some(s), _) => Some(s.1),
        (None, a) => a.map(|a| a.1),
    }
}
