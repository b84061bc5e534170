//! Attribution that cannot cheat: every candidate is fitted on the training blocks and scored
//! on the held-out blocks; the best one is added only if it lowers the held-out error
//! significantly (a paired test over the held-out blocks, Bonferroni-corrected over the
//! candidates), by more than the smallest effect worth claiming, and the Bayesian information
//! criterion on the training rows agrees. The model then really includes it (the full,
//! non-linearised prediction is recomputed and must confirm the gain), and the search starts
//! again. When nothing more is significant, what remains is compared with the capture noise and
//! the features it correlates with are named.

use crate::acceptance::{accept, GN_STEPS};
use crate::backward::{self, Removed};
use crate::context::{Context, Errors};
use crate::effects::{self, Role};
use crate::features::{self, FeatureLink, Features};
use crate::fitted::{Estimate, Fitted};
use crate::model::ExtendedModel;
use crate::options::Options;
use crate::plausibility::{effects_unphysical, leaves_drawing, unphysical};
use crate::scoring::{Reference, Round};
use crate::series::{Blocks, Series};
use pcr_robot::RobotConfig;
use rayon::prelude::*;
use serde::Serialize;

pub use crate::scoring::{Score, MIN_SHARE};

/// Plot data of one feature: its name, the residual component, (feature value, residual).
pub type FeaturePoints = (String, String, Vec<(f64, f64)>);

/// An effect added to the model.
#[derive(Debug, Clone, Serialize)]
pub struct Added {
    /// Vocabulary name.
    pub name: String,
    /// What it is.
    pub description: String,
    /// Its parameters with uncertainties.
    pub params: Vec<Estimate>,
    /// One standard error of each parameter, by name (the same as in `params`; `null` where
    /// none could be estimated).
    pub uncertainty: std::collections::BTreeMap<String, Option<f64>>,
    /// The evidence: the score that selected it.
    pub evidence: Score,
    /// Held-out errors once the full model includes it.
    pub held_out_after: Errors,
}

/// The verdict on the residual.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// What remains is at the noise level.
    Explained,
    /// Effects were added but a significant structure remains.
    PartlyExplained,
    /// A significant structure remains and no candidate explains it.
    Unexplained,
}

/// The result.
#[derive(Debug, Clone, Serialize)]
pub struct Attribution {
    /// The command delay of every recording: declared, shown by the data, used
    /// ([`crate::alignment`]).
    pub timing: Vec<crate::alignment::Timing>,
    /// A timing declaration error, if a recording declares a longer delay than its data show
    /// (part of the verdict: the analysis went on with the data's delay).
    pub timing_finding: Option<String>,
    /// Held-out errors of the starting model.
    pub before: Errors,
    /// Held-out errors of the extended model.
    pub after: Errors,
    /// Effects added, in order (without those the backward pass took out).
    pub effects: Vec<Added>,
    /// Effects the backward pass took out: with all the others in, they no longer earned
    /// their place.
    pub removed: Vec<Removed>,
    /// Every candidate tried in every round.
    pub candidates: Vec<Score>,
    /// The verdict.
    pub verdict: Verdict,
    /// Capture noise of one row (x, y mm; phi deg) from the settled rows, if any.
    pub noise: Option<[f64; 3]>,
    /// RMS of the held-out weighted residual at the end against what the noise explains, mm.
    pub remaining_rms_mm: f64,
    /// The part of it above the noise, mm.
    pub remaining_excess_mm: f64,
    /// Features the remaining residual correlates with (held-out R^2), strongest first.
    pub correlated_features: Vec<FeatureLink>,
    /// Training rows, held-out rows.
    pub rows: [usize; 2],
    /// Blocks (train, held out).
    pub blocks: [usize; 2],
    /// Settings.
    pub options: Options,
    /// The extended robot configuration.
    #[serde(skip)]
    pub robot: RobotConfig,
    /// Plot data: per added effect, (change its linearised model predicts, residual along that
    /// change) on held-out rows, mm.
    #[serde(skip)]
    pub effect_points: Vec<(String, Vec<(f64, f64)>)>,
    /// Plot data: held-out rows' time (s, from the start of their recording) and position
    /// residual before and after, mm.
    #[serde(skip)]
    pub residual_time: Vec<(f64, f64, f64)>,
    /// Plot data: the strongest features of the remainder, (feature value, residual component).
    #[serde(skip)]
    pub feature_points: Vec<FeaturePoints>,
}

/// Why the attribution failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AttributionError {
    /// The model cannot be built.
    #[error(transparent)]
    Model(#[from] crate::model::ModelError),
    /// Not enough rows.
    #[error("{0}")]
    Data(String),
}

fn mark(scores: &mut [Score], round: usize, name: &str, note: String) {
    if let Some(last) = scores
        .iter_mut()
        .rev()
        .find(|x| x.name == name && x.round == round)
    {
        last.significant = false;
        last.note = note;
    }
}

/// An effect's parameters as the configuration holds them now
/// ([`crate::effects::Effect::declared`]), with the uncertainties of the fit that found it
/// (matched by name); the fitted ones where the effect reads none back.
fn current_params(c: &RobotConfig, name: &str, fitted: &[Estimate]) -> Vec<Estimate> {
    let std = |n: &str| fitted.iter().find(|p| p.name == n).and_then(|p| p.std);
    effects::named(name)
        .and_then(|e| e.declared(&c.effects, fitted))
        .map(|ps| {
            ps.into_iter()
                .map(|p| Estimate {
                    std: std(&p.name),
                    ..p
                })
                .collect()
        })
        .unwrap_or_else(|| fitted.to_vec())
}

/// (predicted change, residual along it) on held-out rows, at most 3000 points.
fn effect_points(ctx: &Context, delta: &[[f64; 3]], test: &[usize]) -> Vec<(f64, f64)> {
    let step = test.len().div_ceil(3000).max(1);
    test.iter()
        .step_by(step)
        .filter_map(|&i| {
            let d = delta[i];
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            (n > 1e-9).then(|| {
                let r = ctx.rows[i].r;
                (n, (r[0] * d[0] + r[1] * d[1] + r[2] * d[2]) / n)
            })
        })
        .collect()
}

/// The residuals and features of a robot file on the series (no fitting): what `pcr residuals`
/// writes as `residuals.csv`.
pub fn residual_table(
    robot: &RobotConfig,
    series: &[Series],
    blocks: &Blocks,
    out: &mut dyn std::io::Write,
) -> Result<(), AttributionError> {
    let w_phi = robot.legs.iter().map(|l| l.r_p_mm).sum::<f64>() / 3.0;
    let ctx = Context::new(
        series,
        ExtendedModel::new(robot, effects::chain())?,
        blocks,
        w_phi,
    );
    let feats = Features::of(&ctx);
    features::write_csv(&ctx, &feats, out).map_err(|e| AttributionError::Data(e.to_string()))
}

/// Runs the attribution: starting from `start` (the calibrated robot; `drawing` is the robot
/// file the analysis began with, whose geometry a plausible explanation stays near), on `series`
/// with `blocks`.
///
/// Before anything is attributed, every recording's command delay is estimated from its moving
/// rows and set against what it declares ([`crate::alignment`]); a recording whose data answer
/// their commands sooner than declared is analysed with the delay the data show, and the
/// finding is part of the result.
pub fn attribute(
    start: &RobotConfig,
    drawing: &RobotConfig,
    series: &[Series],
    blocks: &Blocks,
    opts: &Options,
) -> Result<Attribution, AttributionError> {
    // On a thread of rayon's pool ([`crate::on_the_pool`]).
    crate::on_the_pool(|| attribute_here(start, drawing, series, blocks, opts))
}

/// [`attribute`], on the thread it is called on.
fn attribute_here(
    start: &RobotConfig,
    drawing: &RobotConfig,
    series: &[Series],
    blocks: &Blocks,
    opts: &Options,
) -> Result<Attribution, AttributionError> {
    let w_phi = start.legs.iter().map(|l| l.r_p_mm).sum::<f64>() / 3.0;
    let mut model = ExtendedModel::new(start, effects::chain())?;
    model.exact = opts.exact;
    let rows: usize = series.iter().map(|s| s.samples.len()).sum();
    opts.progress
        .stage(0, "predicting the starting model", rows, 0);
    let ctx0 = Context::new(series, model.clone(), blocks, w_phi);
    opts.progress
        .stage(0, "estimating the command delay", ctx0.rows.len(), 0);
    let timing = crate::alignment::align(&ctx0);
    let finding = crate::alignment::declaration_errors(&timing);
    let a = match crate::alignment::realigned(series, &timing) {
        None => attribute_from(ctx0, start, drawing, series, blocks, opts),
        Some(aligned) => {
            let ctx = Context::new(&aligned, model, blocks, w_phi);
            attribute_from(ctx, start, drawing, &aligned, blocks, opts)
        }
    };
    // The passes kept for this analysis are of no use to the next one.
    crate::model::forget_kept();
    let mut a = a?;
    a.timing = timing;
    a.timing_finding = finding;
    Ok(a)
}

