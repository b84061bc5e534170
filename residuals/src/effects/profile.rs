//! The 1-D profile search of a parameter that enters a candidate non-linearly (a latency, a
//! play, a creep time constant): the training rows' squared residual minimised over it on a
//! grid and by golden section, its standard error from the curvature there.

use crate::context::Context;

/// Rows the 1-D profile searches and scans run on: the training rows, thinned evenly to at most
/// [`SEARCH_ROWS`] (the final fit uses every training row).
pub(crate) fn search_rows(train: &[usize]) -> Vec<usize> {
    let step = train.len().div_ceil(SEARCH_ROWS).max(1);
    train.iter().step_by(step).copied().collect()
}

/// At most this many rows in a profile search or scan.
pub const SEARCH_ROWS: usize = 8000;

/// SSE of the rows `rows` after subtracting changes given for those rows (aligned).
pub(crate) fn sse_at(ctx: &Context, rows: &[usize], delta: &[[f64; 3]]) -> f64 {
    rows.iter()
        .zip(delta)
        .map(|(&i, d)| {
            let r = ctx.rows[i].r;
            (r[0] - d[0]).powi(2) + (r[1] - d[1]).powi(2) + (r[2] - d[2]).powi(2)
        })
        .sum()
}

/// The golden section stops when its bracket is this fraction of the grid's bracket around
/// the best point (20 evaluations; 30 before, which bracketed the minimum within 5e-7 of it).
/// The smallest errors of the sweep's profiled parameters are far wider: a play of 0.3 steps
/// +- 0.007 is bracketed within 1e-4 steps, a latency of 4 ms +- 2.7e-5 s within 2e-6 s, and
/// the joint refinement takes every continuous parameter the rest of the way.
const GOLDEN_BRACKET: f64 = 1e-4;

/// Most golden-section evaluations (where rounding keeps the bracket above its fraction).
const GOLDEN_MAX: usize = 60;

/// A 1-D minimisation of `f` on a grid, refined by golden section around the best point;
/// returns (x, f(x), curvature estimate).
pub(crate) fn minimise_1d(f: &mut dyn FnMut(f64) -> f64, grid: &[f64]) -> (f64, f64, Option<f64>) {
    let vals: Vec<f64> = grid.iter().map(|&x| f(x)).collect();
    let k = (0..grid.len())
        .min_by(|a, b| vals[*a].total_cmp(&vals[*b]))
        .unwrap_or(0);
    let lo = grid[k.saturating_sub(1)];
    let hi = grid[(k + 1).min(grid.len() - 1)];
    let (mut a, mut b) = (lo, hi);
    let gr = 0.5 * (5f64.sqrt() - 1.0);
    let mut c = b - gr * (b - a);
    let mut d = a + gr * (b - a);
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..GOLDEN_MAX {
        if b - a <= GOLDEN_BRACKET * (hi - lo) {
            break;
        }
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - gr * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + gr * (b - a);
            fd = f(d);
        }
    }
    let (x, fx) = if fc < fd { (c, fc) } else { (d, fd) };
    let (x, fx) = if vals[k] < fx {
        (grid[k], vals[k])
    } else {
        (x, fx)
    };
    // The curvature over a twentieth of the bracket; where the SSE is not smooth on that scale
    // (a play acting on whole steps), over wider steps, up to the bracket's half.
    let mut h = ((hi - lo) * 0.05).max(1e-9);
    let mut curv = None;
    for _ in 0..3 {
        let c = (f(x + h) - 2.0 * fx + f(x - h)) / (h * h);
        if c > 0.0 {
            curv = Some(c);
            break;
        }
        h *= 3.0;
    }
    (x, fx, curv)
}

/// Standard error of a profiled parameter from the curvature of the SSE.
pub(crate) fn profile_std(sse: f64, n: usize, curv: Option<f64>) -> Option<f64> {
    let s2 = sse / n.max(2) as f64;
    curv.map(|c| (2.0 * s2 / c).sqrt())
}
