//! Putting an accepted candidate into the model for real: its linearised change is damped
//! until the full (non-linearised) model lowers the training error, re-linearised and refitted
//! (Gauss-Newton) while that helps, and then every effect's parameters are refined together.

use crate::context::Context;
use crate::effects;
use crate::fitted::Fitted;
use crate::model::ExtendedModel;
use crate::series::{Blocks, Series};
use pcr_robot::RobotConfig;

/// Largest number of Gauss-Newton steps when a candidate goes into the model.
pub(crate) const GN_STEPS: usize = 10;

/// An acceptance's Gauss-Newton steps stop when one keeps more than this share of the training
/// error (gains less than 3 %).
const GN_MIN_GAIN: f64 = 0.97;

/// The acceptance's steps run on every so many training rows (of each series): the joint
/// refinement that follows runs on fewer ([`crate::refine::SEARCH_ROWS`]), and the steps only
/// take the parameters near it (rows 20 ms apart at 50 Hz: four of them 80 ms apart). Not
/// every eighth: on joint springs at 10x its steps stopped one short, and the calibration from
/// the drawing, started from there, went the wrong way (a load, a frame and a map named beside
/// the springs, k_M 2425 +- 62 against 3000).
const ACCEPTANCE_EVERY: usize = 4;

/// Puts an accepted candidate into the model for real: the linearised change, damped until the
/// full model lowers the training error, re-linearised and refitted (Gauss-Newton) while that
/// helps, then every effect's parameters refined together on the full model. `None` when the
/// full model does not improve on the training rows.
pub(crate) fn accept<'a>(
    config: &RobotConfig,
    ctx: &Context<'a>,
    first: Fitted,
    series: &'a [Series],
    blocks: &Blocks,
    w_phi: f64,
    progress: &crate::progress::ProgressSink,
) -> Option<(RobotConfig, Context<'a>)> {
    let effect = effects::named(first.name);
    // The steps compare training errors: their contexts hold every `ACCEPTANCE_EVERY`-th
    // training row alone.
    let start = ctx.training_subset(ACCEPTANCE_EVERY);
    let n_train = start.len();
    let start_sse = ctx.sse(&start, None);
    let mut cur: Option<(RobotConfig, Context<'a>, f64)> = None;
    let mut step = Some(first);
    // Damping carried from one step to the next (a step that needed 1/4 starts the next at 1/2).
    let mut trust = 1.0f64;
    for it in 0..GN_STEPS {
        let Some(f) = step.take() else { break };
        let (base_cfg, base_sse) = match &cur {
            Some((c, _, s)) => (c.clone(), *s),
            None => (config.clone(), start_sse),
        };
        let mut full = base_cfg.clone();
        (f.change)(&mut full);
        let mut improved = false;
        let mut frac = trust;
        while frac >= 1.0 / 16.0 {
            let cand = blend(&base_cfg, &full, frac);
            let nctx = cand
                .validate("extended robot")
                .ok()
                .and_then(|_| ExtendedModel::like(&cand, &ctx.model).ok())
                .map(|mut m| {
                    // The step after this one, and the refinement, linearise its friction.
                    m.friction_derivatives = true;
                    let least = n_train.saturating_sub(5);
                    Context::training(series, m, blocks, w_phi, ACCEPTANCE_EVERY, least)
                })
                .filter(|n| n.rows.len() + 5 >= n_train);
            if let Some(nctx) = nctx {
                if let Some((_, c, _)) = &cur {
                    nctx.reuse_nuisance_of(c);
                }
                let sse = nctx.sse(&nctx.train(), None);
                if sse < base_sse {
                    cur = Some((cand, nctx, sse));
                    improved = true;
                    break;
                }
            }
            frac *= 0.5;
        }
        trust = (2.0 * frac).min(1.0);
        tracing::debug!(
            step = it,
            improved,
            frac,
            sse = cur.as_ref().map_or(base_sse, |c| c.2),
            base_sse,
            "acceptance step"
        );
        progress.step();
        if !improved || !effect.is_none_or(|e| e.iterable()) || it + 1 == GN_STEPS {
            break;
        }
        let (_, c, s) = cur.as_ref()?;
        // Stop when the step gained less than 3 %: the joint refinement and the calibration
        // from the drawing that follow take every parameter the rest of the way (a load's
        // steps gained 1-3 % each, nine of them, at a loaded prediction of every training row
        // and a loaded nuisance table apiece; stopping there changes its force by a fifth of
        // its error and takes 3 s off 11).
        let min_gain = effect.map_or(GN_MIN_GAIN, |e| e.acceptance_min_gain());
        if *s > min_gain * base_sse {
            break;
        }
        step = effect.and_then(|e| e.step(c, &c.train()));
        // Nor is a step taken whose own linearised fit expects less than that: its prediction
        // of every training row would cost more than it brings (joint springs' fifth step: a
        // 0.02 % gain for a loaded prediction).
        if step
            .as_ref()
            .is_some_and(|f| f.train_sse > GN_MIN_GAIN * *s)
        {
            break;
        }
    }
    let (cfg, _, sse) = cur?;
    // Every effect's parameters together on the full model.
    let refined = crate::refine::search(&cfg, &ctx.model, series, blocks, w_phi);
    // The model returned is predicted with its friction's derivatives: the calibration from
    // the drawing that follows reads that pass, and the refinement after it linearises its
    // friction with the same pass (`refine::search_with_errors`).
    let linearised = |mut m: ExtendedModel| {
        m.friction_derivatives = true;
        m
    };
    if refined != cfg {
        if let Ok(model) = ExtendedModel::like(&refined, &ctx.model).map(linearised) {
            let least = ctx.rows.len().saturating_sub(5);
            let rctx = Context::at_least(series, model, blocks, w_phi, least);
            if rctx.rows.len() + 5 >= ctx.rows.len()
                && rctx.sse(&rctx.training_subset(ACCEPTANCE_EVERY), None) < sse
            {
                return Some((refined, rctx));
            }
        }
    }
    // The held-out rows too, for the scoring that follows.
    let model = ExtendedModel::like(&cfg, &ctx.model).ok().map(linearised)?;
    Some((cfg, Context::new(series, model, blocks, w_phi)))
}

/// The configuration a fraction `s` of the way from `old` to `new`: every effect's part of the
/// robot file interpolated ([`crate::effects::Effect::blend`]: the legs' geometry, map
/// coefficients of the same family, the effects' continuous parameters; an effect absent from
/// `old` counts as zero), structural differences (another map family, other periodic terms)
/// taken from `new`. Damps a linearised step.
pub(crate) fn blend(old: &RobotConfig, new: &RobotConfig, s: f64) -> RobotConfig {
    let mut out = new.clone();
    for effect in effects::ALL {
        effect.blend(old, &mut out, s);
    }
    out
}
