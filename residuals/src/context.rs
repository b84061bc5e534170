//! The residuals of the current model on every measured row, with what the candidate effects
//! need to fit against them (the model's Jacobians at each row) and the held-out blocks.

use crate::interpolation::Interpolation;
use crate::model::{ExtendedModel, Prediction};
use crate::nuisance::{Nuisance, NuisanceTable};
use crate::series::{Blocks, Series};
use pcr_kinematics::friction::Friction;
use rayon::prelude::*;

/// Rows of one series solved in sequence, warm-started from the row before (a chunk each for
/// the threads).
const CHUNK: usize = 256;

/// One measured row with its residual.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowRef {
    /// Series index.
    pub s: usize,
    /// Row index in the series.
    pub k: usize,
    /// Block index.
    pub block: usize,
    /// Held out (scored, never fitted).
    pub held_out: bool,
    /// Residual measured - predicted: x mm, y mm, and phi as `w_phi * dphi` (mm).
    pub r: [f64; 3],
}

impl RowRef {
    /// A training row whose index is a multiple of `every` (of [`Context::training`]'s rows).
    pub fn in_training_subset(&self, every: usize) -> bool {
        in_training_subset(self.held_out, self.k, every)
    }
}

/// Whether row `k` (held out or not) is one of every `every` training rows.
fn in_training_subset(held_out: bool, k: usize, every: usize) -> bool {
    !held_out && k.is_multiple_of(every.max(1))
}

/// The residuals of one model.
#[derive(Debug, Clone)]
pub struct Context<'a> {
    /// The recordings.
    pub series: &'a [Series],
    /// The model.
    pub model: ExtendedModel,
    /// Its predictions, per series and row.
    pub preds: Vec<Vec<Prediction>>,
    /// Every measured row the model predicts.
    pub rows: Vec<RowRef>,
    /// Weight of the orientation residual, mm per rad (the platform joint radius).
    pub w_phi: f64,
    /// Rows the model could not predict (FK failed).
    pub unpredicted: usize,
    /// The calibration parameters' columns of every row, computed on first use.
    nuisance: std::sync::OnceLock<std::sync::Arc<NuisanceTable>>,
    /// The five load responses of every row, computed on first use, and how they were
    /// interpolated.
    loads: std::sync::OnceLock<LoadResponses>,
    /// Per series, the rigid pose and the curvatures of every row (the path the friction runs
    /// along), computed on first use.
    paths: std::sync::OnceLock<std::sync::Arc<Vec<Path>>>,
    /// The first friction tangent pass along [`Context::paths`] and the friction it was run at
    /// ([`Context::friction_tangents`]).
    friction_tangents: std::sync::OnceLock<(Friction, std::sync::Arc<Vec<Tangents>>)>,
}

/// A friction tangent pass along one series: per row, the deflection and its derivatives
/// ([`crate::model::ExtendedModel::friction_path_tangent`]).
pub type Tangents = Vec<Option<crate::model::DeflectionTangent>>;

/// The rigid pose (if any) and the curvatures of every row of one series.
pub type Path = (std::sync::Arc<crate::model::RigidPath>, Vec<[f64; 3]>);

/// The load responses of every row and how they were interpolated (`None`: every row solved,
/// the exact model).
type LoadResponses = (std::sync::Arc<Vec<[[f64; 3]; 5]>>, Option<Interpolation>);

/// Largest error of an interpolated load response, relative to the largest response of that
/// parameter over the rows solved ([`crate::interpolation`]); a stretch off by more is bisected.
pub const MAX_RESPONSE_ERROR: f64 = 0.005;

impl<'a> Context<'a> {
    /// Predicts every series with `model` and collects the residuals.
    pub fn new(series: &'a [Series], model: ExtendedModel, blocks: &Blocks, w_phi: f64) -> Self {
        Self::of_rows(series, model, blocks, w_phi, &|_, _| true, 0)
    }

    /// [`Context::new`] for a model that is only of use when it predicts at least `min_rows`
    /// rows: the prediction stops once it cannot (the context then holds fewer).
    pub fn at_least(
        series: &'a [Series],
        model: ExtendedModel,
        blocks: &Blocks,
        w_phi: f64,
        min_rows: usize,
    ) -> Self {
        Self::of_rows(series, model, blocks, w_phi, &|_, _| true, min_rows)
    }

