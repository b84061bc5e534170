//! Alignment from the data: before anything is attributed, the delay between a command and the
//! measurement that answers it is estimated from the moving rows of every recording and set
//! against what the file declares (`# command_delay_s = D`, `shared/spec/recording.md`,
//! "Timing"; D = 0 when the file says nothing).
//!
//! The estimate is a profile of the training rows' squared residual over the delay: the motors of
//! the model are where the command was `d` earlier (linearised through each row's Jacobian, as
//! the `latency` candidate does), `d` on a grid of half a millisecond around the best of a coarse
//! scan, the minimum refined by a parabola. It is signed (a measurement that leads its command
//! gives a negative delay) and finer than a cycle. Its uncertainty is a delete-one-block
//! jackknife over the time blocks, so that the residual's correlation in time is accounted for.
//!
//! - A delay longer than D is what `latency` explains: the attribution decides on held-out
//!   evidence, as for every effect.
//! - A delay shorter than D cannot be physical (the drive cannot answer a command before it
//!   executes it): the declaration is wrong. It is reported as a timing finding, with the delay
//!   the data show, and the analysis goes on with that delay, so that no effect is named for it.

use crate::context::Context;
use crate::effects::latency;
use crate::linear::motor_delta;
use crate::series::Series;
use rayon::prelude::*;
use serde::Serialize;

/// What the data say about a recording's declared delay.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TimingFinding {
    /// The data's delay agrees with the declared one.
    Consistent,
    /// The data lag their commands by more than declared: a latency (or an effect that acts like
    /// one, such as backlash) for the attribution to decide.
    LaterThanDeclared,
    /// The data answer their commands sooner than declared: the declaration is wrong.
    DeclarationError,
    /// Too few moving rows to estimate a delay: the declared one is used.
    NotEstimable,
}

/// The alignment of one recording.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Timing {
    /// The file.
    pub origin: String,
    /// The delay the file declares, s (0 when it declares none).
    pub declared_s: f64,
    /// Whether the file declares it (`# command_delay_s`).
    pub declared: bool,
    /// The delay the data show, s (signed), if it could be estimated.
    pub estimated_s: Option<f64>,
    /// Its standard error (block jackknife), s.
    pub std_s: Option<f64>,
    /// Estimate minus declaration, s.
    pub excess_s: Option<f64>,
    /// Share of the moving rows' residual above the capture noise that the data's delay explains
    /// against the declared one (a wrong declaration explains most of it; a delay that only
    /// trades against an unexplained structure explains little). Negative when the declared
    /// delay fits better once the calibration parameters are refitted (the estimate's scan does
    /// not refit them).
    pub explained_share: Option<f64>,
    /// One-sided p-value of the paired test over the blocks that the data's delay fits better
    /// than the declared one.
    pub p_value: Option<f64>,
    /// Moving rows the estimate used.
    pub moving_rows: usize,
    /// Time blocks they lie in.
    pub blocks: usize,
    /// The verdict on the declaration.
    pub finding: TimingFinding,
    /// The delay the analysis uses, s: the declared one, or the data's on a declaration error.
    pub delay_used_s: f64,
    /// One sentence for the report.
    pub message: String,
}

/// At most this many rows of a recording enter the profile (evenly thinned).
const PROFILE_ROWS: usize = 8000;
/// Fewest moving rows and blocks for an estimate.
const MIN_ROWS: usize = 50;
const MIN_BLOCKS: usize = 3;
/// Coarse scan: from `min(-SCAN_BEFORE, D - SCAN_BEFORE)` to `D + SCAN_AFTER`, step `SCAN_STEP`,
/// then `SCAN_STEP / 4` over one coarse step either side of its minimum, s. (The SSE over the
/// delay is smooth on the scale of a move's acceleration, tens of milliseconds.)
const SCAN_BEFORE: f64 = 0.1;
const SCAN_AFTER: f64 = 0.5;
const SCAN_STEP: f64 = 0.02;
/// Fine grid: +- `FINE_HALF` around the coarse minimum, step `FINE_STEP`, s.
const FINE_HALF: f64 = 0.01;
const FINE_STEP: f64 = 0.001;
/// A departure from the declaration is reported when it exceeds this many standard errors and
/// `MIN_DEPARTURE_PERIODS` control periods (a tenth of a cycle is well inside what a recorder's
/// timing can be; a wrong declaration is a whole cycle or more).
const SIGMAS: f64 = 4.0;
const MIN_DEPARTURE_PERIODS: f64 = 0.1;
/// ... and when the data's delay explains at least this share of the moving rows' residual above
/// the noise (the attribution's rule for a cause, `scoring::MIN_SHARE`), significantly over
/// the blocks (one-sided paired test below `ALPHA`).
const ALPHA: f64 = 0.01;

