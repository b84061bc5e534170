//! `friction`: Coulomb friction of the passive joints and of their supports on the base plate.
//! Each joint (M_i and P_i) and each joint's support is an elastic-perfectly-plastic element
//! that sticks until its load reaches its limit and then slips; the segments bend under those
//! loads, so that the pose depends on the path that led to it: a hysteresis in the platform's
//! pose, like a play but acting on the pose through the structure's compliance rather than on
//! the motors (`[effects.friction]`; the small-load statics of `pcr_kinematics::friction`). The
//! two limits (one per joint, one per support) and the joints' pre-sliding travel are fitted;
//! the supports' pre-sliding travel and the segments' bending stiffness are assumed (the robot
//! file's, or the library's defaults). The chain's IK feeds the deflection the path predicts
//! forward.
//!
//! The fit is linearised at the model's friction: from none, through the derivatives at zero
//! friction (each element's stop operator on its rigid coordinate, the structure answering
//! its limit: [`crate::model::ExtendedModel::friction_onset_path`]), then by the
//! derivatives of the whole path at the estimate in one pass (the tangent pass,
//! [`crate::model::ExtendedModel::friction_path_tangent`]), re-linearised while the step is
//! large. Stuck
//! supports hold their joints against the segments' compliance, which the derivatives at zero
//! friction do not see, so that the first step's estimate is far from the friction's own (the
//! joints' couple at about half its value); the re-linearised steps reach it.

use super::joint_fit::{fit_joint, fit_joint_beside, nuisance_change};
use super::{lerp, Effect, Parameter};
use crate::context::Context;
use crate::context::Tangents;
use crate::extension::Extension;
use crate::fitted::{Estimate, Fitted};
use crate::linear::Columns;
use crate::model::DeflectionTangent;
use pcr_kinematics::friction::Friction as Rubbing;
use pcr_robot::effects::{self as robot, Effects};
use pcr_robot::RobotConfig;
use rayon::prelude::*;

/// The `friction` candidate.
#[derive(Debug)]
pub struct Friction;

/// Re-linearisations of a fit from no friction at most (each a pass over every row of every
/// series with the derivatives).
const RELINEARISATIONS: usize = 4;

/// The share of the training error (what the calibration parameters alone leave) a first step
/// from no friction must take off for the fit to be re-linearised.
const ONSET_GAIN: f64 = 0.1;

/// A fit from no friction is re-linearised at its estimate while a step moves a value by more
/// than this share of it. The acceptance's steps and the joint refinement that follow take the
/// rest: at 5 % the supports alone with backlash at 1x walked 0.019, 0.049, 0.068, 0.072 and
/// 0.0725 N, the last pass (0.15 s) made only because the step before it moved the force by 6 %;
/// at 10 % the analyses of the sweep's friction cases ended with the same effects and values
/// within a tenth of their errors.
const STEP_SHARE: f64 = 0.1;

/// The re-linearisations of a fit end where one changes the training error by less than this
/// share of it: from no friction the error settles by the second or third linearisation while
/// the joints' pre-sliding travel, which the data tell poorly, still swings by more than
/// [`STEP_SHARE`] (backlash + friction at 1x: 7281, 2385.6, 2385.3, 2388.1, 2387.8 over five
/// linearisations, the travel 2.6, 0.65, 0.77, 0.87 mrad; joint springs + frame + backlash at
/// 3x, no friction in the data: 121425, 106388, 106208, 106189, 106183), and the acceptance's
/// steps and the joint refinement take the travel from there. Two passes with the derivatives
/// fewer, 0.4-0.5 s of such an analysis.
const SSE_SETTLED: f64 = 0.005;

/// A limit's estimate must be this many standard errors above zero for the fit from no friction
/// to be re-linearised (otherwise the data show no friction and the first step stands).
const SIGNIFICANT: f64 = 3.0;