    /// [`Context::new`] on every `every`-th training row of each series alone (row index a
    /// multiple of `every`): the other rows are neither predicted nor listed. For the steps of
    /// a search that compare training errors only. As [`Context::at_least`] `min_rows`.
    pub fn training(
        series: &'a [Series],
        model: ExtendedModel,
        blocks: &Blocks,
        w_phi: f64,
        every: usize,
        min_rows: usize,
    ) -> Self {
        let wanted = |si: usize, k: usize| {
            in_training_subset(blocks.held_out[blocks.block[si][k]], k, every)
        };
        Self::of_rows(series, model, blocks, w_phi, &wanted, min_rows)
    }

    /// [`Context::new`] on every held-out row and every `every`-th training row of each series
    /// (row index a multiple of `every`): for a comparison on the held-out rows whose
    /// linearised fits on the training rows need not see every one of them (rows 20 ms apart
    /// carry much the same residual). Its [`Context::training_subset`] of a multiple of
    /// `every` is that of the full context.
    pub fn thinned(
        series: &'a [Series],
        model: ExtendedModel,
        blocks: &Blocks,
        w_phi: f64,
        every: usize,
    ) -> Self {
        let wanted = |si: usize, k: usize| {
            let held_out = blocks.held_out[blocks.block[si][k]];
            held_out || in_training_subset(held_out, k, every)
        };
        Self::of_rows(series, model, blocks, w_phi, &wanted, 0)
    }

    /// [`Context::new`] on the held-out rows alone: the training rows are neither solved nor
    /// listed (their predictions carry the effective motor positions and tendon displacements
    /// only). For judging a model on the held-out rows. As [`Context::at_least`] `min_rows`.
    pub fn held_out(
        series: &'a [Series],
        model: ExtendedModel,
        blocks: &Blocks,
        w_phi: f64,
        min_rows: usize,
    ) -> Self {
        let wanted = |si: usize, k: usize| blocks.held_out[blocks.block[si][k]];
        Self::of_rows(series, model, blocks, w_phi, &wanted, min_rows)
    }

    /// Indices (into `rows`) of the training rows [`Context::training`] with `every` keeps.
    pub fn training_subset(&self, every: usize) -> Vec<usize> {
        (0..self.rows.len())
            .filter(|&i| self.rows[i].in_training_subset(every))
            .collect()
    }

