//! Joint refinement of every accepted effect's parameters on the full (non-linearised) model.
//!
//! Candidates are fitted one at a time and linearised; once several effects are in the model,
//! their parameters are refined together against the training rows with the bounded
//! trust-region solver of the calibration (`pcr_calibration::lsq`). An effect that stood in for
//! another one (a latency estimate biased by a backlash found later) is corrected here.

use crate::context::wrap;
use crate::model::ExtendedModel;
use crate::series::{Blocks, Series};
use pcr_calibration::lsq::{self, Options, Problem};
use pcr_robot::effects::Effects;
use pcr_robot::RobotConfig;

/// A continuous effect parameter: (get, set, lower, upper).
struct Slot {
    get: fn(&Effects, usize) -> f64,
    set: fn(&mut Effects, usize, f64),
    index: usize,
    lo: f64,
    hi: f64,
}

fn slots(e: &Effects) -> Vec<Slot> {
    let mut v = Vec::new();
    if e.latency.is_some() {
        v.push(Slot {
            get: |e, _| e.latency.as_ref().map_or(0.0, |l| l.latency_s),
            set: |e, _, x| {
                if let Some(l) = e.latency.as_mut() {
                    l.latency_s = x
                }
            },
            index: 0,
            lo: -0.2,
            hi: 1.0,
        });
    }
    if e.backlash.is_some() {
        for i in 0..3 {
            v.push(Slot {
                get: |e, i| e.backlash.as_ref().map_or(0.0, |b| b.steps[i]),
                set: |e, i, x| {
                    if let Some(b) = e.backlash.as_mut() {
                        b.steps[i] = x
                    }
                },
                index: i,
                lo: 0.0,
                hi: 50.0,
            });
        }
    }
    if e.creep.is_some() {
        for i in 0..3 {
            v.push(Slot {
                get: |e, i| e.creep.as_ref().map_or(0.0, |c| c.gain[i]),
                set: |e, i, x| {
                    if let Some(c) = e.creep.as_mut() {
                        c.gain[i] = x
                    }
                },
                index: i,
                lo: -0.5,
                hi: 0.5,
            });
        }
        v.push(Slot {
            get: |e, _| e.creep.as_ref().map_or(1.0, |c| c.time_constant_s.ln()),
            set: |e, _, x| {
                if let Some(c) = e.creep.as_mut() {
                    c.time_constant_s = x.exp()
                }
            },
            index: 0,
            lo: 0.5f64.ln(),
            hi: 5000f64.ln(),
        });
    }
    if e.drift.is_some() {
        for i in 0..3 {
            v.push(Slot {
                // mm per 1000 s, so that the solver's steps are of the order of the others.
                get: |e, i| e.drift.as_ref().map_or(0.0, |d| 1e3 * d.rate_mm_per_s[i]),
                set: |e, i, x| {
                    if let Some(d) = e.drift.as_mut() {
                        d.rate_mm_per_s[i] = 1e-3 * x
                    }
                },
                index: i,
                lo: -1e3,
                hi: 1e3,
            });
        }
    }
    if let Some(c) = &e.compliance {
        let active = [
            c.force_n[0] != 0.0 || c.force_n[1] != 0.0 || c.couple_n_mm != 0.0,
            c.k_m_n_mm_per_rad != 0.0 || c.k_p_n_mm_per_rad != 0.0,
        ];
        if active[0] {
            for j in 0..3 {
                v.push(Slot {
                    get: |e, j| {
                        e.compliance.as_ref().map_or(0.0, |c| match j {
                            0 => c.force_n[0],
                            1 => c.force_n[1],
                            _ => c.couple_n_mm / 100.0,
                        })
                    },
                    set: |e, j, x| {
                        if let Some(c) = e.compliance.as_mut() {
                            match j {
                                0 => c.force_n[0] = x,
                                1 => c.force_n[1] = x,
                                _ => c.couple_n_mm = 100.0 * x,
                            }
                        }
                    },
                    index: j,
                    lo: -50.0,
                    hi: 50.0,
                });
            }
        }
        if active[1] {
            for j in 0..2 {
                v.push(Slot {
                    get: |e, j| {
                        e.compliance.as_ref().map_or(0.0, |c| {
                            if j == 0 {
                                c.k_m_n_mm_per_rad / 100.0
                            } else {
                                c.k_p_n_mm_per_rad / 100.0
                            }
                        })
                    },
                    set: |e, j, x| {
                        if let Some(c) = e.compliance.as_mut() {
                            if j == 0 {
                                c.k_m_n_mm_per_rad = 100.0 * x
                            } else {
                                c.k_p_n_mm_per_rad = 100.0 * x
                            }
                        }
                    },
                    index: j,
                    lo: -100.0,
                    hi: 100.0,
                });
            }
        }
    }
    if e.frame.is_some() {
        for j in 0..3 {
            v.push(Slot {
                get: |e, j| {
                    e.frame.as_ref().map_or(0.0, |f| match j {
                        0 => f.dx_mm,
                        1 => f.dy_mm,
                        _ => f.dphi_deg,
                    })
                },
                set: |e, j, x| {
                    if let Some(f) = e.frame.as_mut() {
                        match j {
                            0 => f.dx_mm = x,
                            1 => f.dy_mm = x,
                            _ => f.dphi_deg = x,
                        }
                    }
                },
                index: j,
                lo: -50.0,
                hi: 50.0,
            });
        }
    }
    for k in 0..e.periodic.len() {
        v.push(Slot {
            get: |e, k| e.periodic[k].amplitude_steps,
            set: |e, k, x| e.periodic[k].amplitude_steps = x,
            index: k,
            lo: -50.0,
            hi: 50.0,
        });
        v.push(Slot {
            get: |e, k| e.periodic[k].phase_deg,
            set: |e, k, x| e.periodic[k].phase_deg = x,
            index: k,
            lo: -720.0,
            hi: 720.0,
        });
    }
    v
}

