//! Joint refinement of every accepted effect's parameters on the full (non-linearised) model.
//!
//! Candidates are fitted one at a time and linearised; once several effects are in the model,
//! their parameters are refined together against the training rows with the bounded
//! trust-region solver of the calibration (`pcr_calibration::lsq`). An effect that stood in for
//! another one (a latency estimate biased by a backlash found later) is corrected here.
//!
//! The calibration parameters are refined with them, linearised as the candidates fit them (the
//! nuisance, with its prior): every candidate's fit moves them, so an effect found early leaves
//! them where they suited it alone, and a later effect could otherwise only be fitted around
//! that.

use crate::effects::{self, Parameter};
use crate::model::{ExtendedModel, Prediction, Sensitivity};
use crate::nuisance::Nuisance;
use crate::series::{Blocks, Series};
use pcr_calibration::lsq::{self, Options, Problem};
use pcr_robot::effects::Effects;
use pcr_robot::geometry::wrap_angle as wrap;
use pcr_robot::RobotConfig;
use rayon::prelude::*;

/// The continuous parameters of every effect `e` declares, in the order of the robot file's
/// entries ([`crate::effects::Effect::file_position`]).
fn slots(e: &Effects) -> Vec<Parameter> {
    effects::in_file_order()
        .iter()
        .flat_map(|x| x.parameters(e))
        .collect()
}

/// Which of [`slots`] mean nothing where `e` stands ([`crate::effects::Effect::holds`]): a
/// refinement holds them there and states no error for them.
fn held(e: &Effects) -> Vec<bool> {
    effects::in_file_order()
        .iter()
        .flat_map(|x| (0..x.parameters(e).len()).map(move |j| x.holds(e, j)))
        .collect()
}

/// The errors of the parameters a refinement moved (`moved`, in [`slots`]' order without the
/// ones it held) in [`slots`]' order: zero for a held one.
fn with_held(held: &[bool], moved: &[f64]) -> Vec<f64> {
    let mut moved = moved.iter();
    held.iter()
        .map(|&h| {
            if h {
                0.0
            } else {
                *moved.next().unwrap_or(&0.0)
            }
        })
        .collect()
}

/// The continuous parameters of every effect `e` declares ([`slots`]' order): the iterates the
/// joint estimation from the drawing extrapolates, and the refinement's start.
pub(crate) fn values(e: &Effects) -> Vec<f64> {
    slots(e).iter().map(|s| (s.get)(e, s.index)).collect()
}

/// Sets the continuous parameters of every effect `e` declares ([`values`]' order), each held
/// within its bounds.
pub(crate) fn set_values(e: &mut Effects, v: &[f64]) {
    for (s, x) in slots(e).iter().zip(v) {
        (s.set)(e, s.index, x.clamp(s.lo, s.hi));
    }
}

/// The standard errors of the parameters of the effect `name` as it reports them
/// ([`crate::effects::Effect::declared`], `fitted` naming the entry), from the errors
/// `slot_std` of every effect's continuous parameters in `effects` ([`values`]' order): each of
/// its parameters moved by its error, the reported values' changes added in quadrature. Empty
/// when the effect reports nothing from the file.
pub(crate) fn reported_errors(
    effects: &Effects,
    slot_std: &[f64],
    name: &str,
    fitted: &[crate::fitted::Estimate],
) -> Vec<(String, f64)> {
    let mut offset = 0;
    for e in effects::in_file_order() {
        let own = e.parameters(effects);
        if e.name() != name {
            offset += own.len();
            continue;
        }
        let Some(base) = e.declared(effects, fitted) else {
            return Vec::new();
        };
        let mut var = vec![0.0f64; base.len()];
        for (j, s) in own.iter().enumerate() {
            let Some(&sd) = slot_std.get(offset + j) else {
                return Vec::new();
            };
            let mut moved = effects.clone();
            (s.set)(&mut moved, s.index, (s.get)(effects, s.index) + sd);
            let Some(after) = e.declared(&moved, fitted) else {
                return Vec::new();
            };
            for (v, (a, b)) in var.iter_mut().zip(after.iter().zip(&base)) {
                *v += (a.value - b.value).powi(2);
            }
        }
        return base
            .iter()
            .zip(var)
            .filter(|(p, _)| {
                fitted.iter().any(|f| {
                    f.name == p.name && (f.std.is_some() || !f.name.ends_with("(assumed)"))
                })
            })
            .map(|(p, v)| (p.name.clone(), v.sqrt()))
            .collect();
    }
    Vec::new()
}

/// Training rows the joint refinements of the search run on (every so many of them): a loaded
/// refinement's evaluation costs about 0.1 s on these; the final estimate
/// ([`refine_with_errors`]) says what their noise does to the values.
pub(crate) const SEARCH_ROWS: usize = 3000;

/// The refinements' first trust-region radius, as a multiple of the starting point's length in
/// the solver's scaled variables (MINPACK's `factor`: [`pcr_calibration::lsq::Options`]).
/// SciPy's radius (1) is the length of the effects' values alone, the calibration parameters
/// starting at zero, and a refinement took its steps at that radius doubling each time: on
/// springs + frame + backlash at 3x, 8 Jacobians where the Gauss-Newton steps, taken at once,
/// reach the same cost in 3 or 4.
const FIRST_RADIUS: f64 = 100.0;

/// Steps of a refinement after each evaluated Jacobian whose effects' columns are Broyden's
/// update of the last ones instead ([`pcr_calibration::lsq::Options::secant_steps`]): every
/// second step. The columns linear and constant in the refinement stay exact (the calibration
/// parameters', and the frozen friction's values': updated too, they took up the plays'
/// nonlinearity, and two plant tests of friction beside a play found plays of 5 steps for 3),
/// and the Jacobian at the optimum of a refinement that reports its errors is evaluated. A
/// Jacobian costs the kinematics' responses at every refined row and a forward difference
/// through the cheap stages of every row of the recording per parameter that moves the
/// curvatures, 1.2-1.4 evaluations of the model; the steps after the first follow directions
/// the last Jacobian nearly has. On springs + frame + backlash at 3x the 13 refinements
/// evaluated 27 Jacobians instead of 46 and the model 60 times instead of 63 (2.23 s -> 1.76
/// s), the values within 0.001 of their errors and the approximate errors the same to three
/// digits; two secant steps in a row took another 0.5 % off and moved the values more.
const SECANT_STEPS: usize = 1;

/// Most re-linearisations of the friction in a refinement that reports its errors
/// ([`FrozenFriction`]), as in a search's refinement: one. A second (made where the first moved
/// a play by more than a thousandth of it) moved the plays of backlash + friction at 1x by a
/// tenth of their stated errors for 0.6 s of the final estimate's 22k rows; beside the
/// supports' friction at 3x the plays creep with the supports' force along their valley,
/// 9.013 -> 9.040 -> ... steps, each re-linearisation a little less than the one before, and
/// a second one does not end that either.
const FRICTION_RELINEARISATIONS: usize = 1;

/// Most evaluations of the model in a refinement of the search (7-13 reach the tolerance).
const MAX_EVALUATIONS: usize = 200;

/// A search's refinement ends when its last [`STALL_STEPS`] steps together took less than
/// [`STALL_FTOL`] of the cost off: a loaded model's residuals are solved from the last
/// evaluation's equilibria, not smooth at that level, and a model that does not hold the
/// data's effect (a load for a tendon cross-coupling of 15 %) crawled on through 53 evaluations
/// (3.2 s), each step taking just more than the tolerance of 1e-6 off, some refused, for 0.4 %
/// of the cost after the 13th. 5e-5 of the cost over four steps is a change of chi^2 of about
/// 0.4 on 3000 rows (three coordinates each, at the cost's own level per coordinate).
const STALL_STEPS: usize = 4;
const STALL_FTOL: f64 = 5e-5;

