//! The residuals of the current model on every measured row, with what the candidate effects
//! need to fit against them (the model's Jacobians at each row) and the held-out blocks.

use crate::model::{ExtendedModel, Prediction};
use crate::nuisance::{Nuisance, NuisanceTable};
use crate::series::{Blocks, Series};
use rayon::prelude::*;

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
}

/// The load responses of every row and how they were interpolated (`None`: every row solved).
type LoadResponses = (std::sync::Arc<Vec<[[f64; 3]; 5]>>, Option<ResponseCheck>);

/// Largest change of a segment's bending (rad) between two anchor rows of the load responses.
pub const ANCHOR_BENDING_RAD: f64 = 0.05;

/// Largest distance (a segment's bending, rad) of a row's configuration from the chord between
/// the anchors it is interpolated between.
pub const ANCHOR_DEVIATION_RAD: f64 = 0.002;

/// Every this many interpolated rows, one is solved to measure the interpolation error.
pub const CHECK_EVERY: usize = 25;

/// Largest relative error of the interpolated load responses on the check sample (against the
/// largest response of each parameter); above it, every row is solved.
pub const MAX_RESPONSE_ERROR: f64 = 0.02;

/// The interpolation of the load responses, measured.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ResponseCheck {
    /// Rows solved as anchors.
    pub anchors: usize,
    /// Interpolated rows solved to check the interpolation.
    pub checked: usize,
    /// Rows solved in all.
    pub solved: usize,
    /// Largest error of an interpolated response on the check sample, relative to the largest
    /// response of that parameter.
    pub max_relative_error: f64,
}

impl<'a> Context<'a> {
    /// Predicts every series with `model` and collects the residuals.
    pub fn new(series: &'a [Series], model: ExtendedModel, blocks: &Blocks, w_phi: f64) -> Self {
        Self::of_rows(series, model, blocks, w_phi, true)
    }

    /// [`Context::new`] on the training rows alone: the held-out rows are neither predicted nor
    /// listed. For the steps of a search that compare training errors only.
    pub fn training(
        series: &'a [Series],
        model: ExtendedModel,
        blocks: &Blocks,
        w_phi: f64,
    ) -> Self {
        Self::of_rows(series, model, blocks, w_phi, false)
    }