/// The attribution from the starting model's residuals `ctx0` on series whose delays are set.
fn attribute_from<'a>(
    ctx0: Context<'a>,
    start: &RobotConfig,
    drawing: &RobotConfig,
    series: &'a [Series],
    blocks: &Blocks,
    opts: &Options,
) -> Result<Attribution, AttributionError> {
    let w_phi = ctx0.w_phi;
    let (train0, test0) = (ctx0.train(), ctx0.test());
    if train0.len() < 20 || test0.is_empty() {
        return Err(AttributionError::Data(format!(
            "{} training and {} held-out rows with a measured pose: too few to attribute anything",
            train0.len(),
            test0.len()
        )));
    }
    let before = Errors::of(&ctx0, &test0);
    let set = Setting {
        series,
        blocks,
        drawing,
        opts,
        w_phi,
        noise_ms: capture_noise_ms(series, w_phi),
        visits_disagree: visits_disagree(opts),
    };
    let first_residuals: Vec<f64> = ctx0.rows.iter().map(|r| r.r[0].hypot(r.r[1])).collect();
    let mut search = Search {
        config: start.clone(),
        ctx: ctx0,
        scores: Vec::new(),
        added: Vec::new(),
        effect_plots: Vec::new(),
        provisional: None,
        banned: Vec::new(),
        redo: None,
    };
    // The forward rounds; when effects taken in provisionally leave the drawing with every
    // effect found, the search goes back and tries the next candidate of that round instead
    // (at most `MAX_RESTARTS` times).
    let mut first = 1;
    for restart in 0..=MAX_RESTARTS {
        for round in first..=opts.max_rounds {
            let fits = search.fit_and_score(round, &set);
            if !search.add_best(round, fits, &set) {
                break;
            }
        }
        match search.settle_provisional(&set) {
            Some(round) if restart < MAX_RESTARTS => {
                // The scores of the rounds searched again are those of the new search.
                search.scores.retain(|s| s.round < round);
                first = round;
            }
            _ => break,
        }
    }
    let removed = search.backward(&set.backward());
    let slot_std = search.final_estimate(&set);
    let Search {
        config,
        ctx,
        scores,
        mut added,
        effect_plots,
        provisional: _,
        banned: _,
        redo: _,
    } = search;
    opts.progress.stage(0, "what remains", ctx.rows.len(), 0);
    // The values the final model holds (joint refinements move earlier effects too).
    // With the errors of the estimate the model holds where they are the larger.
    for a in &mut added {
        a.params = current_params(&config, &a.name, &a.params);
        if let Some(sd) = &slot_std {
            for (n, e) in crate::refine::reported_errors(&config.effects, sd, &a.name, &a.params) {
                if let Some(p) = a.params.iter_mut().find(|p| p.name == n) {
                    // A value its round held (a limit at its bound) that the refinements
                    // moved states the final estimate's error; an assumed one none.
                    p.std = match p.std {
                        Some(s) => Some(s.max(e)),
                        None if e > 0.0 => Some(e),
                        None => None,
                    };
                }
            }
        }
        a.uncertainty = a.params.iter().map(|p| (p.name.clone(), p.std)).collect();
    }
    let rest = Remainder::of(&ctx, &first_residuals, set.noise_ms, opts);
    Ok(Attribution {
        timing: Vec::new(),
        timing_finding: None,
        before,
        after: rest.after,
        verdict: Verdict::of(&added, rest.remains),
        effects: added,
        removed,
        candidates: scores,
        noise: series
            .iter()
            .find_map(|s| s.row_noise)
            .map(|n| [n[0], n[1], n[2].to_degrees()]),
        remaining_rms_mm: rest.remaining_ms.sqrt(),
        remaining_excess_mm: rest.excess_mm,
        correlated_features: if rest.remains {
            rest.structured
        } else {
            Vec::new()
        },
        rows: [ctx.train().len(), ctx.test().len()],
        blocks: [
            blocks.held_out.iter().filter(|h| !**h).count(),
            blocks.held_out.iter().filter(|h| **h).count(),
        ],
        options: opts.clone(),
        robot: config,
        effect_points: effect_plots,
        residual_time: rest.residual_time,
        feature_points: rest.feature_points,
    })
}

/// What every round shares: the data, the drawing, the settings.
struct Setting<'a, 'o> {
    series: &'a [Series],
    blocks: &'o Blocks,
    /// The robot file the analysis began with.
    drawing: &'o RobotConfig,
    opts: &'o Options,
    /// Weight of the orientation in the residual, mm/rad.
    w_phi: f64,
    /// What the capture noise explains of a row's weighted mean square, mm^2.
    noise_ms: f64,
    /// Whether the calibration's repeated visits of one target disagree over time.
    visits_disagree: bool,
}

impl Setting<'_, '_> {
    /// What the backward pass (and the full-model test of a near miss) needs of it.
    fn backward(&self) -> backward::Setting<'_> {
        backward::Setting {
            series: self.series,
            blocks: self.blocks,
            opts: self.opts,
            w_phi: self.w_phi,
            noise_ms: self.noise_ms,
        }
    }
}

/// What the capture noise explains of a row's weighted mean square, mm^2 (0 without settled
/// rows to measure it on).
fn capture_noise_ms(series: &[Series], w_phi: f64) -> f64 {
    series
        .iter()
        .find_map(|s| s.row_noise)
        .map_or(0.0, |n| n[0] * n[0] + n[1] * n[1] + (w_phi * n[2]).powi(2))
}

/// The search between rounds: the model as it stands and what was found so far.
struct Search<'a> {
    config: RobotConfig,
    /// The model's residuals on the series.
    ctx: Context<'a>,
    /// Every candidate's score in every round.
    scores: Vec<Score>,
    /// Effects added, in order.
    added: Vec<Added>,
    /// Per added effect, its plot data ([`effect_points`]).
    effect_plots: Vec<(String, Vec<(f64, f64)>)>,
    /// The search as it was before the first effect taken in provisionally, and the effects
    /// taken in so (round, name, why).
    provisional: Option<(Snapshot<'a>, Vec<Taken>)>,
    /// Candidates not to put into the model again in a round (round, name): taken in
    /// provisionally there and gone back on.
    banned: Vec<(usize, String, String)>,
    /// The round the search went back to, as it was searched the first time.
    redo: Option<Redo>,
}

/// A round searched again after going back ([`Search::settle_provisional`]): the model is as
/// it was when the round was first searched, so that its fits and the full model's refusals
/// are what they were (each fit is deterministic; on the 15 % cross-coupling the round's fits
/// cost 0.6 s, a refused acceptance 1-3 s).
struct Redo {
    round: usize,
    /// The round's fits with their scores, best first, and its scores as they were recorded
    /// (`None` once taken again).
    fits: Option<RoundFits>,
    /// The candidates the full model refused in the round before the one taken in
    /// provisionally, with why.
    refused: Vec<(String, String)>,
}

/// A round's fits with their scores, best first, and its scores in the order they were recorded.
type RoundFits = (Vec<(Fitted, Score)>, Vec<Score>);

/// An effect taken in provisionally: round, name, why its geometry leaves the drawing.
type Taken = (usize, String, String);

/// The state of a [`Search`] to go back to.
struct Snapshot<'a> {
    config: RobotConfig,
    ctx: Context<'a>,
    added: usize,
    plots: usize,
    /// The round it was taken in, as it was searched.
    redo: Redo,
}

/// An effect the full model confirmed; `provisional`: why its geometry leaves the drawing when
/// it is taken in provisionally.
struct Confirmed<'a> {
    config: RobotConfig,
    ctx: Context<'a>,
    added: Added,
    points: Vec<(f64, f64)>,
    provisional: Option<String>,
}