struct Refit<'a> {
    base: &'a RobotConfig,
    like: &'a ExtendedModel,
    slots: Vec<Parameter>,
    series: &'a [Series],
    rows: Vec<Vec<usize>>,
    n: usize,
    w_phi: f64,
    /// The calibration parameters, linearised at `base`.
    nuisance: Option<Linearised>,
    /// Per series, the loaded solver's state at each refined row, from the evaluation before
    /// (each evaluation starts a row from its own last equilibrium).
    states: Vec<crate::model::RowStates>,
    /// The friction's deflection of the refined rows linearised at the start.
    friction: Option<FrozenFriction>,
}

/// A refined row's friction deflection at the linearisation's start and its derivative by each
/// parameter that acts along the path.
type RowLinearisation = ([f64; 3], Vec<[f64; 3]>);

/// The friction's deflection of the refined rows, linearised in the friction's own parameters
/// at the refinement's start and held there for the other parameters' changes: a pass through
/// every row of a series (the friction's history) costs as much as a few thousand rows of the
/// rest of the model, and the refinement evaluates the model a dozen times and more. The
/// deflection moves with the friction's parameters and hardly with the others' (a play or a
/// calibration parameter moves the path it runs along by a fraction of a step): the
/// refinement's steps are a chord method for it, and the search that calls the refinement
/// again starts each time from the deflection of its own model. Where a parameter that moves
/// the path moved, the refinement linearises again where it arrived, and the deflection's
/// change between the two linearisations gives it a secant by those parameters
/// ([`FrozenFriction::update_secants`]).
struct FrozenFriction {
    /// The slots of the parameters that act along the path (`Parameter::along_path`).
    slots: Vec<usize>,
    /// Their values at the start (solver's units).
    x0: Vec<f64>,
    /// Per series and refined row: the deflection at the start (x mm, y mm, phi rad), and its
    /// derivative by each of those parameters (solver's units).
    rows: Vec<Vec<RowLinearisation>>,
    /// The slots of the parameters that move the curvatures (`Parameter::moves_curvatures`),
    /// and with them the path the friction's history runs along.
    path_slots: Vec<usize>,
    /// Their values at the start (solver's units).
    path_x0: Vec<f64>,
    /// Per series and refined row, the deflection's secant by each of them (per solver's
    /// unit): zero at a refinement's first linearisation, then Broyden's update at each
    /// re-linearisation.
    path: Vec<Vec<Vec<[f64; 3]>>>,
}

impl FrozenFriction {
    /// The linearisation at `config` on the refined rows `rows` of each series: one pass of the
    /// friction along every row of each series with its derivatives
    /// ([`ExtendedModel::friction_path_tangent`]); `None` when no parameter acts along the path,
    /// or the model has no friction.
    fn new(
        config: &RobotConfig,
        like: &ExtendedModel,
        slots: &[Parameter],
        series: &[Series],
        rows: &[Vec<usize>],
    ) -> Option<FrozenFriction> {
        let along: Vec<usize> = (0..slots.len())
            .filter(|&p| slots[p].along_path.is_some())
            .collect();
        if along.is_empty() {
            return None;
        }
        let model = ExtendedModel::like(config, like).ok()?;
        let f = model.friction?;
        let x0: Vec<f64> = along
            .iter()
            .map(|&p| (slots[p].get)(&config.effects, slots[p].index))
            .collect();
        // The deflection and its derivatives by the friction's values, in one pass a series.
        let per: Vec<Vec<RowLinearisation>> = series
            .par_iter()
            .zip(rows)
            .map(|(s, rows)| {
                // The history along every row (none without a refined row: no pass), the
                // pass a prediction of the model makes ([`ExtendedModel::friction_path`]: a
                // model just predicted is not passed again).
                if rows.is_empty() {
                    return Vec::new();
                }
                let all: Vec<usize> = (0..s.samples.len()).collect();
                let kappa = model.curvatures(s, &all);
                let rigid = model.rigid_path(s, &kappa);
                let path = model.friction_path_tangent(&rigid, &kappa, &f);
                rows.iter()
                    .map(|&k| {
                        let (b, t) = path[k].unwrap_or(([0.0; 3], [[0.0; 3]; 3]));
                        let cols = along
                            .iter()
                            .map(|&p| {
                                let (j, per_unit) = slots[p].along_path.unwrap_or((0, 0.0));
                                t[j.min(2)].map(|v| v * per_unit)
                            })
                            .collect();
                        (b, cols)
                    })
                    .collect()
            })
            .collect();
        let path_slots: Vec<usize> = (0..slots.len())
            .filter(|&p| slots[p].moves_curvatures)
            .collect();
        let path_x0 = path_slots
            .iter()
            .map(|&p| (slots[p].get)(&config.effects, slots[p].index))
            .collect();
        let path = per
            .iter()
            .map(|rows| vec![vec![[0.0; 3]; path_slots.len()]; rows.len()])
            .collect();
        Some(FrozenFriction {
            slots: along,
            x0,
            rows: per,
            path_slots,
            path_x0,
            path,
        })
    }

    /// The linearisation made again at `config` (the parameters `x`, every slot's), with the
    /// secants by the path's parameters carried over from this one and updated
    /// ([`Self::update_secants`]).
    fn again(
        &self,
        config: &RobotConfig,
        like: &ExtendedModel,
        slots: &[Parameter],
        series: &[Series],
        rows: &[Vec<usize>],
        x: &[f64],
    ) -> Option<FrozenFriction> {
        let mut next = FrozenFriction::new(config, like, slots, series, rows)?;
        self.update_secants(&mut next, x);
        Some(next)
    }

    /// Broyden's update of the secants by the path's parameters, from this linearisation to
    /// `next` (made at the parameters `x`): what the deflection did beyond what this one
    /// predicted at `x`, spread along the move of the path's parameters, so that `next`
    /// predicts at this one's start what this one did there (to the change of the friction's
    /// own tangents). The friction's columns are tangents; the path's cannot be (a play's or
    /// a delay's derivative runs through every reversal after the row), and without a column
    /// for them a refinement's steps stop short: the deflection held on the path where it was
    /// pulls a play back towards the value that path had (backlash + friction at 3x: plays of
    /// 0.1 -> 1.3 -> 2.7 steps in three linearisations, 9 the truth; with the secants 0.1 ->
    /// 1.3 -> 4.4). Left as they were where the path's parameters did not move.
    fn update_secants(&self, next: &mut FrozenFriction, x: &[f64]) {
        let dx: Vec<f64> = self
            .path_slots
            .iter()
            .zip(&self.path_x0)
            .map(|(&p, x0)| x[p] - x0)
            .collect();
        let norm2: f64 = dx.iter().map(|d| d * d).sum();
        if next.path_slots != self.path_slots {
            return;
        }
        if norm2 == 0.0 {
            next.path.clone_from(&self.path);
            return;
        }
        for (si, rows) in next.path.iter_mut().enumerate() {
            for (r, secants) in rows.iter_mut().enumerate() {
                let old = &self.path[si][r];
                let was = self.at(si, r, x);
                let now = next.rows[si][r].0;
                let miss: [f64; 3] = std::array::from_fn(|c| now[c] - was[c]);
                for ((g, old), d) in secants.iter_mut().zip(old).zip(&dx) {
                    *g = std::array::from_fn(|c| old[c] + miss[c] * d / norm2);
                }
            }
        }
    }