    fn of_rows(
        series: &'a [Series],
        model: ExtendedModel,
        blocks: &Blocks,
        w_phi: f64,
        held_out_too: bool,
    ) -> Self {
        let wanted = |si: usize, k: usize| held_out_too || !blocks.held_out[blocks.block[si][k]];
        let preds: Vec<Vec<Prediction>> = series
            .iter()
            .enumerate()
            .map(|(si, s)| model.predict_where(s, &|k| wanted(si, k)))
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
                let m = model.corrected(m);
                let dphi = wrap(m[2] - p[2]);
                let b = blocks.block[si][k];
                rows.push(RowRef {
                    s: si,
                    k,
                    block: b,
                    held_out: blocks.held_out[b],
                    r: [m[0] - p[0], m[1] - p[1], w_phi * dphi],
                });
            }
        }
        Context {
            series,
            model,
            preds,
            rows,
            w_phi,
            unpredicted,
            nuisance: std::sync::OnceLock::new(),
            loads: std::sync::OnceLock::new(),
        }
    }

    /// The nuisance columns of every row (computed once per context).
    pub fn nuisance(&self) -> std::sync::Arc<NuisanceTable> {
        self.nuisance
            .get_or_init(|| {
                let nui = Nuisance::of(&self.model.config);
                let cols = (0..self.rows.len())
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
                    .collect();
                std::sync::Arc::new(NuisanceTable::new(nui, cols))
            })
            .clone()
    }

    /// The first-order responses of every row's pose to the five load parameters at `loads`
    /// (computed once per context; the loads are those of the context's model).
    pub fn load_responses(
        &self,
        loads: &pcr_kinematics::statics::Loads,
    ) -> std::sync::Arc<Vec<[[f64; 3]; 5]>> {
        self.loads
            .get_or_init(|| {
                let exact = |i: usize| self.load_response_at(i, loads);
                if self.model.exact {
                    return (
                        std::sync::Arc::new((0..self.rows.len()).into_par_iter().map(exact).collect()),
                        None,
                    );
                }
                let (resp, check) = self.interpolated_load_responses(loads);
                match check {
                    Some(c) if c.max_relative_error <= MAX_RESPONSE_ERROR => {
                        tracing::debug!(
                            "load responses: {} of {} rows solved ({} anchors, {} checks), \
                             largest relative interpolation error {:.2e}",
                            c.solved,
                            self.rows.len(),
                            c.anchors,
                            c.checked,
                            c.max_relative_error
                        );
                        (std::sync::Arc::new(resp), Some(c))
                    }
                    _ => {
                        tracing::debug!(
                            "load responses: interpolation error {:?} above {MAX_RESPONSE_ERROR}, every row solved",
                            check.map(|c| c.max_relative_error)
                        );
                        (
                            std::sync::Arc::new(
                                (0..self.rows.len()).into_par_iter().map(exact).collect(),
                            ),
                            None,
                        )
                    }
                }
            })
            .0
            .clone()
    }

    /// How the load responses of this context were interpolated (`None` before they are
    /// computed, or when every row was solved).
    pub fn load_response_check(&self) -> Option<ResponseCheck> {
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
        const CHUNK: usize = 256;
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

    /// The load responses solved at anchor rows (the first row of every series and every row
    /// whose segments' bending differs from the last anchor's by more than
    /// [`ANCHOR_BENDING_RAD`]) and interpolated between consecutive anchors along the
    /// configuration (the projection of a row's curvatures on the segment between the two
    /// anchors'); rows with the same curvatures as an anchor take its response. The error of
    /// the interpolation is measured on a check sample of the other rows, solved.
    fn interpolated_load_responses(
        &self,
        loads: &pcr_kinematics::statics::Loads,
    ) -> (Vec<[[f64; 3]; 5]>, Option<ResponseCheck>) {
        let n = self.rows.len();
        let lc: [f64; 3] = std::array::from_fn(|i| self.model.robot.legs[i].l_c);
        let kappa = |i: usize| self.pred(&self.rows[i]).kappa;
        let bending = |a: &[f64; 3], b: &[f64; 3]| {
            (0..3)
                .map(|l| ((a[l] - b[l]) * lc[l]).abs())
                .fold(0.0, f64::max)
        };
        // Anchors: the first and last row of every series, then, between consecutive anchors,
        // the row farthest (in bending) from where the interpolation would put it, until every
        // row is within ANCHOR_DEVIATION_RAD of the chord between its anchors and no chord is
        // longer than ANCHOR_BENDING_RAD (the path of the configuration simplified to a
        // polyline, Douglas-Peucker).
        let mut anchor = vec![false; n];
        let mut stack: Vec<(usize, usize)> = Vec::new();
        let mut first = 0usize;
        for i in 0..n {
            if i + 1 == n || self.rows[i + 1].s != self.rows[i].s {
                anchor[first] = true;
                anchor[i] = true;
                if i > first + 1 {
                    stack.push((first, i));
                }
                first = i + 1;
            }
        }
        let chord_t = |a: usize, b: usize, i: usize| {
            let (ka, kb, k) = (kappa(a), kappa(b), kappa(i));
            let d: [f64; 3] = std::array::from_fn(|l| (kb[l] - ka[l]) * lc[l]);
            let dd: f64 = d.iter().map(|v| v * v).sum();
            let t = if dd > 0.0 {
                ((0..3).map(|l| (k[l] - ka[l]) * lc[l] * d[l]).sum::<f64>() / dd).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let dev = (0..3)
                .map(|l| ((k[l] - ka[l] - t * (kb[l] - ka[l])) * lc[l]).abs())
                .fold(0.0, f64::max);
            (t, dev)
        };
        while let Some((a, b)) = stack.pop() {
            let mut worst = (0.0f64, a);
            for i in a + 1..b {
                let (_, dev) = chord_t(a, b, i);
                if dev > worst.0 {
                    worst = (dev, i);
                }
            }
            let split = if worst.0 > ANCHOR_DEVIATION_RAD {
                Some(worst.1)
            } else if bending(&kappa(a), &kappa(b)) > ANCHOR_BENDING_RAD {
                Some((a + b) / 2)
            } else {
                None
            };
            if let Some(m) = split.filter(|&m| m > a && m < b) {
                anchor[m] = true;
                if m > a + 1 {
                    stack.push((a, m));
                }
                if b > m + 1 {
                    stack.push((m, b));
                }
            }
        }
        let mut out = vec![[[0.0; 3]; 5]; n];
        let mut solved = 0usize;
        let mut anchors = 0usize;
        let mut scale = [0.0f64; 5];
        let idx: Vec<usize> = (0..n).filter(|&i| anchor[i]).collect();
        let solved_at = self.load_responses_warm(&idx, loads);
        for (&i, r) in idx.iter().zip(solved_at) {
            out[i] = r;
            for (sc, r) in scale.iter_mut().zip(&out[i]) {
                *sc = sc.max(r.iter().map(|v| v * v).sum::<f64>().sqrt());
            }
            solved += 1;
            anchors += 1;
        }
        // Between anchors a < b of one series.
        for w in idx.windows(2) {
            let (a, b) = (w[0], w[1]);
            if self.rows[a].s != self.rows[b].s {
                continue;
            }
            for i in a + 1..b {
                let (t, _) = chord_t(a, b, i);
                let (ra, rb) = (&out[a], &out[b]);
                out[i] = std::array::from_fn(|j| {
                    std::array::from_fn(|c| ra[j][c] + t * (rb[j][c] - ra[j][c]))
                });
            }
        }
        // The check sample: every CHECK_EVERY-th interpolated row with a prediction, solved.
        let mut worst = 0.0f64;
        let mut checked = 0usize;
        let mut errs: Vec<[f64; 5]> = Vec::new();
        let sample: Vec<usize> = (0..n)
            .filter(|&i| !anchor[i] && self.pred(&self.rows[i]).pose.is_some())
            .step_by(CHECK_EVERY)
            .collect();
        let exact = self.load_responses_warm(&sample, loads);
        for (&i, e) in sample.iter().zip(exact) {
            solved += 1;
            checked += 1;
            let mut err = [0.0; 5];
            for j in 0..5 {
                let norm = e[j].iter().map(|v| v * v).sum::<f64>().sqrt();
                scale[j] = scale[j].max(norm);
                err[j] = (0..3)
                    .map(|c| (out[i][j][c] - e[j][c]).powi(2))
                    .sum::<f64>()
                    .sqrt();
            }
            errs.push(err);
            out[i] = e;
        }
        for err in &errs {
            for j in 0..5 {
                if scale[j] > 0.0 {
                    worst = worst.max(err[j] / scale[j]);
                }
            }
        }
        let check = (checked > 0 || anchors == n).then_some(ResponseCheck {
            anchors,
            checked,
            solved,
            max_relative_error: worst,
        });
        (out, check)
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

/// Wraps an angle to (-pi, pi].
pub fn wrap(a: f64) -> f64 {
    let t = std::f64::consts::TAU;
    let w = a.rem_euclid(t);
    if w > std::f64::consts::PI {
        w - t
    } else {
        w
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
