//! `creep`: slow drift by tendon creep. Each tendon lengthens by `e`,
//! `de/dt = (gain dl - e) / T` (`[effects.creep]`), so its segment sees `dl - e`; the chain adds
//! the predicted elongation to the command.

use super::joint_fit::{fit_joint, nuisance_change};
use super::profile::{minimise_1d, profile_std, search_rows};
use super::{lerp, Effect, Parameter};
use crate::context::Context;
use crate::extension::Extension;
use crate::fitted::{Estimate, Fitted};
use crate::linear::{self, motor_delta, Columns};
use crate::series::Series;
use pcr_robot::effects::{self as robot, Effects};
use pcr_robot::RobotConfig;

/// The `creep` candidate.
#[derive(Debug)]
pub struct Creep;

/// Tendon creep over a series: the elongation state run over the rows, and the tendon
/// displacements `dl` (mm, one entry per row) made the effective ones, in place.
pub fn apply(s: &Series, dl: &mut [[f64; 3]], c: &robot::Creep) {
    let mut e = [0.0f64; 3];
    let mut prev_t = s.samples.first().map_or(0.0, |x| x.t_s);
    for (d, x) in dl.iter_mut().zip(&s.samples) {
        let dt = (x.t_s - prev_t).max(0.0);
        prev_t = x.t_s;
        let a = 1.0 - (-dt / c.time_constant_s).exp();
        for i in 0..3 {
            e[i] += (c.gain[i] * d[i] - e[i]) * a;
            d[i] -= e[i];
        }
    }
}

impl Extension for Creep {
    /// The declared creep.
    fn tendons(&self, effects: &Effects, series: &Series, dl: &mut [[f64; 3]]) {
        if let Some(c) = &effects.creep {
            apply(series, dl, c);
        }
    }
}