    /// The deflection of refined row `r` of series `s` at the parameters `x` (every slot's).
    fn at(&self, s: usize, r: usize, x: &[f64]) -> [f64; 3] {
        let (b, cols) = &self.rows[s][r];
        let mut d = *b;
        // The tangents by the friction's values, then the secants by the path's parameters.
        let moves = [
            (cols, &self.slots, &self.x0),
            (&self.path[s][r], &self.path_slots, &self.path_x0),
        ];
        for (cols, slots, x0) in moves {
            for ((col, &p), x0) in cols.iter().zip(slots).zip(x0) {
                let dx = x[p] - x0;
                for c in 0..3 {
                    d[c] += col[c] * dx;
                }
            }
        }
        d
    }

    /// Which of the path's secants slot `p` has, if it has one.
    fn path_column(&self, p: usize) -> Option<usize> {
        self.path_slots.iter().position(|&q| q == p)
    }

    /// Which of the linearised parameters slot `p` is, if it is one.
    fn column(&self, p: usize) -> Option<usize> {
        self.slots.iter().position(|&q| q == p)
    }
}

/// The calibration parameters linearised at the refinement's start: their columns on the
/// refined rows (computed for those rows only) and their prior.
struct Linearised {
    nui: Nuisance,
    /// Per refined row (in `Refit::rows` order), its columns, if the model predicts the row.
    cols: Vec<Option<Vec<[f64; 3]>>>,
    /// sqrt(1 / sigma^2) of each parameter.
    prior_sqrt: Vec<f64>,
}

impl Linearised {
    /// The columns at `config` on the refined rows `rows` (per series), predicted here for
    /// those rows alone (a few thousand, not the whole recording). `share`: the refined rows'
    /// share of the training rows (the prior is the candidates' prior on every training row, so
    /// it weighs the same against the data on a subsample).
    fn new(
        config: &RobotConfig,
        like: &ExtendedModel,
        series: &[Series],
        rows: &[Vec<usize>],
        w_phi: f64,
        share: f64,
    ) -> Result<Linearised, String> {
        let mut model = ExtendedModel::like(config, like).map_err(|e| e.0)?;
        model.interpolate = false;
        let nui = Nuisance::of(&model.config);
        // The rows' curvatures and rigid poses: under loads the columns solve each row's
        // equilibrium themselves (from the rigid pose, warm-started along the rows), so the
        // rows are not solved loaded twice.
        // The friction's small deflection leaves the columns as they are: the model without it
        // (no pass over every row of the series for a few thousand).
        let model = ExtendedModel {
            friction: None,
            ..model
        };
        let rigid = model.loads.is_some().then(|| ExtendedModel {
            loads: None,
            ..model.clone()
        });
        let preds: Vec<Vec<Prediction>> = series
            .iter()
            .zip(rows)
            .map(|(s, ks)| {
                let want = crate::model::mask(s.samples.len(), ks);
                let how = crate::model::Solving {
                    poses_only: rigid.is_some(),
                    ..Default::default()
                };
                rigid
                    .as_ref()
                    .unwrap_or(&model)
                    .predict_where_from(s, &|k| want[k], how)
            })
            .collect();
        let at: Vec<(usize, usize)> = rows
            .iter()
            .enumerate()
            .flat_map(|(s, ks)| ks.iter().map(move |&k| (s, k)))
            .collect();
        // Under loads, the loaded columns ([`crate::nuisance::LoadedChanges`]), warm-started
        // along each series' rows.
        let loaded = model
            .loads
            .filter(|l| !l.is_unloaded())
            .and_then(|l| nui.loaded_changes(&model.config, &model.robot, l));
        let cols = match &loaded {
            Some(changes) => {
                let mut per: Vec<Vec<(usize, usize)>> = Vec::new();
                for &(s, k) in &at {
                    match per.last_mut() {
                        Some(c) if c[0].0 == s && c.len() < 256 => c.push((s, k)),
                        _ => per.push(vec![(s, k)]),
                    }
                }
                per.par_iter()
                    .flat_map_iter(|chunk| {
                        let mut warm = pcr_kinematics::statics::LoadedWarm::default();
                        // The last row solved: a row at rest (the same curvatures and tendon
                        // displacements) takes its columns.
                        let mut last: Option<(&Prediction, Vec<[f64; 3]>)> = None;
                        chunk
                            .iter()
                            .map(|&(s, k)| {
                                let p = &preds[s][k];
                                p.pose?;
                                if let Some((q, c)) = &last {
                                    if q.kappa == p.kappa && q.dl_eff == p.dl_eff {
                                        return Some(c.clone());
                                    }
                                }
                                let mut c = vec![[0.0; 3]; nui.n];
                                let ok = nui.loaded_columns(changes, p, w_phi, &mut warm, &mut c);
                                last = ok.then(|| (p, c.clone()));
                                ok.then_some(c)
                            })
                            .collect::<Vec<_>>()
                    })
                    .collect()
            }
            None => at
                .par_iter()
                .map(|&(s, k)| {
                    let p = &preds[s][k];
                    p.pose.map(|_| {
                        let mut c = vec![[0.0; 3]; nui.n];
                        nui.columns(&model.robot, p, w_phi, &mut c);
                        c
                    })
                })
                .collect(),
        };
        let prior_sqrt = nui.prior().iter().map(|p| (p * share).sqrt()).collect();
        Ok(Linearised {
            nui,
            cols,
            prior_sqrt,
        })
    }

    fn n(&self) -> usize {
        self.nui.n
    }
}