    /// The rows of this context predicted by another model, in the same order with the same
    /// blocks (the held-out rows too); `None` when the model does not predict one of them (the
    /// prediction stops at the first: a model whose rigid kinematics do not close anywhere, a
    /// large linearised step of the calibration, cost 4 s of joint springs at 10x solving
    /// every row in vain).
    pub fn same_rows(&self, model: ExtendedModel) -> Option<Context<'a>> {
        let started = std::time::Instant::now();
        let mut want: Vec<Vec<bool>> = self
            .series
            .iter()
            .map(|s| vec![false; s.samples.len()])
            .collect();
        for r in &self.rows {
            want[r.s][r.k] = true;
        }
        let failures = std::sync::atomic::AtomicUsize::new(0);
        let preds: Vec<Vec<Prediction>> = self
            .series
            .iter()
            .zip(&want)
            .map(|(s, w)| {
                let how = crate::model::Solving {
                    failures: Some((&failures, 0)),
                    ..Default::default()
                };
                model.predict_where_from(s, &|k| w[k], how)
            })
            .collect();
        if failures.load(std::sync::atomic::Ordering::Relaxed) > 0 {
            tracing::debug!(
                seconds = started.elapsed().as_secs_f64(),
                "context on the same rows: a row is not predicted"
            );
            return None;
        }
        let mut rows = Vec::with_capacity(self.rows.len());
        for r in &self.rows {
            let m = self.series[r.s].samples[r.k].pose?;
            let p = preds[r.s][r.k].pose?;
            rows.push(RowRef {
                r: model.residual(m, p, self.w_phi),
                ..*r
            });
        }
        tracing::debug!(
            rows = rows.len(),
            seconds = started.elapsed().as_secs_f64(),
            "context predicted on the same rows"
        );
        Some(Context {
            series: self.series,
            model,
            preds,
            rows,
            w_phi: self.w_phi,
            unpredicted: self.unpredicted,
            nuisance: std::sync::OnceLock::new(),
            loads: std::sync::OnceLock::new(),
            paths: std::sync::OnceLock::new(),
            friction_tangents: std::sync::OnceLock::new(),
        })
    }

    /// The context of the `wanted` rows (series, row); the prediction stops once fewer than
    /// `min_rows` of them could be predicted.
    fn of_rows(
        series: &'a [Series],
        model: ExtendedModel,
        blocks: &Blocks,
        w_phi: f64,
        wanted: &(dyn Fn(usize, usize) -> bool + Sync),
        min_rows: usize,
    ) -> Self {
        let started = std::time::Instant::now();
        // The measured rows wanted: more failures than these less `min_rows` and the context
        // is of no use.
        let measured: usize = series
            .iter()
            .enumerate()
            .map(|(si, s)| {
                (0..s.samples.len())
                    .filter(|&k| s.samples[k].pose.is_some() && wanted(si, k))
                    .count()
            })
            .sum();
        let failures = std::sync::atomic::AtomicUsize::new(0);
        let how = crate::model::Solving {
            failures: (min_rows > 0).then_some((&failures, measured.saturating_sub(min_rows))),
            ..Default::default()
        };
        let preds: Vec<Vec<Prediction>> = series
            .iter()
            .enumerate()
            .map(|(si, s)| {
                // A row without a measurement is not counted.
                model.predict_where_from(s, &|k| wanted(si, k), how)
            })
            .collect();
        let mut rows = Vec::new();
        let mut unpredicted = 0;
        for (si, s) in series.iter().enumerate() {
            for (k, smp) in s.samples.iter().enumerate() {
                let Some(m) = smp.pose else { continue };
                if !wanted(si, k) {
                    continue;
                }
                let Some(p) = preds[si][k].pose else {
                    unpredicted += 1;
                    continue;
                };
                let b = blocks.block[si][k];
                rows.push(RowRef {
                    s: si,
                    k,
                    block: b,
                    held_out: blocks.held_out[b],
                    r: model.residual(m, p, w_phi),
                });
            }
        }
        tracing::debug!(
            rows = rows.len(),
            held_out_too = rows.iter().any(|r| r.held_out),
            loaded = model.loads.is_some(),
            seconds = started.elapsed().as_secs_f64(),
            "context predicted"
        );
        Context {
            series,
            model,
            preds,
            rows,
            w_phi,
            unpredicted,
            nuisance: std::sync::OnceLock::new(),
            loads: std::sync::OnceLock::new(),
            paths: std::sync::OnceLock::new(),
            friction_tangents: std::sync::OnceLock::new(),
        }
    }

    /// The rows' configuration (each segment's bending, rad) and where a new series breaks
    /// the path: what [`crate::interpolation::interpolate`] interpolates along.
    fn configuration_path(&self) -> (Vec<[f64; 3]>, Vec<bool>) {
        let lc: [f64; 3] = std::array::from_fn(|i| self.model.robot.legs[i].l_c);
        let cfg: Vec<[f64; 3]> = self
            .rows
            .iter()
            .map(|r| {
                let k = self.pred(r).kappa;
                std::array::from_fn(|l| k[l] * lc[l])
            })
            .collect();
        let breaks: Vec<bool> = (0..self.rows.len())
            .map(|i| i > 0 && self.rows[i].s != self.rows[i - 1].s)
            .collect();
        (cfg, breaks)
    }

    /// The rigid model's nuisance columns of every row ([`Nuisance::columns`]).
    fn rigid_nuisance(&self, nui: &Nuisance) -> Vec<Vec<[f64; 3]>> {
        (0..self.rows.len())
            .into_par_iter()
            .map(|i| {
                let mut c = vec![[0.0; 3]; nui.n];
                nui.columns(
                    &self.model.robot,
                    self.pred(&self.rows[i]),
                    self.w_phi,
                    &mut c,
                );
                c
            })
            .collect()
    }

    /// The nuisance columns of every row under the loads of a loaded model
    /// ([`crate::nuisance::LoadedChanges`]); `None` for a model without loads. An exact model
    /// solves them at every row; otherwise the rigid columns are computed at every row and the
    /// loads' change of them is interpolated along the configuration
    /// ([`crate::interpolation::interpolate`]), each stretch checked to
    /// [`MAX_RESPONSE_ERROR`] of the largest loaded column of its parameter.
    fn loaded_nuisance(&self, nui: &Nuisance) -> Option<Vec<Vec<[f64; 3]>>> {
        let loads = self.model.loads.filter(|l| !l.is_unloaded())?;
        let started = std::time::Instant::now();
        let changes = nui.loaded_changes(&self.model.config, &self.model.robot, loads)?;
        let n = nui.n;
        let solve_rows = |idx: &[usize]| -> Vec<Option<Vec<[f64; 3]>>> {
            let parts: Vec<Vec<Option<Vec<[f64; 3]>>>> = self
                .chunks(idx)
                .par_iter()
                .map(|c| {
                    let mut warm = pcr_kinematics::statics::LoadedWarm::default();
                    c.iter()
                        .map(|&i| {
                            let mut col = vec![[0.0; 3]; n];
                            nui.loaded_columns(
                                &changes,
                                self.pred(&self.rows[i]),
                                self.w_phi,
                                &mut warm,
                                &mut col,
                            )
                            .then_some(col)
                        })
                        .collect()
                })
                .collect();
            parts.into_iter().flatten().collect()
        };
        let rigid = self.rigid_nuisance(nui);
        if self.model.exact {
            // Every row solved; a row whose equilibrium is not found keeps its rigid columns,
            // as an interpolated one does.
            let all: Vec<usize> = (0..self.rows.len()).collect();
            let cols = solve_rows(&all)
                .into_iter()
                .zip(rigid)
                .map(|(c, r)| c.unwrap_or(r))
                .collect();
            return Some(cols);
        }
        let (cfg, breaks) = self.configuration_path();
        // The largest loaded column of each parameter over the rows solved so far.
        let scale = std::cell::RefCell::new(vec![0.0f64; n]);
        let mut solve = |idx: &[usize]| -> Vec<Option<Vec<f64>>> {
            let solved = solve_rows(idx);
            let mut sc = scale.borrow_mut();
            idx.iter()
                .zip(solved)
                .map(|(&i, c)| {
                    let c = c?;
                    for (s, col) in sc.iter_mut().zip(&c) {
                        *s = s.max(col.iter().map(|v| v * v).sum::<f64>().sqrt());
                    }
                    // The loads' change of the rigid columns.
                    Some(
                        c.iter()
                            .zip(&rigid[i])
                            .flat_map(|(l, r)| (0..3).map(move |k| l[k] - r[k]))
                            .collect(),
                    )
                })
                .collect()
        };
        let within = |a: &Vec<f64>, b: &Vec<f64>| {
            let sc = scale.borrow();
            (0..n).all(|j| {
                let e = (0..3)
                    .map(|c| (a[3 * j + c] - b[3 * j + c]).powi(2))
                    .sum::<f64>();
                e.sqrt() <= MAX_RESPONSE_ERROR * sc[j]
            })
        };
        let (vals, st) =
            crate::interpolation::interpolate::<Vec<f64>>(&cfg, &breaks, &mut solve, &within);
        let cols = vals
            .into_iter()
            .zip(rigid)
            .map(|(v, mut r)| {
                if let Some(v) = v {
                    for (j, c) in r.iter_mut().enumerate() {
                        for k in 0..3 {
                            c[k] += v[3 * j + k];
                        }
                    }
                }
                r
            })
            .collect();
        tracing::debug!(
            "loaded nuisance columns: {} of {} rows solved ({} anchors, {} checks, {} bisected) in {:.3} s",
            st.solved,
            st.rows,
            st.anchors,
            st.checked,
            st.bisected,
            started.elapsed().as_secs_f64()
        );
        Some(cols)
    }

    /// `idx` (row indices, ascending) cut into chunks of at most [`CHUNK`] consecutive rows of
    /// one series.
    fn chunks<'i>(&self, idx: &'i [usize]) -> Vec<&'i [usize]> {
        let mut chunks: Vec<&[usize]> = Vec::new();
        let mut start = 0;
        for k in 1..=idx.len() {
            if k == idx.len()
                || k - start == CHUNK
                || self.rows[idx[k]].s != self.rows[idx[start]].s
            {
                chunks.push(&idx[start..k]);
                start = k;
            }
        }
        chunks
    }

    /// Takes the nuisance columns of `other` for this context's, where both hold the same
    /// rows with the same calibration parameters (a Gauss-Newton step's model after the one
    /// before it: the columns at the step's start, as a chord method keeps its Jacobian).
    /// Nothing changes when the rows or the parameters differ, or when this context has
    /// computed its own.
    pub fn reuse_nuisance_of(&self, other: &Context) {
        let (Some(table), true) = (other.nuisance.get(), self.rows.len() == other.rows.len())
        else {
            return;
        };
        let same_rows = self
            .rows
            .iter()
            .zip(&other.rows)
            .all(|(a, b)| a.s == b.s && a.k == b.k);
        if same_rows && table.nui.same_parameters(&self.model.config) {
            let _ = self.nuisance.set(table.clone());
        }
    }

    /// Per series, the rigid pose and the curvatures of every row of the context's model
    /// ([`ExtendedModel::rigid_path`]; computed once per context): the path its friction runs
    /// along.
    pub fn paths(&self) -> std::sync::Arc<Vec<Path>> {
        self.paths
            .get_or_init(|| {
                std::sync::Arc::new(
                    self.series
                        .par_iter()
                        .zip(&self.preds)
                        .map(|(s, p)| {
                            let kappa: Vec<[f64; 3]> = p.iter().map(|x| x.kappa).collect();
                            (self.model.rigid_path(s, &kappa), kappa)
                        })
                        .collect(),
                )
            })
            .clone()
    }

    /// The friction tangent pass at `f` along every series' path ([`Context::paths`]), by
    /// `run`; the first pass a context runs is kept and given again at the same friction (the
    /// consistency check fits both parts of the data from the whole fit's values, in one
    /// context).
    pub fn friction_tangents(
        &self,
        f: &Friction,
        run: impl FnOnce() -> Vec<Tangents>,
    ) -> std::sync::Arc<Vec<Tangents>> {
        if let Some((g, t)) = self.friction_tangents.get() {
            if g == f {
                return t.clone();
            }
            return std::sync::Arc::new(run());
        }
        let t = std::sync::Arc::new(run());
        let _ = self.friction_tangents.set((*f, t.clone()));
        t
    }

    /// The nuisance columns of every row (computed once per context).
    pub fn nuisance(&self) -> std::sync::Arc<NuisanceTable> {
        self.nuisance
            .get_or_init(|| {
                let nui = Nuisance::of(&self.model.config);
                if let Some(cols) = self.loaded_nuisance(&nui) {
                    return std::sync::Arc::new(NuisanceTable::new(nui, cols));
                }
                let cols = self.rigid_nuisance(&nui);
                std::sync::Arc::new(NuisanceTable::new(nui, cols))
            })
            .clone()
    }

    /// The first-order responses of every row's pose to the five load parameters at `loads`
    /// (computed once per context; the loads are those of the context's model): solved at
    /// every row for an exact model, interpolated along the configuration otherwise
    /// ([`Context::interpolated_load_responses`]).
    pub fn load_responses(
        &self,
        loads: &pcr_kinematics::statics::Loads,
    ) -> std::sync::Arc<Vec<[[f64; 3]; 5]>> {
        self.loads
            .get_or_init(|| {
                if self.model.exact {
                    let exact = |i: usize| self.load_response_at(i, loads);
                    return (
                        std::sync::Arc::new(
                            (0..self.rows.len()).into_par_iter().map(exact).collect(),
                        ),
                        None,
                    );
                }
                let (resp, st) = self.interpolated_load_responses(loads);
                tracing::debug!(
                    "load responses: {} of {} rows solved ({} anchors, {} checks, {} bisected)",
                    st.solved,
                    st.rows,
                    st.anchors,
                    st.checked,
                    st.bisected
                );
                (std::sync::Arc::new(resp), Some(st))
            })
            .0
            .clone()
    }

    /// How the load responses of this context were interpolated (`None` before they are
    /// computed, or when every row was solved).
    pub fn load_response_check(&self) -> Option<Interpolation> {
        self.loads.get().and_then(|l| l.1)
    }

    /// Row `i`'s curvatures and predicted pose, the start of its loaded equilibrium (`None`
    /// when the model could not predict it).
    fn loaded_start(&self, i: usize) -> Option<([f64; 3], pcr_kinematics::Pose)> {
        let p = self.pred(&self.rows[i]);
        let pose = p.pose?;
        Some((
            p.kappa,
            pcr_kinematics::Pose::new(pose[0], pose[1], pose[2]),
        ))
    }

    /// The load response of row `i`, solved.
    fn load_response_at(&self, i: usize, loads: &pcr_kinematics::statics::Loads) -> [[f64; 3]; 5] {
        self.loaded_start(i)
            .and_then(|(kappa, guess)| self.model.robot.load_response(&kappa, loads, &guess).ok())
            .unwrap_or([[0.0; 3]; 5])
    }

    /// The load responses of the rows `idx` (in row order), solved: in chunks of consecutive
    /// rows of one series, each warm-started along the chunk
    /// ([`pcr_kinematics::Robot::load_response_warm`]), the chunks in parallel.
    fn load_responses_warm(
        &self,
        idx: &[usize],
        loads: &pcr_kinematics::statics::Loads,
    ) -> Vec<[[f64; 3]; 5]> {
        let chunks = self.chunks(idx);
        let parts: Vec<Vec<[[f64; 3]; 5]>> = chunks
            .par_iter()
            .map(|c| {
                let mut warm = pcr_kinematics::statics::LoadedWarm::default();
                c.iter()
                    .map(|&i| {
                        self.loaded_start(i)
                            .and_then(|(kappa, guess)| {
                                self.model
                                    .robot
                                    .load_response_warm(&kappa, loads, &guess, &mut warm)
                                    .ok()
                            })
                            .unwrap_or([[0.0; 3]; 5])
                    })
                    .collect()
            })
            .collect();
        parts.concat()
    }

    /// The load responses interpolated along the configuration of the rows
    /// ([`crate::interpolation::interpolate`]: solved at the anchors of its path and at the
    /// middle of every stretch between them, a stretch bisected where the interpolation is off
    /// by more than [`MAX_RESPONSE_ERROR`] of the largest response of a parameter).
    fn interpolated_load_responses(
        &self,
        loads: &pcr_kinematics::statics::Loads,
    ) -> (Vec<[[f64; 3]; 5]>, Interpolation) {
        let (cfg, breaks) = self.configuration_path();
        // The largest response of each parameter over the rows solved so far.
        let scale = std::cell::Cell::new([0.0f64; 5]);
        let flat = |r: &[[f64; 3]; 5]| -> [f64; 15] { std::array::from_fn(|j| r[j / 3][j % 3]) };
        let mut solve = |idx: &[usize]| -> Vec<Option<[f64; 15]>> {
            let have: Vec<usize> = idx
                .iter()
                .copied()
                .filter(|&i| self.pred(&self.rows[i]).pose.is_some())
                .collect();
            let solved = self.load_responses_warm(&have, loads);
            let mut sc = scale.get();
            for r in &solved {
                for (s, c) in sc.iter_mut().zip(r) {
                    *s = s.max(c.iter().map(|v| v * v).sum::<f64>().sqrt());
                }
            }
            scale.set(sc);
            let mut it = solved.iter();
            idx.iter()
                .map(|&i| {
                    self.pred(&self.rows[i])
                        .pose
                        .and_then(|_| it.next().map(flat))
                })
                .collect()
        };
        let within = |a: &[f64; 15], b: &[f64; 15]| {
            let sc = scale.get();
            (0..5).all(|j| {
                let e = (0..3)
                    .map(|c| (a[3 * j + c] - b[3 * j + c]).powi(2))
                    .sum::<f64>();
                e.sqrt() <= MAX_RESPONSE_ERROR * sc[j]
            })
        };
        let (vals, st) =
            crate::interpolation::interpolate::<[f64; 15]>(&cfg, &breaks, &mut solve, &within);
        let out = vals
            .into_iter()
            .map(|v| {
                v.map_or([[0.0; 3]; 5], |v| {
                    std::array::from_fn(|j| std::array::from_fn(|c| v[3 * j + c]))
                })
            })
            .collect();
        (out, st)
    }

    /// The prediction of a row.
    pub fn pred(&self, r: &RowRef) -> &Prediction {
        &self.preds[r.s][r.k]
    }

    /// Indices (into `rows`) of the training rows.
    pub fn train(&self) -> Vec<usize> {
        (0..self.rows.len())
            .filter(|&i| !self.rows[i].held_out)
            .collect()
    }

    /// Indices of the held-out rows.
    pub fn test(&self) -> Vec<usize> {
        (0..self.rows.len())
            .filter(|&i| self.rows[i].held_out)
            .collect()
    }

    /// Sum of squared residuals over some rows, after subtracting `delta` (a candidate's
    /// predicted residual change, or none).
    pub fn sse(&self, idx: &[usize], delta: Option<&[[f64; 3]]>) -> f64 {
        idx.iter()
            .map(|&i| {
                let r = self.rows[i].r;
                let d = delta.map_or([0.0; 3], |d| d[i]);
                (r[0] - d[0]).powi(2) + (r[1] - d[1]).powi(2) + (r[2] - d[2]).powi(2)
            })
            .sum()
    }
}

