//! The library of candidate effects a tendon-driven parallel continuum robot is known to have.
//! Each has a name from a fixed vocabulary, a physical parameterisation, a fit against the
//! residuals of the current model (linearised: the model's Jacobians at each row turn the
//! effect's change of motor position, curvature, load or frame into a change of the predicted
//! pose), and the change it makes to the robot file when it is accepted.
//!
//! Every candidate is fitted together with the calibration parameters (`Nuisance`: the paper's
//! step-1 and step-2 set), so that an effect the calibration partly absorbed is estimated whole,
//! and so that no effect gets the credit for a plain recalibration (which is the `geometry`
//! candidate of its own).
//!
//! | name | effect | parameters |
//! |---|---|---|
//! | `backlash` | gear backlash / friction hysteresis: play on each motor | play b_i, steps |
//! | `latency` | command-to-motion latency | tau, s |
//! | `creep` | slow drift: tendon creep, first-order in time | gain_i, time constant T s |
//! | `drift` | steady drift: each tendon lengthens at a constant rate | rate_i mm/s |
//! | `joint_springs` | compliance under the coupling forces: springs in the passive joints bend the segments (kineto-static) | k_M, k_P N mm/rad |
//! | `external_load` | compliance under an external load: a constant wrench on the platform | F_x, F_y N, M N mm |
//! | `frame` | capture-frame misregistration | dx, dy mm, dphi deg |
//! | `tendon_map` | remaining tendon-map nonlinearity | a richer Table I function per leg |
//! | `geometry` | remaining geometric error (recalibration on every row) | the calibration parameters |
//! | `periodic` | periodic transmission error of one motor | period P steps, amplitude A steps, phase |

use crate::context::Context;
use crate::linear::{self, motor_delta, Columns, Nuisance};
use pcr_kinematics::statics::Loads;
use pcr_kinematics::TendonMap;
use pcr_robot::effects::{Backlash, Compliance, Creep, Drift, FrameCorrection, Latency, Periodic};
use pcr_robot::{RobotConfig, TendonMapKind, TendonMapSpec};
use serde::Serialize;

/// Bending stiffness assumed for the compliance candidate when the robot file declares none,
/// N mm^2 (the segments' nominal value; the loads found scale with it).
pub const DEFAULT_EI: f64 = 6.5e4;

/// A fitted parameter.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Estimate {
    /// Name.
    pub name: String,
    /// Value.
    pub value: f64,
    /// Standard error (`None` where it could not be estimated).
    pub std: Option<f64>,
    /// Unit.
    pub unit: String,
}

fn est(name: &str, value: f64, std: Option<f64>, unit: &str) -> Estimate {
    Estimate {
        name: name.into(),
        value,
        std: std.filter(|s| s.is_finite()),
        unit: unit.into(),
    }
}

/// The change an accepted candidate makes to the robot file.
pub type Change = Box<dyn Fn(&mut RobotConfig) + Send + Sync>;

/// A candidate fitted to the training rows.
pub struct Fitted {
    /// Vocabulary name.
    pub name: &'static str,
    /// The effect's parameters (not the nuisance).
    pub params: Vec<Estimate>,
    /// Number of free parameters of the effect (information criterion).
    pub k: usize,
    /// Predicted change of the residual of every row (effect and nuisance).
    pub delta: Vec<[f64; 3]>,
    /// The effect's change alone, fitted without the nuisance (`None` for `geometry`): when it
    /// covers what a recalibration gains, the physical effect is preferred to the recalibration.
    pub alone: Option<Vec<[f64; 3]>>,
    /// Training SSE after the fit.
    pub train_sse: f64,
    /// What it writes into the robot file.
    pub change: Change,
}

/// The names of the candidates, in the order they are tried.
pub const NAMES: [&str; 10] = [
    "geometry",
    "tendon_map",
    "frame",
    "latency",
    "backlash",
    "creep",
    "drift",
    "joint_springs",
    "external_load",
    "periodic",
];