impl Refit<'_> {
    /// Number of effect parameters (the first ones of `x`).
    fn n_effects(&self) -> usize {
        self.slots.len()
    }

    fn config(&self, x: &[f64]) -> RobotConfig {
        let mut c = self.base.clone();
        for (s, v) in self.slots.iter().zip(x) {
            (s.set)(&mut c.effects, s.index, *v);
        }
        if let Some(l) = &self.nuisance {
            l.nui.apply(&x[self.n_effects()..], &mut c);
        }
        c
    }

    /// The model with the effects at `x` (calibration parameters as in `base`).
    fn effects_model(&self, x: &[f64]) -> Result<ExtendedModel, String> {
        let mut c = self.base.clone();
        for (s, v) in self.slots.iter().zip(x) {
            (s.set)(&mut c.effects, s.index, *v);
        }
        let mut m = ExtendedModel::like(&c, self.like).map_err(|e| e.0)?;
        m.interpolate = false;
        if self.friction.is_some() {
            // Its deflection is added linearised ([`FrozenFriction`]).
            m.friction = None;
        }
        Ok(m)
    }

    /// The effects' columns of the Jacobian at `x` into the first 3 n rows of `j`'s first
    /// columns. A parameter acts on a row through the curvatures (timing, transmission, play,
    /// tendons, map), the loads, or the correction of the measurement; the kinematics are
    /// solved once, at `x`, with their responses to the curvatures and the loads
    /// ([`ExtendedModel::sensitivities`]), and each parameter's column is its forward
    /// difference through the cheap stages times those responses. A parameter that changes
    /// what the responses do not cover (the bending stiffness, or the springs' rest angles
    /// through the map, or the friction) gets the forward difference of the full model.
    fn effect_columns(
        &self,
        x: &[f64],
        upper: &[f64],
        j: &mut nalgebra::DMatrix<f64>,
    ) -> Result<(), String> {
        let model = self.effects_model(x)?;
        let sens: Vec<Vec<Option<Sensitivity>>> = self
            .series
            .iter()
            .zip(&self.rows)
            .zip(&self.states)
            .map(|((s, rows), st)| model.sensitivities(s, rows, Some(st)))
            .collect();
        let springs = model.loads.is_some_and(|l| l.k_m != 0.0 || l.k_p != 0.0);
        let rest = springs.then(|| model.robot.home_joint_angles());
        // Every column that the responses or the friction's linearisation give, in parallel
        // (each reads the model at `x` and builds its own at its step: on two cores the
        // refinements were the analysis's longest stretch on one, backlash + friction at 3x,
        // each parameter that moves the curvatures taking the tendons of every row of the
        // recording); `None`: the parameter needs the full model's forward difference, made
        // after, in order, since those evaluations keep their rows' loaded states.
        let cols: Vec<Option<Vec<f64>>> = (0..x.len())
            .into_par_iter()
            .map(|p| self.response_column(p, x, upper, &model, &sens, rest))
            .collect::<Result<_, String>>()?;
        let mut xp = x.to_vec();
        let mut fd_base: Option<Vec<f64>> = None;
        for (p, col) in cols.into_iter().enumerate() {
            if let Some(col) = col {
                j.column_mut(p).rows_mut(0, col.len()).copy_from_slice(&col);
                continue;
            }
            let h = step(x[p], upper[p]);
            xp[p] = x[p] + h;
            let h = xp[p] - x[p];
            if fd_base.is_none() {
                let mut b = vec![0.0; 3 * self.n];
                self.effect_residuals(x, &mut b)?;
                fd_base = Some(b);
            }
            let base = fd_base.as_deref().unwrap_or_default();
            let mut rp = vec![0.0; 3 * self.n];
            self.effect_residuals(&xp, &mut rp)?;
            for i in 0..3 * self.n {
                j[(i, p)] = (rp[i] - base[i]) / h;
            }
            xp[p] = x[p];
        }
        Ok(())
    }

    /// Parameter `p`'s column of [`Refit::effect_columns`] (3 n entries) where it needs no
    /// evaluation of the full model: the friction's linearised deflection's own derivative, or
    /// the forward difference through the cheap stages times the kinematics' responses `sens`
    /// at `x` (`model`: the model at `x`; `rest`: its springs' rest angles, if it has springs).
    /// `None`: the full model's forward difference is needed.
    fn response_column(
        &self,
        p: usize,
        x: &[f64],
        upper: &[f64],
        model: &ExtendedModel,
        sens: &[Vec<Option<Sensitivity>>],
        rest: Option<[(f64, f64); 3]>,
    ) -> Result<Option<Vec<f64>>, String> {
        let mut out = vec![0.0; 3 * self.n];
        if let Some((fr, j0)) = self
            .friction
            .as_ref()
            .and_then(|f| f.column(p).map(|j0| (f, j0)))
        {
            // The linearised deflection's own column: its derivative, in the residual's
            // sign (measured less predicted).
            let mut k = 0;
            for (si, rows) in self.rows.iter().enumerate() {
                for (r, &i) in rows.iter().enumerate() {
                    if self.series[si].samples[i].pose.is_some() {
                        let d = fr.rows[si][r].1[j0];
                        out[3 * k..3 * k + 3].copy_from_slice(&[-d[0], -d[1], -self.w_phi * d[2]]);
                    }
                    k += 1;
                }
            }
            return Ok(Some(out));
        }
        let mut xp = x.to_vec();
        xp[p] = x[p] + step(x[p], upper[p]);
        let h = xp[p] - x[p];
        let mk = self.effects_model(&xp)?;
        let dl = match (&model.loads, &mk.loads) {
            // The friction's deflection is not among the kinematics' responses.
            _ if model.friction != mk.friction => return Ok(None),
            (None, None) => [0.0; 5],
            (Some(a), Some(b))
                if a.ei == b.ei && rest.is_none_or(|r| r == mk.robot.home_joint_angles()) =>
            {
                [
                    b.force[0] - a.force[0],
                    b.force[1] - a.force[1],
                    b.couple - a.couple,
                    b.k_m - a.k_m,
                    b.k_p - a.k_p,
                ]
            }
            _ => return Ok(None),
        };
        let secant = self
            .friction
            .as_ref()
            .and_then(|f| f.path_column(p).map(|c| (f, c)));
        let mut k = 0;
        for (si, ((s, rows), sens)) in self.series.iter().zip(&self.rows).zip(sens).enumerate() {
            // A load or the frame leaves the curvatures where they are at `x`.
            let moved = self.slots[p]
                .moves_curvatures
                .then(|| mk.curvatures(s, rows));
            for (r, (&i, sn)) in rows.iter().zip(sens).enumerate() {
                if let (Some(m), Some(sn)) = (s.samples[i].pose, sn) {
                    let (m0, m1) = (model.corrected(m), mk.corrected(m));
                    let kappa = moved.as_ref().map_or(sn.kappa, |c| c[r]);
                    let dk =
                        nalgebra::Vector3::from(std::array::from_fn(|l| kappa[l] - sn.kappa[l]));
                    let mut dp = sn.d_kappa * dk;
                    for (c, d) in sn.d_loads.iter().zip(&dl) {
                        dp += nalgebra::Vector3::from(*c) * *d;
                    }
                    // The friction's secant along the path, if any.
                    let g = secant.map_or([0.0; 3], |(fr, c)| fr.path[si][r][c]);
                    out[3 * k..3 * k + 3].copy_from_slice(&[
                        (m1[0] - m0[0] - dp[0]) / h - g[0],
                        (m1[1] - m0[1] - dp[1]) / h - g[1],
                        self.w_phi * ((wrap(m1[2] - m0[2]) - dp[2]) / h - g[2]),
                    ]);
                }
                k += 1;
            }
        }
        Ok(Some(out))
    }

    /// The full model's residuals with the effects at `x` (calibration parameters as in
    /// `base`) into the first 3 n entries of `r`.
    fn effect_residuals(&self, x: &[f64], r: &mut [f64]) -> Result<(), String> {
        let model = self.effects_model(x)?;
        let mut k = 0;
        for (si, ((s, rows), st)) in self
            .series
            .iter()
            .zip(&self.rows)
            .zip(&self.states)
            .enumerate()
        {
            let how = crate::model::Solving {
                states: Some(st),
                poses_only: true,
                ..Default::default()
            };
            let mut poses = model.predict_poses(s, rows, how);
            if let Some(fr) = &self.friction {
                for (r, pose) in poses.iter_mut().enumerate() {
                    if let Some(p) = pose.as_mut() {
                        let d = fr.at(si, r, x);
                        for c in 0..3 {
                            p[c] += d[c];
                        }
                    }
                }
            }
            for (&i, pose) in rows.iter().zip(poses) {
                let (Some(m), Some(p)) = (s.samples[i].pose, pose) else {
                    r[3 * k] = 0.0;
                    r[3 * k + 1] = 0.0;
                    r[3 * k + 2] = 0.0;
                    k += 1;
                    continue;
                };
                r[3 * k..3 * k + 3].copy_from_slice(&model.residual(m, p, self.w_phi));
                k += 1;
            }
        }
        Ok(())
    }
}