/// Errors of a model on a set of rows: the figures of `before` / `after`.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Errors {
    /// Rows.
    pub rows: usize,
    /// Mean position error, mm.
    pub position_mean_mm: f64,
    /// Largest position error, mm.
    pub position_max_mm: f64,
    /// RMS position error, mm.
    pub position_rms_mm: f64,
    /// RMS orientation error, deg.
    pub orientation_rms_deg: f64,
}

impl Errors {
    /// The errors of the rows `idx` of a context.
    pub fn of(ctx: &Context, idx: &[usize]) -> Errors {
        let mut e = Errors {
            rows: idx.len(),
            ..Errors::default()
        };
        if idx.is_empty() {
            return e;
        }
        let (mut s, mut s2, mut o2) = (0.0, 0.0, 0.0);
        for &i in idx {
            let r = ctx.rows[i].r;
            let d = r[0].hypot(r[1]);
            s += d;
            s2 += d * d;
            o2 += (r[2] / ctx.w_phi).to_degrees().powi(2);
            e.position_max_mm = e.position_max_mm.max(d);
        }
        let n = idx.len() as f64;
        e.position_mean_mm = s / n;
        e.position_rms_mm = (s2 / n).sqrt();
        e.orientation_rms_deg = (o2 / n).sqrt();
        e
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use pcr_robot::RobotConfig;

    /// A recording of `n` rows 20 ms apart of the nominal robot: the motors at `q(k, t, home)`,
    /// measured at `pose(t)`.
    fn series_of(
        n: usize,
        q: impl Fn(usize, f64, &[f64; 3]) -> [i32; 3],
        pose: impl Fn(f64) -> [Option<f64>; 3],
    ) -> Vec<Series> {
        let robot = pcr_kinematics::Robot::new(&RobotConfig::nominal()).unwrap();
        let home = robot.home_motor_steps();
        let mut rec = pcr_recording::Recording::default();
        for k in 0..n {
            let t = k as f64 * 0.02;
            let mut r = pcr_recording::Row::new(t, q(k, t, &home));
            r.pose = pose(t);
            rec.rows.push(r);
        }
        vec![Series::from_recording(&rec, "t").unwrap()]
    }

    /// 403 rows of the three motors swinging around home, measured a little off the model's
    /// poses, so that every residual differs.
    pub(crate) fn moving_series() -> Vec<Series> {
        series_of(
            403,
            |_, t, home| {
                std::array::from_fn(|i| {
                    (home[i] + 60.0 * (0.7 * t + i as f64).sin()).round() as i32
                })
            },
            |t| {
                [
                    Some(0.1 * (3.0 * t).sin()),
                    Some(0.05 * t),
                    Some(0.001 * (5.0 * t).cos()),
                ]
            },
        )
    }

    /// The acceptance compares the training error of a context made on every fourth training
    /// row ([`Context::training`]) with that of a full context cut down to the same rows
    /// ([`Context::training_subset`]): both must hold the same
    /// rows with the same residuals, and no held-out row.
    #[test]
    fn a_training_context_on_every_fourth_row_is_the_full_context_cut_down() {
        let cfg = RobotConfig::nominal();
        let series = moving_series();
        let blocks = Blocks::in_time(&series, 1.0, 3);
        assert!(blocks.held_out.iter().any(|&h| h));
        let model = ExtendedModel::new(&cfg, crate::effects::chain()).unwrap();
        let full = Context::new(&series, model.clone(), &blocks, 50.0);
        let thin = Context::training(&series, model, &blocks, 50.0, 4, 0);
        let cut = full.training_subset(4);
        assert!(!thin.rows.is_empty() && thin.rows.len() < full.train().len() / 3);
        // The same rows; the residuals to the forward kinematics' tolerance (each solve is
        // started from the row solved before it, which differs).
        assert_eq!(thin.rows.len(), cut.len());
        for (a, b) in thin.rows.iter().zip(cut.iter().map(|&i| &full.rows[i])) {
            assert_eq!(
                (a.s, a.k, a.block, a.held_out),
                (b.s, b.k, b.block, b.held_out)
            );
            assert!(!a.held_out && a.k % 4 == 0);
            for c in 0..3 {
                assert!((a.r[c] - b.r[c]).abs() < 1e-9, "{a:?} {b:?}");
            }
        }
        let sse = thin.sse(&thin.train(), None);
        assert!(sse > 0.0);
        assert!((full.sse(&cut, None) - sse).abs() < 1e-9 * sse);
    }

    /// The backward pass compares models on a context of every held-out row and every second
    /// training row ([`Context::thinned`]): those rows of the full context with their
    /// residuals, and the acceptance's subset of it is the full context's.
    #[test]
    fn a_thinned_context_holds_every_held_out_row_and_every_second_training_row() {
        let cfg = RobotConfig::nominal();
        let series = moving_series();
        let blocks = Blocks::in_time(&series, 1.0, 3);
        let model = ExtendedModel::new(&cfg, crate::effects::chain()).unwrap();
        let full = Context::new(&series, model.clone(), &blocks, 50.0);
        let thin = Context::thinned(&series, model, &blocks, 50.0, 2);
        let kept: Vec<&RowRef> = full
            .rows
            .iter()
            .filter(|r| r.held_out || r.k % 2 == 0)
            .collect();
        assert!(kept.len() < full.rows.len() && !full.test().is_empty());
        assert_eq!(thin.rows.len(), kept.len());
        for (a, b) in thin.rows.iter().zip(kept) {
            assert_eq!((a.k, a.block, a.held_out), (b.k, b.block, b.held_out));
            for c in 0..3 {
                assert!((a.r[c] - b.r[c]).abs() < 1e-9, "{a:?} {b:?}");
            }
        }
        assert_eq!(thin.test().len(), full.test().len());
        let sub: Vec<usize> = thin.training_subset(4);
        let full_sub: Vec<usize> = full.training_subset(4);
        assert_eq!(sub.len(), full_sub.len());
        assert!(sub
            .iter()
            .zip(&full_sub)
            .all(|(&i, &j)| thin.rows[i].k == full.rows[j].k));
    }

    /// What the fits of a compliance read of a context that every fit on it shares, the
    /// nuisance columns and the load responses, is computed by [`crate::effects::Effect::share`]
    /// before the fits (which run in parallel on it), and a fit then reads those: the same fit
    /// as on a context that computes them itself.
    #[test]
    fn a_compliance_shares_its_nuisance_and_load_responses_before_its_fits() {
        let mut cfg = RobotConfig::nominal();
        cfg.effects.compliance = Some(pcr_robot::effects::Compliance {
            ei_n_mm2: 6.5e4,
            force_n: [0.4, -0.3],
            couple_n_mm: 0.0,
            k_m_n_mm_per_rad: 0.0,
            k_p_n_mm_per_rad: 0.0,
        });
        let series = moving_series();
        let blocks = Blocks::in_time(&series, 1.0, 3);
        let model = ExtendedModel::new(&cfg, crate::effects::chain()).unwrap();
        let shared = Context::new(&series, model.clone(), &blocks, 50.0);
        let alone = Context::new(&series, model, &blocks, 50.0);
        assert!(shared.nuisance.get().is_none() && shared.load_response_check().is_none());
        let load = crate::effects::named("external_load").unwrap();
        load.share(&shared);
        assert!(shared.nuisance.get().is_some() && shared.load_response_check().is_some());
        let train = shared.train();
        let a = load.fit(&shared, &train).unwrap();
        let b = load.fit(&alone, &train).unwrap();
        assert_eq!(a.train_sse, b.train_sse);
        for (p, q) in a.params.iter().zip(&b.params) {
            assert_eq!((&p.name, p.value, p.std), (&q.name, q.value, q.std));
        }
    }

    /// A context that must hold at least so many rows stops predicting once it cannot
    /// ([`Context::at_least`]), and holds every row it can where it can.
    #[test]
    fn a_context_that_cannot_hold_enough_rows_stops_predicting() {
        let cfg = RobotConfig::nominal();
        // 100 rows the robot cannot reach (the motors far beyond any curvature the legs take),
        // then 100 it can.
        let series = series_of(
            200,
            |k, t, home| {
                let far = if k < 100 { 1e7 } else { 0.0 };
                std::array::from_fn(|i| {
                    (home[i] + far + 40.0 * (0.7 * t + i as f64).sin()).round() as i32
                })
            },
            |_| [Some(0.0); 3],
        );
        let blocks = Blocks::in_time(&series, 1.0, 3);
        let model = ExtendedModel::new(&cfg, crate::effects::chain()).unwrap();
        let full = Context::new(&series, model.clone(), &blocks, 50.0);
        assert_eq!((full.rows.len(), full.unpredicted), (100, 100));
        // Enough rows: the same context.
        let enough = Context::at_least(&series, model.clone(), &blocks, 50.0, 100);
        assert_eq!(enough.rows.len(), 100);
        for (a, b) in enough.rows.iter().zip(&full.rows) {
            assert_eq!((a.s, a.k, a.r), (b.s, b.k, b.r));
        }
        // One more than it can hold: it stops after the 100 failures, before the rows it could
        // have predicted.
        let short = Context::at_least(&series, model.clone(), &blocks, 50.0, 101);
        assert!(short.rows.is_empty(), "{}", short.rows.len());
        // The same rows predicted by a model that fails on one of them: none.
        assert!(full.same_rows(model.clone()).is_some());
        let mut all = Context::new(&series, model.clone(), &blocks, 50.0);
        all.rows.push(RowRef {
            k: 0,
            ..all.rows[0]
        });
        assert!(all.same_rows(model).is_none());
    }
}
