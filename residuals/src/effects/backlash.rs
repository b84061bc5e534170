//! `backlash`: gear backlash or friction hysteresis. The output of each motor follows it
//! through a play of `b_i` steps (`[effects.backlash]`); the drive adds half the play in the
//! direction of motion.

use super::joint_fit::{fit_joint, nuisance_change};
use super::motor_change::motor_change;
use super::profile::{minimise_1d, profile_std, search_rows};
use super::{lerp, Effect, Parameter};
use crate::context::Context;
use crate::extension::Extension;
use crate::fitted::{Estimate, Fitted};
use crate::linear::motor_delta;
use pcr_robot::effects::{self as robot, Effects};
use pcr_robot::RobotConfig;

/// The `backlash` candidate.
#[derive(Debug)]
pub struct Backlash;

/// Backlash on motor outputs (steps, one entry per row), in place: each motor's output
/// follows it through a dead band of `b.steps` (starting at the first row's position).
pub fn apply(q: &mut [[f64; 3]], b: &robot::Backlash) {
    for i in 0..3 {
        if b.steps[i] == 0.0 {
            continue;
        }
        let h = 0.5 * b.steps[i];
        let mut out = q.first().map_or(0.0, |v| v[i]);
        for v in q.iter_mut() {
            out = out.clamp(v[i] - h, v[i] + h);
            v[i] = out;
        }
    }
}

/// The output of motor `m` through a play of `b` steps (as [`apply`] computes it), written to
/// `out`.
fn play_on(q: &[[f64; 3]], m: usize, b: f64, out: &mut [f64]) {
    if b == 0.0 {
        for (o, v) in out.iter_mut().zip(q) {
            *o = v[m];
        }
        return;
    }
    let h = 0.5 * b;
    let mut y = q.first().map_or(0.0, |v| v[m]);
    for (o, v) in out.iter_mut().zip(q) {
        y = y.clamp(v[m] - h, v[m] + h);
        *o = y;
    }
}

/// The play a column of [`play_columns`] is taken at (steps): the change per step of play
/// from the model's plays to this much more, each motor alone.
const PROBE_STEPS: f64 = 2.0;

/// Per measured row of `ctx`, the change of its pose (orientation weighted) per step of play on
/// each motor, about the model's plays ([`PROBE_STEPS`] more on that motor alone, linearised
/// through each row's Jacobian): what a gear play takes up where another hysteresis is fitted
/// beside it ([`crate::effects::friction`]'s supports from no friction).
pub(crate) fn play_columns(ctx: &Context) -> Vec<[[f64; 3]; 3]> {
    let e = &ctx.model.config.effects;
    let held = e.backlash.as_ref().map_or([0.0; 3], |b| b.steps);
    let pre: Vec<Vec<[f64; 3]>> = ctx
        .series
        .iter()
        .map(|s| ctx.model.steps_before_play(s, e))
        .collect();
    let per_motor: Vec<Vec<[f64; 3]>> = (0..3)
        .map(|m| {
            let mut steps = held;
            steps[m] += PROBE_STEPS;
            let q_new: Vec<Vec<[f64; 3]>> = pre
                .iter()
                .map(|q| {
                    let mut q = q.clone();
                    apply(&mut q, &robot::Backlash { steps });
                    q
                })
                .collect();
            motor_change(ctx, &q_new, None)
        })
        .collect();
    (0..ctx.rows.len())
        .map(|i| std::array::from_fn(|m| per_motor[m][i].map(|v| v / PROBE_STEPS)))
        .collect()
}

/// What a profile over one motor's play reads of each searched row, so that the training
/// SSE at a play is a few products per searched row and a step per monotone run of the motor's
/// input, instead of the play run through every row and a linearised pose change per row
/// ([`motor_delta`]).
///
/// With the other motors' outputs held, row i's residual after the change is `h_i - g_i u_i`,
/// where `u_i` is motor m's output less the model's effective position there, `g_i` the row's
/// Jacobian column of motor m (orientation weighted) and `h_i` the residual less the other
/// motors' change: its square is `|h_i|^2 - 2 u_i g_i.h_i + u_i^2 |g_i|^2`.
///
/// The output itself: while the input rises (or holds), the play's upper edge never binds (the
/// output is already within half the play of the input before), so the output is the larger of
/// what it was when the rise began and the input less half the play; while it falls, the
/// smaller of that and the input plus half the play. The output at a row is then its run's
/// entry and its own input, and each run's entry the run before's at its last row: the same
/// selections as [`play_on`]'s, bit for bit.
struct PlayTerms {
    /// Per searched row: its run (an index into `runs`), motor m's input there (steps), the
    /// model's effective position of motor m (steps), `g.h` and `|g|^2`.
    rows: Vec<(usize, f64, f64, f64, f64)>,
    /// Per series, its monotone runs of motor m's input up to its last searched row.
    runs: Vec<Runs>,
    /// The sum of `|h_i|^2`.
    constant: f64,
}