/// One-line description of a candidate.
pub fn describe(name: &str) -> &'static str {
    match name {
        "backlash" => "gear backlash / friction hysteresis: the output follows each motor through a play",
        "latency" => "command-to-motion latency: the motion lags the command",
        "creep" => "slow drift: tendon creep, elongation toward a share of the displacement with a time constant",
        "drift" => "steady drift: each tendon lengthens at a constant rate with the time since the start of the recording",
        "joint_springs" => "compliance under the coupling forces: springs in the passive joints bend the segments (kineto-static)",
        "external_load" => "compliance under an external load: a constant wrench on the platform bends the segments (kineto-static)",
        "frame" => "capture-frame misregistration: a rigid transform between the measured and the robot frame",
        "tendon_map" => "remaining tendon-map nonlinearity: a richer function of the tendon displacement",
        "geometry" => "remaining geometric error: the calibration parameters refitted on every row",
        "periodic" => "periodic transmission error: the output of one motor lags it periodically in its position",
        _ => "unknown",
    }
}

/// A joint fit: the solution, every row's change, and the effect's change alone.
type JointFit = (linear::LinearFit, Vec<[f64; 3]>, Option<Vec<[f64; 3]>>);

/// Fits with the nuisance: effect columns first, then the calibration parameters. `offset` is a
/// fixed change of the residual (an effect with no free linear parameter at the chosen value).
fn fit_joint(
    ctx: &Context,
    nui: &Nuisance,
    train: &[usize],
    n_e: usize,
    effect: &dyn Fn(usize, &mut Columns),
    offset: Option<&[[f64; 3]]>,
) -> Option<JointFit> {
    let n_g = nui.n;
    let n = n_e + n_g;
    let mut prior = vec![0.0; n_e];
    prior.extend(nui.prior().into_iter().take(n_g));
    if n == 0 {
        // Nothing free: the offset alone (a profiled effect without the nuisance).
        let o = offset?;
        let sse = ctx.sse(train, Some(o));
        return Some((
            linear::LinearFit {
                x: Vec::new(),
                std: Vec::new(),
                sse,
            },
            o.to_vec(),
            Some(o.to_vec()),
        ));
    }
    let alone = match offset {
        Some(o) => Some(o.to_vec()),
        None if n_e > 0 => {
            linear::solve(ctx, train, n_e, effect).map(|f| linear::deltas(ctx, n_e, &f.x, effect))
        }
        None => None,
    };
    let table = (n_g > 0).then(|| ctx.nuisance());
    let cols = |i: usize, c: &mut Columns| {
        effect(i, c);
        if let Some(t) = &table {
            c[n_e..n].copy_from_slice(&t.cols[i]);
        }
    };
    // Residual with the offset taken out: solve on a shifted context copy of r.
    let fit = match offset {
        Some(o) => {
            let mut shifted = ctx.clone();
            for (row, d) in shifted.rows.iter_mut().zip(o) {
                for k in 0..3 {
                    row.r[k] -= d[k];
                }
            }
            linear::solve_with_prior(&shifted, train, n, &cols, Some(&prior))?
        }
        None => linear::solve_with_prior(ctx, train, n, &cols, Some(&prior))?,
    };
    let mut delta = linear::deltas(ctx, n, &fit.x, &cols);
    if let Some(o) = offset {
        for (d, oo) in delta.iter_mut().zip(o) {
            for k in 0..3 {
                d[k] += oo[k];
            }
        }
    }
    Some((fit, delta, alone))
}

/// Applies the nuisance part (after `n_e` effect parameters) of a joint fit to a config.
fn nuisance_change(nui: Nuisance, x: Vec<f64>, n_e: usize) -> impl Fn(&mut RobotConfig) {
    move |c: &mut RobotConfig| {
        if x.len() > n_e {
            nui.apply(&x[n_e..], c)
        }
    }
}

/// `geometry`: the calibration parameters refitted on every training row.
pub fn geometry(ctx: &Context, train: &[usize]) -> Option<Fitted> {
    let nui = ctx.nuisance().nui.clone();
    let (fit, delta, alone) = fit_joint(ctx, &nui, train, 0, &|_, _| {}, None)?;
    let params = nui
        .names()
        .iter()
        .zip(&fit.x)
        .zip(&fit.std)
        .map(|((n, v), s)| est(n, *v, Some(*s), "change"))
        .collect();
    let k = nui.n;
    let sse = fit.sse;
    let x = fit.x;
    Some(Fitted {
        name: "geometry",
        params,
        k,
        delta,
        alone,
        train_sse: sse,
        change: Box::new(move |c| nui.apply(&x, c)),
    })
}