impl<'a> Search<'a> {
    /// One round's candidates fitted on the training rows (in parallel; each fit is
    /// deterministic) and scored on the held-out rows, best total gain first. The reference
    /// (the recalibration, [`Role::Reference`]) is fitted first: the scoring of the effects and
    /// its parsimony rule need it.
    fn fit_and_score(&mut self, round: usize, set: &Setting) -> Vec<(Fitted, Score)> {
        if let Some((fits, scores)) = self
            .redo
            .as_mut()
            .filter(|r| r.round == round)
            .and_then(|r| r.fits.take())
        {
            self.scores.extend(scores);
            return fits;
        }
        let ctx = &self.ctx;
        let (train, test) = (ctx.train(), ctx.test());
        let names: Vec<&String> = set
            .opts
            .candidates
            .iter()
            .filter(|n| {
                effects::named(n).is_some_and(|e| e.repeatable())
                    || !self.added.iter().any(|a| &a.name == *n)
            })
            .collect();
        // The reference for the effects: the recalibration fit; for the recalibration itself,
        // the model as it is.
        // Each candidate's fit, timed (`PCR_LOG=pcr_residuals::attribution=debug`).
        let timed = |name: &str, fit: &dyn Fn() -> Option<Fitted>| {
            let t0 = std::time::Instant::now();
            let f = fit();
            let seconds = t0.elapsed().as_secs_f64();
            let sse = f.as_ref().map(|f| f.train_sse);
            tracing::debug!(round, name, seconds, ?sse, "candidate fitted");
            f
        };
        let mut recal = timed("reference", &|| {
            effects::reference().and_then(|g| g.fit(ctx, &train))
        });
        // A recalibration that would leave the drawing only mimics another cause: it is then no
        // reference (the effects are measured against the model as it is).
        let recal_physical = recal.as_ref().is_some_and(|g| {
            let mut probe = self.config.clone();
            (g.change)(&mut probe);
            unphysical(&probe, &self.config, set.drawing, set.opts).is_none()
        });
        let recal_delta = recal
            .as_ref()
            .filter(|_| recal_physical)
            .map(|g| (g.delta.clone(), g.train_sse, g.k));
        let mut effect_reference = Reference {
            delta: recal_delta.as_ref().map(|g| g.0.as_slice()),
            train_sse: recal_delta
                .as_ref()
                .map_or_else(|| ctx.sse(&train, None), |g| g.1),
            k: recal_delta.as_ref().map_or(0, |g| g.2),
            recalibration_gain_ms: recal_delta.as_ref().map(|g| {
                (ctx.sse(&test, None) - ctx.sse(&test, Some(&g.0))) / test.len().max(1) as f64
            }),
            recalibration_significant: false,
        };
        set.opts
            .progress
            .stage(round, "fitting candidates", ctx.rows.len(), names.len());
        // The candidates fitted last ([`effects::Effect::fitted_last`]: the friction, whose
        // re-linearisations are passes along every row) are fitted against the best training
        // error of the others.
        let last = |name: &String| effects::named(name).is_some_and(|e| e.fitted_last());
        let fit_each = |names: Vec<(usize, &&String)>, beaten: Option<f64>| {
            names
                .into_par_iter()
                .map(|(i, name)| {
                    let f = timed(name, &|| {
                        let e = effects::named(name).filter(|e| e.role() != Role::Reference)?;
                        match beaten {
                            Some(b) => e.fit_against(ctx, &train, b),
                            None => e.fit(ctx, &train),
                        }
                    });
                    set.opts.progress.step();
                    (i, f)
                })
                .collect::<Vec<_>>()
        };
        let (later, first): (Vec<_>, Vec<_>) = names.iter().enumerate().partition(|(_, n)| last(n));
        // What the candidates read of the context that they share, computed before they run in
        // parallel ([`effects::Effect::share`]).
        for name in &names {
            if let Some(e) = effects::named(name) {
                e.share(ctx);
            }
        }
        let mut fitted_all: Vec<Option<Fitted>> = vec![None; names.len()];
        for (i, f) in fit_each(first, None) {
            fitted_all[i] = f;
        }
        let beaten = fitted_all
            .iter()
            .flatten()
            .map(|f| f.train_sse)
            .fold(f64::INFINITY, f64::min);
        for (i, f) in fit_each(later, Some(beaten)) {
            fitted_all[i] = f;
        }
        let scoring = Round {
            round,
            ctx,
            train: &train,
            test: &test,
            blocks: set.blocks,
            opts: set.opts,
            n_candidates: names.len(),
            noise_ms: set.noise_ms,
        };
        let mut fits: Vec<(Fitted, Score)> = Vec::new();
        for (name, pre) in names.iter().zip(fitted_all) {
            let fitted = if is_reference(name) {
                recal.take()
            } else {
                pre
            };
            let Some(f) = fitted.map(within_linearisation) else {
                continue;
            };
            let s = if is_reference(f.name) {
                let s = scoring.score(&f, &Reference::model_as_is(ctx, &train));
                effect_reference.recalibration_significant = s.significant;
                s
            } else {
                scoring.score(&f, &effect_reference)
            };
            self.scores.push(s.clone());
            fits.push((f, s));
        }
        fits.sort_by(|a, b| b.1.total_gain_mm.total_cmp(&a.1.total_gain_mm));
        // Repeated visits of one target in the calibration that disagree over time are evidence
        // for a time-dependent effect: a significant one is tried first.
        if set.visits_disagree {
            fits.sort_by_key(|(f, s)| !(s.significant && is_time_dependent(f.name)));
        }
        fits
    }

    /// Adds the best significant candidate whose full model confirms its gain; marks the ones
    /// it does not confirm. False when none is added, or when the one added beside effects
    /// taken in provisionally does not bring the geometry nearer the drawing (the forward
    /// rounds end).
    fn add_best(
        &mut self,
        round: usize,
        fits: Vec<(Fitted, Score)>,
        set: &Setting<'a, '_>,
    ) -> bool {
        let test = self.ctx.test();
        let n_candidates = fits.len();
        // The round as it is searched, for a search that goes back to it: only before the
        // first effect taken in provisionally (the search goes back to there).
        let mut kept = self.provisional.is_none().then(|| {
            let scores = self.scores.iter().filter(|s| s.round == round).cloned();
            (fits.clone(), scores.collect())
        });
        let mut refused: Vec<(String, String)> = Vec::new();
        let banned: Vec<(String, String)> = self
            .banned
            .iter()
            .filter(|(r, _, _)| *r == round)
            .map(|(_, n, why)| (n.clone(), why.clone()))
            .collect();
        for (n, why) in &banned {
            mark(&mut self.scores, round, n, why.clone());
        }
        let (sure, near): (Vec<_>, Vec<_>) = fits
            .into_iter()
            .filter(|(f, _)| !banned.iter().any(|(n, _)| n == f.name))
            .partition(|(_, s)| s.significant);
        // A near miss must do better than every recalibration of the round (linearised): a
        // richer tendon map that explains more is the simpler account of the same residual
        // (on foreign-f0, a 0.1-step "periodic" of 240 steps imitated the map).
        let recal_best = near
            .iter()
            .chain(sure.iter())
            .filter(|(f, _)| effects::named(f.name).is_some_and(|e| e.role() != Role::Physical))
            .map(|(_, s)| s.held_out_rms_after_mm)
            .fold(f64::INFINITY, f64::min);
        // A candidate that imitates an effect already in the model ([`mimics`]) is judged in
        // the full model wherever it gains the smallest effect worth claiming.
        let mimic = |name: &str| self.added.iter().any(|a| mimics(&a.name, name));
        let near: Vec<_> = near
            .into_iter()
            .filter(|(f, s)| {
                (near_miss(f.name, s, set.opts) && s.held_out_rms_after_mm < recal_best)
                    || (mimic(f.name) && s.effect_mm >= set.opts.min_effect_mm)
            })
            .collect();
        // While effects taken in provisionally keep the geometry out of the drawing (as
        // [`Search::settle_provisional`] judges it), the round's best candidate alone: the
        // search then looks for the effect that brings the geometry back, and each
        // confirmation costs a full acceptance (on drift + creep at 3x, creep taken first, a
        // latency, a load and springs were put into the full model and refused, 4.4 s, before
        // the search went back and found drift, then creep). Once the geometry is back, the
        // search is as without them.
        let still_out = self.provisional.as_ref().is_some_and(|(snap, _)| {
            leaves_drawing(&self.config, &snap.config, set.drawing, set.opts).is_some()
        });
        let most = if still_out { 1 } else { MAX_CONFIRMATIONS };
        for ((f, s), judged_whole) in sure
            .into_iter()
            .map(|x| (x, false))
            .chain(near.into_iter().map(|x| (x, true)))
            .take(most)
        {
            let name = f.name;
            let whole = judged_whole.then_some(n_candidates);
            let before = self
                .redo
                .as_ref()
                .filter(|r| r.round == round)
                .and_then(|r| r.refused.iter().find(|(n, _)| n == name))
                .map(|(_, why)| why.clone());
            let confirmed = match before {
                Some(why) => Err(why),
                None => self.confirm(round, f, &s, &test, set, whole),
            };
            match confirmed {
                Ok(c) => {
                    // An effect confirmed beside effects taken in provisionally, while the
                    // geometry is still out, that does not bring it nearer the drawing ends
                    // the forward rounds: the search goes back
                    // ([`Search::settle_provisional`]). Where the geometry came back
                    // (backlash + latency + creep: latency first, then creep; drift + creep:
                    // drift first, then creep), the first effect confirmed beside it brought
                    // it back; on the tendon cross-coupling springs beside a tendon map took
                    // it further out, and three more acceptances were made and refused (10 s
                    // at 7 %) before the search went back.
                    let mut stalls = false;
                    if let Some((snap, taken)) = &mut self.provisional {
                        let lim = set.opts.max_geometry_change;
                        let excess =
                            |c: &RobotConfig| crate::plausibility::excess(c, set.drawing, lim).0;
                        let (before, after) = (excess(&self.config), excess(&c.config));
                        tracing::debug!(
                            name,
                            before_provisional = excess(&snap.config),
                            before,
                            after,
                            "confirmed beside effects taken in provisionally"
                        );
                        stalls = still_out && after >= before;
                        if stalls && c.provisional.is_none() {
                            let first = taken.first().map_or("", |t| t.1.as_str());
                            taken.push((
                                round,
                                name.to_string(),
                                format!("it does not bring back the geometry {first} took out"),
                            ));
                        }
                    }
                    if let Some(why) = &c.provisional {
                        let mut snap = || Snapshot {
                            config: self.config.clone(),
                            ctx: self.ctx.clone(),
                            added: self.added.len(),
                            plots: self.effect_plots.len(),
                            redo: Redo {
                                round,
                                fits: kept.take(),
                                refused: std::mem::take(&mut refused),
                            },
                        };
                        self.provisional
                            .get_or_insert_with(|| (snap(), Vec::new()))
                            .1
                            .push((round, name.to_string(), why.clone()));
                    }
                    if judged_whole {
                        if let Some(x) = self
                            .scores
                            .iter_mut()
                            .rev()
                            .find(|x| x.name == name && x.round == round)
                        {
                            *x = c.added.evidence.clone();
                        }
                    }
                    self.effect_plots.push((name.to_string(), c.points));
                    self.added.push(c.added);
                    self.config = c.config;
                    self.ctx = c.ctx;
                    return !stalls;
                }
                Err(why) => {
                    refused.push((name.to_string(), why.clone()));
                    mark(&mut self.scores, round, name, why);
                }
            }
        }
        false
    }