/// Re-linearisations a fit's training error is extrapolated over, each taking off the share the
/// last one took, to judge whether it can still come below another candidate's
/// ([`Effect::fit_against`]). The first re-linearisation from no friction takes off the most
/// (184284 -> 30300 -> 12548 on backlash + friction at 3x, 7281 -> 2386 at 1x) and the later
/// ones far less; on joint springs + frame + backlash at 3x (no friction) the fit went 131616 ->
/// 107721 -> 106183 -> 106178 beside springs at 60288, two passes (0.4 s) for a candidate that
/// could not win.
const EXTRAPOLATED_STEPS: i32 = 2;

/// Whether a fit whose training error went from `last` to `sse` in its last re-linearisation
/// would stay above `beaten` after [`EXTRAPOLATED_STEPS`] more that take off the same share.
fn cannot_come_below(last: f64, sse: f64, beaten: f64) -> bool {
    let r = sse / last;
    r < 1.0 && sse * r.powi(EXTRAPOLATED_STEPS) > beaten
}

/// The friction entry of a robot file's effects, with zero limits and the assumed pre-sliding
/// travels and bending stiffness (the compliance's, when the file declares one) when it
/// declares none.
fn held(effects: &Effects) -> robot::Friction {
    effects.friction.clone().unwrap_or_else(|| robot::Friction {
        joint_torque_n_mm: 0.0,
        support_force_n: 0.0,
        joint_presliding_rad: robot::Friction::default_joint_presliding(),
        support_presliding_mm: robot::Friction::default_support_presliding(),
        ei_n_mm2: effects
            .compliance
            .as_ref()
            .map_or(robot::Friction::default_ei(), |c| c.ei_n_mm2),
    })
}

/// The fitted values of a friction entry: the joints' couple (N mm), the supports' force (N)
/// and the joints' pre-sliding travel (rad).
type Theta = [f64; 3];

/// `entry` with the fitted values `theta`.
fn with_values(entry: &robot::Friction, theta: Theta) -> robot::Friction {
    robot::Friction {
        joint_torque_n_mm: theta[0],
        support_force_n: theta[1],
        joint_presliding_rad: theta[2],
        ..entry.clone()
    }
}

/// The fitted values of `entry`.
fn values_of(entry: &robot::Friction) -> Theta {
    [
        entry.joint_torque_n_mm,
        entry.support_force_n,
        entry.joint_presliding_rad,
    ]
}

/// Each context row's friction deflection at `entry` (x, y mm and the weighted phi, mm), from
/// the context's rigid paths; `None` where a row has none. At the model's own friction, the
/// deflection its predictions hold (the same pass along the same path, run when the context
/// was predicted).
fn deflections(ctx: &Context, entry: &robot::Friction) -> Vec<Option<[f64; 3]>> {
    let started = std::time::Instant::now();
    let f = Rubbing::from_effect(entry);
    if ctx.model.friction == Some(f) {
        return ctx
            .rows
            .iter()
            .map(|r| ctx.pred(r).friction.map(|d| [d[0], d[1], ctx.w_phi * d[2]]))
            .collect();
    }
    let paths = ctx.paths();
    let per: Vec<Vec<Option<[f64; 3]>>> = paths
        .par_iter()
        .map(|(rigid, kappa)| {
            if f.is_off() {
                vec![Some([0.0; 3]); rigid.poses.len()]
            } else {
                ctx.model.friction_path(rigid, kappa, &f)
            }
        })
        .collect();
    tracing::debug!(
        seconds = started.elapsed().as_secs_f64(),
        "friction path of a fit"
    );
    ctx.rows
        .iter()
        .map(|r| per[r.s][r.k].map(|d| [d[0], d[1], ctx.w_phi * d[2]]))
        .collect()
}

/// Columns of the fitted values, in the solver's units: N mm, N / 100 (the two limits' steps of
/// one order), mrad.
const SCALE: Theta = [1.0, 0.01, 1e-3];

/// The joints' couple (N mm) below which their pre-sliding travel is not estimated
/// ([`Effect::holds`]): a fortieth of the prototype's 2 N mm and a quarter of the smallest the
/// sweep tries (0.2 N mm, below detection). A limit held at zero comes out a little inside its
/// bound (1e-25 to 6e-4 N mm, errors of 0.006), and a refinement that starts with the travel
/// held does not take the couple across this.
const RUBS: f64 = 0.05;