/// Estimates the delay of every recording of `ctx` (the starting model's residuals) and sets it
/// against its declaration.
pub fn align(ctx: &Context) -> Vec<Timing> {
    (0..ctx.series.len())
        .into_par_iter()
        .map(|s| align_series(ctx, s))
        .collect()
}

/// The series with the delays the analysis uses (`None` when they are the declared ones).
pub fn realigned(series: &[Series], timing: &[Timing]) -> Option<Vec<Series>> {
    let changed = series
        .iter()
        .zip(timing)
        .any(|(s, t)| t.delay_used_s != s.delay_s);
    changed.then(|| {
        series
            .iter()
            .zip(timing)
            .map(|(s, t)| Series {
                delay_s: t.delay_used_s,
                ..s.clone()
            })
            .collect()
    })
}

/// One sentence on the recordings whose declaration the data contradict, if any.
pub fn declaration_errors(timing: &[Timing]) -> Option<String> {
    let bad: Vec<String> = timing
        .iter()
        .filter(|t| t.finding == TimingFinding::DeclarationError)
        .map(|t| t.message.clone())
        .collect();
    (!bad.is_empty()).then(|| bad.join(" "))
}

fn align_series(ctx: &Context, si: usize) -> Timing {
    let s = &ctx.series[si];
    let declared = s.declared_delay_s;
    let mut out = Timing {
        origin: s.origin.clone(),
        declared_s: declared,
        declared: s.delay_declared,
        estimated_s: None,
        std_s: None,
        excess_s: None,
        explained_share: None,
        p_value: None,
        moving_rows: 0,
        blocks: 0,
        finding: TimingFinding::NotEstimable,
        delay_used_s: s.delay_s,
        message: String::new(),
    };
    let rows = moving_rows(ctx, si);
    let mut blocks: Vec<usize> = rows.iter().map(|&i| ctx.rows[i].block).collect();
    blocks.sort_unstable();
    blocks.dedup();
    out.moving_rows = rows.len();
    out.blocks = blocks.len();
    let delay_now = s.delay_s + latency::held_s(&ctx.model.config.effects);
    if rows.len() < MIN_ROWS || blocks.len() < MIN_BLOCKS {
        out.message = format!(
            "{}: {} moving rows in {} blocks: too few to estimate the command delay; the declared {} s is used.",
            s.origin,
            rows.len(),
            blocks.len(),
            declared
        );
        return out;
    }
    // Coarse scan of the total SSE, then a finer one around its minimum; the delays of a scan
    // in parallel (it ran on one core before the candidates' first round).
    let lo = (-SCAN_BEFORE).min(declared - SCAN_BEFORE);
    let n = ((declared + SCAN_AFTER - lo) / SCAN_STEP).round() as usize;
    let total_at = |d: f64| -> f64 {
        per_block_sse(ctx, si, &rows, d - delay_now, &blocks, None)
            .iter()
            .sum()
    };
    let argmin = |pts: Vec<(f64, f64)>, or: f64| {
        pts.iter()
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map_or(or, |c| c.0)
    };
    let coarse = argmin(
        (0..=n)
            .into_par_iter()
            .map(|k| {
                let d = lo + k as f64 * SCAN_STEP;
                (d, total_at(d))
            })
            .collect(),
        declared,
    );
    let best = argmin(
        (-4..=4)
            .into_par_iter()
            .map(|k| {
                let d = coarse + f64::from(k) * SCAN_STEP / 4.0;
                (d, total_at(d))
            })
            .collect(),
        coarse,
    );
    // Fine grid with the SSE per block.
    let m = (2.0 * FINE_HALF / FINE_STEP).round() as usize;
    let grid: Vec<f64> = (0..=m)
        .map(|k| best - FINE_HALF + k as f64 * FINE_STEP)
        .collect();
    let table: Vec<Vec<f64>> = grid
        .par_iter()
        .map(|d| per_block_sse(ctx, si, &rows, d - delay_now, &blocks, None))
        .collect();
    let total: Vec<f64> = table.iter().map(|b| b.iter().sum()).collect();
    let est = parabolic_min(&grid, &total);
    let reps: Vec<f64> = (0..blocks.len())
        .map(|b| {
            let without: Vec<f64> = table.iter().zip(&total).map(|(t, s)| s - t[b]).collect();
            parabolic_min(&grid, &without)
        })
        .collect();
    let nb = reps.len() as f64;
    let mean = reps.iter().sum::<f64>() / nb;
    let std = ((nb - 1.0) / nb * reps.iter().map(|r| (r - mean).powi(2)).sum::<f64>())
        .sqrt()
        .max(0.1 * FINE_STEP);
    let excess = est - declared;
    let bound = (SIGMAS * std).max(MIN_DEPARTURE_PERIODS * s.period_s);
    // What the data's delay explains against the declared one, beyond what a recalibration
    // would absorb.
    let nui = ctx.nuisance();
    let at_declared = per_block_sse(ctx, si, &rows, declared - delay_now, &blocks, Some(&nui));
    let at_estimate = per_block_sse(ctx, si, &rows, est - delay_now, &blocks, Some(&nui));
    let noise_ms = s.row_noise.map_or(0.0, |n| {
        n[0] * n[0] + n[1] * n[1] + (ctx.w_phi * n[2]).powi(2)
    });
    let (sd, se): (f64, f64) = (at_declared.iter().sum(), at_estimate.iter().sum());
    let structured = sd - rows.len() as f64 * noise_ms;
    let share = if structured > 0.0 {
        (sd - se) / structured
    } else {
        0.0
    };
    let p = crate::scoring::paired_p(&at_declared, &at_estimate, &vec![true; blocks.len()]);
    let departs = excess.abs() > bound && share >= crate::scoring::MIN_SHARE && p < ALPHA;
    out.estimated_s = Some(est);
    out.std_s = Some(std);
    out.excess_s = Some(excess);
    out.explained_share = Some(share);
    out.p_value = Some(p);
    let said = if s.delay_declared {
        format!("declares a command delay of {} s", declared)
    } else {
        "declares no command delay (so 0 s)".to_string()
    };
    let shows = format!(
        "the data show {:.4} +- {:.4} s ({} moving rows, {} blocks; against the declared delay {}, p = {:.1e})",
        est,
        std,
        rows.len(),
        blocks.len(),
        share_phrase(share),
        p
    );
    if departs && excess < 0.0 {
        out.finding = TimingFinding::DeclarationError;
        out.delay_used_s = whole_cycles_within(est, bound, s.period_s);
        out.message = format!(
            "Timing declaration error: {} {said}, but {shows}: its poses answer their commands {:.4} s sooner than declared, which no drive can do. The analysis takes the drive's delay as the whole number of control periods the data show, {} s, and leaves the rest to `latency`; correct the recorder's `# command_delay_s`.",
            s.origin,
            -excess,
            out.delay_used_s
        );
    } else if departs {
        out.finding = TimingFinding::LaterThanDeclared;
        out.message = format!(
            "{} {said}; {shows}: {:.4} s later than declared, a latency (or an effect acting like one, e.g. backlash) for the attribution to decide.",
            s.origin, excess
        );
    } else {
        out.finding = TimingFinding::Consistent;
        out.message = if excess.abs() > bound {
            format!(
                "{} {said}; {shows}: the best delay explains too little to depart from the declaration (an unexplained structure, not the timing): consistent.",
                s.origin
            )
        } else {
            format!("{} {said}; {shows}: consistent.", s.origin)
        };
    }
    out
}

