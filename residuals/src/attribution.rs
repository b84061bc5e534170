//! Attribution that cannot cheat: every candidate is fitted on the training blocks and scored
//! on the held-out blocks; the best one is added only if it lowers the held-out error
//! significantly (a paired test over the held-out blocks, Bonferroni-corrected over the
//! candidates), by more than the smallest effect worth claiming, and the Bayesian information
//! criterion on the training rows agrees. The model then really includes it (the full,
//! non-linearised prediction is recomputed and must confirm the gain), and the search starts
//! again. When nothing more is significant, what remains is compared with the capture noise and
//! the features it correlates with are named.

use crate::candidates::{self, Estimate, Fitted};
use crate::context::{Context, Errors};
use crate::features::{self, FeatureLink, Features};
use crate::model::ExtendedModel;
use crate::series::{Blocks, Series};
use pcr_robot::RobotConfig;
use rayon::prelude::*;
use serde::Serialize;
use statrs::distribution::{ContinuousCDF, StudentsT};

/// Settings of the attribution.
#[derive(Debug, Clone, Serialize)]
pub struct Options {
    /// Family-wise significance level of one round (divided among the candidates).
    pub alpha: f64,
    /// Smallest RMS reduction of the held-out position error worth claiming, mm.
    pub min_effect_mm: f64,
    /// Largest number of effects added.
    pub max_rounds: usize,
    /// Candidates tried (names of [`candidates::NAMES`]).
    pub candidates: Vec<String>,
    /// Largest distance of the extended model's geometry from the drawing, mm or degrees.
    pub max_geometry_change: f64,
    /// Solve every row on its own: no reuse of a row at rest's prediction, no warm-started
    /// loaded equilibrium, load responses computed at every row instead of interpolated between
    /// anchors. Slow; the reference the fast path is tested against.
    pub exact: bool,
    /// Where progress is reported (nowhere by default).
    #[serde(skip)]
    pub progress: crate::progress::ProgressSink,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            alpha: 1e-2,
            min_effect_mm: 0.01,
            max_rounds: 6,
            candidates: candidates::NAMES.iter().map(|s| s.to_string()).collect(),
            max_geometry_change: 3.0,
            exact: false,
            progress: Default::default(),
        }
    }
}

/// Plot data of one feature: its name, the residual component, (feature value, residual).
pub type FeaturePoints = (String, String, Vec<(f64, f64)>);

/// How one candidate scored in one round.
#[derive(Debug, Clone, Serialize)]
pub struct Score {
    /// Round (1-based).
    pub round: usize,
    /// Candidate name.
    pub name: String,
    /// Its parameters.
    pub params: Vec<Estimate>,
    /// Held-out RMS of the weighted residual before (the reference) and with the candidate, mm.
    pub held_out_rms_before_mm: f64,
    /// With the candidate, mm.
    pub held_out_rms_after_mm: f64,
    /// sqrt of the held-out mean-square reduction against the reference, mm (negative: it made
    /// things worse). The reference of `geometry` is the model as it is; that of every effect is
    /// the recalibration (`geometry`), so an effect is credited only with what it adds to it.
    pub effect_mm: f64,
    /// sqrt of the held-out mean-square reduction against the model as it is, mm: ranks the
    /// significant candidates.
    pub total_gain_mm: f64,
    /// One-sided p-value of the paired held-out block test.
    pub p_value: f64,
    /// BIC(candidate) - BIC(reference) on the training rows.
    pub delta_bic: f64,
    /// Whether it passed every test.
    pub significant: bool,
    /// Why not, if not.
    pub note: String,
}

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
    /// Effects added, in order.
    pub effects: Vec<Added>,
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

fn sse_per_block(ctx: &Context, idx: &[usize], delta: Option<&[[f64; 3]]>, nb: usize) -> Vec<f64> {
    let mut out = vec![0.0; nb];
    for &i in idx {
        let r = ctx.rows[i].r;
        let d = delta.map_or([0.0; 3], |d| d[i]);
        out[ctx.rows[i].block] +=
            (r[0] - d[0]).powi(2) + (r[1] - d[1]).powi(2) + (r[2] - d[2]).powi(2);
    }
    out
}