struct Refit<'a> {
    base: &'a RobotConfig,
    slots: Vec<Slot>,
    series: &'a [Series],
    rows: Vec<Vec<usize>>,
    n: usize,
    w_phi: f64,
}

impl Refit<'_> {
    fn config(&self, x: &[f64]) -> RobotConfig {
        let mut c = self.base.clone();
        for (s, v) in self.slots.iter().zip(x) {
            (s.set)(&mut c.effects, s.index, *v);
        }
        c
    }
}

impl Problem for Refit<'_> {
    fn residual_count(&self) -> usize {
        3 * self.n
    }

    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), String> {
        let model = ExtendedModel::new(&self.config(x)).map_err(|e| e.0)?;
        let mut k = 0;
        for (s, rows) in self.series.iter().zip(&self.rows) {
            let want: std::collections::HashSet<usize> = rows.iter().copied().collect();
            let preds = model.predict_where(s, &|i| want.contains(&i));
            for &i in rows {
                let (Some(m), Some(p)) = (s.samples[i].pose, preds[i].pose) else {
                    r[3 * k] = 0.0;
                    r[3 * k + 1] = 0.0;
                    r[3 * k + 2] = 0.0;
                    k += 1;
                    continue;
                };
                let m = model.corrected(m);
                r[3 * k] = m[0] - p[0];
                r[3 * k + 1] = m[1] - p[1];
                r[3 * k + 2] = self.w_phi * wrap(m[2] - p[2]);
                k += 1;
            }
        }
        Ok(())
    }
}

/// Refines the continuous parameters of every effect of `config` on (at most `max_rows` of)
/// the training rows; returns the refined configuration (or the input when there is nothing to
/// refine or the solver fails).
pub fn refine(
    config: &RobotConfig,
    series: &[Series],
    blocks: &Blocks,
    w_phi: f64,
    max_rows: usize,
) -> RobotConfig {
    let slots = slots(&config.effects);
    if slots.is_empty() {
        return config.clone();
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
    let x0: Vec<f64> = slots
        .iter()
        .map(|s| (s.get)(&config.effects, s.index))
        .collect();
    let lo: Vec<f64> = slots.iter().map(|s| s.lo).collect();
    let hi: Vec<f64> = slots.iter().map(|s| s.hi).collect();
    let x0: Vec<f64> = x0
        .iter()
        .zip(lo.iter().zip(&hi))
        .map(|(v, (l, h))| v.clamp(*l, *h))
        .collect();
    let mut p = Refit {
        base: config,
        slots,
        series,
        rows,
        n,
        w_phi,
    };
    let opts = Options {
        max_evaluations: 200,
        ..Options::default()
    };
    match lsq::solve(&mut p, &x0, &lo, &hi, &opts) {
        Ok(fit) => p.config(&fit.x),
        Err(_) => config.clone(),
    }
}