/// The report's words for the share of the residual above the noise that the data's delay
/// explains against the declared one.
fn share_phrase(share: f64) -> String {
    if share > 0.0 {
        format!(
            "it explains {:.0} % of their residual above the noise",
            100.0 * share
        )
    } else {
        "it explains none of their residual above the noise (with the calibration parameters refitted the declared delay fits as well or better)".to_string()
    }
}

/// The drive delay a recording with a wrong declaration is analysed with: the largest whole
/// number of control periods (a drive executes a command over whole cycles; 0 for a recorder that
/// writes the position reached) not beyond the estimate and its tolerance. What the data show
/// beyond it is a latency, which the attribution claims only on held-out evidence, like any
/// effect.
fn whole_cycles_within(estimate: f64, tolerance: f64, period: f64) -> f64 {
    if period <= 0.0 {
        return estimate;
    }
    let k = ((estimate + tolerance) / period).floor();
    (k * period * 1e9).round() / 1e9
}

/// Training rows of series `si` whose prediction depends on the delay (the command moved
/// within a few cycles before them); all its rows when the whole series is held out. Evenly
/// thinned to [`PROFILE_ROWS`].
fn moving_rows(ctx: &Context, si: usize) -> Vec<usize> {
    let s = &ctx.series[si];
    let before = crate::model::delayed_steps(s, s.delay_s - 0.05);
    let after = crate::model::delayed_steps(s, s.delay_s + 0.05);
    let mine: Vec<usize> = (0..ctx.rows.len())
        .filter(|&i| ctx.rows[i].s == si)
        .collect();
    let any_train = mine.iter().any(|&i| !ctx.rows[i].held_out);
    let moving: Vec<usize> = mine
        .into_iter()
        .filter(|&i| !any_train || !ctx.rows[i].held_out)
        .filter(|&i| {
            let k = ctx.rows[i].k;
            (0..3).any(|m| (before[k][m] - after[k][m]).abs() >= 0.5)
        })
        .collect();
    let step = moving.len().div_ceil(PROFILE_ROWS).max(1);
    moving.into_iter().step_by(step).collect()
}