/// One-sided paired t-test over the held-out blocks that `b` is smaller than `a`.
pub(crate) fn paired_p(a: &[f64], b: &[f64], held: &[bool]) -> f64 {
    let d: Vec<f64> = a
        .iter()
        .zip(b)
        .zip(held)
        .filter(|(_, h)| **h)
        .map(|((x, y), _)| x - y)
        .collect();
    let n = d.len();
    if n < 3 {
        return 1.0;
    }
    let m = d.iter().sum::<f64>() / n as f64;
    let sd = (d.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
    if sd == 0.0 {
        return if m > 0.0 { 0.0 } else { 1.0 };
    }
    let t = m / (sd / (n as f64).sqrt());
    let Ok(dist) = StudentsT::new(0.0, 1.0, (n - 1) as f64) else {
        return 1.0;
    };
    1.0 - dist.cdf(t)
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

/// Puts an accepted candidate into the model for real: the linearised change, damped until the
/// full model lowers the training error, re-linearised and refitted (Gauss-Newton) while that
/// helps, then every effect's parameters refined together on the full model. `None` when the
/// full model does not improve on the training rows.
/// Smallest share of the held-out mean square above the capture noise that a candidate must
/// explain to be claimed.
pub const MIN_SHARE: f64 = 0.25;

/// Largest number of Gauss-Newton steps when a candidate goes into the model.
const GN_STEPS: usize = 10;

fn accept<'a>(
    config: &RobotConfig,
    ctx: &Context<'a>,
    first: Fitted,
    series: &'a [Series],
    blocks: &Blocks,
    w_phi: f64,
    progress: &crate::progress::ProgressSink,
) -> Option<(RobotConfig, Context<'a>)> {
    let name = first.name;
    let start_sse = ctx.sse(&ctx.train(), None);
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
            let cand = crate::model::blend(&base_cfg, &full, frac);
            let nctx = cand
                .validate("extended robot")
                .ok()
                .and_then(|_| ExtendedModel::like(&cand, &ctx.model).ok())
                .map(|m| Context::new(series, m, blocks, w_phi))
                .filter(|n| n.rows.len() + 5 >= ctx.rows.len());
            if let Some(nctx) = nctx {
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
        progress.step();
        if !improved || !candidates::iterable(name) || it + 1 == GN_STEPS {
            break;
        }
        let (_, c, s) = cur.as_ref()?;
        // Stop when the step gained less than 0.1 %.
        if *s > 0.999 * base_sse {
            break;
        }
        step = candidates::fit(name, c, &c.train());
    }
    let (cfg, nctx, sse) = cur?;
    // Every effect's parameters together on the full model.
    let refined = crate::refine::refine(&cfg, &ctx.model, series, blocks, w_phi, 3000);
    if refined != cfg {
        if let Ok(model) = ExtendedModel::like(&refined, &ctx.model) {
            let rctx = Context::new(series, model, blocks, w_phi);
            if rctx.rows.len() + 5 >= ctx.rows.len() && rctx.sse(&rctx.train(), None) < sse {
                return Some((refined, rctx));
            }
        }
    }
    Some((cfg, nctx))
}

/// An effect's parameters as the configuration holds them now, with the uncertainties of the
/// fit that found it (matched by name).
fn current_params(c: &RobotConfig, name: &str, fitted: &[Estimate]) -> Vec<Estimate> {
    let e = &c.effects;
    let std = |n: &str| fitted.iter().find(|p| p.name == n).and_then(|p| p.std);
    let p = |n: &str, v: f64, unit: &str| Estimate {
        name: n.into(),
        value: v,
        std: std(n),
        unit: unit.into(),
    };
    match name {
        "latency" => e
            .latency
            .as_ref()
            .map(|l| vec![p("latency", l.latency_s, "s")]),
        "backlash" => e.backlash.as_ref().map(|b| {
            (0..3)
                .map(|i| p(&format!("play motor {}", i + 1), b.steps[i], "steps"))
                .collect()
        }),
        "creep" => e.creep.as_ref().map(|cr| {
            let mut v: Vec<Estimate> = (0..3)
                .map(|i| p(&format!("gain leg {}", i + 1), cr.gain[i], "mm/mm"))
                .collect();
            v.push(p("time constant", cr.time_constant_s, "s"));
            v
        }),
        "drift" => e.drift.as_ref().map(|d| {
            (0..3)
                .map(|i| p(&format!("rate leg {}", i + 1), d.rate_mm_per_s[i], "mm/s"))
                .collect()
        }),
        "joint_springs" => e.compliance.as_ref().map(|k| {
            vec![
                p("k_M", k.k_m_n_mm_per_rad, "N mm/rad"),
                p("k_P", k.k_p_n_mm_per_rad, "N mm/rad"),
                p("EI (assumed)", k.ei_n_mm2, "N mm^2"),
            ]
        }),
        "external_load" => e.compliance.as_ref().map(|k| {
            vec![
                p("force x", k.force_n[0], "N"),
                p("force y", k.force_n[1], "N"),
                p("couple", k.couple_n_mm, "N mm"),
                p("EI (assumed)", k.ei_n_mm2, "N mm^2"),
            ]
        }),
        "frame" => e.frame.as_ref().map(|f| {
            vec![
                p("dx", f.dx_mm, "mm"),
                p("dy", f.dy_mm, "mm"),
                p("dphi", f.dphi_deg, "deg"),
            ]
        }),
        _ => None,
    }
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

/// Why a model is not a physical explanation, if it is not: its geometry more than
/// `max_geometry_change` (mm, deg) away from the drawing the analysis started from (the
/// calibration parameters would then only mimic another cause), or springs, creep or a latency
/// of the wrong sign.
fn unphysical(
    c: &RobotConfig,
    current: &RobotConfig,
    drawing: &RobotConfig,
    opts: &Options,
) -> Option<String> {
    let lim = opts.max_geometry_change;
    let params = |l: &pcr_robot::LegConfig| {
        [
            ("psi_deg", l.psi_deg),
            ("l_c_mm", l.l_c_mm),
            ("r_p_mm", l.r_p_mm),
            ("theta_p_deg", l.theta_p_deg),
            ("l_st_mm", l.l_st_mm),
            ("r_base_mm", l.r_base_mm),
            ("beta_deg", l.beta_deg),
        ]
    };
    // How far beyond the bound a geometry is, summed over the parameters: a candidate may not
    // push it further out (it may bring a geometry the calibration pushed out back).
    let excess = |c: &RobotConfig| -> (f64, Vec<String>) {
        let mut total = 0.0;
        let mut far = Vec::new();
        for i in 0..3 {
            let (n, d) = (params(&c.legs[i]), params(&drawing.legs[i]));
            for k in 0..n.len() {
                let away = (n[k].1 - d[k].1).abs();
                if away > lim {
                    total += (away - lim).powi(2);
                    far.push(format!("{}[{}] {:+.2}", n[k].0, i + 1, n[k].1 - d[k].1));
                }
            }
        }
        (total, far)
    };
    let (new_excess, far) = excess(c);
    let (old_excess, _) = excess(current);
    let mut why = Vec::new();
    if new_excess > old_excess + 1e-9 {
        why.push(format!(
            "the geometry would leave the drawing ({}; more than {lim} mm or deg)",
            far.join(", ")
        ));
    }
    let e = &c.effects;
    if let Some(f) = &e.frame {
        // A registration off by more than this would be seen at once: 1 deg is 5 mm at the
        // base points.
        if f.dx_mm.hypot(f.dy_mm) > lim || f.dphi_deg.abs() > lim / 3.0 {
            why.push(format!(
                "a capture frame off by ({:.2}, {:.2}) mm and {:.2} deg",
                f.dx_mm, f.dy_mm, f.dphi_deg
            ));
        }
    }
    if let Some(k) = &e.compliance {
        if k.k_m_n_mm_per_rad < 0.0 || k.k_p_n_mm_per_rad < 0.0 {
            why.push(format!(
                "negative joint springs (k_M {:.1}, k_P {:.1} N mm/rad)",
                k.k_m_n_mm_per_rad, k.k_p_n_mm_per_rad
            ));
        }
    }
    if let Some(cr) = &e.creep {
        if cr.gain.iter().any(|g| *g < 0.0) {
            why.push(format!(
                "a tendon that shortens under load (creep gains {:?})",
                cr.gain
            ));
        }
    }
    if let Some(l) = &e.latency {
        if l.latency_s < -0.01 {
            why.push(format!(
                "the motion leads the command by {:.3} s",
                -l.latency_s
            ));
        }
    }
    (!why.is_empty()).then(|| format!("unphysical: {}", why.join(", ")))
}

fn rms(sse: f64, n: usize) -> f64 {
    (sse / n.max(1) as f64).sqrt()
}

/// Scores a fitted candidate against a reference (residual change `reference`, or none).
#[allow(clippy::too_many_arguments)]
fn score(
    round: usize,
    ctx: &Context,
    f: &Fitted,
    reference: Option<&[[f64; 3]]>,
    ref_train_sse: f64,
    ref_k: usize,
    train: &[usize],
    test: &[usize],
    blocks: &Blocks,
    opts: &Options,
    n_candidates: usize,
    geometry_gain_ms: Option<f64>,
    geometry_significant: bool,
    noise_ms: f64,
) -> Score {
    let nb = blocks.len();
    let raw: f64 = sse_per_block(ctx, test, None, nb).iter().sum();
    let a = sse_per_block(ctx, test, reference, nb);
    let b = sse_per_block(ctx, test, Some(&f.delta), nb);
    let (sa, sb): (f64, f64) = (a.iter().sum(), b.iter().sum());
    let p = paired_p(&a, &b, &blocks.held_out);
    let n = 3 * train.len();
    let bic = |sse: f64, k: usize| {
        n as f64 * (sse.max(1e-300) / n as f64).ln() + k as f64 * (n as f64).ln()
    };
    let delta_bic = bic(f.train_sse, ref_k + f.k) - bic(ref_train_sse, ref_k);
    // Position part of the reduction, per row (mm^2): the weighted residual has three parts.
    let red = (sa - sb) / test.len().max(1) as f64;
    let effect_mm = red.signum() * red.abs().sqrt();
    let alpha = opts.alpha / n_candidates.max(1) as f64;
    let mut note = Vec::new();
    if p >= alpha {
        note.push(format!("p = {p:.2e} >= {alpha:.1e}"));
    }
    if effect_mm < opts.min_effect_mm {
        note.push(format!(
            "held-out gain {effect_mm:.4} mm < {} mm",
            opts.min_effect_mm
        ));
    }
    if delta_bic >= 0.0 {
        note.push(format!("BIC does not improve ({delta_bic:+.1})"));
    }
    // A cause explains a good part of the structure it is tested on; a candidate that only
    // projects a little of an unknown cause is not claimed.
    let excess = sa / test.len().max(1) as f64 - noise_ms;
    let share = if excess > 0.0 { red / excess } else { 0.0 };
    if share < MIN_SHARE {
        note.push(format!(
            "explains {:.0} % of the structured residual (< {:.0} %)",
            100.0 * share,
            100.0 * MIN_SHARE
        ));
    }
    // Parsimony: an effect that alone (without the recalibration) gains at least 90 % of what
    // the recalibration gains, significantly, is the simpler explanation of the same residual.
    if !note.is_empty() {
        if let (Some(alone), Some(geo)) = (&f.alone, geometry_gain_ms) {
            let c = sse_per_block(ctx, test, Some(alone), nb);
            let raw_b = sse_per_block(ctx, test, None, nb);
            let sc: f64 = c.iter().sum();
            let gain = (raw - sc) / test.len().max(1) as f64;
            let pa = paired_p(&raw_b, &c, &blocks.held_out);
            if geometry_significant
                && geo > 0.0
                && gain >= 0.9 * geo
                && pa < alpha
                && gain.sqrt() >= opts.min_effect_mm
            {
                note.clear();
            }
        }
    }
    Score {
        round,
        name: f.name.to_string(),
        params: f.params.clone(),
        held_out_rms_before_mm: rms(sa, test.len()),
        held_out_rms_after_mm: rms(sb, test.len()),
        effect_mm,
        total_gain_mm: {
            let t = (raw - sb) / test.len().max(1) as f64;
            t.signum() * t.abs().sqrt()
        },
        p_value: p,
        delta_bic,
        significant: note.is_empty(),
        note: note.join("; "),
    }
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
    let ctx = Context::new(series, ExtendedModel::new(robot)?, blocks, w_phi);
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
    let w_phi = start.legs.iter().map(|l| l.r_p_mm).sum::<f64>() / 3.0;
    let mut model = ExtendedModel::new(start)?;
    model.exact = opts.exact;
    let rows: usize = series.iter().map(|s| s.samples.len()).sum();
    opts.progress
        .stage(0, "predicting the starting model", rows, 0);
    let ctx0 = Context::new(series, model.clone(), blocks, w_phi);
    opts.progress
        .stage(0, "estimating the command delay", ctx0.rows.len(), 0);
    let timing = crate::alignment::align(&ctx0);
    let finding = crate::alignment::declaration_errors(&timing);
    let mut a = match crate::alignment::realigned(series, &timing) {
        None => attribute_from(ctx0, start, drawing, series, blocks, opts)?,
        Some(aligned) => {
            let ctx = Context::new(&aligned, model, blocks, w_phi);
            attribute_from(ctx, start, drawing, &aligned, blocks, opts)?
        }
    };
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
    let mut config = start.clone();
    let (train0, test0) = (ctx0.train(), ctx0.test());
    if train0.len() < 20 || test0.is_empty() {
        return Err(AttributionError::Data(format!(
            "{} training and {} held-out rows with a measured pose: too few to attribute anything",
            train0.len(),
            test0.len()
        )));
    }
    let before = Errors::of(&ctx0, &test0);
    // What the capture noise explains of a row's weighted mean square (mm^2).
    let noise_ms = series
        .iter()
        .find_map(|s| s.row_noise)
        .map_or(0.0, |n| n[0] * n[0] + n[1] * n[1] + (w_phi * n[2]).powi(2));
    let mut ctx = ctx0;
    let mut scores = Vec::new();
    let mut added: Vec<Added> = Vec::new();
    let mut used: Vec<String> = Vec::new();
    let mut effect_plots: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    let first_residuals: Vec<f64> = ctx.rows.iter().map(|r| r.r[0].hypot(r.r[1])).collect();
    for round in 1..=opts.max_rounds {
        let (train, test) = (ctx.train(), ctx.test());
        let names: Vec<&String> = opts
            .candidates
            .iter()
            .filter(|n| !used.contains(n) || *n == "periodic")
            .collect();
        // The reference for the effects: the recalibration (geometry) fit; for geometry itself,
        // the model as it is.
        let mut geo = candidates::geometry(&ctx, &train);
        // A recalibration that would leave the drawing only mimics another cause: it is then no
        // reference (the effects are measured against the model as it is).
        let geo_physical = geo.as_ref().is_some_and(|g| {
            let mut probe = config.clone();
            (g.change)(&mut probe);
            unphysical(&probe, &config, drawing, opts).is_none()
        });
        let reference = geo.as_ref().filter(|_| geo_physical);
        let geo_delta = reference.map(|g| g.delta.clone());
        let geo_sse = reference.map_or(ctx.sse(&train, None), |g| g.train_sse);
        let geo_k = reference.map_or(0, |g| g.k);
        let geo_gain_ms = geo_delta
            .as_ref()
            .map(|d| (ctx.sse(&test, None) - ctx.sse(&test, Some(d))) / test.len().max(1) as f64);
        let mut fits: Vec<(Fitted, Score)> = Vec::new();
        // Every candidate fitted (in parallel; each fit is deterministic).
        opts.progress
            .stage(round, "fitting candidates", ctx.rows.len(), names.len());
        let fitted_all: Vec<Option<Fitted>> = names
            .par_iter()
            .map(|name| {
                let f = (name.as_str() != "geometry")
                    .then(|| candidates::fit(name, &ctx, &train))
                    .flatten();
                opts.progress.step();
                f
            })
            .collect();
        // `geometry` is scored first: the parsimony rule of the effects needs its verdict.
        let mut geo_significant = false;
        for (name, pre) in names.iter().zip(fitted_all) {
            let fitted = if name.as_str() == "geometry" {
                geo.take()
            } else {
                pre
            };
            let Some(f) = fitted else {
                continue;
            };
            // A linearised change of more than 20 mm on a row is outside the linearisation.
            if f.delta
                .iter()
                .any(|d| !(d[0].hypot(d[1]) < 20.0 && d[2].abs() < 20.0))
            {
                continue;
            }
            let s = if f.name == "geometry" {
                score(
                    round,
                    &ctx,
                    &f,
                    None,
                    ctx.sse(&train, None),
                    0,
                    &train,
                    &test,
                    blocks,
                    opts,
                    names.len(),
                    None,
                    false,
                    noise_ms,
                )
            } else {
                score(
                    round,
                    &ctx,
                    &f,
                    geo_delta.as_deref(),
                    geo_sse,
                    geo_k,
                    &train,
                    &test,
                    blocks,
                    opts,
                    names.len(),
                    geo_gain_ms,
                    geo_significant,
                    noise_ms,
                )
            };
            if f.name == "geometry" {
                geo_significant = s.significant;
            }
            scores.push(s.clone());
            fits.push((f, s));
        }
        // The best significant candidate whose full model confirms the gain.
        fits.sort_by(|a, b| b.1.total_gain_mm.total_cmp(&a.1.total_gain_mm));
        let mut accepted = false;
        for (f, s) in fits.into_iter().filter(|(_, s)| s.significant) {
            let name = f.name;
            let points = effect_points(&ctx, &f.delta, &test);
            opts.progress.stage(
                round,
                &format!("adding {name} to the model"),
                ctx.rows.len(),
                GN_STEPS + 1,
            );
            let Some((next, nctx)) =
                accept(&config, &ctx, f, series, blocks, w_phi, &opts.progress)
            else {
                mark(
                    &mut scores,
                    round,
                    name,
                    "the full model does not lower the training error".into(),
                );
                continue;
            };
            // The model it makes, converged, must be physical: its geometry near the drawing, its
            // springs and creep positive, its frame small.
            if let Some(why) = unphysical(&next, &config, drawing, opts) {
                mark(&mut scores, round, name, why);
                continue;
            }
            let ntest = nctx.test();
            let old = ctx.sse(&test, None) / test.len() as f64;
            let new = nctx.sse(&ntest, None) / ntest.len().max(1) as f64;
            // The full model must keep at least half the linearised held-out gain.
            let target = s.held_out_rms_after_mm.powi(2);
            if ntest.len() + 5 < test.len() || new >= old || old - new < 0.5 * (old - target) {
                mark(
                    &mut scores,
                    round,
                    name,
                    format!(
                        "the full model does not confirm the gain (held-out mean square {old:.5} -> {new:.5} mm^2, linearised {target:.5})"
                    ),
                );
                continue;
            }
            used.push(name.to_string());
            effect_plots.push((name.to_string(), points));
            added.push(Added {
                name: name.to_string(),
                description: candidates::describe(name).to_string(),
                params: s.params.clone(),
                uncertainty: s.params.iter().map(|p| (p.name.clone(), p.std)).collect(),
                evidence: s.clone(),
                held_out_after: Errors::of(&nctx, &ntest),
            });
            config = next;
            ctx = nctx;
            accepted = true;
            break;
        }
        if !accepted {
            break;
        }
    }
    let (train, test) = (ctx.train(), ctx.test());
    opts.progress.stage(0, "what remains", ctx.rows.len(), 0);
    let after = Errors::of(&ctx, &test);
    // The values the final model holds (joint refinements move earlier effects too).
    for a in &mut added {
        a.params = current_params(&config, &a.name, &a.params);
        a.uncertainty = a.params.iter().map(|p| (p.name.clone(), p.std)).collect();
    }
    // What remains: against the noise, and the features it follows.
    let noise = series.iter().find_map(|s| s.row_noise);
    let remaining_ms = ctx.sse(&test, None) / test.len().max(1) as f64;
    let excess = (remaining_ms - noise_ms).max(0.0).sqrt();
    let feats = Features::of(&ctx);
    let links = features::links(&ctx, &feats, &train, &test);
    let structured: Vec<FeatureLink> = links
        .into_iter()
        .filter(|l| l.held_out_r2 > 0.05)
        .take(6)
        .collect();
    let remains = excess > opts.min_effect_mm.max(0.25 * noise_ms.sqrt()) && !structured.is_empty();
    let step = test.len().div_ceil(4000).max(1);
    let residual_time: Vec<(f64, f64, f64)> = test
        .iter()
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
        .collect();
    let feature_points: Vec<FeaturePoints> = structured
        .iter()
        .take(if remains { 3 } else { 0 })
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
        .collect();
    // A refit of the calibration parameters (geometry, tendon map) absorbs, it does not
    // explain: the verdict counts physical effects.
    let physical = added
        .iter()
        .any(|a| !matches!(a.name.as_str(), "geometry" | "tendon_map"));
    let verdict = match (physical, remains) {
        (_, false) => Verdict::Explained,
        (true, true) => Verdict::PartlyExplained,
        (false, true) => Verdict::Unexplained,
    };
    Ok(Attribution {
        timing: Vec::new(),
        timing_finding: None,
        before,
        after,
        effects: added,
        candidates: scores,
        verdict,
        noise: noise.map(|n| [n[0], n[1], n[2].to_degrees()]),
        remaining_rms_mm: remaining_ms.sqrt(),
        remaining_excess_mm: excess,
        correlated_features: if remains { structured } else { Vec::new() },
        rows: [train.len(), test.len()],
        blocks: [
            blocks.held_out.iter().filter(|h| !**h).count(),
            blocks.held_out.iter().filter(|h| **h).count(),
        ],
        options: opts.clone(),
        robot: config,
        effect_points: effect_plots,
        residual_time,
        feature_points,
    })
}