impl Problem for Refit<'_> {
    fn residual_count(&self) -> usize {
        3 * self.n + self.nuisance.as_ref().map_or(0, Linearised::n)
    }

    /// The effects' columns but the friction's: the calibration parameters' and the frozen
    /// friction's values' columns are linear and constant ([`FrozenFriction`]).
    fn secant_column(&self, c: usize) -> bool {
        c < self.n_effects() && self.friction.as_ref().is_none_or(|f| f.column(c).is_none())
    }

    /// The full model's residuals at the effects' values, less the linearised change of the
    /// calibration parameters, then the prior's rows.
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), String> {
        let ne = self.n_effects();
        self.effect_residuals(&x[..ne], r)?;
        let Some(l) = &self.nuisance else {
            return Ok(());
        };
        let g = &x[ne..];
        for (k, cols) in l.cols.iter().enumerate() {
            let Some(cols) = cols else { continue };
            for (col, gj) in cols.iter().zip(g) {
                for c in 0..3 {
                    r[3 * k + c] -= col[c] * gj;
                }
            }
        }
        for (j, gj) in g.iter().enumerate() {
            r[3 * self.n + j] = l.prior_sqrt[j] * gj;
        }
        Ok(())
    }

    /// The effects' columns from the kinematics' responses ([`Refit::effect_columns`]); the
    /// calibration parameters' columns are the linearisation's own.
    fn jacobian(
        &mut self,
        x: &[f64],
        _r: &[f64],
        upper: &[f64],
        j: &mut nalgebra::DMatrix<f64>,
    ) -> Result<(), String> {
        let ne = self.n_effects();
        // The calibration parameters' columns, one per thread (column-major storage: each
        // column a slice), the effects' ones zeroed for [`Refit::effect_columns`].
        let rows = j.nrows();
        j.as_mut_slice()
            .par_chunks_mut(rows)
            .enumerate()
            .for_each(|(p, col)| {
                col.fill(0.0);
                let Some(l) = self.nuisance.as_ref().filter(|_| p >= ne) else {
                    return;
                };
                let gj = p - ne;
                for (k, cols) in l.cols.iter().enumerate() {
                    if let Some(cols) = cols {
                        for c in 0..3 {
                            col[3 * k + c] = -cols[gj][c];
                        }
                    }
                }
                col[3 * self.n + gj] = l.prior_sqrt[gj];
            });
        self.effect_columns(&x[..ne], &upper[..ne], j)
    }
}

/// The forward-difference step of a parameter at `x` with upper bound `upper` (backwards
/// where forwards would cross it).
fn step(x: f64, upper: f64) -> f64 {
    let h = f64::EPSILON.sqrt() * x.abs().max(1.0);
    if x + h > upper {
        -h
    } else {
        h
    }
}

/// Refines the continuous parameters of every effect of `config` on (at most `max_rows` of)
/// the training rows; returns the refined configuration (or the input when there is nothing to
/// refine or the solver fails). The models are solved as `like` is (exact or fast). With
/// `calibration`, the calibration parameters are refined with them, linearised at `config`.
pub fn refine(
    config: &RobotConfig,
    like: &ExtendedModel,
    series: &[Series],
    blocks: &Blocks,
    w_phi: f64,
    max_rows: usize,
    calibration: bool,
) -> RobotConfig {
    refine_with_errors(
        config,
        like,
        series,
        blocks,
        w_phi,
        max_rows,
        calibration,
        MAX_EVALUATIONS,
        Errors::No,
        None,
    )
    .0
}

/// [`refine`] as the search runs it: on [`SEARCH_ROWS`] of the training rows, with the
/// calibration parameters.
pub(crate) fn search(
    config: &RobotConfig,
    like: &ExtendedModel,
    series: &[Series],
    blocks: &Blocks,
    w_phi: f64,
) -> RobotConfig {
    search_with_errors(config, None, like, series, blocks, w_phi, Errors::No).0
}

/// The standard errors a refinement gives with its configuration ([`refine_with_errors`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Errors {
    /// None: a search's refinement, which ends where its cost stalls, re-linearises the
    /// friction once, and evaluates no Jacobian at its end.
    No,
    /// A search's refinement with the errors from the Jacobian the solver last had (at the
    /// point before its last step, evaluated or a secant one: [`SECANT_STEPS`]) and the
    /// residuals where it ended: the scale of each parameter's error, for a decision, not for
    /// a report.
    Approximate,
    /// The errors at the optimum, for the report: the solver evaluates the Jacobian there, has
    /// no stall test, and re-linearises the friction up to [`FRICTION_RELINEARISATIONS`] times.
    AtOptimum,
}

/// [`search`] with the standard errors `errors` asks for ([`Errors::No`] or
/// [`Errors::Approximate`]; `None` as [`refine_with_errors`] gives it), the friction linearised
/// on the geometry of `at` where given, a robot file whose effects are `config`'s.
pub(crate) fn search_with_errors(
    config: &RobotConfig,
    at: Option<&RobotConfig>,
    like: &ExtendedModel,
    series: &[Series],
    blocks: &Blocks,
    w_phi: f64,
    errors: Errors,
) -> (RobotConfig, Option<Vec<f64>>) {
    refine_with_errors(
        config,
        like,
        series,
        blocks,
        w_phi,
        SEARCH_ROWS,
        true,
        MAX_EVALUATIONS,
        errors,
        at,
    )
}

/// Where a refinement of `config`'s parameters `slots` linearises its friction first, and
/// whether that linearisation is stale ([`refine_with_errors`]): at `at` where it is another
/// robot file with the same values of those parameters (to the bit), else at `config`.
fn linearisation_start<'c>(
    config: &'c RobotConfig,
    at: Option<&'c RobotConfig>,
    slots: &[Parameter],
) -> (&'c RobotConfig, bool) {
    let same_values = |a: &Effects, b: &Effects| {
        slots
            .iter()
            .all(|s| (s.get)(a, s.index).to_bits() == (s.get)(b, s.index).to_bits())
    };
    match at {
        Some(a) if a != config && same_values(&a.effects, &config.effects) => (a, true),
        _ => (config, false),
    }
}