/// `frame`: measured = robot pose through a small rigid transform.
pub fn frame(ctx: &Context, train: &[usize]) -> Option<Fitted> {
    let nui = ctx.nuisance().nui.clone();
    let effect = |i: usize, c: &mut Columns| {
        let row = &ctx.rows[i];
        let m = ctx.series[row.s].samples[row.k].pose.unwrap_or([0.0; 3]);
        // Correcting the measurement by (dx, dy, dphi) adds these to the residual; as a
        // predicted change of the residual they enter with the opposite sign.
        c[0] = [-1.0, 0.0, 0.0];
        c[1] = [0.0, -1.0, 0.0];
        c[2] = [m[1], -m[0], -ctx.w_phi];
    };
    let (fit, delta, alone) = fit_joint(ctx, &nui, train, 3, &effect, None)?;
    let prev = ctx
        .model
        .config
        .effects
        .frame
        .clone()
        .unwrap_or(FrameCorrection {
            dx_mm: 0.0,
            dy_mm: 0.0,
            dphi_deg: 0.0,
        });
    let f = FrameCorrection {
        dx_mm: prev.dx_mm + fit.x[0],
        dy_mm: prev.dy_mm + fit.x[1],
        dphi_deg: prev.dphi_deg + fit.x[2].to_degrees(),
    };
    let params = vec![
        est("dx", f.dx_mm, Some(fit.std[0]), "mm"),
        est("dy", f.dy_mm, Some(fit.std[1]), "mm"),
        est("dphi", f.dphi_deg, Some(fit.std[2].to_degrees()), "deg"),
    ];
    let nuis = nuisance_change(nui, fit.x.clone(), 3);
    Some(Fitted {
        name: "frame",
        params,
        k: 3,
        delta,
        alone,
        train_sse: fit.sse,
        change: Box::new(move |c| {
            c.effects.frame = Some(f.clone());
            nuis(c);
        }),
    })
}

/// Rows the 1-D profile searches and scans run on: the training rows, thinned evenly to at most
/// [`SEARCH_ROWS`] (the final fit uses every training row).
fn search_rows(train: &[usize]) -> Vec<usize> {
    let step = train.len().div_ceil(SEARCH_ROWS).max(1);
    train.iter().step_by(step).copied().collect()
}

/// At most this many rows in a profile search or scan.
pub const SEARCH_ROWS: usize = 8000;

/// SSE of the rows `rows` after subtracting changes given for those rows (aligned).
fn sse_at(ctx: &Context, rows: &[usize], delta: &[[f64; 3]]) -> f64 {
    rows.iter()
        .zip(delta)
        .map(|(&i, d)| {
            let r = ctx.rows[i].r;
            (r[0] - d[0]).powi(2) + (r[1] - d[1]).powi(2) + (r[2] - d[2]).powi(2)
        })
        .sum()
}

/// A 1-D minimisation of `f` on a grid, refined by golden section around the best point;
/// returns (x, f(x), curvature estimate).
fn minimise_1d(f: &mut dyn FnMut(f64) -> f64, grid: &[f64]) -> (f64, f64, Option<f64>) {
    let vals: Vec<f64> = grid.iter().map(|&x| f(x)).collect();
    let k = (0..grid.len())
        .min_by(|a, b| vals[*a].total_cmp(&vals[*b]))
        .unwrap_or(0);
    let lo = grid[k.saturating_sub(1)];
    let hi = grid[(k + 1).min(grid.len() - 1)];
    let (mut a, mut b) = (lo, hi);
    let gr = 0.5 * (5f64.sqrt() - 1.0);
    let mut c = b - gr * (b - a);
    let mut d = a + gr * (b - a);
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..30 {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - gr * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + gr * (b - a);
            fd = f(d);
        }
    }
    let (x, fx) = if fc < fd { (c, fc) } else { (d, fd) };
    let (x, fx) = if vals[k] < fx {
        (grid[k], vals[k])
    } else {
        (x, fx)
    };
    let h = ((hi - lo) * 0.05).max(1e-9);
    let curv = (f(x + h) - 2.0 * fx + f(x - h)) / (h * h);
    (x, fx, (curv > 0.0).then_some(curv))
}

/// Standard error of a profiled parameter from the curvature of the SSE.
fn profile_std(sse: f64, n: usize, curv: Option<f64>) -> Option<f64> {
    let s2 = sse / n.max(2) as f64;
    curv.map(|c| (2.0 * s2 / c).sqrt())
}

