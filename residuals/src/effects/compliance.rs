//! The kineto-static compliance `joint_springs` and `external_load` share: the robot file's
//! `[effects.compliance]` (the segments bend under the link forces, loaded by springs in the
//! passive joints and by a wrench on the platform, the segments Kirchhoff elastica;
//! `kinematics/src/statics.rs`), its part of
//! the prediction, and the fit of some of its five load parameters with the calibration
//! parameters.

use super::joint_fit::{fit_joint, nuisance_change};
use crate::context::Context;
use crate::fitted::{Estimate, Fitted};
use crate::linear::Columns;
use pcr_kinematics::statics::Loads;
use pcr_robot::effects::{Compliance, Effects};

/// Bending stiffness assumed for the compliance candidates when the robot file declares none,
/// N mm^2 (the segments' nominal value; the loads found scale with it).
pub const DEFAULT_EI: f64 = 6.5e4;

/// The loads of the kineto-static model, when the robot file declares a compliance.
pub fn loads(effects: &Effects) -> Option<Loads> {
    effects.compliance.as_ref().map(Loads::from_compliance)
}

/// The compliance of a robot file's effects, zero loads with [`DEFAULT_EI`] when it declares
/// none.
pub fn held(effects: &Effects) -> Compliance {
    effects.compliance.clone().unwrap_or(Compliance {
        ei_n_mm2: DEFAULT_EI,
        force_n: [0.0; 2],
        couple_n_mm: 0.0,
        k_m_n_mm_per_rad: 0.0,
        k_p_n_mm_per_rad: 0.0,
    })
}

/// Training RMS of a fit's change (mm) above which the kineto-static fit is linearised again
/// at its own estimate before it is scored: loads that move the pose by millimetres are far
/// outside the linearisation at the model's loads (joint springs at ten times the sweep's test
/// strength, 16 N at the segment tips: the fit from zero load reached a third of them, and a
/// recalibration that left the drawing outscored it).
const RELINEARISE_MM: f64 = 4.0;

/// Most re-linearisations of a large kineto-static fit.
const RELINEARISATIONS: usize = 3;

/// The kineto-static fit: `which` selects the load parameters freed (indices into force x,
/// force y, couple, k_M, k_P), added to those the model holds; `name` is the candidate's. EI
/// comes from the robot file or [`DEFAULT_EI`]. A fit whose change is large
/// ([`RELINEARISE_MM`]) is linearised again at its own estimate (the model with it, its rows
/// predicted again) and refitted, up to [`RELINEARISATIONS`] times while the change stays
/// large; its change of every row is then the sum of the steps'.
pub(crate) fn fit(
    ctx: &Context,
    train: &[usize],
    name: &'static str,
    which: &[usize],
) -> Option<Fitted> {
    let mut f = fit_at(ctx, train, name, which)?;
    let rms = |d: &[[f64; 3]]| {
        (train
            .iter()
            .map(|&i| d[i][0] * d[i][0] + d[i][1] * d[i][1] + d[i][2] * d[i][2])
            .sum::<f64>()
            / train.len().max(1) as f64)
            .sqrt()
    };
    // The last step's own change of every row.
    let mut step = rms(&f.delta);
    for _ in 0..RELINEARISATIONS {
        if step < RELINEARISE_MM {
            break;
        }
        // The estimate so far: every step's change on the model the fit began at.
        let mut next = ctx.model.config.clone();
        (f.change)(&mut next);
        let Ok(model) = crate::model::ExtendedModel::like(&next, &ctx.model) else {
            break;
        };
        let Some(c1) = ctx.same_rows(model) else {
            break;
        };
        let Some(g) = fit_at(&c1, train, name, which) else {
            break;
        };
        step = rms(&g.delta);
        // The change of every row from the context the fit began at: to the model of this
        // step, then this step's.
        let delta: Vec<[f64; 3]> = (0..ctx.rows.len())
            .map(|i| {
                let (r0, r1) = (ctx.rows[i].r, c1.rows[i].r);
                std::array::from_fn(|k| r0[k] - r1[k] + g.delta[i][k])
            })
            .collect();
        let first = f.change;
        let second = g.change;
        f = Fitted {
            name,
            params: g.params,
            k: g.k,
            delta,
            // The effect alone as first fitted, at the model's loads: it understates a large
            // fit, so the parsimony rule (the effect preferred to a recalibration it covers)
            // errs toward the recalibration, which the search then judges on the drawing.
            alone: f.alone,
            train_sse: g.train_sse,
            change: std::sync::Arc::new(move |c| {
                first(c);
                second(c);
            }),
        };
    }
    Some(f)
}

/// What a fit of a compliance reads of a context that every fit on it shares
/// ([`crate::effects::Effect::share`]): the nuisance columns and the load responses at the
/// loads of its model.
pub(crate) fn share(ctx: &Context) {
    let _ = ctx.nuisance();
    let _ = model_load_responses(ctx);
}

/// The load responses of every row of `ctx` at the loads of its model (none: a compliance of
/// zero).
fn model_load_responses(ctx: &Context) -> std::sync::Arc<Vec<[[f64; 3]; 5]>> {
    let base = held(&ctx.model.config.effects);
    ctx.load_responses(&Loads::from_compliance(&base))
}

/// One linearised kineto-static fit at the loads of `ctx`'s model ([`fit`]).
fn fit_at(ctx: &Context, train: &[usize], name: &'static str, which: &[usize]) -> Option<Fitted> {
    let base = held(&ctx.model.config.effects);
    // Per-row responses (per N, per 100 N mm, per 100 N mm/rad for conditioning).
    let scale = [1.0, 1.0, 100.0, 100.0, 100.0];
    let resp = model_load_responses(ctx);
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
        .map(|&j| Estimate::new(all[j].0, all[j].1, sd[j], all[j].2))
        .collect();
    params.push(Estimate::new("EI (assumed)", new.ei_n_mm2, None, "N mm^2"));
    let nuis = nuisance_change(nui, fit.x.clone(), n_e);
    Some(Fitted {
        name,
        params,
        k: n_e,
        delta,
        alone,
        train_sse: fit.sse,
        change: std::sync::Arc::new(move |c| {
            c.effects.compliance = Some(new.clone());
            nuis(c);
        }),
    })
}