/// SSE of `rows` per block (in the order of `blocks`) when the motors of series `si` are where
/// the command was `extra` s later than the model has them (linearised), after the best offset
/// of half a play against each motor's direction of motion is taken out: backlash and friction
/// hysteresis make the motion lag by a play, which on a path at one speed looks like a delay;
/// with the offset free, the profile measures the delay alone. With `nuisance`, the calibration
/// parameters are fitted too (what a recalibration would absorb is not counted).
fn per_block_sse(
    ctx: &Context,
    si: usize,
    rows: &[usize],
    extra: f64,
    blocks: &[usize],
    nuisance: Option<&crate::nuisance::NuisanceTable>,
) -> Vec<f64> {
    let s = &ctx.series[si];
    let e = &ctx.model.config.effects;
    let q = ctx
        .model
        .effective_steps(s, &latency::with(e, latency::held_s(e) + extra));
    let dir = motion_direction(&q);
    // Residual after the delay's change, and the columns fitted with it, per row (`m` columns
    // a row, one after the other: no allocation per row, this runs some sixty times a series).
    let m = 3 + nuisance.map_or(0, |t| t.nui.n);
    let mut res = Vec::with_capacity(rows.len());
    let mut cols: Vec<[f64; 3]> = Vec::with_capacity(rows.len() * m);
    for &i in rows {
        let row = &ctx.rows[i];
        let d = crate::effects::motor_change::towards(ctx, i, q[row.k]);
        res.push([row.r[0] - d[0], row.r[1] - d[1], row.r[2] - d[2]]);
        for mo in 0..3 {
            let mut dq = [0.0; 3];
            dq[mo] = -dir[row.k][mo];
            cols.push(motor_delta(ctx, i, dq));
        }
        if let Some(t) = nuisance {
            debug_assert_eq!(t.cols[i].len(), t.nui.n);
            cols.extend_from_slice(&t.cols[i]);
        }
    }
    let beta = least_squares(&res, &cols, m);
    let mut out = vec![0.0; blocks.len()];
    for (n, &i) in rows.iter().enumerate() {
        let b = blocks.binary_search(&ctx.rows[i].block).unwrap_or(0);
        let c = &cols[n * m..(n + 1) * m];
        for a in 0..3 {
            let fit: f64 = c.iter().zip(&beta).map(|(c, x)| c[a] * x).sum();
            out[b] += (res[n][a] - fit).powi(2);
        }
    }
    out
}