/// The change of the predicted pose of the rows `rows` (every measured row when `None`) when
/// their motors' outputs become `q_new` (per series and row).
fn motor_change(ctx: &Context, q_new: &[Vec<[f64; 3]>], rows: Option<&[usize]>) -> Vec<[f64; 3]> {
    let one = |i: usize| {
        let row = &ctx.rows[i];
        let q = ctx.pred(row).q_eff;
        let o = q_new[row.s][row.k];
        motor_delta(ctx, i, [o[0] - q[0], o[1] - q[1], o[2] - q[2]])
    };
    match rows {
        Some(r) => r.iter().map(|&i| one(i)).collect(),
        None => (0..ctx.rows.len()).map(one).collect(),
    }
}

/// The change of every measured row's predicted pose when the motor-side effects of the model
/// are replaced by `effects` (latency, periodic errors, backlash, in the model's chain order).
fn motor_side_delta(
    ctx: &Context,
    effects: &pcr_robot::effects::Effects,
    rows: Option<&[usize]>,
) -> Vec<[f64; 3]> {
    let q_new: Vec<Vec<[f64; 3]>> = ctx
        .series
        .iter()
        .map(|s| {
            crate::model::effective_steps(
                s,
                effects.latency.as_ref(),
                &effects.periodic,
                effects.backlash.as_ref(),
            )
        })
        .collect();
    motor_change(ctx, &q_new, rows)
}

/// `latency`: the motion lags the command by tau.
pub fn latency(ctx: &Context, train: &[usize]) -> Option<Fitted> {
    let rows = search_rows(train);
    let shift = |tau: f64, rows: Option<&[usize]>| -> Vec<[f64; 3]> {
        let mut e = ctx.model.config.effects.clone();
        e.latency = Some(Latency { latency_s: tau });
        motor_side_delta(ctx, &e, rows)
    };
    // From scratch: -50 ms to 0.5 s. Once the model holds a latency (a Gauss-Newton step of
    // its acceptance), it moves little from one step to the next: 30 ms around it.
    let grid: Vec<f64> = match &ctx.model.config.effects.latency {
        None => (0..=55).map(|k| -0.05 + 0.01 * k as f64).collect(),
        Some(l) => (-3..=3).map(|k| l.latency_s + 0.01 * k as f64).collect(),
    };
    let (tau, sse, curv) = minimise_1d(&mut |t| sse_at(ctx, &rows, &shift(t, Some(&rows))), &grid);
    let std = profile_std(sse, 3 * rows.len(), curv);
    let nui = ctx.nuisance().nui.clone();
    let off = shift(tau, None);
    let (fit, delta, alone) = fit_joint(ctx, &nui, train, 0, &|_, _| {}, Some(&off))?;
    let nuis = nuisance_change(nui, fit.x.clone(), 0);
    Some(Fitted {
        name: "latency",
        params: vec![est("latency", tau, std, "s")],
        k: 1,
        delta,
        alone,
        train_sse: fit.sse,
        change: Box::new(move |c| {
            c.effects.latency = Some(Latency { latency_s: tau });
            nuis(c);
        }),
    })
}