/// One linearised step of a fit.
struct Step {
    fit: crate::effects::joint_fit::JointFit,
    /// The step of each fitted value (zero for one not fitted) and its standard error.
    x: Theta,
    sd: [Option<f64>; 3],
    /// The tangent pass it was linearised with, per series, where it skipped the series
    /// without training rows ([`Scope::Training`]): what [`Scope::Complete`] takes again.
    partial: Option<std::sync::Arc<Vec<Tangents>>>,
    /// Columns fitted beside the friction's and the calibration's and left out of its change
    /// (a play's, [`Beside`]).
    beside: usize,
}

/// Per measured row, the change of the pose per step of play on each motor
/// ([`crate::effects::backlash::play_columns`]): fitted beside the limits' derivatives at zero
/// in the first step from no friction while the model holds no play, and left out of the
/// friction's change. A play and the supports' friction are both a hysteresis of the pose at
/// each reversal, and the derivatives at zero see no stuck element holding: beside an unmodelled
/// play of 3-4 steps with the joints' and the supports' friction at 3x, the joints' first step
/// went below zero, and the supports, fitted alone from there, took the joints' couple and the
/// play (0.195 N for 0.12; no play was named); beside the plays' columns it was 1.2 N mm and
/// 0.049 N, and the analysis went on to name both with their values
/// (`finds_friction_beside_backlash_and_tells_them_apart`). On a play alone the supports'
/// first step beside it is nothing (1e-6 N), and the fit stops there, without a pass with the
/// derivatives. The steps after the first keep them while the joints' limit is held at zero
/// (the supports alone, the friction most like a play), and have none where the joints rub
/// (beside every step, backlash + friction 3x took 15 % more time for the same result).
type Beside = Vec<[[f64; 3]; BESIDE]>;

/// Columns beside the friction's ([`Beside`]): a play on each motor. (A delay's column beside
/// them too kept the supports alone from taking up part of a 120 ms latency beside a play,
/// which costs backlash + latency 3x a quarter more time, 3.7 s; but on backlash + friction 3x
/// the play then won the first round and the supports' force came out 4.5 errors off.)
const BESIDE: usize = 3;

/// The rows a step's tangent pass must answer.
#[derive(Clone, Copy)]
enum Scope<'p> {
    /// Every row: the step whose change is scored.
    All,
    /// The series with training rows alone: a step the fit goes on from, whose change at the
    /// held-out rows is not read (the held-out recording's 16.8k rows of 60.9k are a quarter of
    /// a pass).
    Training,
    /// Every row, the series with training rows taken from a [`Scope::Training`] pass at the
    /// same values.
    Complete(&'p [Tangents]),
}

/// Per series and row, the derivatives of the deflection by the joints' and the supports'
/// limits at zero ([`crate::model::ExtendedModel::friction_onset_path`]).
type OnsetPath = Vec<Vec<Option<[[f64; 3]; 2]>>>;

/// The onset derivatives of a fit's last step from no friction, and the values they were
/// taken at ([`step_at`]).
type Onset = std::cell::RefCell<Option<(Theta, std::sync::Arc<OnsetPath>)>>;

