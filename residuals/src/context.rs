//! The residuals of the current model on every measured row, with what the candidate effects
//! need to fit against them (the model's Jacobians at each row) and the held-out blocks.

use crate::model::{ExtendedModel, Prediction};
use crate::series::{Blocks, Series};

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
    /// The five load responses of every row, computed on first use.
    loads: std::sync::OnceLock<std::sync::Arc<Vec<[[f64; 3]; 5]>>>,
}

/// The nuisance parameters and their columns for every row of a context.
#[derive(Debug)]
pub struct NuisanceTable {
    /// The parameters.
    pub nui: crate::linear::Nuisance,
    /// Columns per row.
    pub cols: Vec<crate::linear::Columns>,
}

impl<'a> Context<'a> {
    /// Predicts every series with `model` and collects the residuals.
    pub fn new(series: &'a [Series], model: ExtendedModel, blocks: &Blocks, w_phi: f64) -> Self {
        let preds: Vec<Vec<Prediction>> = series.iter().map(|s| model.predict(s)).collect();
        let mut rows = Vec::new();
        let mut unpredicted = 0;
        for (si, s) in series.iter().enumerate() {
            for (k, smp) in s.samples.iter().enumerate() {
                let Some(m) = smp.pose else { continue };
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
                let nui = crate::linear::Nuisance::of(self);
                let cols = nui.table(self);
                std::sync::Arc::new(NuisanceTable { nui, cols })
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
                std::sync::Arc::new(
                    self.rows
                        .iter()
                        .map(|row| {
                            let p = self.pred(row);
                            let Some(pose) = p.pose else {
                                return [[0.0; 3]; 5];
                            };
                            let guess = pcr_kinematics::Pose::new(pose[0], pose[1], pose[2]);
                            self.model
                                .robot
                                .load_response(&p.kappa, loads, &guess)
                                .unwrap_or([[0.0; 3]; 5])
                        })
                        .collect(),
                )
            })
            .clone()
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