/// `backlash`: play of b_i steps on each motor.
pub fn backlash(ctx: &Context, train: &[usize]) -> Option<Fitted> {
    let e = &ctx.model.config.effects;
    let pre: Vec<Vec<[f64; 3]>> = ctx
        .series
        .iter()
        .map(|s| crate::model::steps_before_backlash(s, e.latency.as_ref(), &e.periodic))
        .collect();
    let rows = search_rows(train);
    let delta_of = |b: [f64; 3], rows: Option<&[usize]>| -> Vec<[f64; 3]> {
        let q_new: Vec<Vec<[f64; 3]>> = pre
            .iter()
            .map(|q| {
                let mut q = q.clone();
                crate::model::apply_backlash(&mut q, &Backlash { steps: b });
                q
            })
            .collect();
        motor_change(ctx, &q_new, rows)
    };
    // From scratch: every play up to 20 steps. Once the model holds a play (a Gauss-Newton step
    // of its acceptance), the play moves little from one step to the next: 3 steps around it.
    let held = e.backlash.as_ref().map(|b| b.steps);
    let grid_of = |m: usize| -> Vec<f64> {
        match held {
            None => (0..=40).map(|k| 0.5 * k as f64).collect(),
            Some(h) => (-6..=6)
                .map(|k| h[m] + 0.5 * k as f64)
                .filter(|v| *v >= 0.0)
                .collect(),
        }
    };
    let mut b = [0.0; 3];
    let mut stds = [None; 3];
    // The play acts on each motor alone: a profile over motor m's play runs the play operator
    // on that motor only, the others' outputs held at the current plays.
    let mut cur: Vec<Vec<[f64; 3]>> = pre
        .iter()
        .map(|q| {
            let mut q = q.clone();
            crate::model::apply_backlash(&mut q, &Backlash { steps: b });
            q
        })
        .collect();
    let mut col: Vec<Vec<f64>> = pre.iter().map(|q| vec![0.0; q.len()]).collect();
    for _sweep in 0..2 {
        for m in 0..3 {
            let (x, s, curv) = minimise_1d(
                &mut |v| {
                    for (c, q) in col.iter_mut().zip(&pre) {
                        play_on(q, m, v.max(0.0), c);
                    }
                    let d: Vec<[f64; 3]> = rows
                        .iter()
                        .map(|&i| {
                            let row = &ctx.rows[i];
                            let q = ctx.pred(row).q_eff;
                            let mut o = cur[row.s][row.k];
                            o[m] = col[row.s][row.k];
                            motor_delta(ctx, i, [o[0] - q[0], o[1] - q[1], o[2] - q[2]])
                        })
                        .collect();
                    sse_at(ctx, &rows, &d)
                },
                &grid_of(m),
            );
            b[m] = x.max(0.0);
            stds[m] = profile_std(s, 3 * rows.len(), curv);
            for (c, q) in cur.iter_mut().zip(&pre) {
                let mut out = vec![0.0; q.len()];
                play_on(q, m, b[m], &mut out);
                for (v, o) in c.iter_mut().zip(out) {
                    v[m] = o;
                }
            }
        }
    }
    let nui = ctx.nuisance().nui.clone();
    let off = delta_of(b, None);
    let (fit, delta, alone) = fit_joint(ctx, &nui, train, 0, &|_, _| {}, Some(&off))?;
    let nuis = nuisance_change(nui, fit.x.clone(), 0);
    Some(Fitted {
        name: "backlash",
        params: (0..3)
            .map(|m| est(&format!("play motor {}", m + 1), b[m], stds[m], "steps"))
            .collect(),
        k: 3,
        delta,
        alone,
        train_sse: fit.sse,
        change: Box::new(move |c| {
            c.effects.backlash = Some(Backlash { steps: b });
            nuis(c);
        }),
    })
}

/// The output of motor `m` through a play of `b` steps (as [`crate::model::apply_backlash`]
/// computes it), written to `out`.
fn play_on(q: &[[f64; 3]], m: usize, b: f64, out: &mut [f64]) {
    if b == 0.0 {
        for (o, v) in out.iter_mut().zip(q) {
            *o = v[m];
        }
        return;
    }
    let h = 0.5 * b;
    let mut y = q.first().map_or(0.0, |v| v[m]);
    for (o, v) in out.iter_mut().zip(q) {
        y = y.clamp(v[m] - h, v[m] + h);
        *o = y;
    }
}