/// One linearised fit of the friction with the calibration parameters about `theta` (the
/// context's model holds `at`: its residuals already take that friction's deflection). From no
/// friction the columns of the limits are their derivatives at zero (the pre-sliding travel
/// has none there, and keeps its value); elsewhere the derivatives of the whole path at
/// `theta` (the tangent pass), the joints' pre-sliding travel among them while the joints rub.
/// `scope` says which series its tangent pass runs on. The derivatives at zero are kept in
/// `onset` for the next step at the same `theta` (a limit that came out below zero is held and
/// the step made again: the same passes).
#[allow(clippy::too_many_arguments)]
fn step_at(
    ctx: &Context,
    train: &[usize],
    entry: &robot::Friction,
    at: &[Option<[f64; 3]>],
    theta: Theta,
    held: [bool; 3],
    scope: Scope,
    onset: &Onset,
    beside: Option<&Beside>,
) -> Option<Step> {
    let n = ctx.rows.len();
    let rubs = theta[0] != 0.0 || theta[1] != 0.0;
    // The values fitted: the limits not held, and the joints' pre-sliding travel where they
    // rub (it has no derivative at zero friction). Where the other elements rub, a limit at
    // zero has no derivative in the tangent pass either (its elements are not there): it is
    // held.
    let free: Vec<usize> = (0..3)
        .filter(|&j| {
            !held[j]
                && match j {
                    2 => rubs && theta[0] > 0.0,
                    _ => !rubs || theta[j] > 0.0,
                }
        })
        .collect();
    if free.is_empty() {
        return None;
    }
    let diff = |a: Option<[f64; 3]>, b: Option<[f64; 3]>| match (a, b) {
        (Some(a), Some(b)) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]],
        _ => [0.0; 3],
    };
    // Per row: the change from the model's friction to `theta` (the offset), and the columns.
    let mut pass = None;
    let (offset, cols): (Vec<[f64; 3]>, Vec<Vec<[f64; 3]>>) = if !rubs {
        let kept = onset
            .borrow()
            .as_ref()
            .filter(|(t, _)| *t == theta)
            .map(|(_, p)| p.clone());
        let per = kept.unwrap_or_else(|| {
            let f = Rubbing::from_effect(&with_values(entry, theta));
            let per: std::sync::Arc<OnsetPath> = std::sync::Arc::new(
                ctx.paths()
                    .par_iter()
                    .map(|(rigid, kappa)| ctx.model.friction_onset_path(rigid, kappa, &f))
                    .collect(),
            );
            *onset.borrow_mut() = Some((theta, per.clone()));
            per
        });
        // The columns of the limits fitted, in `free`'s order: where the joints' limit is held
        // at zero (its first step went below), the supports on their own column (they were
        // fitted on the joints' column once, and friction in the supports alone was named a
        // backlash and a latency, plays of 5.1-5.2 steps).
        let cols = ctx
            .rows
            .iter()
            .map(|r| {
                let c = per[r.s][r.k].unwrap_or([[0.0; 3]; 2]);
                free.iter()
                    .map(|&j| {
                        let d = c[j];
                        [d[0], d[1], ctx.w_phi * d[2]]
                    })
                    .collect()
            })
            .collect();
        let offset = (0..n).map(|i| diff(Some([0.0; 3]), at[i])).collect();
        (offset, cols)
    } else {
        // The deflection at `theta` and its derivatives, in one pass along each series.
        let f = Rubbing::from_effect(&with_values(entry, theta));
        let mut trained = vec![false; ctx.series.len()];
        for &i in train {
            trained[ctx.rows[i].s] = true;
        }
        let per = match scope {
            Scope::All => ctx.friction_tangents(&f, || {
                ctx.paths()
                    .par_iter()
                    .map(|(rigid, kappa)| ctx.model.friction_path_tangent(rigid, kappa, &f))
                    .collect()
            }),
            _ => std::sync::Arc::new(
                ctx.paths()
                    .par_iter()
                    .enumerate()
                    .map(|(s, (rigid, kappa))| match scope {
                        Scope::Complete(done) if trained[s] => done[s].clone(),
                        Scope::Training if !trained[s] => Vec::new(),
                        _ => ctx.model.friction_path_tangent(rigid, kappa, &f),
                    })
                    .collect(),
            ),
        };
        if matches!(scope, Scope::Training) && trained.contains(&false) {
            pass = Some(per.clone());
        }
        let w = |d: [f64; 3]| [d[0], d[1], ctx.w_phi * d[2]];
        let at_theta: Vec<Option<DeflectionTangent>> = ctx
            .rows
            .iter()
            .map(|r| per[r.s].get(r.k).copied().flatten())
            .collect();
        let offset = (0..n)
            .map(|i| diff(at_theta[i].map(|(d, _)| w(d)), at[i]))
            .collect();
        let cols = (0..n)
            .map(|i| {
                free.iter()
                    .map(|&j| at_theta[i].map_or([0.0; 3], |(_, t)| w(t[j])))
                    .collect()
            })
            .collect();
        (offset, cols)
    };
    let n_free = free.len();
    let n_e = n_free + beside.map_or(0, |_| BESIDE);
    let effect = |i: usize, c: &mut Columns| {
        for (a, &j) in free.iter().enumerate() {
            c[a] = cols[i][a].map(|v| v * SCALE[j]);
        }
        if let Some(b) = beside {
            c[n_free..n_free + BESIDE].copy_from_slice(&b[i]);
        }
    };
    let nui = ctx.nuisance().nui.clone();
    let moved = offset.iter().any(|o| *o != [0.0; 3]);
    // The plays' part left out of the friction's change: what the supports explain beyond a
    // play.
    let fit = fit_joint_beside(
        ctx,
        &nui,
        train,
        n_e,
        n_e - n_free,
        &effect,
        moved.then_some(&offset[..]),
    )?;
    let mut x = [0.0; 3];
    let mut sd = [None; 3];
    for (a, &j) in free.iter().enumerate() {
        x[j] = fit.0.x[a] * SCALE[j];
        sd[j] = Some(fit.0.std[a] * SCALE[j]);
    }
    Some(Step {
        fit,
        x,
        sd,
        partial: pass,
        beside: n_e - n_free,
    })
}