/// A series' input of one motor up to some row, as monotone runs: the input at its first row
/// (where the play's output starts), and per run its input at its last row and whether it rises
/// (a run of rows that hold their input rises).
struct Runs {
    /// The input at the series' first row, steps.
    first: f64,
    /// Per run, the input at its last row (steps) and whether it rises.
    runs: Vec<(f64, bool)>,
    /// The index of its first run among every series' runs (of [`PlayTerms`]).
    offset: usize,
}

impl Runs {
    /// The runs of `q[..end]`'s motor `m`, and the run of each row (an index from 0).
    fn of(q: &[[f64; 3]], m: usize, end: usize) -> (Runs, Vec<usize>) {
        let mut runs = Vec::new();
        let mut run_of = vec![0; end];
        let mut rises: Option<bool> = None;
        for k in 1..end {
            let d = q[k][m] - q[k - 1][m];
            if d != 0.0 {
                let up = d > 0.0;
                if rises.is_some_and(|r| r != up) {
                    runs.push((q[k - 1][m], !up));
                }
                rises = Some(up);
            }
            run_of[k] = runs.len();
        }
        if end > 0 {
            runs.push((q[end - 1][m], rises.unwrap_or(true)));
        }
        let first = q.first().map_or(0.0, |v| v[m]);
        (
            Runs {
                first,
                runs,
                offset: 0,
            },
            run_of,
        )
    }
}

impl PlayTerms {
    /// The terms of the rows `rows` of `ctx` for motor `m`: its input before the play `pre`
    /// and the other motors' outputs `cur` (per series and row, steps).
    fn new(
        ctx: &Context,
        rows: &[usize],
        pre: &[Vec<[f64; 3]>],
        cur: &[Vec<[f64; 3]>],
        m: usize,
    ) -> PlayTerms {
        let mut ends = vec![0usize; pre.len()];
        for &i in rows {
            let row = &ctx.rows[i];
            ends[row.s] = ends[row.s].max(row.k + 1);
        }
        let mut offset = 0;
        let (runs, run_of): (Vec<Runs>, Vec<Vec<usize>>) = pre
            .iter()
            .zip(&ends)
            .map(|(q, &end)| {
                let (mut r, of) = Runs::of(q, m, end);
                r.offset = offset;
                offset += r.runs.len();
                (r, of)
            })
            .unzip();
        let mut constant = 0.0;
        let rows = rows
            .iter()
            .map(|&i| {
                let row = &ctx.rows[i];
                let q = ctx.pred(row).q_eff;
                let mut o = cur[row.s][row.k];
                o[m] = q[m];
                let others = motor_delta(ctx, i, [o[0] - q[0], o[1] - q[1], o[2] - q[2]]);
                let mut unit = [0.0; 3];
                unit[m] = 1.0;
                let g = motor_delta(ctx, i, unit);
                let h: [f64; 3] = std::array::from_fn(|a| row.r[a] - others[a]);
                constant += h[0] * h[0] + h[1] * h[1] + h[2] * h[2];
                let gh = g[0] * h[0] + g[1] * h[1] + g[2] * h[2];
                let gg = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
                let run = runs[row.s].offset + run_of[row.s][row.k];
                (run, pre[row.s][row.k][m], q[m], gh, gg)
            })
            .collect();
        PlayTerms {
            rows,
            runs,
            constant,
        }
    }

    /// The searched rows' SSE with a play of `b` steps (not negative) on motor m.
    fn sse(&self, b: f64, entries: &mut Vec<(f64, bool)>) -> f64 {
        let h = 0.5 * b;
        entries.clear();
        for r in &self.runs {
            let mut y = r.first;
            for &(last, rises) in &r.runs {
                entries.push((y, rises));
                y = if rises {
                    y.max(last - h)
                } else {
                    y.min(last + h)
                };
            }
        }
        self.constant
            + self
                .rows
                .iter()
                .map(|&(run, input, q, gh, gg)| {
                    let (y, rises) = entries[run];
                    let out = if rises {
                        y.max(input - h)
                    } else {
                        y.min(input + h)
                    };
                    let u = out - q;
                    u * (u * gg - 2.0 * gh)
                })
                .sum::<f64>()
    }
}