/// `creep`: the tendon lengthens toward gain_i dl_i with time constant T.
pub fn creep(ctx: &Context, train: &[usize]) -> Option<Fitted> {
    let mmps: [f64; 3] = std::array::from_fn(|i| ctx.model.config.legs[i].actuation.mm_per_step());
    // E_i(T): the first-order lag of dl_i, per row (in steps: divided by mm/step).
    let lag = |t_c: f64| -> Vec<Vec<[f64; 3]>> {
        ctx.series
            .iter()
            .zip(&ctx.preds)
            .map(|(s, p)| {
                let mut e = [0.0f64; 3];
                let mut prev = s.samples.first().map_or(0.0, |x| x.t_s);
                s.samples
                    .iter()
                    .zip(p)
                    .map(|(x, pr)| {
                        let a = 1.0 - (-(x.t_s - prev).max(0.0) / t_c).exp();
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
    let sse_for = |t_c: f64| -> f64 {
        let l = lag(t_c);
        linear::solve(ctx, &rows, 3, &|i, c| effect_for(&l, i, c)).map_or(f64::INFINITY, |f| f.sse)
    };
    let grid: Vec<f64> = [2.0f64, 5.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0, 640.0]
        .iter()
        .map(|v| v.ln())
        .collect();
    let (lt, sse, curv) = minimise_1d(&mut |x| sse_for(x.exp()), &grid);
    let t_c = lt.exp();
    let std_t = profile_std(sse, 3 * rows.len(), curv).map(|s| s * t_c);
    let l = lag(t_c);
    let (fit, delta, alone) = fit_joint(ctx, &nui, train, 3, &|i, c| effect_for(&l, i, c), None)?;
    let gain = [fit.x[0], fit.x[1], fit.x[2]];
    let mut params: Vec<Estimate> = (0..3)
        .map(|m| {
            est(
                &format!("gain leg {}", m + 1),
                gain[m],
                Some(fit.std[m]),
                "mm/mm",
            )
        })
        .collect();
    params.push(est("time constant", t_c, std_t, "s"));
    let nuis = nuisance_change(nui, fit.x.clone(), 3);
    let ok = gain.iter().all(|g| g.abs() < 0.5);
    ok.then(|| Fitted {
        name: "creep",
        params,
        k: 4,
        delta,
        alone,
        train_sse: fit.sse,
        change: Box::new(move |c| {
            c.effects.creep = Some(Creep {
                gain,
                time_constant_s: t_c,
            });
            nuis(c);
        }),
    })
}

/// `drift`: each tendon lengthens at a constant rate with the time since the start of its
/// recording (linear in the three rates, fitted with the nuisance). Where creep saturates with a
/// time constant, drift keeps growing; the held-out blocks choose between them.
pub fn drift(ctx: &Context, train: &[usize]) -> Option<Fitted> {
    let mmps: [f64; 3] = std::array::from_fn(|i| ctx.model.config.legs[i].actuation.mm_per_step());
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
    let prev = ctx
        .model
        .config
        .effects
        .drift
        .as_ref()
        .map_or([0.0; 3], |d| d.rate_mm_per_s);
    let rate: [f64; 3] = std::array::from_fn(|m| prev[m] + UNIT * fit.x[m]);
    let params = (0..3)
        .map(|m| {
            est(
                &format!("rate leg {}", m + 1),
                rate[m],
                Some(UNIT * fit.std[m]),
                "mm/s",
            )
        })
        .collect();
    let nuis = nuisance_change(nui, fit.x.clone(), 3);
    Some(Fitted {
        name: "drift",
        params,
        k: 3,
        delta,
        alone,
        train_sse: fit.sse,
        change: Box::new(move |c| {
            c.effects.drift = Some(Drift {
                rate_mm_per_s: rate,
            });
            nuis(c);
        }),
    })
}

/// The kineto-static candidates: `which` selects the load parameters freed (indices into
/// force x, force y, couple, k_M, k_P). EI comes from the robot file or [`DEFAULT_EI`].
fn loaded(ctx: &Context, train: &[usize], name: &'static str, which: &[usize]) -> Option<Fitted> {
    let base = ctx
        .model
        .config
        .effects
        .compliance
        .clone()
        .unwrap_or(Compliance {
            ei_n_mm2: DEFAULT_EI,
            force_n: [0.0; 2],
            couple_n_mm: 0.0,
            k_m_n_mm_per_rad: 0.0,
            k_p_n_mm_per_rad: 0.0,
        });
    let loads = Loads::from_compliance(&base);
    // Per-row responses (per N, per 100 N mm, per 100 N mm/rad for conditioning).
    let scale = [1.0, 1.0, 100.0, 100.0, 100.0];
    let resp = ctx.load_responses(&loads);
    let n_e = which.len();
    let effect = |i: usize, c: &mut Columns| {
        for (a, &j) in which.iter().enumerate() {
            let r = resp[i][j];
            c[a] = [
                r[0] * scale[j],
                r[1] * scale[j],
                r[2] * scale[j] * ctx.w_phi,
            ];
        }
    };
    let nui = ctx.nuisance().nui.clone();
    let (fit, delta, alone) = fit_joint(ctx, &nui, train, n_e, &effect, None)?;
    let mut v = [0.0; 5];
    let mut sd = [None; 5];
    for (a, &j) in which.iter().enumerate() {
        v[j] = fit.x[a] * scale[j];
        sd[j] = Some(fit.std[a] * scale[j]);
    }
    let new = Compliance {
        ei_n_mm2: base.ei_n_mm2,
        force_n: [base.force_n[0] + v[0], base.force_n[1] + v[1]],
        couple_n_mm: base.couple_n_mm + v[2],
        k_m_n_mm_per_rad: base.k_m_n_mm_per_rad + v[3],
        k_p_n_mm_per_rad: base.k_p_n_mm_per_rad + v[4],
    };
    let all = [
        ("force x", new.force_n[0], "N"),
        ("force y", new.force_n[1], "N"),
        ("couple", new.couple_n_mm, "N mm"),
        ("k_M", new.k_m_n_mm_per_rad, "N mm/rad"),
        ("k_P", new.k_p_n_mm_per_rad, "N mm/rad"),
    ];
    let mut params: Vec<Estimate> = which
        .iter()
        .map(|&j| est(all[j].0, all[j].1, sd[j], all[j].2))
        .collect();
    params.push(est("EI (assumed)", new.ei_n_mm2, None, "N mm^2"));
    let nuis = nuisance_change(nui, fit.x.clone(), n_e);
    Some(Fitted {
        name,
        params,
        k: n_e,
        delta,
        alone,
        train_sse: fit.sse,
        change: Box::new(move |c| {
            c.effects.compliance = Some(new.clone());
            nuis(c);
        }),
    })
}

/// `joint_springs`: springs in the passive joints (relaxed at home) bend the segments through
/// the link forces (kineto-static).
pub fn joint_springs(ctx: &Context, train: &[usize]) -> Option<Fitted> {
    loaded(ctx, train, "joint_springs", &[3, 4])
}

/// `external_load`: a constant wrench on the platform bends the segments (kineto-static).
pub fn external_load(ctx: &Context, train: &[usize]) -> Option<Fitted> {
    loaded(ctx, train, "external_load", &[0, 1, 2])
}

/// `tendon_map`: a richer function of the tendon displacement per leg: the current map plus a
/// correction in the basis of the richest Table I family (root series to dl^(1/6)) and dl|dl|,
/// dl^3; written back as the Table I function that reproduces it best over the data's range.
pub fn tendon_map(ctx: &Context, train: &[usize]) -> Option<Fitted> {
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
                est(
                    &format!("leg {} {n}", leg + 1),
                    fit.x[leg * NB + j],
                    Some(fit.std[leg * NB + j]),
                    "1/mm per unit",
                )
            })
        })
        .collect();
    Some(Fitted {
        name: "tendon_map",
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
                let current = TendonMap::from_leg(&c.legs[leg]);
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
                    let m = TendonMap::from_spec(spec);
                    pcr_calibration::step1::is_monotonic(&m, lo, hi)
                        && pcr_calibration::step1::reaches_bending_limit(&m, l_c, bending_max)
                }) {
                    c.legs[leg].tendon_map = spec;
                }
            }
        }),
    })
}