    /// Puts a significant candidate into the model ([`accept`]) and checks the result: the full
    /// model must lower the training error, be physical (its geometry near the drawing, its
    /// springs and creep positive, its frame small) and keep at least half the linearised
    /// held-out gain. `Err`: why not.
    fn confirm(
        &self,
        round: usize,
        f: Fitted,
        s: &Score,
        test: &[usize],
        set: &Setting<'a, '_>,
        whole: Option<usize>,
    ) -> Result<Confirmed<'a>, String> {
        let name = f.name;
        let points = effect_points(&self.ctx, &f.delta, test);
        // A linearised fit already unphysical in the effects' own terms (negative springs or
        // creep gains, a motion that leads its command, a frame beyond twice what a
        // registration error is allowed) does not become physical in the full model, and an
        // acceptance under loads costs 4-6 s: on frame-3x, negative springs (k_M 4.8, k_P -1.4)
        // were refused only after theirs. Twice the frame's limit, so that a frame within it
        // that its linearisation overstates is still fitted in full.
        let mut linearised = self.config.clone();
        (f.change)(&mut linearised);
        let bad = effects_unphysical_unless_confirmed(
            &linearised,
            2.0 * set.opts.max_geometry_change,
            &self.ctx,
            set,
        );
        if !bad.is_empty() {
            return Err(format!("unphysical (linearised): {}", bad.join(", ")));
        }
        set.opts.progress.stage(
            round,
            &format!("adding {name} to the model"),
            self.ctx.rows.len(),
            GN_STEPS + 1,
        );
        let (config, ctx) = accept(
            &self.config,
            &self.ctx,
            f,
            set.series,
            set.blocks,
            set.w_phi,
            &set.opts.progress,
        )
        .ok_or_else(|| "the full model does not lower the training error".to_string())?;
        let unphysical = |config: &RobotConfig, bad: Vec<String>| {
            let leaves = leaves_drawing(config, &self.config, set.drawing, set.opts);
            let all: Vec<String> = leaves.into_iter().chain(bad).collect();
            format!("unphysical: {}", all.join(", "))
        };
        // A near miss whose full model, before the calibration from the drawing, fails the
        // rules and explains less than half the share they ask for is refused here: the
        // calibration from the drawing keeps the better of its result and this model, and
        // would have to double the share (on friction at 10x, a latency and a load judged so
        // explained 5.0 % and 4.9 % here, 5.0 % and 6.5 % after it, 2.6 + 2.2 s later; a
        // backlash beside friction that the full model confirmed, 78 % and 99.8 %).
        if let Some(n_candidates) = whole {
            if let Err(why) = judge_full_model(&self.ctx, &ctx, n_candidates, set) {
                if held_out_share(&self.ctx, &ctx, set) < 0.5 * MIN_SHARE {
                    return Err(format!("{}; in the full model: {why}", s.note));
                }
            }
        }
        let (config, ctx) = match from_drawing(config, ctx, set) {
            Ok(kept) => kept,
            Err(refused) => {
                let (config, bad) = *refused;
                return Err(unphysical(&config, bad));
            }
        };
        let limit = set.opts.max_geometry_change;
        let bad = effects_unphysical_unless_confirmed(&config, limit, &ctx, set);
        if !bad.is_empty() {
            return Err(unphysical(&config, bad));
        }
        let leaves = leaves_drawing(&config, &self.config, set.drawing, set.opts);
        // A geometry that leaves the drawing with the effect in may be an effect not yet in the
        // model that is in the static poses (a creep beside a drift): the effect is taken in
        // provisionally, and the search judges the geometry once the others are in
        // ([`Search::settle_provisional`]). Only a physical effect with a held-out gain.
        let provisional = leaves.map(|why| format!("unphysical: {why}"));
        // Consistency before naming: a physical effect takes the same parameters in independent
        // parts of the data. Judged around the model that holds it (where the linearisation
        // holds), with the values the model holds.
        if let Some(e) = effects::named(name).filter(|e| e.role() == Role::Physical) {
            set.opts.progress.stage(
                round,
                &format!("checking {name} on parts of the data"),
                0,
                0,
            );
            let held = current_params(&config, name, &s.params);
            if let Some(why) = crate::consistency::inconsistency(e, &ctx, &ctx.train(), &held) {
                return Err(why);
            }
        }
        let ntest = ctx.test();
        let mut full_p = None;
        if let Some(n_candidates) = whole {
            match judge_full_model(&self.ctx, &ctx, n_candidates, set) {
                Err(why) => return Err(format!("{}; in the full model: {why}", s.note)),
                Ok(p) => full_p = Some(p),
            }
        }
        let old = self.ctx.sse(test, None) / test.len() as f64;
        let new = ctx.sse(&ntest, None) / ntest.len().max(1) as f64;
        let target = s.held_out_rms_after_mm.powi(2);
        if ntest.len() + 5 < test.len() || new >= old || old - new < 0.5 * (old - target) {
            return Err(format!(
                "the full model does not confirm the gain (held-out mean square {old:.5} -> {new:.5} mm^2, linearised {target:.5})"
            ));
        }
        let added = Added {
            name: name.to_string(),
            description: effects::named(name)
                .map_or("unknown", |e| e.description())
                .to_string(),
            params: s.params.clone(),
            uncertainty: s.params.iter().map(|p| (p.name.clone(), p.std)).collect(),
            evidence: match full_p {
                // Judged in the full model: its p-value is the evidence.
                Some(p) => Score {
                    p_value: p,
                    significant: true,
                    note: format!("linearised: {}; significant in the full model", s.note),
                    ..s.clone()
                },
                None => s.clone(),
            },
            held_out_after: Errors::of(&ctx, &ntest),
        };
        Ok(Confirmed {
            config,
            ctx,
            added,
            points,
            provisional,
        })
    }
}

impl<'a> Search<'a> {
    /// The final estimate of every effect's parameters, with their errors ([`values`]' order,
    /// the solver's units): a last joint refinement on every training row where the model is
    /// unloaded (up to [`FINAL_ROW_PARAMETERS`]; kept when it lowers the training error); under
    /// loads (a loaded refinement on every row would cost 10 s) only the errors at the point
    /// the search left, from the Jacobian on the refinements' 3000 rows. The refinements of the
    /// search use 3000 rows, and the values they leave carry those rows' noise (periodic-10x:
    /// 10.014 +- 0.0032 steps, 4.3 errors off; on every row 10.004).
    ///
    /// [`values`]: crate::refine::values
    fn final_estimate(&mut self, set: &Setting<'a, '_>) -> Option<Vec<f64>> {
        if self.added.is_empty() {
            return None;
        }
        let refine = |config: &RobotConfig, rows: usize, evaluations: usize| {
            crate::refine::refine_with_errors(
                config,
                &self.ctx.model,
                set.series,
                set.blocks,
                set.w_phi,
                rows,
                true,
                evaluations,
                crate::refine::Errors::AtOptimum,
                None,
            )
        };
        set.opts.progress.stage(
            0,
            "estimating the effects on every row",
            self.ctx.rows.len(),
            0,
        );
        // Under loads only the errors at the point the search left: its Jacobian (one
        // evaluation) on the search's rows.
        if self.ctx.model.loads.is_some_and(|l| !l.is_unloaded()) {
            return refine(&self.config, crate::refine::SEARCH_ROWS, 1).1;
        }
        let n_params = crate::refine::values(&self.config.effects).len()
            + crate::nuisance::Nuisance::of(&self.config).n;
        let rows = (FINAL_ROW_PARAMETERS / n_params.max(1)).max(crate::refine::SEARCH_ROWS);
        let (refined, std) = refine(&self.config, rows, FINAL_EVALUATIONS);
        if refined == self.config {
            return std;
        }
        let train = self.ctx.train();
        let before = self.ctx.sse(&train, None) / train.len().max(1) as f64;
        let model = ExtendedModel::like(&refined, &self.ctx.model).ok()?;
        let ctx = Context::new(set.series, model, set.blocks, set.w_phi);
        let t = ctx.train();
        let after = ctx.sse(&t, None) / t.len().max(1) as f64;
        tracing::debug!(before, after, "final estimate on every training row");
        if ctx.rows.len() + 5 >= self.ctx.rows.len() && after <= before {
            self.config = refined;
            self.ctx = ctx;
            return std;
        }
        // Kept where it was: the errors there, on the search's rows.
        refine(&self.config, crate::refine::SEARCH_ROWS, 1).1
    }