/// The values after a step `x` from `theta`: the limits not below zero, the pre-sliding travel
/// within a quarter and four times its value (a step of a travel that enters through the
/// elements' kinks).
fn stepped(theta: Theta, x: Theta) -> Theta {
    [
        (theta[0] + x[0]).max(0.0),
        (theta[1] + x[1]).max(0.0),
        (theta[2] + x[2]).clamp(0.25 * theta[2], 4.0 * theta[2]),
    ]
}

/// The fit of the friction from the context's model's friction: a linearised step,
/// re-linearised at its estimate while it moves a value by more than [`STEP_SHARE`] (from no
/// friction only where a limit comes out significant), up to `steps` times. A limit a step
/// takes below zero is held at zero and the step made again without it (the bounded fit: a
/// support that does not rub is no support pushing along the motion); without
/// `free_presliding` the joints' pre-sliding travel is held at its start. With `beaten` (another
/// candidate's training error), the re-linearisations end where the fit can no longer come
/// below it ([`EXTRAPOLATED_STEPS`]).
fn fit_from(
    ctx: &Context,
    train: &[usize],
    start: Option<Theta>,
    steps: usize,
    free_presliding: bool,
    beaten: Option<f64>,
) -> Option<Fitted> {
    let entry = held(&ctx.model.config.effects);
    let at = deflections(ctx, &entry);
    let mut theta = start.unwrap_or(values_of(&entry));
    let mut bound = [false, false, !free_presliding];
    // The steps the fit goes on from need the training rows alone; the last one, whose change
    // is scored, every row (its pass completed on the series skipped).
    let scope = if steps > 1 {
        Scope::Training
    } else {
        Scope::All
    };
    let onset = Onset::default();
    // A play's columns beside the first step from no friction, and beside the steps after it
    // while the joints' limit is held at zero ([`Beside`]).
    let candidate = steps > 1
        && start.is_none()
        && theta[0] == 0.0
        && theta[1] == 0.0
        && ctx.model.config.effects.backlash.is_none();
    let plays: Option<Beside> = candidate.then(|| crate::effects::backlash::play_columns(ctx));
    let beside = |theta: Theta, bound: [bool; 3]| {
        plays
            .as_ref()
            .filter(|_| bound[0] || (theta[0] == 0.0 && theta[1] == 0.0))
    };
    let step_of = |theta: Theta, bound: [bool; 3], scope: Scope<'_>| {
        step_at(
            ctx,
            train,
            &entry,
            &at,
            theta,
            bound,
            scope,
            &onset,
            beside(theta, bound),
        )
    };
    let mut step = step_of(theta, bound, scope)?;
    // The training error the calibration parameters alone leave (what a friction's step must
    // improve on).
    let sse0 = || {
        let nui = ctx.nuisance().nui.clone();
        fit_joint(ctx, &nui, train, 0, &|_, _| {}, None).map_or(ctx.sse(train, None), |f| f.0.sse)
    };
    let mut left = steps;
    let mut last_sse: Option<f64> = None;
    loop {
        if let Some(j) = (0..2).find(|&j| !bound[j] && theta[j] + step.x[j] < 0.0) {
            bound[j] = true;
            theta[j] = 0.0;
            if bound[0] && bound[1] {
                return None;
            }
            step = step_of(theta, bound, scope)?;
            continue;
        }
        let sse = step.fit.0.sse;
        tracing::debug!(?theta, x = ?step.x, sse, left, "friction step");
        if left == 0 || last_sse.is_some_and(|p: f64| (p - sse).abs() <= SSE_SETTLED * p) {
            break;
        }
        // Nor where the error, falling on as the last re-linearisation made it fall, would
        // not come below another candidate's of the round ([`EXTRAPOLATED_STEPS`]).
        if last_sse
            .zip(beaten)
            .is_some_and(|(p, b)| cannot_come_below(p, sse, b))
        {
            tracing::debug!(
                sse,
                beaten,
                "friction fit stops: another candidate is below it"
            );
            break;
        }
        last_sse = Some(sse);
        left -= 1;
        let next = stepped(theta, step.x);
        let significant = (0..2).any(|j| step.sd[j].is_some_and(|s| step.x[j] > SIGNIFICANT * s));
        let large = (0..3).any(|j| (next[j] - theta[j]).abs() > STEP_SHARE * next[j].abs());
        let from_none = theta[0] == 0.0 && theta[1] == 0.0;
        // From no friction, a first step that takes less than a tenth of what the calibration
        // parameters alone leave is not worth the passes of the re-linearisation: such a candidate does not win
        // its round, and one the model takes in is refined by its acceptance's steps (a
        // periodic error or a play of the sweep half-imitated by the first step took a second
        // or two of every round before).
        if !large || (from_none && !(significant && step.fit.0.sse < (1.0 - ONSET_GAIN) * sse0())) {
            break;
        }
        theta = next;
        step = step_of(theta, bound, scope)?;
    }
    if let Some(done) = step.partial.take() {
        step = step_of(theta, bound, Scope::Complete(&done))?;
    }
    let Step {
        fit, x, sd, beside, ..
    } = step;
    let (lin, delta, alone) = fit;
    let value = [theta[0] + x[0], theta[1] + x[1], stepped(theta, x)[2]];
    let new = with_values(&entry, value);
    let presliding = if sd[2].is_some() {
        "joint pre-sliding"
    } else {
        "joint pre-sliding (assumed)"
    };
    let params = vec![
        Estimate::new("joint torque", value[0], sd[0], "N mm"),
        Estimate::new("support force", value[1], sd[1], "N"),
        Estimate::new(presliding, value[2], sd[2], "rad"),
        Estimate::new(
            "support pre-sliding (assumed)",
            entry.support_presliding_mm,
            None,
            "mm",
        ),
        Estimate::new("EI (assumed)", entry.ei_n_mm2, None, "N mm^2"),
    ];
    let n_e = lin.x.len() - ctx.nuisance().nui.n.min(lin.x.len());
    let nuis = nuisance_change(ctx.nuisance().nui.clone(), lin.x.clone(), n_e);
    Some(Fitted {
        name: "friction",
        params,
        k: n_e - beside,
        delta,
        alone,
        train_sse: lin.sse,
        change: std::sync::Arc::new(move |c: &mut RobotConfig| {
            c.effects.friction = Some(new.clone());
            nuis(c);
        }),
    })
}