/// [`refine`] (at most `max_evaluations` of the model), with the standard errors of the
/// effects' parameters ([`values`]' order, the solver's units) on the rows it refined on, as
/// `errors` asks ([`Errors`]):
/// clustered by time block as the linear fits'
/// ([`crate::linear::standard_errors`]), the calibration parameters' prior weighed as in theirs
/// ([`crate::linear::PRIOR_IN_ERRORS`]). `None` when there is nothing to refine or the solver
/// fails, and with [`Errors::No`]; only [`Errors::AtOptimum`] has the solver evaluate the
/// Jacobian at the optimum (a Jacobian costs the model's responses on every refined row, about
/// a tenth of a loaded refinement).
///
/// A refinement on a subsample estimates with the subsample's noise: the errors of the fit
/// that found an effect (every training row) are then too small for the values the model
/// holds (periodic-10x: 10.014 +- 0.0032 steps from 2,938 of 44,071 rows, 4.3 errors off).
///
/// The friction is linearised ([`FrozenFriction`]) on the geometry of `at` where given,
/// another robot file with the same values of the refined parameters: the one a calibration
/// from the drawing started from, whose pass along every row that calibration
/// made with the derivatives ([`crate::recalibration`]). One pass with the derivatives then
/// replaces a pass without them and one with them, 0.15-0.2 s of each alternation. The
/// refinement holds the friction's deflection on the geometry as it does while its own
/// calibration parameters move (and where the plays move it linearises again, on its own
/// geometry). The calibration moves the geometry by tenths of a millimetre and of a degree,
/// which moves the deflection by a small share along most of a path but not everywhere: on a
/// swinging path at three times the prototype's friction, with psi 0.3 deg and l_C and r_p
/// 0.2 mm further, under 1 % of the largest deflection on most rows and up to 0.75 of 1.2 mm on
/// a stretch of 70 rows of 300, where the history of stick and slip turned out otherwise.
/// Linearising again on its own geometry after every first solve was tried: on backlash +
/// friction at 3x the joints' pre-sliding travel, which the data tell poorly, then went to its
/// bound in the friction's alternation, and the plays came out 3.6 errors off.
#[allow(clippy::too_many_arguments)]
pub(crate) fn refine_with_errors(
    config: &RobotConfig,
    like: &ExtendedModel,
    series: &[Series],
    blocks: &Blocks,
    w_phi: f64,
    max_rows: usize,
    calibration: bool,
    max_evaluations: usize,
    errors: Errors,
    at: Option<&RobotConfig>,
) -> (RobotConfig, Option<Vec<f64>>) {
    let at_optimum = errors == Errors::AtOptimum;
    // The parameters that mean nothing where the effects stand are held there.
    let held = held(&config.effects);
    let slots: Vec<Parameter> = slots(&config.effects)
        .into_iter()
        .zip(&held)
        .filter_map(|(s, &h)| (!h).then_some(s))
        .collect();
    if slots.is_empty() {
        return (config.clone(), None);
    }
    let total: usize = series
        .iter()
        .enumerate()
        .map(|(si, s)| {
            s.samples
                .iter()
                .enumerate()
                .filter(|(k, x)| x.pose.is_some() && !blocks.held_out[blocks.block[si][*k]])
                .count()
        })
        .sum();
    let every = total.div_ceil(max_rows.max(1)).max(1);
    let mut count = 0usize;
    let rows: Vec<Vec<usize>> = series
        .iter()
        .enumerate()
        .map(|(si, s)| {
            s.samples
                .iter()
                .enumerate()
                .filter(|(k, x)| x.pose.is_some() && !blocks.held_out[blocks.block[si][*k]])
                .filter_map(|(k, _)| {
                    count += 1;
                    count.is_multiple_of(every).then_some(k)
                })
                .collect()
        })
        .collect();
    let n = rows.iter().map(Vec::len).sum();
    let x0 = values(&config.effects);
    let mut lo: Vec<f64> = slots.iter().map(|s| s.lo).collect();
    let mut hi: Vec<f64> = slots.iter().map(|s| s.hi).collect();
    let mut x0: Vec<f64> = x0
        .iter()
        .zip(lo.iter().zip(&hi))
        .map(|(v, (l, h))| v.clamp(*l, *h))
        .collect();
    let nuisance = if calibration {
        let share = n as f64 / total.max(1) as f64;
        match Linearised::new(config, like, series, &rows, w_phi, share) {
            Ok(l) => Some(l),
            Err(_) => return (config.clone(), None),
        }
    } else {
        None
    };
    if let Some(l) = &nuisance {
        x0.resize(x0.len() + l.n(), 0.0);
        lo.resize(x0.len(), f64::NEG_INFINITY);
        hi.resize(x0.len(), f64::INFINITY);
    }
    let (at, stale) = linearisation_start(config, at, &slots);
    let friction = FrozenFriction::new(at, like, &slots, series, &rows);
    if stale && friction.is_some() {
        tracing::debug!("friction linearised on the geometry the calibration started from");
    }
    let mut p = Refit {
        base: config,
        like,
        slots,
        series,
        rows,
        n,
        w_phi,
        nuisance,
        states: series.iter().map(|_| Default::default()).collect(),
        friction,
    };
    // A relative cost change of 1e-6 is a change of chi^2 of about 0.01 on 3000 rows (three
    // coordinates each, at the noise): it moves no parameter by a tenth of its error, and the
    // default's 1e-8 took up to 23 evaluations of a loaded model where 7-13 reach this.
    // A search's refinement (no errors) ends where the cost stalls ([`STALL_STEPS`]). A step
    // refused whose actual and predicted gains are both within that tolerance ends it too
    // (MINPACK's test, `Options::ftol_refused`): at the optimum a loaded model's residuals,
    // solved from the last evaluation's equilibria, carry noise of some 1e-9 of the cost, and
    // SciPy's test refused step after step a quarter of the last (a frame's refinement on
    // springs + frame + backlash at 3x: eight refused steps of 1e-8 of the cost, 0.15 s).
    let opts = Options {
        max_evaluations,
        ftol: 1e-6,
        jacobian_at_end: at_optimum,
        initial_radius_factor: FIRST_RADIUS,
        stall_window: if at_optimum { 0 } else { STALL_STEPS },
        stall_ftol: STALL_FTOL,
        ftol_refused: true,
        secant_steps: SECANT_STEPS,
        ..Options::default()
    };
    let started = std::time::Instant::now();
    let mut fit = lsq::solve(&mut p, &x0, &lo, &hi, &opts);
    // The friction linearised at the start holds its path where the parameters that move the
    // curvatures left it (a play of 5.4 steps refined to 3 moves every reversal by more than a
    // step): linearised again where the refinement arrived and refined from there, while they
    // move.
    for _ in 0..FRICTION_RELINEARISATIONS {
        let Ok(f) = &fit else { break };
        let moved = p.friction.is_some()
            && p.slots.iter().enumerate().any(|(k, s)| {
                s.moves_curvatures && (f.x[k] - x0[k]).abs() > 1e-3 * x0[k].abs().max(1.0)
            });
        if !moved {
            break;
        }
        let here = p.config(&f.x);
        let Some(frozen) = p
            .friction
            .as_ref()
            .and_then(|fr| fr.again(&here, like, &p.slots, series, &p.rows, &f.x))
        else {
            break;
        };
        let start = f.x.clone();
        p.friction = Some(frozen);
        let again = lsq::solve(&mut p, &start, &lo, &hi, &opts);
        let done = again.as_ref().is_ok_and(|g| {
            p.slots.iter().enumerate().all(|(k, s)| {
                !s.moves_curvatures || (g.x[k] - start[k]).abs() <= 1e-3 * start[k].abs().max(1.0)
            })
        });
        fit = again;
        if done {
            break;
        }
    }
    tracing::debug!(
        rows = n,
        parameters = x0.len(),
        evaluations = fit.as_ref().map_or(0, |f| f.evaluations),
        jacobians = fit.as_ref().map_or(0, |f| f.jacobians),
        seconds = started.elapsed().as_secs_f64(),
        "joint refinement"
    );
    match fit {
        Ok(fit) => {
            let out = p.config(&fit.x);
            // The maps' coefficients move with the calibration parameters: a refinement that
            // turns a map back within the recordings' displacements (which the refined rows
            // need not show) is not taken ([`crate::nuisance::map_refusal`]).
            if let Some(why) = crate::nuisance::map_refusal(&out, series) {
                tracing::debug!(why, "joint refinement refused");
                return (config.clone(), None);
            }
            let errors = match errors {
                Errors::No => None,
                Errors::Approximate | Errors::AtOptimum => p.errors(&fit, blocks),
            };
            let errors = errors.map(|e| with_held(&held, &e));
            (out, errors)
        }
        Err(_) => (config.clone(), None),
    }
}