    /// Plausibility on the joint solution: effects taken in while the geometry left the drawing
    /// stay when the model with every effect found brings the geometry back (no further from
    /// the drawing than before the first of them); otherwise the search goes back to where it
    /// was before them, and they are marked with the reason.
    /// Returns the round to search again from when it went back.
    fn settle_provisional(&mut self, set: &Setting<'a, '_>) -> Option<usize> {
        let (snap, taken) = self.provisional.take()?;
        let why = leaves_drawing(&self.config, &snap.config, set.drawing, set.opts);
        tracing::debug!(
            went_back = why.is_some(),
            ?taken,
            "effects taken in provisionally settled"
        );
        let why = why?;
        self.config = snap.config;
        self.ctx = snap.ctx;
        self.redo = Some(snap.redo);
        self.added.truncate(snap.added);
        self.effect_plots.truncate(snap.plots);
        let first = taken.first().map(|(r, n, _)| (*r, n.clone()));
        for (round, name, _) in taken {
            mark(
                &mut self.scores,
                round,
                &name,
                format!("unphysical with every effect found in: {why}"),
            );
        }
        let (round, name) = first?;
        let note = self
            .scores
            .iter()
            .rev()
            .find(|s| s.round == round && s.name == name)
            .map(|s| s.note.clone())
            .unwrap_or_default();
        self.banned.push((round, name, note));
        Some(round)
    }