impl Extension for Friction {
    /// The declared friction.
    fn friction(&self, effects: &Effects) -> Option<Rubbing> {
        effects.friction.as_ref().map(Rubbing::from_effect)
    }
}

impl Effect for Friction {
    fn name(&self) -> &'static str {
        "friction"
    }

    /// The first against the second half of the training time (or one recording against the
    /// others): each holds moves and static poses. Not the static rows against the moving ones:
    /// at rest the friction leaves each pose off by what its approach left stuck, a pattern
    /// over the poses the calibration's geometry takes in large part (it is fitted on those
    /// poses), so that the static rows alone cannot tell the supports' force from a change of
    /// the geometry (on the sweep's recordings at 1x: 0.026 +- 0.001 N on the static rows,
    /// 0.040 on the moving ones and on the whole, noise-free or not).
    fn consistency(&self) -> super::Parts {
        super::Parts::Halves
    }

    /// Its acceptance's steps stop below a 15 % gain: each is a pass of the history with its
    /// derivatives along every row (a third of a second on the sweep's recordings), and at 10x
    /// the steps after the second gained 5-13 % each, eight of them, where the joint refinement
    /// that follows (the friction linearised once, `refine::FrozenFriction`) takes the rest.
    fn acceptance_min_gain(&self) -> f64 {
        0.85
    }

    fn description(&self) -> &'static str {
        "friction of the passive joints and their supports: stick-slip hysteresis of the pose through the segments' compliance"
    }

    /// The joints' and the supports' limits with the calibration parameters, linearised at the
    /// model's friction and re-linearised at the estimate ([`RELINEARISATIONS`]).
    fn fit(&self, ctx: &Context, train: &[usize]) -> Option<Fitted> {
        fit_from(ctx, train, None, RELINEARISATIONS, true, None)
    }

    /// [`Effect::fit`], its re-linearisations ended where it can no longer come below the
    /// round's best other candidate ([`EXTRAPOLATED_STEPS`]).
    fn fit_against(&self, ctx: &Context, train: &[usize], beaten: f64) -> Option<Fitted> {
        fit_from(ctx, train, None, RELINEARISATIONS, true, Some(beaten))
    }

    /// Each re-linearisation is a pass with the derivatives along every row (a fifth of a
    /// second on the sweep's recordings), the other candidates' fits a few hundredths.
    fn fitted_last(&self) -> bool {
        true
    }

    /// One linearised step from the model's friction, not re-linearised: the acceptance's own
    /// steps re-linearise it, each checked on the model and damped (re-linearised inside as
    /// well, a step took five passes with the derivatives, the joints' pre-sliding travel
    /// swinging between 0.9 and 3.6 mrad from pass to pass on backlash + friction at 3x).
    fn step(&self, ctx: &Context, train: &[usize]) -> Option<Fitted> {
        fit_from(ctx, train, None, 0, true, None)
    }

    /// The nuisance columns and the rigid paths its passes run along.
    fn share(&self, ctx: &Context) {
        let _ = ctx.nuisance();
        let _ = ctx.paths();
    }

    /// One step from the whole fit's values, the joints' pre-sliding travel held there: a shape
    /// of the elements' law that a part of the data tells poorly (at the prototype's friction
    /// 0.2 +- 0.2 mrad in one half of the recording, 2.0 +- 0.5 in the other), not a strength
    /// that an imitation would need to change from part to part.
    fn fit_like(&self, ctx: &Context, train: &[usize], whole: &[Estimate]) -> Option<Fitted> {
        let get = |n: &str| whole.iter().find(|e| e.name == n).map(|e| e.value);
        let presliding = get("joint pre-sliding")
            .or(get("joint pre-sliding (assumed)"))
            .unwrap_or(held(&ctx.model.config.effects).joint_presliding_rad);
        let start = get("joint torque")
            .zip(get("support force"))
            .map(|(a, b)| [a.max(0.0), b.max(0.0), presliding]);
        fit_from(ctx, train, start, 1, false, None)
    }

    fn declared(&self, effects: &Effects, _fitted: &[Estimate]) -> Option<Vec<Estimate>> {
        // Held where the joints do not rub, the travel is the assumed one.
        let presliding = if self.holds(effects, 2) {
            "joint pre-sliding (assumed)"
        } else {
            "joint pre-sliding"
        };
        effects.friction.as_ref().map(|f| {
            vec![
                Estimate::new("joint torque", f.joint_torque_n_mm, None, "N mm"),
                Estimate::new("support force", f.support_force_n, None, "N"),
                Estimate::new(presliding, f.joint_presliding_rad, None, "rad"),
                Estimate::new(
                    "support pre-sliding (assumed)",
                    f.support_presliding_mm,
                    None,
                    "mm",
                ),
                Estimate::new("EI (assumed)", f.ei_n_mm2, None, "N mm^2"),
            ]
        })
    }

    fn remove(&self, effects: &mut Effects, _params: &[Estimate]) {
        effects.friction = None;
    }

    fn file_position(&self) -> u8 {
        9
    }

    /// The joints' couple (N mm), the supports' force (in 0.01 N) and the joints' pre-sliding
    /// travel (mrad), when the file declares friction.
    fn parameters(&self, effects: &Effects) -> Vec<Parameter> {
        if effects.friction.is_none() {
            return Vec::new();
        }
        (0..3)
            .map(|j| Parameter {
                get: |e, j| {
                    e.friction
                        .as_ref()
                        .map_or(0.0, |f| values_of(f)[j] / SCALE[j])
                },
                set: |e, j, x| {
                    if let Some(f) = e.friction.as_mut() {
                        let mut v = values_of(f);
                        v[j] = x * SCALE[j];
                        *f = with_values(f, v);
                    }
                },
                index: j,
                lo: if j == 2 { 0.01 } else { 0.0 },
                hi: if j == 2 { 50.0 } else { 1000.0 },
                moves_curvatures: false,
                along_path: Some((j, SCALE[j])),
            })
            .collect()
    }

    /// The joints' pre-sliding travel while the joints' couple is zero ([`RUBS`]): it has no
    /// derivative there, and a refinement that moved it took it to a bound, with an error of
    /// 1e30 rad (the supports alone).
    fn holds(&self, effects: &Effects, index: usize) -> bool {
        index == 2
            && effects
                .friction
                .as_ref()
                .is_some_and(|f| f.joint_torque_n_mm < RUBS)
    }

    fn blend(&self, old: &RobotConfig, new: &mut RobotConfig, s: f64) {
        if let Some(f) = new.effects.friction.as_mut() {
            let (t0, f0) = old
                .effects
                .friction
                .as_ref()
                .map_or((0.0, 0.0), |o| (o.joint_torque_n_mm, o.support_force_n));
            f.joint_torque_n_mm = lerp(t0, f.joint_torque_n_mm, s);
            f.support_force_n = lerp(f0, f.support_force_n, s);
            if let Some(o) = &old.effects.friction {
                f.joint_presliding_rad = lerp(o.joint_presliding_rad, f.joint_presliding_rad, s);
            }
        }
    }

    /// Negative limits: friction that pushes along the motion.
    fn unphysical(&self, effects: &Effects, _max_change: f64) -> Option<String> {
        let f = effects.friction.as_ref()?;
        (f.joint_torque_n_mm < 0.0 || f.support_force_n < 0.0).then(|| {
            format!(
                "negative friction (joints {:.3} N mm, supports {:.4} N)",
                f.joint_torque_n_mm, f.support_force_n
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fits of the sweep's recordings: on joint springs + frame + backlash at 3x (no
    /// friction) the friction's fit from no friction cannot come below the springs' 60288 after
    /// its first re-linearisation; on backlash + friction at 3x and 1x it can come below a
    /// play's fit that leaves far more; a re-linearisation that took nothing off, or made the
    /// error larger, says nothing.
    #[test]
    fn a_fit_stops_where_it_cannot_come_below_another_candidate() {
        assert!(cannot_come_below(131616.0, 107721.0, 60288.0));
        assert!(!cannot_come_below(184284.0, 30300.0, 10000.0));
        assert!(!cannot_come_below(7281.0, 2386.0, 1000.0));
        assert!(!cannot_come_below(12548.0, 12579.0, 100.0));
        assert!(!cannot_come_below(100.0, 100.0, 50.0));
    }
}