/// The direction (+1, -1; 0 before the first motion) of each motor's last motion, per row.
fn motion_direction(q: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let mut dir = [0.0f64; 3];
    let mut prev = q.first().copied().unwrap_or([0.0; 3]);
    q.iter()
        .map(|v| {
            for m in 0..3 {
                let d = v[m] - prev[m];
                if d.abs() > 1e-9 {
                    dir[m] = d.signum();
                }
            }
            prev = *v;
            dir
        })
        .collect()
}

/// The coefficients that best fit `res` by the columns `cols` (`m` a row, one row after the
/// other; least squares on equilibrated columns, with a tiny ridge so that an empty column,
/// e.g. a motor that never moved, gets 0).
fn least_squares(res: &[[f64; 3]], cols: &[[f64; 3]], m: usize) -> Vec<f64> {
    let mut a = nalgebra::DMatrix::<f64>::zeros(m, m);
    let mut b = nalgebra::DVector::<f64>::zeros(m);
    for (r, c) in res.iter().zip(cols.chunks_exact(m.max(1))) {
        for j in 0..m {
            for k in j..m {
                a[(j, k)] += c[j][0] * c[k][0] + c[j][1] * c[k][1] + c[j][2] * c[k][2];
            }
            b[j] += c[j][0] * r[0] + c[j][1] * r[1] + c[j][2] * r[2];
        }
    }
    for j in 0..m {
        for k in 0..j {
            a[(j, k)] = a[(k, j)];
        }
    }
    let scale: Vec<f64> = (0..m)
        .map(|j| {
            if a[(j, j)] > 0.0 {
                1.0 / a[(j, j)].sqrt()
            } else {
                0.0
            }
        })
        .collect();
    for j in 0..m {
        b[j] *= scale[j];
        for k in 0..m {
            a[(j, k)] *= scale[j] * scale[k];
        }
        a[(j, j)] += 1e-9;
    }
    match a.cholesky() {
        Some(ch) => {
            let x = ch.solve(&b);
            (0..m).map(|j| x[j] * scale[j]).collect()
        }
        None => vec![0.0; m],
    }
}

/// The minimum of a sampled function: the best grid point refined by the parabola through it and
/// its neighbours.
fn parabolic_min(x: &[f64], y: &[f64]) -> f64 {
    let k = (0..y.len())
        .min_by(|a, b| y[*a].total_cmp(&y[*b]))
        .unwrap_or(0);
    if k == 0 || k + 1 >= y.len() {
        return x[k];
    }
    let (y0, y1, y2) = (y[k - 1], y[k], y[k + 1]);
    let den = y0 - 2.0 * y1 + y2;
    if den <= 0.0 {
        return x[k];
    }
    let h = x[k + 1] - x[k];
    x[k] + 0.5 * h * (y0 - y2) / den
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_parabola_finds_a_minimum_between_grid_points() {
        let x: Vec<f64> = (0..11).map(|k| k as f64 * 0.1).collect();
        let y: Vec<f64> = x.iter().map(|v| (v - 0.437).powi(2) + 3.0).collect();
        assert!((parabolic_min(&x, &y) - 0.437).abs() < 1e-12);
        // At the edge: the edge point.
        let y: Vec<f64> = x.iter().map(|v| (v + 1.0).powi(2)).collect();
        assert_eq!(parabolic_min(&x, &y), 0.0);
    }

    #[test]
    fn a_wrong_declaration_is_replaced_by_whole_cycles() {
        // A recorder of the reached position (0) whose data lag a little (backlash, friction).
        assert_eq!(whole_cycles_within(0.0124, 0.004, 0.02), 0.0);
        // One cycle, estimated a little short.
        assert_eq!(whole_cycles_within(0.0185, 0.004, 0.02), 0.02);
        // A measurement that leads by a cycle.
        assert_eq!(whole_cycles_within(-0.0195, 0.002, 0.02), -0.02);
    }

    #[test]
    fn a_share_at_or_below_zero_is_said_as_none() {
        assert!(share_phrase(0.231).contains("explains 23 %"));
        assert!(share_phrase(-0.12).contains("explains none"));
        assert!(!share_phrase(-0.12).contains('-'));
    }
}
