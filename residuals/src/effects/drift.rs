//! `drift`: steady drift of the tendon length. Each tendon lengthens at a constant rate with
//! the time since the start of its recording (`[effects.drift]`), so its segment sees
//! `dl - rate (t - t0)`; the chain adds the elongation grown since its first command.

use super::joint_fit::{fit_joint, nuisance_change};
use super::{lerp, Effect, Parameter};
use crate::context::Context;
use crate::extension::Extension;
use crate::fitted::{Estimate, Fitted};
use crate::linear::{motor_delta, Columns};
use crate::series::Series;
use pcr_robot::effects::{self as robot, Effects};
use pcr_robot::RobotConfig;

/// The `drift` candidate.
#[derive(Debug)]
pub struct Drift;

/// Tendon drift over a series: the tendon displacements `dl` (mm, one entry per row)
/// shortened by `rate * (t - t0)`, t0 the series' first row, in place.
pub fn apply(s: &Series, dl: &mut [[f64; 3]], d: &robot::Drift) {
    let t0 = s.samples.first().map_or(0.0, |x| x.t_s);
    for (v, x) in dl.iter_mut().zip(&s.samples) {
        for i in 0..3 {
            v[i] -= d.rate_mm_per_s[i] * (x.t_s - t0);
        }
    }
}

/// The rates the robot file declares, mm/s (0 without `[effects.drift]`).
fn held(effects: &Effects) -> [f64; 3] {
    effects.drift.as_ref().map_or([0.0; 3], |d| d.rate_mm_per_s)
}

impl Extension for Drift {
    /// The declared drift.
    fn tendons(&self, effects: &Effects, series: &Series, dl: &mut [[f64; 3]]) {
        if let Some(d) = &effects.drift {
            apply(series, dl, d);
        }
    }
}

impl Effect for Drift {
    fn name(&self) -> &'static str {
        "drift"
    }

    fn description(&self) -> &'static str {
        "steady drift: each tendon lengthens at a constant rate with the time since the start of the recording"
    }

    /// Each tendon lengthens at a constant rate with the time since the start of its recording
    /// (linear in the three rates, fitted with the nuisance). Where creep saturates with a time
    /// constant, drift keeps growing; the held-out blocks choose between them.
    fn fit(&self, ctx: &Context, train: &[usize]) -> Option<Fitted> {
        let mmps: [f64; 3] =
            std::array::from_fn(|i| ctx.model.config.legs[i].actuation.mm_per_step());
        let nui = ctx.nuisance().nui.clone();
        // Rates in mm per 1000 s for conditioning.
        const UNIT: f64 = 1e-3;
        let t0: Vec<f64> = ctx
            .series
            .iter()
            .map(|s| s.samples.first().map_or(0.0, |x| x.t_s))
            .collect();
        let effect = |i: usize, c: &mut Columns| {
            let row = &ctx.rows[i];
            let age = ctx.series[row.s].samples[row.k].t_s - t0[row.s];
            for m in 0..3 {
                // A longer tendon is a shorter effective displacement: motor output lower by
                // rate * age / (mm/step).
                let mut dq = [0.0; 3];
                dq[m] = -UNIT * age / mmps[m];
                c[m] = motor_delta(ctx, i, dq);
            }
        };
        let (fit, delta, alone) = fit_joint(ctx, &nui, train, 3, &effect, None)?;
        let prev = held(&ctx.model.config.effects);
        let rate: [f64; 3] = std::array::from_fn(|m| prev[m] + UNIT * fit.x[m]);
        let params = (0..3)
            .map(|m| {
                Estimate::new(
                    &format!("rate leg {}", m + 1),
                    rate[m],
                    Some(UNIT * fit.std[m]),
                    "mm/s",
                )
            })
            .collect();
        let nuis = nuisance_change(nui, fit.x.clone(), 3);
        Some(Fitted {
            name: self.name(),
            params,
            k: 3,
            delta,
            alone,
            train_sse: fit.sse,
            change: std::sync::Arc::new(move |c| {
                c.effects.drift = Some(robot::Drift {
                    rate_mm_per_s: rate,
                });
                nuis(c);
            }),
        })
    }

    fn declared(&self, effects: &Effects, _fitted: &[Estimate]) -> Option<Vec<Estimate>> {
        effects.drift.as_ref().map(|d| {
            (0..3)
                .map(|i| {
                    Estimate::new(
                        &format!("rate leg {}", i + 1),
                        d.rate_mm_per_s[i],
                        None,
                        "mm/s",
                    )
                })
                .collect()
        })
    }

    fn remove(&self, effects: &mut Effects, _params: &[Estimate]) {
        effects.drift = None;
    }

    fn file_position(&self) -> u8 {
        4
    }

    /// The rate of each leg, in mm per 1000 s (so that the solver's steps are of the order of
    /// the others).
    fn parameters(&self, effects: &Effects) -> Vec<Parameter> {
        if effects.drift.is_none() {
            return Vec::new();
        }
        (0..3)
            .map(|i| Parameter {
                get: |e, i| e.drift.as_ref().map_or(0.0, |d| 1e3 * d.rate_mm_per_s[i]),
                set: |e, i, x| {
                    if let Some(d) = e.drift.as_mut() {
                        d.rate_mm_per_s[i] = 1e-3 * x
                    }
                },
                index: i,
                lo: -1e3,
                hi: 1e3,
                moves_curvatures: true,
                along_path: None,
            })
            .collect()
    }

    fn blend(&self, old: &RobotConfig, new: &mut RobotConfig, s: f64) {
        if let Some(d) = new.effects.drift.as_mut() {
            let o = held(&old.effects);
            d.rate_mm_per_s = std::array::from_fn(|i| lerp(o[i], d.rate_mm_per_s[i], s));
        }
    }
}