impl Effect for Creep {
    fn name(&self) -> &'static str {
        "creep"
    }

    fn description(&self) -> &'static str {
        "slow drift: tendon creep, elongation toward a share of the displacement with a time constant"
    }

    /// Fitted once: its time constant is profiled from scratch.
    fn iterable(&self) -> bool {
        false
    }

    /// The tendon lengthens toward gain_i dl_i with time constant T: a profile over log T (the
    /// gains linear at each), then the gains with the calibration parameters. `None` when a gain
    /// comes out at 0.5 or more (no creep is that large).
    fn fit(&self, ctx: &Context, train: &[usize]) -> Option<Fitted> {
        let mmps: [f64; 3] =
            std::array::from_fn(|i| ctx.model.config.legs[i].actuation.mm_per_step());
        // E_i(T): the first-order lag of dl_i, per row (in steps: divided by mm/step), of the
        // series `needed` (the others empty). The rows' spacing repeats: its factor is computed
        // when it changes.
        let lag = |t_c: f64, needed: &[bool]| -> Vec<Vec<[f64; 3]>> {
            ctx.series
                .iter()
                .zip(&ctx.preds)
                .zip(needed)
                .map(|((s, p), &needed)| {
                    if !needed {
                        return Vec::new();
                    }
                    let mut e = [0.0f64; 3];
                    let mut prev = s.samples.first().map_or(0.0, |x| x.t_s);
                    let (mut last_dt, mut last_a) = (f64::NAN, 0.0);
                    s.samples
                        .iter()
                        .zip(p)
                        .map(|(x, pr)| {
                            let dt = (x.t_s - prev).max(0.0);
                            if dt != last_dt {
                                (last_dt, last_a) = (dt, 1.0 - (-dt / t_c).exp());
                            }
                            let a = last_a;
                            prev = x.t_s;
                            std::array::from_fn(|i| {
                                e[i] += (pr.dl_eff[i] - e[i]) * a;
                                e[i] / mmps[i]
                            })
                        })
                        .collect()
                })
                .collect()
        };
        let nui = ctx.nuisance().nui.clone();
        let effect_for = |l: &Vec<Vec<[f64; 3]>>, i: usize, c: &mut Columns| {
            let row = &ctx.rows[i];
            let e = l[row.s][row.k];
            for m in 0..3 {
                let mut dq = [0.0; 3];
                dq[m] = -e[m];
                c[m] = motor_delta(ctx, i, dq);
            }
        };
        let rows = search_rows(train);
        let mut searched = vec![false; ctx.series.len()];
        for &i in &rows {
            searched[ctx.rows[i].s] = true;
        }
        let sse_for = |t_c: f64| -> f64 {
            let l = lag(t_c, &searched);
            linear::solve(ctx, &rows, 3, &|i, c| effect_for(&l, i, c))
                .map_or(f64::INFINITY, |f| f.sse)
        };
        let grid: Vec<f64> = [2.0f64, 5.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0, 640.0]
            .iter()
            .map(|v| v.ln())
            .collect();
        let (lt, sse, curv) = minimise_1d(&mut |x| sse_for(x.exp()), &grid);
        let t_c = lt.exp();
        let std_t = profile_std(sse, 3 * rows.len(), curv).map(|s| s * t_c);
        let l = lag(t_c, &vec![true; ctx.series.len()]);
        let (fit, delta, alone) =
            fit_joint(ctx, &nui, train, 3, &|i, c| effect_for(&l, i, c), None)?;
        let gain = [fit.x[0], fit.x[1], fit.x[2]];
        let mut params: Vec<Estimate> = (0..3)
            .map(|m| {
                Estimate::new(
                    &format!("gain leg {}", m + 1),
                    gain[m],
                    Some(fit.std[m]),
                    "mm/mm",
                )
            })
            .collect();
        params.push(Estimate::new("time constant", t_c, std_t, "s"));
        let nuis = nuisance_change(nui, fit.x.clone(), 3);
        let ok = gain.iter().all(|g| g.abs() < 0.5);
        ok.then(|| Fitted {
            name: self.name(),
            params,
            k: 4,
            delta,
            alone,
            train_sse: fit.sse,
            change: std::sync::Arc::new(move |c| {
                c.effects.creep = Some(robot::Creep {
                    gain,
                    time_constant_s: t_c,
                });
                nuis(c);
            }),
        })
    }

    fn declared(&self, effects: &Effects, _fitted: &[Estimate]) -> Option<Vec<Estimate>> {
        effects.creep.as_ref().map(|cr| {
            let mut v: Vec<Estimate> = (0..3)
                .map(|i| Estimate::new(&format!("gain leg {}", i + 1), cr.gain[i], None, "mm/mm"))
                .collect();
            v.push(Estimate::new(
                "time constant",
                cr.time_constant_s,
                None,
                "s",
            ));
            v
        })
    }

    fn remove(&self, effects: &mut Effects, _params: &[Estimate]) {
        effects.creep = None;
    }

    /// A history effect: the first against the second half of the training time.
    fn consistency(&self) -> super::Parts {
        super::Parts::Halves
    }

    fn file_position(&self) -> u8 {
        3
    }

    /// The gain of each leg, then the time constant (its logarithm, ln s).
    fn parameters(&self, effects: &Effects) -> Vec<Parameter> {
        if effects.creep.is_none() {
            return Vec::new();
        }
        let mut v: Vec<Parameter> = (0..3)
            .map(|i| Parameter {
                get: |e, i| e.creep.as_ref().map_or(0.0, |c| c.gain[i]),
                set: |e, i, x| {
                    if let Some(c) = e.creep.as_mut() {
                        c.gain[i] = x
                    }
                },
                index: i,
                lo: -0.5,
                hi: 0.5,
                moves_curvatures: true,
                along_path: None,
            })
            .collect();
        v.push(Parameter {
            get: |e, _| e.creep.as_ref().map_or(1.0, |c| c.time_constant_s.ln()),
            set: |e, _, x| {
                if let Some(c) = e.creep.as_mut() {
                    c.time_constant_s = x.exp()
                }
            },
            index: 0,
            lo: 0.5f64.ln(),
            hi: 5000f64.ln(),
            moves_curvatures: true,
            along_path: None,
        });
        v
    }

    /// The gains; the time constant only when `old` has one.
    fn blend(&self, old: &RobotConfig, new: &mut RobotConfig, s: f64) {
        if let Some(c) = new.effects.creep.as_mut() {
            let o = old.effects.creep.as_ref().map_or([0.0; 3], |x| x.gain);
            c.gain = std::array::from_fn(|i| lerp(o[i], c.gain[i], s));
            if let Some(oc) = &old.effects.creep {
                c.time_constant_s = lerp(oc.time_constant_s, c.time_constant_s, s);
            }
        }
    }

    /// A tendon that shortens under load.
    fn unphysical(&self, effects: &Effects, _max_change: f64) -> Option<String> {
        let cr = effects.creep.as_ref()?;
        cr.gain.iter().any(|g| *g < 0.0).then(|| {
            format!(
                "a tendon that shortens under load (creep gains {:?})",
                cr.gain
            )
        })
    }
}