    /// The backward pass ([`crate::backward`]): every physical effect is tested against the
    /// model without it; of those that fail, the one that earns least is taken out and the
    /// others refitted, until every effect passes. Returns what was taken out.
    fn backward(&mut self, set: &backward::Setting<'a>) -> Vec<Removed> {
        let mut removed = Vec::new();
        loop {
            // Every physical effect, the last one added too: the model without it, refitted
            // now, is not the model it was added to (on the 15 % cross-coupling a load added
            // last leaves 1.81 mm held out where the model refitted without it leaves 1.15).
            let judged: Vec<usize> = (0..self.added.len())
                .filter(|&i| backward::judged(&self.added[i].name))
                .collect();
            set.opts.progress.stage(
                0,
                "checking every effect with the others in",
                self.ctx.rows.len(),
                judged.len(),
            );
            let mut worst: Option<(usize, backward::Without<'a>, String)> = None;
            // The models without each effect are independent: one per thread.
            let withouts: Vec<(usize, Option<backward::Without<'a>>)> = judged
                .par_iter()
                .map(|&i| {
                    let a = &self.added[i];
                    let w = backward::without(&self.config, &self.ctx, &a.name, &a.params, set);
                    set.opts.progress.step();
                    (i, w)
                })
                .collect();
            for (i, w) in withouts {
                let Some(w) = w else { continue };
                if let Some(why) = backward::fails(&w.cmp, judged.len(), set) {
                    let gain = w.cmp.ms[0] - w.cmp.ms[1];
                    if worst
                        .as_ref()
                        .is_none_or(|x| gain < x.1.cmp.ms[0] - x.1.cmp.ms[1])
                    {
                        worst = Some((i, w, why));
                    }
                }
            }
            let Some((i, w, why)) = worst else { break };
            let a = self.added.remove(i);
            if let Some(k) = self.effect_plots.iter().rposition(|(n, _)| *n == a.name) {
                self.effect_plots.remove(k);
            }
            removed.push(Removed {
                params: current_params(&self.config, &a.name, &a.params),
                name: a.name,
                held_out_rms_without_mm: w.cmp.ms[0].sqrt(),
                held_out_rms_with_mm: w.cmp.ms[1].sqrt(),
                p_value: w.cmp.p,
                note: why,
            });
            (self.config, self.ctx) = w.into_full(set.series, set.blocks);
        }
        removed
    }
}

/// Whether the effect `b` imitates the effect `a` already in the model, so that `a`, taken in
/// first, takes up part of `b`'s signature, and `b`'s linearised fit (which moves the
/// calibration, not the effects in the model) shows too little of it to count even as a near
/// miss ([`near_miss`]): such a candidate is judged in the full model wherever it gains the
/// smallest effect worth claiming ([`Search::add_best`]). A friction's supports and a gear
/// play are both a hysteresis of the pose at each reversal: on the prototype plant (plays of
/// 3-4 steps, the prototype's friction) the friction, taken in first, put the supports at
/// 0.095 N for 0.04 and the play's linearised fit then gained 0.02 mm (p = 0.29); in the full
/// model the play came out at 3.00 / 3.85 / 2.93 steps and the supports at 0.041 N, p = 5e-7.
/// The other way (a friction judged in the full model beside a play) is not made: no case of
/// the sweep or the tests needs it, and it is a friction's acceptance, refused, on every
/// recording with a play (1.5-2.4 s more on each of the sweep's, springs + frame + backlash 3x
/// 8.3 -> 9.8 s).
fn mimics(a: &str, b: &str) -> bool {
    matches!((a, b), ("friction", "backlash"))
}

/// Whether a physical candidate that failed the linearised test came close enough to be judged
/// in the full model: a held-out gain above the smallest effect, and either p < 0.05 or at
/// least a tenth of the held-out mean square taken off.
///
/// The linearised fit moves the candidate and the calibration, not the effects already in the
/// model; when one of those took part of this candidate's signature in an earlier round (a
/// latency that took the delay a backlash adds at each reversal: 52 ms for a truth of 40), the
/// candidate shows only what is left, and its linearised score understates it. The full model
/// refits every effect together.
fn near_miss(name: &str, s: &Score, opts: &Options) -> bool {
    let physical = effects::named(name).is_some_and(|e| e.role() == Role::Physical);
    let share = s.effect_mm.max(0.0).powi(2) / (s.held_out_rms_before_mm.powi(2)).max(1e-300);
    physical && s.effect_mm >= opts.min_effect_mm && (s.p_value < 0.05 || share >= 0.1)
}

/// Whether the full model `after` (a near miss put in, everything refitted) earns its place
/// against `before` on the held-out rows: the linearised test's rules (the paired ratio test
/// at the round's Bonferroni level, the smallest effect, the share of the structured residual)
/// applied to the two full models, each on its own held-out rows (a row index of one context is
/// not the same row in another when a model does not predict some rows). `Ok(p)` when it does,
/// `Err(why not)`.
fn judge_full_model(
    before: &Context,
    after: &Context,
    n_candidates: usize,
    set: &Setting,
) -> Result<f64, String> {
    let nb = set.blocks.len();
    let (tb, ta) = (before.test(), after.test());
    if ta.len() + 5 < tb.len() {
        return Err(format!(
            "the full model does not predict {} of the held-out rows",
            tb.len() - ta.len()
        ));
    }
    let a = crate::scoring::sse_per_block(before, &tb, None, nb);
    let b = crate::scoring::sse_per_block(after, &ta, None, nb);
    let p = crate::scoring::paired_ratio_p(&a, &b, &set.blocks.held_out);
    let ms = [
        a.iter().sum::<f64>() / tb.len().max(1) as f64,
        b.iter().sum::<f64>() / ta.len().max(1) as f64,
    ];
    let cmp = backward::Comparison {
        ms,
        p,
        unrecalibrated: (ms[0], p),
    };
    let alpha = set.opts.alpha / n_candidates.max(1) as f64;
    match backward::main_rule(&cmp, alpha, &set.backward()) {
        None => Ok(p),
        Some(why) => Err(why),
    }
}

/// The share of what `before` leaves above the noise on its held-out rows that `after` takes
/// off (the share of [`backward::main_rule`]).
fn held_out_share(before: &Context, after: &Context, set: &Setting) -> f64 {
    let (tb, ta) = (before.test(), after.test());
    let ms = |c: &Context, t: &[usize]| c.sse(t, None) / t.len().max(1) as f64;
    let (b, a) = (ms(before, &tb), ms(after, &ta));
    let excess = b - set.noise_ms;
    if excess > 0.0 {
        (b - a) / excess
    } else {
        0.0
    }
}

/// Most evaluations of the model in the final estimate ([`Search::final_estimate`]): it starts
/// where the refinements on 3000 rows ended, and its first steps take nearly all there is to
/// take (the rest would cost 0.1-0.5 s each on every row).
const FINAL_EVALUATIONS: usize = 4;

/// Rows times parameters of the final estimate of an unloaded model: every training row of a
/// 44,000-row recording for a periodic error with the calibration parameters (17 parameters,
/// 0.9 s), 20,000 of them beside a `tendon_map` recalibration (38 parameters; every row took
/// 1.8 s).
const FINAL_ROW_PARAMETERS: usize = 750_000;

/// Most times the forward search goes back on effects taken in provisionally
/// ([`Search::settle_provisional`]) and searches again.
const MAX_RESTARTS: usize = 1;

/// Most significant candidates of a round put into the full model: when the best three are
/// not confirmed (the full model does not keep their gain, they leave the drawing, their
/// parameters disagree between parts of the data), the ones that explain less are not tried
/// (each costs a full acceptance) and the search ends. With effects taken in provisionally, one
/// ([`Search::add_best`]).
const MAX_CONFIRMATIONS: usize = 3;

/// Most alternations of the calibration from the drawing and the effects' refinement.
const FROM_DRAWING_ROUNDS: usize = 3;

/// The alternations go on while one takes more than 1 % off the held-out mean square, and
/// while the next is expected to (the last two gains continued as a geometric sequence: after
/// 25 % and 2.7 % on backlash + friction at 1x a third alternation took 0.015 % off, 0.8 s;
/// after 9 % and 2.4 % on joint springs + frame + backlash at 3x it took nothing off, 0.4 s);
/// the extrapolation after them ([`aitken`]) takes the rest of a slow convergence in one step
/// (0.1 % before it: a third alternation of 1-1.5 s under loads for a gain of 0.1 %).
const FROM_DRAWING_GAIN: f64 = 0.99;

/// Largest move of any effect's parameter in one alternation, in its standard errors (the
/// refinement's, on its subsample), after which no further alternation is made: the next
/// calibration from the drawing starts from effects that moved by so little that it comes out
/// as this one did. On the sweep's recordings every alternation that moved no parameter by more
/// than 1.3 errors was followed by one that took nothing off the held-out error (-0.03 % to
/// +0.003 %: friction, supports alone and backlash, alone and in pairs; 0.6 s each where the
/// friction is in the model), and those after moves of 4.5 to 7.5 errors took off 0.2 % at
/// most but once 1.1 % (a load of 1.2 N with backlash, after 6.8 errors).
const SETTLED_ERRORS: f64 = 3.0;

/// Smallest move of a parameter, relative to its value, that the extrapolation after the
/// alternations ([`aitken`]) is made for: a smaller one is far inside the parameter's error
/// (joint springs at a tenth of the sweep's test strength: k_M 29.337 -> 29.374 N mm/rad
/// predicted, against an error of 0.57, for another second of recalibration and refinement),
/// where a load creeping along its valley with the calibration moves by several percent
/// (-0.273, -0.288 and then -0.300 N).
const MIN_EXTRAPOLATION: f64 = 0.01;

/// Smallest move of a parameter, in its standard errors, that the extrapolation after the
/// alternations ([`aitken`]) is made for: a parameter near zero moves by many times
/// [`MIN_EXTRAPOLATION`] of its value and by little of its error (springs + frame + backlash at
/// 1x: the frame's dy -0.029 -> -0.019 mm predicted, against an error of 0.052, for another
/// alternation of 0.5 s whose held-out error was no lower), where a load creeping along its
/// valley with the calibration moves by two errors (external_load-1x: force y -0.273 -> -0.308
/// N, an error of 0.017).
const EXTRAPOLATION_ERRORS: f64 = 0.25;

/// Largest ratio of two successive alternation steps of a parameter that is extrapolated
/// ([`aitken`]): above it the sequence is not converging fast enough for three iterates to say
/// where it goes.
const MAX_RATIO: f64 = 0.9;

/// Smallest ratio extrapolated: below it the next steps add less than a tenth of the last one.
const MIN_RATIO: f64 = 0.1;

/// An iterate of the calibration from the drawing refused as it stands ([`from_drawing`]): its
/// configuration and why it is unphysical.
type Refused = (RobotConfig, Vec<String>);

/// Joint estimation from the drawing ([`crate::recalibration`]): the calibration made again from
/// the drawing with the effects of `config` in the model, the effects refitted on it, alternated
/// while the held-out error falls by more than 1 % ([`FROM_DRAWING_GAIN`]); the better held-out
/// result of that and `config` (refined from the first calibration) is returned. `Err`: the
/// iterate kept would be an unphysical capture frame (and why), known before its every row is
/// predicted.
///
/// Where the data hardly tell an effect from the calibration (a load of 0.4 N that the legs'
/// geometry and maps nearly absorb), the alternation creeps along that valley, each step a
/// near-constant fraction of the one before: on external_load-1x force y goes -0.236, -0.273,
/// -0.288 N in three alternations and reaches -0.300 (the truth) after twelve, while the
/// held-out error changes by 0.4 %. So the effects' parameters are extrapolated from the last
/// three iterates to where that geometric sequence ends ([`aitken`]), the calibration is made
/// again at that point and the effects refitted once more; the result is kept when its
/// held-out error is lower.
fn from_drawing<'a>(
    config: RobotConfig,
    ctx: Context<'a>,
    set: &Setting<'a, '_>,
) -> Result<(RobotConfig, Context<'a>), Box<Refused>> {
    let Some(recal) = &set.opts.recalibration else {
        return Ok((config, ctx));
    };
    let held_out = |c: &Context| {
        let t = c.test();
        c.sse(&t, None) / t.len().max(1) as f64
    };
    // The iterates are judged on the held-out rows alone: their contexts predict those
    // ([`Context::held_out`]; the recalibration reads the static poses' tendon displacements,
    // which every row's prediction carries, solved or not), and the one returned is predicted
    // on every row at the end.
    let n_test = ctx.test().len();
    let judged = |model: ExtendedModel| {
        let least = n_test.saturating_sub(5);
        Some(Context::held_out(
            set.series, model, set.blocks, set.w_phi, least,
        ))
        .filter(|c| c.rows.len() + 5 >= n_test)
    };
    // One alternation from (config, ctx): the calibration from the drawing with its effects,
    // then its effects refined on it, with their errors there (approximate: what a move of the
    // extrapolation is weighed against).
    let alternate = |config: &RobotConfig,
                     ctx: &Context<'a>|
     -> Option<(RobotConfig, Context<'a>, Option<Vec<f64>>)> {
        let cal = crate::recalibration::recalibrated(config, ctx, set.drawing, recal)?;
        let (refined, errors) = crate::refine::search_with_errors(
            &cal,
            Some(config),
            &ctx.model,
            set.series,
            set.blocks,
            set.w_phi,
            crate::refine::Errors::Approximate,
        );
        let model = ExtendedModel::like(&refined, &ctx.model).ok()?;
        judged(model).map(|c| (refined, c, errors))
    };
    // The iterate kept (the best held-out result, `None`: the start) with every row predicted;
    // the start where its model does not predict them.
    let finish = |best: Option<(RobotConfig, Context<'a>)>, start: (RobotConfig, Context<'a>)| {
        let Some((config, judged)) = best else {
            return start;
        };
        let least = start.1.rows.len().saturating_sub(5);
        // The consistency check and the final estimate linearise its friction next.
        let mut model = judged.model;
        model.friction_derivatives = true;
        let full = Context::at_least(set.series, model, set.blocks, set.w_phi, least);
        if full.rows.len() + 5 >= start.1.rows.len() {
            (config, full)
        } else {
            start
        }
    };
    let mut best_ms = held_out(&ctx);
    // The effects' parameters of every iterate, the first one included.
    let mut iterates = vec![crate::refine::values(&config.effects)];
    let start = (config, ctx);
    let mut best: Option<(RobotConfig, Context<'a>)> = None;
    let mut last: Option<(RobotConfig, Context<'a>)> = None;
    let mut last_share: Option<f64> = None;
    // The errors of the effects' parameters at the last iterate.
    let mut errors: Option<Vec<f64>> = None;
    for _ in 0..FROM_DRAWING_ROUNDS {
        let from = last.as_ref().or(best.as_ref()).unwrap_or(&start);
        let Some((refined, full, e)) = alternate(&from.0, &from.1) else {
            break;
        };
        errors = e;
        let ms = held_out(&full);
        let values = crate::refine::values(&refined.effects);
        tracing::debug!(
            held_out_ms = ms,
            best_ms,
            ?values,
            ?errors,
            "calibration from the drawing"
        );
        let settled = settled(
            iterates.last().map(Vec::as_slice),
            &values,
            errors.as_deref(),
        );
        iterates.push(values);
        let gain = ms < FROM_DRAWING_GAIN * best_ms && !settled;
        // A capture frame that the alternation takes further beyond a registration error,
        // where the static poses do not confirm it, is refused at the end whatever the
        // alternations after this one make of it (cross-coupling at 7 %: -3.4, -4.7 deg); they
        // are not made.
        let limit = set.opts.max_geometry_change;
        let leaving = {
            let e = crate::effects::frame::excess(&refined.effects, limit);
            let grows = e > 1.0 && e > crate::effects::frame::excess(&from.0.effects, limit);
            let bad = if grows {
                effects_unphysical_unless_confirmed(&refined, limit, &full, set)
            } else {
                Vec::new()
            };
            (!bad.is_empty()).then_some(bad)
        };
        if let Some(bad) = leaving {
            tracing::debug!("calibration from the drawing: the frame leaves a registration error");
            // Kept, it is refused as it stands (the same judgement): no prediction of every
            // row for it.
            if ms < best_ms {
                return Err(Box::new((refined, bad)));
            }
            return Ok(finish(best, start));
        }
        // Nor while the next one is expected to take less than that off, the gains falling as
        // a geometric sequence ([`FROM_DRAWING_GAIN`]).
        let share = 1.0 - ms / best_ms;
        let expected = expected_gain(last_share, share);
        last_share = Some(share);
        let gain = gain && expected.is_none_or(|e| e >= 1.0 - FROM_DRAWING_GAIN);
        if ms < best_ms {
            best_ms = ms;
            best = Some((refined, full));
            last = None;
        } else {
            last = Some((refined, full));
        }
        if !gain {
            break;
        }
    }
    // Where the alternation is heading.
    let n = iterates.len();
    let Some(target) = (n >= 3)
        .then(|| aitken(&iterates[n - 3], &iterates[n - 2], &iterates[n - 1]))
        .flatten()
    else {
        return Ok(finish(best, start));
    };
    // Where the alternation has arrived, another alternation is not made for it.
    if arrived(&target, &iterates[n - 1], errors.as_deref()) {
        return Ok(finish(best, start));
    }
    let from = last.as_ref().or(best.as_ref()).unwrap_or(&start);
    let mut jumped = from.0.clone();
    crate::refine::set_values(&mut jumped.effects, &target);
    let Some(jctx) = ExtendedModel::like(&jumped, &from.1.model)
        .ok()
        .and_then(judged)
    else {
        return Ok(finish(best, start));
    };
    if let Some((refined, full, _)) = alternate(&jumped, &jctx) {
        let ms = held_out(&full);
        tracing::debug!(
            held_out_ms = ms,
            best_ms,
            ?target,
            values = ?crate::refine::values(&refined.effects),
            "calibration from the drawing, extrapolated"
        );
        if ms < best_ms {
            best = Some((refined, full));
        }
    }
    Ok(finish(best, start))
}

/// Why the effects of `c` are not physical ([`effects_unphysical`] at `max_change`), except a
/// capture frame beyond a registration error that the static poses confirm
/// ([`crate::recalibration::confirms_frame`], judged with the static poses as the model of `ctx`
/// says they were reached), up to [`CONFIRMED_FRAME_SCALE`] times the limit: a frame of 8 mm and
/// 3 deg is a registration error that the calibration's own poses show, where the 3 % tendon
/// cross-coupling's 1.6 deg "frame" is not.
///
/// [`CONFIRMED_FRAME_SCALE`]: crate::effects::frame::CONFIRMED_FRAME_SCALE
fn effects_unphysical_unless_confirmed(
    c: &RobotConfig,
    max_change: f64,
    ctx: &Context,
    set: &Setting,
) -> Vec<String> {
    let bad = effects_unphysical(c, max_change);
    if bad.is_empty() || c.effects.frame.is_none() {
        return bad;
    }
    let mut without = c.clone();
    without.effects.frame = None;
    let scale = crate::effects::frame::CONFIRMED_FRAME_SCALE;
    let only_the_frame = effects_unphysical(&without, max_change).is_empty()
        && effects_unphysical(c, scale * max_change).is_empty();
    let confirmed = only_the_frame
        && set
            .opts
            .recalibration
            .as_ref()
            .is_some_and(|r| crate::recalibration::confirms_frame(c, ctx, set.drawing, r));
    tracing::debug!(only_the_frame, confirmed, frame = ?c.effects.frame, "frame beyond a registration error");
    if confirmed {
        Vec::new()
    } else {
        bad
    }
}

/// Whether the alternations of the calibration from the drawing have arrived where their
/// extrapolation `target` says they are heading from the last iterate `last` (both [`values`]'
/// order): no parameter would move by more than [`MIN_EXTRAPOLATION`] of its value, or, with the
/// parameters' standard errors `errors`, by more than [`EXTRAPOLATION_ERRORS`] of its error.
///
/// [`values`]: crate::refine::values
fn arrived(target: &[f64], last: &[f64], errors: Option<&[f64]>) -> bool {
    target.iter().zip(last).enumerate().all(|(k, (t, v))| {
        let d = (t - v).abs();
        d <= MIN_EXTRAPOLATION * v.abs()
            || errors
                .and_then(|e| e.get(k))
                .is_some_and(|s| d <= EXTRAPOLATION_ERRORS * s)
    })
}

/// Whether an alternation that took the effects' parameters from `before` to `after` (both
/// [`values`]' order) moved none by more than [`SETTLED_ERRORS`] of its standard error
/// `errors`; not without the errors, nor for iterates of different effects.
///
/// [`values`]: crate::refine::values
fn settled(before: Option<&[f64]>, after: &[f64], errors: Option<&[f64]>) -> bool {
    let (Some(before), Some(errors)) = (before, errors) else {
        return false;
    };
    before.len() == after.len()
        && errors.len() == after.len()
        && after
            .iter()
            .zip(before)
            .zip(errors)
            .all(|((a, b), e)| a == b || (a - b).abs() <= SETTLED_ERRORS * e)
}

/// The share of the held-out mean square the next alternation of the calibration from the
/// drawing is expected to take off after two that took `last` and `share` off: the gains
/// continued as a geometric sequence; `None` where either took nothing off.
fn expected_gain(last: Option<f64>, share: f64) -> Option<f64> {
    last.filter(|&g| g > 0.0 && share > 0.0)
        .map(|g| share * share / g)
}

/// Aitken's extrapolation of three iterates `a`, `b`, `c` of a linearly converging sequence,
/// parameter by parameter: `c + d r / (1 - r)` with `d = c - b` and `r = d / (b - a)`, for the
/// parameters whose steps shrink by a ratio in [[`MIN_RATIO`], [`MAX_RATIO`]]; the others stay at
/// `c`. `None` when no parameter qualifies (nothing to gain from another alternation).
fn aitken(a: &[f64], b: &[f64], c: &[f64]) -> Option<Vec<f64>> {
    if a.len() != c.len() || b.len() != c.len() {
        return None;
    }
    let mut any = false;
    let out = (0..c.len())
        .map(|i| {
            let (d1, d2) = (b[i] - a[i], c[i] - b[i]);
            let r = d2 / d1;
            if d1 != 0.0 && (MIN_RATIO..=MAX_RATIO).contains(&r) {
                any = true;
                c[i] + d2 * r / (1.0 - r)
            } else {
                c[i]
            }
        })
        .collect();
    any.then_some(out)
}

/// Whether an effect changes with time rather than with the pose or the motion's history.
fn is_time_dependent(name: &str) -> bool {
    matches!(name, "drift" | "creep")
}

/// Repeated visits of one target this many times further apart than their noise explains are
/// evidence for a time-dependent effect in the static poses.
const VISITS_DISAGREE: f64 = 3.0;

/// Whether the calibration's repeated visits of one target disagree over time
/// ([`VISITS_DISAGREE`]).
fn visits_disagree(opts: &Options) -> bool {
    opts.recalibration.as_ref().is_some_and(|r| {
        r.data.row_noise.is_some_and(|n| {
            pcr_calibration::diagnosis::visit_spread(&r.data, n)
                .is_some_and(|(_, ratio)| ratio > VISITS_DISAGREE)
        })
    })
}

/// Whether `name` is the reference of the scoring ([`Role::Reference`]).
fn is_reference(name: &str) -> bool {
    effects::named(name).is_some_and(|e| e.role() == Role::Reference)
}

/// Largest linearised change of a row that is scored as it is, mm (or weighted mm of
/// orientation).
const LINEARISATION_MM: f64 = 20.0;

/// A fit whose linearised change exceeds [`LINEARISATION_MM`] on some row is outside the
/// linearisation: it is scored on the step that keeps every row within it (its change scaled
/// down; the damped first step of its acceptance), which understates its gain. Such a fit is
/// not dropped: an effect strong enough to have bent the calibration (a tendon drifting 2.6 mm
/// over the calibration recording) asks the calibration parameters for a change that large, and
/// it is the one the data need most.
fn within_linearisation(mut f: Fitted) -> Fitted {
    damp_within(&mut f.delta);
    if let Some(a) = f.alone.as_mut() {
        damp_within(a);
    }
    f
}

/// Scales the row changes `d` to half of [`LINEARISATION_MM`] at the largest when they exceed it.
fn damp_within(d: &mut [[f64; 3]]) {
    // Clearly within (the squares compared first: `hypot` costs a division and a root a
    // row, and this runs on every row of every candidate).
    let squares = d.iter().fold(0.0f64, |m, v| {
        m.max(v[0] * v[0] + v[1] * v[1]).max(v[2] * v[2])
    });
    if squares < 0.99 * LINEARISATION_MM * LINEARISATION_MM {
        return;
    }
    let largest = d
        .iter()
        .fold(0.0f64, |m, v| m.max(v[0].hypot(v[1])).max(v[2].abs()));
    if largest >= LINEARISATION_MM {
        let s = 0.5 * LINEARISATION_MM / largest;
        d.iter_mut().flatten().for_each(|v| *v *= s);
    }
}

impl Verdict {
    /// The verdict from the effects added and whether a structure remains. A refit of the
    /// calibration parameters ([`Role::Recalibration`], [`Role::Reference`]) absorbs, it does
    /// not explain: the verdict counts physical effects.
    fn of(added: &[Added], remains: bool) -> Verdict {
        let physical = added
            .iter()
            .any(|a| effects::named(&a.name).is_none_or(|e| e.role() == Role::Physical));
        match (physical, remains) {
            (_, false) => Verdict::Explained,
            (true, true) => Verdict::PartlyExplained,
            (false, true) => Verdict::Unexplained,
        }
    }
}

/// What remains after the last round: against the noise, and the features it follows.
struct Remainder {
    /// Held-out errors of the final model.
    after: Errors,
    /// Held-out weighted mean square per row, mm^2.
    remaining_ms: f64,
    /// The part of its RMS above the noise, mm.
    excess_mm: f64,
    /// Features it correlates with on held-out rows (R^2 > 0.05), at most six, strongest first.
    structured: Vec<FeatureLink>,
    /// Whether a structure worth claiming remains.
    remains: bool,
    residual_time: Vec<(f64, f64, f64)>,
    feature_points: Vec<FeaturePoints>,
}

impl Remainder {
    fn of(ctx: &Context, first_residuals: &[f64], noise_ms: f64, opts: &Options) -> Remainder {
        let (train, test) = (ctx.train(), ctx.test());
        let remaining_ms = ctx.sse(&test, None) / test.len().max(1) as f64;
        let excess_mm = (remaining_ms - noise_ms).max(0.0).sqrt();
        let feats = Features::of(ctx);
        let structured: Vec<FeatureLink> = features::links(ctx, &feats, &train, &test)
            .into_iter()
            .filter(|l| l.held_out_r2 > 0.05)
            .take(6)
            .collect();
        let remains =
            excess_mm > opts.min_effect_mm.max(0.25 * noise_ms.sqrt()) && !structured.is_empty();
        let step = test.len().div_ceil(4000).max(1);
        let plotted = if remains { 3 } else { 0 };
        Remainder {
            after: Errors::of(ctx, &test),
            remaining_ms,
            excess_mm,
            residual_time: residual_over_time(ctx, &test, first_residuals, step),
            feature_points: feature_plots(
                ctx,
                &feats,
                structured.iter().take(plotted),
                &test,
                step,
            ),
            structured,
            remains,
        }
    }
}

/// Every `step`-th held-out row: its time from the start of its recording (s) and its position
/// residual before the first round and now, mm.
fn residual_over_time(
    ctx: &Context,
    test: &[usize],
    first_residuals: &[f64],
    step: usize,
) -> Vec<(f64, f64, f64)> {
    test.iter()
        .step_by(step)
        .map(|&i| {
            let row = &ctx.rows[i];
            let s = &ctx.series[row.s];
            let t0 = s.samples.first().map_or(0.0, |x| x.t_s);
            (
                s.samples[row.k].t_s - t0,
                first_residuals.get(i).copied().unwrap_or(0.0),
                row.r[0].hypot(row.r[1]),
            )
        })
        .collect()
}

/// (feature value, residual component) on every `step`-th held-out row, per linked feature.
fn feature_plots<'l>(
    ctx: &Context,
    feats: &Features,
    links: impl Iterator<Item = &'l FeatureLink>,
    test: &[usize],
    step: usize,
) -> Vec<FeaturePoints> {
    links
        .filter_map(|l| {
            let j = feats.names.iter().position(|n| *n == l.feature)?;
            let c = ["x", "y", "phi"].iter().position(|n| *n == l.component)?;
            Some((
                l.feature.clone(),
                l.component.clone(),
                test.iter()
                    .step_by(step)
                    .map(|&i| (feats.values[i][j], ctx.rows[i].r[c]))
                    .collect(),
            ))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A geometric sequence's limit from three of its terms, parameter by parameter; a
    /// parameter that does not converge geometrically (a step that grows, changes sign or
    /// hardly shrinks) stays where it is.
    #[test]
    fn aitken_finds_where_a_geometric_sequence_ends() {
        // x_k = L + C r^k for r = 0.4 (force y -0.300 N) and 0.3 (force x 0.400 N).
        let seq = |l: f64, c: f64, r: f64, k: i32| l + c * r.powi(k);
        let it = |k| {
            [
                seq(-0.3, 0.1, 0.4, k),
                seq(0.4, -0.05, 0.3, k),
                7.0 + k as f64,
            ]
        };
        let x = aitken(&it(1), &it(2), &it(3)).expect("converging");
        assert!((x[0] + 0.3).abs() < 1e-12, "{x:?}");
        assert!((x[1] - 0.4).abs() < 1e-12, "{x:?}");
        // Steps of equal length (ratio 1): not extrapolated.
        assert_eq!(x[2], 10.0);
        // An oscillation (ratio < 0), or steps that shrink too little to say: nothing to gain.
        assert!(aitken(&[0.0], &[1.0], &[0.5]).is_none());
        assert!(aitken(&[0.0], &[1.0], &[1.95]).is_none());
        assert!(aitken(&[0.0], &[1.0], &[1.01]).is_none());
        // Iterates of different effects (another effect came in): nothing.
        assert!(aitken(&[0.0], &[1.0, 2.0], &[1.5, 2.0]).is_none());
    }

    #[test]
    fn the_alternations_arrive_where_no_parameter_would_move_by_a_share_of_its_error() {
        // A frame's dy near zero: 36 % of its value, a fifth of its error (springs + frame +
        // backlash at 1x).
        let frame = ([0.7308, -0.0187], [0.7308, -0.0291], [0.049, 0.0526]);
        assert!(!arrived(&frame.0, &frame.1, None));
        assert!(arrived(&frame.0, &frame.1, Some(&frame.2)));
        // A load creeping along its valley: two errors (external_load-1x).
        let load = ([0.4016, -0.3079], [0.3988, -0.2726], [0.0131, 0.0164]);
        assert!(!arrived(&load.0, &load.1, Some(&load.2)));
        // Within 1 % of every value: arrived, with or without errors.
        assert!(arrived(&[300.5, 2.0], &[300.1, 2.01], None));
        assert!(arrived(&[300.5, 2.0], &[300.1, 2.01], Some(&[0.1, 0.001])));
    }

    /// An alternation that moved no parameter by more than three of its errors is the last;
    /// one error where the parameter's own is zero (held) is a move.
    #[test]
    fn an_alternation_that_moved_nothing_by_three_errors_is_the_last() {
        // Supports alone with backlash at 1x: the force moved by 1.0 error, the joints' couple
        // held at zero, their pre-sliding travel held (no error).
        let before = [0.0, 9.621, 1.0];
        let after = [1e-26, 9.6877, 1.0];
        let errors = [0.106, 0.0555, 0.0];
        assert!(settled(Some(&before), &after, Some(&errors)));
        // Backlash coming in beside friction: the plays moved by 35 errors.
        assert!(!settled(Some(&[2.0]), &[2.9], Some(&[0.0245])));
        // A held parameter that moved, no errors, or different effects: not settled.
        assert!(!settled(Some(&[1.0]), &[1.1], Some(&[0.0])));
        assert!(!settled(Some(&[1.0]), &[1.0], None));
        assert!(!settled(Some(&[1.0]), &[1.0, 2.0], Some(&[0.1, 0.1])));
        assert!(!settled(None, &[1.0], Some(&[0.1])));
    }

    /// The next alternation's expected gain continues the last two as a geometric sequence:
    /// after 25 % and 2.7 % (backlash + friction at 1x) it is below the 1 % an alternation must
    /// take off, after 10 % and 5 % above; none is expected from the first alternation alone,
    /// nor after one that took nothing off.
    #[test]
    fn the_next_alternation_is_expected_to_gain_as_the_last_two_did() {
        let threshold = 1.0 - FROM_DRAWING_GAIN;
        let after = expected_gain(Some(0.25), 0.027).expect("two gains");
        assert!((after - 0.027 * 0.027 / 0.25).abs() < 1e-15 && after < threshold);
        assert!(expected_gain(Some(0.1), 0.05).expect("two gains") > threshold);
        assert_eq!(expected_gain(None, 0.1), None);
        assert_eq!(expected_gain(Some(0.1), 0.0), None);
        assert_eq!(expected_gain(Some(0.1), -0.01), None);
        assert_eq!(expected_gain(Some(-0.01), 0.02), None);
    }
}