/// The Table I function that reproduces (dl, kappa) samples best (least squares, smallest
/// maximum error), with its coefficients.
pub fn best_family(target: &[(f64, f64)]) -> Option<TendonMapSpec> {
    let mut best: Option<(f64, TendonMapSpec)> = None;
    for kind in TendonMapKind::ALL {
        let Some(c) = linear_fit(kind, target) else {
            continue;
        };
        let m = TendonMap::new(kind, &c);
        if m.dl_for_kappa(m.kappa(0.0)).is_err() {
            continue;
        }
        let err = target
            .iter()
            .map(|(d, k)| (m.kappa(*d) - k).abs())
            .fold(0.0, f64::max);
        if best.as_ref().is_none_or(|b| err < b.0 * 0.999) {
            best = Some((err, TendonMapSpec::symmetric(kind, c)));
        }
    }
    best.map(|b| b.1)
}

fn linear_fit(kind: TendonMapKind, pts: &[(f64, f64)]) -> Option<Vec<f64>> {
    let off = usize::from(!kind.has_offset());
    let nc = kind.n_coeffs();
    let mut a = nalgebra::DMatrix::zeros(pts.len(), nc);
    let mut b = nalgebra::DVector::zeros(pts.len());
    let mut basis = [0.0; 7];
    for (r, (dl, k)) in pts.iter().enumerate() {
        TendonMap::basis(kind, *dl, &mut basis);
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

/// `periodic`: the output of one motor lags it by A sin(2 pi q / P + phase); every motor and
/// every period from 4 steps to a revolution is scanned, the best pair is fitted.
pub fn periodic(ctx: &Context, train: &[usize]) -> Option<Fitted> {
    let spr = ctx.model.config.legs[0].actuation.steps_per_rev as f64;
    let mut periods: Vec<f64> = (4..=256).map(f64::from).collect();
    let mut p = 272.0;
    while p <= spr {
        periods.push(p);
        p += 16.0;
    }
    // Precompute each train row's motor column (d weighted pose / d q_m) dotted with r and
    // with itself, then scan.
    let mut best: Option<(f64, usize, f64)> = None; // (sse reduction, motor, period)
    for m in 0..3 {
        let rows: Vec<([f64; 3], [f64; 3], f64)> = search_rows(train)
            .iter()
            .map(|&i| {
                let mut dq = [0.0; 3];
                dq[m] = 1.0;
                let c = motor_delta(ctx, i, dq);
                let row = &ctx.rows[i];
                (c, row.r, ctx.pred(row).q_eff[m])
            })
            .collect();
        for &per in &periods {
            let w = std::f64::consts::TAU / per;
            let (mut ss, mut sc, mut cc, mut rs, mut rc) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for (c, r, q) in &rows {
                let (sn, cs) = (w * q).sin_cos();
                let cr = c[0] * r[0] + c[1] * r[1] + c[2] * r[2];
                let c2 = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
                ss += c2 * sn * sn;
                sc += c2 * sn * cs;
                cc += c2 * cs * cs;
                rs += cr * sn;
                rc += cr * cs;
            }
            let det = ss * cc - sc * sc;
            if det <= 0.0 {
                continue;
            }
            let a = (cc * rs - sc * rc) / det;
            let b = (ss * rc - sc * rs) / det;
            let red = a * rs + b * rc;
            if best.is_none_or(|x| red > x.0) {
                best = Some((red, m, per));
            }
        }
    }
    let (_, m, per) = best?;
    let w = std::f64::consts::TAU / per;
    let effect = |i: usize, c: &mut Columns| {
        let q = ctx.pred(&ctx.rows[i]).q_eff[m];
        let mut dq = [0.0; 3];
        dq[m] = 1.0;
        let col = motor_delta(ctx, i, dq);
        let (sn, cs) = (w * q).sin_cos();
        c[0] = col.map(|v| v * sn);
        c[1] = col.map(|v| v * cs);
    };
    let nui = ctx.nuisance().nui.clone();
    let (fit, delta, alone) = fit_joint(ctx, &nui, train, 2, &effect, None)?;
    // Output = q - A sin(w q + phase): the residual change is -A(sin cos(ph) + cos sin(ph)).
    let (a_s, a_c) = (-fit.x[0], -fit.x[1]);
    let amp = a_s.hypot(a_c);
    let phase = a_c.atan2(a_s);
    let amp_std = (fit.std[0].hypot(fit.std[1])) / 2f64.sqrt();
    let nuis = nuisance_change(nui, fit.x.clone(), 2);
    let entry = Periodic {
        motor: (m + 1) as u8,
        period_steps: per,
        amplitude_steps: amp,
        phase_deg: phase.to_degrees(),
    };
    Some(Fitted {
        name: "periodic",
        params: vec![
            est("motor", (m + 1) as f64, None, ""),
            est("period", per, None, "steps"),
            est("amplitude", amp, Some(amp_std), "steps"),
            est(
                "phase",
                phase.to_degrees(),
                Some((amp_std / amp.max(1e-12)).to_degrees()),
                "deg",
            ),
        ],
        k: 4,
        delta,
        alone,
        train_sse: fit.sse,
        change: Box::new(move |c| {
            c.effects.periodic.push(entry.clone());
            nuis(c);
        }),
    })
}

/// Whether re-running a candidate on a model that already holds its effect refines it (a
/// Gauss-Newton step); `creep` and `periodic` are fitted once.
pub fn iterable(name: &str) -> bool {
    !matches!(name, "creep" | "periodic")
}

/// Fits the candidate `name`.
pub fn fit(name: &str, ctx: &Context, train: &[usize]) -> Option<Fitted> {
    match name {
        "geometry" => geometry(ctx, train),
        "tendon_map" => tendon_map(ctx, train),
        "frame" => frame(ctx, train),
        "latency" => latency(ctx, train),
        "backlash" => backlash(ctx, train),
        "creep" => creep(ctx, train),
        "drift" => drift(ctx, train),
        "joint_springs" => joint_springs(ctx, train),
        "external_load" => external_load(ctx, train),
        "periodic" => periodic(ctx, train),
        _ => None,
    }
}