impl Extension for Backlash {
    /// The declared play on every motor.
    fn play(&self, effects: &Effects, q: &mut [[f64; 3]]) {
        if let Some(b) = &effects.backlash {
            apply(q, b);
        }
    }

    fn plays(&self, effects: &Effects) -> bool {
        effects.backlash.is_some()
    }
}

impl Effect for Backlash {
    fn name(&self) -> &'static str {
        "backlash"
    }

    fn description(&self) -> &'static str {
        "gear backlash / friction hysteresis: the output follows each motor through a play"
    }

    /// Play of b_i steps on each motor: a profile over each motor's play in turn (two sweeps),
    /// then the calibration parameters with the change at the plays found.
    fn fit(&self, ctx: &Context, train: &[usize]) -> Option<Fitted> {
        let e = &ctx.model.config.effects;
        let pre: Vec<Vec<[f64; 3]>> = ctx
            .series
            .iter()
            .map(|s| ctx.model.steps_before_play(s, e))
            .collect();
        let rows = search_rows(train);
        let delta_of = |b: [f64; 3], rows: Option<&[usize]>| -> Vec<[f64; 3]> {
            let q_new: Vec<Vec<[f64; 3]>> = pre
                .iter()
                .map(|q| {
                    let mut q = q.clone();
                    apply(&mut q, &robot::Backlash { steps: b });
                    q
                })
                .collect();
            motor_change(ctx, &q_new, rows)
        };
        // From scratch: every play up to 64 steps. Once the model holds a play (a Gauss-Newton
        // step of its acceptance), the play moves little from one step to the next: 3 steps
        // around it.
        let held = e.backlash.as_ref().map(|b| b.steps);
        let grid_of = |m: usize| -> Vec<f64> {
            match held {
                // Half steps to 20, then every second step to 64 (a play of 40 steps was found at
                // the grid's end and walked to its value by the acceptance, without a std).
                None => (0..=40)
                    .map(|k| 0.5 * k as f64)
                    .chain((11..=32).map(|k| 2.0 * k as f64))
                    .collect(),
                Some(h) => (-6..=6)
                    .map(|k| h[m] + 0.5 * k as f64)
                    .filter(|v| *v >= 0.0)
                    .collect(),
            }
        };
        let mut b = [0.0; 3];
        let mut stds = [None; 3];
        // The play acts on each motor alone: a profile over motor m's play runs the play
        // operator on that motor only, the others' outputs held at the current plays.
        let mut cur: Vec<Vec<[f64; 3]>> = pre
            .iter()
            .map(|q| {
                let mut q = q.clone();
                apply(&mut q, &robot::Backlash { steps: b });
                q
            })
            .collect();
        let mut entries = Vec::new();
        for _sweep in 0..2 {
            for m in 0..3 {
                let terms = PlayTerms::new(ctx, &rows, &pre, &cur, m);
                let (x, s, curv) =
                    minimise_1d(&mut |v| terms.sse(v.max(0.0), &mut entries), &grid_of(m));
                b[m] = x.max(0.0);
                stds[m] = profile_std(s, 3 * rows.len(), curv);
                for (c, q) in cur.iter_mut().zip(&pre) {
                    let mut out = vec![0.0; q.len()];
                    play_on(q, m, b[m], &mut out);
                    for (v, o) in c.iter_mut().zip(out) {
                        v[m] = o;
                    }
                }
            }
        }
        let nui = ctx.nuisance().nui.clone();
        let off = delta_of(b, None);
        let (fit, delta, alone) = fit_joint(ctx, &nui, train, 0, &|_, _| {}, Some(&off))?;
        let nuis = nuisance_change(nui, fit.x.clone(), 0);
        Some(Fitted {
            name: self.name(),
            params: (0..3)
                .map(|m| Estimate::new(&format!("play motor {}", m + 1), b[m], stds[m], "steps"))
                .collect(),
            k: 3,
            delta,
            alone,
            train_sse: fit.sse,
            change: std::sync::Arc::new(move |c| {
                c.effects.backlash = Some(robot::Backlash { steps: b });
                nuis(c);
            }),
        })
    }

    fn declared(&self, effects: &Effects, _fitted: &[Estimate]) -> Option<Vec<Estimate>> {
        effects.backlash.as_ref().map(|b| {
            (0..3)
                .map(|i| Estimate::new(&format!("play motor {}", i + 1), b.steps[i], None, "steps"))
                .collect()
        })
    }

    fn remove(&self, effects: &mut Effects, _params: &[Estimate]) {
        effects.backlash = None;
    }

    /// Visible in motion only: the first against the second half of the training time.
    fn consistency(&self) -> super::Parts {
        super::Parts::Halves
    }

    fn file_position(&self) -> u8 {
        2
    }

    /// The play of each motor, steps.
    fn parameters(&self, effects: &Effects) -> Vec<Parameter> {
        if effects.backlash.is_none() {
            return Vec::new();
        }
        (0..3)
            .map(|i| Parameter {
                get: |e, i| e.backlash.as_ref().map_or(0.0, |b| b.steps[i]),
                set: |e, i, x| {
                    if let Some(b) = e.backlash.as_mut() {
                        b.steps[i] = x
                    }
                },
                index: i,
                lo: 0.0,
                hi: 50.0,
                moves_curvatures: true,
                along_path: None,
            })
            .collect()
    }

    fn blend(&self, old: &RobotConfig, new: &mut RobotConfig, s: f64) {
        if let Some(b) = new.effects.backlash.as_mut() {
            let o = old.effects.backlash.as_ref().map_or([0.0; 3], |x| x.steps);
            b.steps = std::array::from_fn(|i| lerp(o[i], b.steps[i], s));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backlash_is_a_dead_band() {
        let mut q: Vec<[f64; 3]> = [0.0, 1.0, 3.0, 2.0, 1.0, 0.0, 3.0]
            .iter()
            .map(|v| [*v, *v, 0.0])
            .collect();
        apply(
            &mut q,
            &robot::Backlash {
                steps: [2.0, 0.0, 0.0],
            },
        );
        let out: Vec<f64> = q.iter().map(|v| v[0]).collect();
        assert_eq!(out, vec![0.0, 0.0, 2.0, 2.0, 2.0, 1.0, 2.0]);
        assert_eq!(q[2][1], 3.0, "no play on motor 2");
    }

    /// The profile's SSE at a play, from the rows' terms, is the SSE of the residuals after
    /// the linearised pose change ([`motor_change`]) of the outputs through that play.
    #[test]
    fn the_play_terms_give_the_sse_of_the_linearised_change() {
        use crate::effects::profile::sse_at;
        use crate::model::ExtendedModel;
        use crate::series::Blocks;
        let series = crate::context::tests::moving_series();
        let blocks = Blocks::in_time(&series, 1.0, 3);
        let mut cfg = RobotConfig::nominal();
        cfg.effects.backlash = Some(robot::Backlash {
            steps: [2.0, 3.0, 1.0],
        });
        let model = ExtendedModel::new(&cfg, crate::effects::chain()).unwrap();
        let ctx = Context::new(&series, model, &blocks, 50.0);
        let rows = search_rows(&ctx.train());
        let pre: Vec<Vec<[f64; 3]>> = ctx
            .series
            .iter()
            .map(|s| ctx.model.steps_before_play(s, &ctx.model.config.effects))
            .collect();
        // The other motors through plays of their own.
        let cur: Vec<Vec<[f64; 3]>> = pre
            .iter()
            .map(|q| {
                let mut q = q.clone();
                apply(
                    &mut q,
                    &robot::Backlash {
                        steps: [4.0, 1.5, 2.5],
                    },
                );
                q
            })
            .collect();
        for m in 0..3 {
            let terms = PlayTerms::new(&ctx, &rows, &pre, &cur, m);
            for v in [0.0, 0.5, 2.0, 7.0] {
                let out: Vec<Vec<f64>> = pre
                    .iter()
                    .map(|q| {
                        let mut o = vec![0.0; q.len()];
                        play_on(q, m, v, &mut o);
                        o
                    })
                    .collect();
                let q_new: Vec<Vec<[f64; 3]>> = cur
                    .iter()
                    .zip(&out)
                    .map(|(c, o)| {
                        c.iter()
                            .zip(o)
                            .map(|(c, o)| {
                                let mut c = *c;
                                c[m] = *o;
                                c
                            })
                            .collect()
                    })
                    .collect();
                let want = sse_at(&ctx, &rows, &motor_change(&ctx, &q_new, Some(&rows)));
                let got = terms.sse(v, &mut Vec::new());
                assert!(want > 0.0);
                assert!(
                    (got - want).abs() <= 1e-9 * want,
                    "motor {m}, play {v}: {got} {want}"
                );
            }
        }
    }
}