impl Refit<'_> {
    /// The standard errors of the effects' parameters at the solver's optimum `fit`
    /// ([`refine_with_errors`]).
    fn errors(&self, fit: &lsq::Fit, blocks: &Blocks) -> Option<Vec<f64>> {
        let (ne, nt) = (self.n_effects(), fit.x.len());
        let j = &fit.jacobian;
        if j.nrows() < 3 * self.n || j.ncols() != nt || fit.residuals.len() < 3 * self.n {
            return None;
        }
        // Per time block: J_b^T J_b and J_b^T r_b over its rows (r the optimum's residual),
        // the blocks in the order they first appear, each from its rows gathered (a product of
        // matrices, in parallel: on the final estimate's 66k residuals the rank-one updates row
        // by row took 0.1 s on one core).
        let mut order: Vec<usize> = Vec::new();
        let mut members: std::collections::HashMap<usize, Vec<usize>> =
            std::collections::HashMap::new();
        let mut k = 0;
        for (si, rows) in self.rows.iter().enumerate() {
            for &i in rows {
                let b = blocks.block[si][i];
                members
                    .entry(b)
                    .or_insert_with(|| {
                        order.push(b);
                        Vec::new()
                    })
                    .push(k);
                k += 1;
            }
        }
        let r = &fit.residuals;
        let rr: f64 = r[..3 * self.n].iter().map(|v| v * v).sum();
        let per: Vec<(nalgebra::DMatrix<f64>, nalgebra::DVector<f64>)> = order
            .par_iter()
            .map(|b| {
                let ks = &members[b];
                let jb = nalgebra::DMatrix::from_fn(3 * ks.len(), nt, |q, a| {
                    j[(3 * ks[q / 3] + q % 3, a)]
                });
                let rb = nalgebra::DVector::from_fn(3 * ks.len(), |q, _| r[3 * ks[q / 3] + q % 3]);
                (jb.tr_mul(&jb), jb.tr_mul(&rb))
            })
            .collect();
        let mut ata = nalgebra::DMatrix::<f64>::zeros(nt, nt);
        for (m, _) in &per {
            ata += m;
        }
        if let Some(l) = &self.nuisance {
            for (g, ps) in l.prior_sqrt.iter().enumerate() {
                ata[(ne + g, ne + g)] += ps * ps * crate::linear::PRIOR_IN_ERRORS;
            }
        }
        let (pinv, s) = crate::linear::scaled_pinv(&ata)?;
        let dof = (3 * self.n).saturating_sub(nt).max(1) as f64;
        let zero = nalgebra::DVector::zeros(nt);
        let std = crate::linear::standard_errors(&per, &pinv, &s, &zero, rr / dof);
        std.iter()
            .take(ne)
            .all(|v| v.is_finite())
            .then(|| std[..ne].to_vec())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pcr_robot::effects::{
        Backlash, Compliance, Creep, Drift, FrameCorrection, Latency, Periodic,
    };

    /// A latency of 10 ms, plays of 1 / 2 / 3 steps and drift rates of 4 / 5 / 6 um/s.
    fn latency_backlash_drift() -> Effects {
        Effects {
            latency: Some(Latency { latency_s: 0.01 }),
            backlash: Some(Backlash {
                steps: [1.0, 2.0, 3.0],
            }),
            drift: Some(Drift {
                rate_mm_per_s: [4e-3, 5e-3, 6e-3],
            }),
            ..Effects::default()
        }
    }

    /// The joints' pre-sliding travel is held while the joints do not rub, and only then: the
    /// other parameters are moved, and a held one's error is stated as none (zero) in
    /// [`values`]' order.
    #[test]
    fn the_joints_presliding_travel_is_held_while_they_do_not_rub() {
        let with = |joint_torque_n_mm: f64| {
            let mut e = latency_backlash_drift();
            e.friction = Some(pcr_robot::effects::Friction {
                joint_torque_n_mm,
                support_force_n: 0.12,
                joint_presliding_rad: 0.001,
                support_presliding_mm: 0.005,
                ei_n_mm2: 65000.0,
            });
            e
        };
        let n = slots(&with(0.0)).len();
        // Latency 1, plays 3, drift 3, friction 3 (the travel last).
        assert_eq!(n, 10);
        for torque in [0.0, 1e-25, 6e-4] {
            let h = held(&with(torque));
            assert_eq!(h.iter().filter(|&&x| x).count(), 1, "{torque}");
            assert!(h[n - 1], "{torque}: the travel held");
        }
        for torque in [0.2, 2.0] {
            assert!(held(&with(torque)).iter().all(|&x| !x), "{torque}");
        }
        let mut h = vec![false; n];
        h[n - 1] = true;
        let moved: Vec<f64> = (1..n).map(|k| k as f64).collect();
        let all = with_held(&h, &moved);
        assert_eq!(all[..n - 1], moved[..]);
        assert_eq!(all[n - 1], 0.0);
    }

    /// A refinement takes another geometry's linearisation of the friction only where that
    /// robot file differs from its own and holds the same values of the refined parameters (to
    /// the bit).
    #[test]
    fn a_linearisation_on_another_geometry_serves_only_the_same_values_and_is_stale() {
        let mut config = RobotConfig::nominal();
        config.effects = latency_backlash_drift();
        let slots = slots(&config.effects);
        let mut other = config.clone();
        other.legs[0].psi_deg += 0.3;
        let (at, stale) = linearisation_start(&config, Some(&other), &slots);
        assert!(std::ptr::eq(at, &other) && stale);
        // The same robot file, or none: its own, not stale.
        let same = config.clone();
        let (at, stale) = linearisation_start(&config, Some(&same), &slots);
        assert!(std::ptr::eq(at, &config) && !stale);
        let (at, stale) = linearisation_start(&config, None, &slots);
        assert!(std::ptr::eq(at, &config) && !stale);
        // Another value of a refined parameter (a play): its own.
        let mut moved = other.clone();
        (slots[1].set)(&mut moved.effects, slots[1].index, 9.5);
        let (at, stale) = linearisation_start(&config, Some(&moved), &slots);
        assert!(std::ptr::eq(at, &config) && !stale);
    }

    /// A linearisation of the friction by hand: slot 0 a friction value along the path (its
    /// column `col`), slots 1 and 2 parameters that move the path, one series of two rows.
    fn frozen(x0: [f64; 3], b: [[f64; 3]; 2], col: [f64; 3]) -> FrozenFriction {
        FrozenFriction {
            slots: vec![0],
            x0: vec![x0[0]],
            rows: vec![b.iter().map(|b| (*b, vec![col])).collect()],
            path_slots: vec![1, 2],
            path_x0: vec![x0[1], x0[2]],
            path: vec![vec![vec![[0.0; 3]; 2]; 2]],
        }
    }

    /// Broyden's update of the path's secants: linearised again at x1, the deflection predicts
    /// at the first linearisation's start what the first did there (the friction's tangent
    /// unchanged), along the path parameters' move and only along it; a second update keeps
    /// that for the move before it in the direction it shares; without a move the secants
    /// stay.
    #[test]
    fn the_friction_relinearised_keeps_the_deflection_it_had_where_it_was() {
        let col = [0.3, -0.2, 0.01];
        let x0 = [1.0, 2.0, 5.0];
        let old = frozen(x0, [[0.1, 0.2, 0.0], [-0.3, 0.05, 0.002]], col);
        let x1 = [1.5, 3.0, 4.0];
        // At x1 the deflection is not what the frozen one said: the path moved.
        let miss = [[0.04, -0.02, 0.001], [0.0, 0.07, -0.003]];
        let b1: [[f64; 3]; 2] = std::array::from_fn(|r| {
            let was = old.at(0, r, &x1);
            std::array::from_fn(|c| was[c] + miss[r][c])
        });
        let mut next = frozen(x1, b1, col);
        old.update_secants(&mut next, &x1);
        for r in 0..2 {
            // Exact at its own start, as the pass says.
            assert_eq!(next.at(0, r, &x1), b1[r]);
            // Back at x0: the first linearisation's deflection there.
            let back = next.at(0, r, &x0);
            for c in 0..3 {
                assert!(
                    (back[c] - old.at(0, r, &x0)[c]).abs() < 1e-14,
                    "row {r}: {back:?}"
                );
            }
            // Across the move (slot 2 moved by -1 for slot 1's +1): no slope.
            let across = [x1[0], x1[1] + 1.0, x1[2] + 1.0];
            for c in 0..3 {
                assert!((next.at(0, r, &across)[c] - b1[r][c]).abs() < 1e-14);
            }
        }
        // No move of the path: the secants carry over.
        let x2 = [2.0, x1[1], x1[2]];
        let mut still = frozen(x2, b1, col);
        next.update_secants(&mut still, &x2);
        assert_eq!(still.path, next.path);
        assert!(next.path[0][0][0] != [0.0; 3]);
    }

    /// The errors of the solver's parameters come out in the units the report gives, for the
    /// effect asked and no other: a drift rate is refined in mm per 1000 s and reported in mm/s,
    /// and its slots come after the latency's and the backlash's.
    #[test]
    fn the_refinements_errors_are_reported_in_the_effects_units() {
        let e = latency_backlash_drift();
        // latency, three plays, three rates.
        let sd = [0.001, 0.1, 0.2, 0.3, 0.5, 0.25, 2.0];
        let named = |n: &str| crate::effects::named(n).unwrap();
        let fitted = |n: &str| -> Vec<crate::fitted::Estimate> {
            named(n)
                .declared(&e, &[])
                .unwrap()
                .into_iter()
                .map(|p| crate::fitted::Estimate {
                    std: Some(1.0),
                    ..p
                })
                .collect()
        };
        let drift = reported_errors(&e, &sd, "drift", &fitted("drift"));
        assert_eq!(drift.len(), 3);
        for ((name, v), want) in drift.iter().zip([5e-4, 2.5e-4, 2e-3]) {
            assert!(name.starts_with("rate leg"), "{name}");
            assert!((v - want).abs() < 1e-12, "{name}: {v} against {want}");
        }
        let backlash = reported_errors(&e, &sd, "backlash", &fitted("backlash"));
        let values: Vec<f64> = backlash.iter().map(|x| x.1).collect();
        for (v, want) in values.iter().zip([0.1, 0.2, 0.3]) {
            assert!((v - want).abs() < 1e-12, "{values:?}");
        }
        // Too few errors for the effects declared, or an effect the file does not declare:
        // nothing.
        assert!(reported_errors(&e, &sd[..5], "drift", &fitted("drift")).is_empty());
        assert!(reported_errors(&e, &sd, "creep", &[]).is_empty());
    }

    #[test]
    fn the_parameters_are_in_the_robot_files_order() {
        let e = Effects {
            creep: Some(Creep {
                gain: [0.1, 0.2, 0.3],
                time_constant_s: 1.0,
            }),
            compliance: Some(Compliance {
                ei_n_mm2: 6.5e4,
                force_n: [7.0, 8.0],
                couple_n_mm: 900.0,
                k_m_n_mm_per_rad: 1000.0,
                k_p_n_mm_per_rad: 1100.0,
            }),
            frame: Some(FrameCorrection {
                dx_mm: 12.0,
                dy_mm: 13.0,
                dphi_deg: 14.0,
            }),
            periodic: vec![Periodic {
                motor: 1,
                period_steps: 16.0,
                amplitude_steps: 15.0,
                phase_deg: 16.0,
            }],
            ..latency_backlash_drift()
        };
        let values: Vec<f64> = slots(&e).iter().map(|s| (s.get)(&e, s.index)).collect();
        let expected = [
            0.01, 1.0, 2.0, 3.0, 0.1, 0.2, 0.3, 0.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0,
            12.0, 13.0, 14.0, 15.0, 16.0,
        ];
        assert_eq!(values.len(), expected.len());
        for (v, x) in values.iter().zip(expected) {
            assert!((v - x).abs() < 1e-12, "{values:?}");
        }
        // Springs or a wrench alone free only theirs.
        let springs = Effects {
            compliance: Some(Compliance {
                ei_n_mm2: 6.5e4,
                k_m_n_mm_per_rad: 100.0,
                ..Compliance::default()
            }),
            ..Effects::default()
        };
        assert_eq!(slots(&springs).len(), 2);
        assert!(slots(&Effects::default()).is_empty());
    }
    /// A parameter that says it leaves the curvatures alone (a load's, the frame's) leaves
    /// them the same to the bit, and every other one moves them: a refinement's Jacobian relies
    /// on it to skip the stages before the kinematics for the first.
    #[test]
    fn only_the_parameters_that_say_so_move_the_curvatures() {
        let mut cfg = RobotConfig::nominal();
        let home = pcr_kinematics::Robot::new(&cfg).unwrap().home_motor_steps();
        let mut rec = pcr_recording::Recording::default();
        for k in 0..200 {
            let t = k as f64 * 0.02;
            let q: [i32; 3] = std::array::from_fn(|i| {
                (home[i] + 80.0 * (0.9 * t + i as f64).sin()).round() as i32
            });
            let mut r = pcr_recording::Row::new(t, q);
            r.pose = [Some(0.0); 3];
            rec.rows.push(r);
        }
        let s = Series::from_recording(&rec, "t").unwrap();
        cfg.effects = Effects {
            creep: Some(Creep {
                gain: [0.1, 0.2, 0.3],
                time_constant_s: 1.0,
            }),
            compliance: Some(Compliance {
                ei_n_mm2: 6.5e4,
                force_n: [0.4, -0.3],
                couple_n_mm: 20.0,
                k_m_n_mm_per_rad: 300.0,
                k_p_n_mm_per_rad: 200.0,
            }),
            frame: Some(FrameCorrection {
                dx_mm: 0.2,
                dy_mm: -0.1,
                dphi_deg: 0.3,
            }),
            periodic: vec![Periodic {
                motor: 1,
                period_steps: 64.0,
                amplitude_steps: 2.0,
                phase_deg: 30.0,
            }],
            ..latency_backlash_drift()
        };
        let rows: Vec<usize> = (0..200).step_by(7).collect();
        let curvatures = |c: &RobotConfig| {
            let mut m = ExtendedModel::new(c, crate::effects::chain()).unwrap();
            m.interpolate = false;
            m.curvatures(&s, &rows)
        };
        let base = curvatures(&cfg);
        let all = slots(&cfg.effects);
        assert_eq!(all.iter().filter(|p| !p.moves_curvatures).count(), 8);
        for (n, p) in all.iter().enumerate() {
            let mut moved = cfg.clone();
            let v = (p.get)(&cfg.effects, p.index);
            (p.set)(&mut moved.effects, p.index, (v + 0.5).min(p.hi));
            let other = curvatures(&moved);
            if p.moves_curvatures {
                assert_ne!(other, base, "parameter {n} says it moves the curvatures");
            } else {
                assert_eq!(other, base, "parameter {n} says it leaves them");
            }
        }
    }
}
