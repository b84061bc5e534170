//! Values that are costly to solve at every row (a loaded equilibrium, its load responses),
//! solved at some rows and interpolated along the path of the configuration between them, with
//! every interpolated stretch checked.
//!
//! The configuration of a row is its segments' bending (curvature times arc length, rad). The
//! path of a recording through it is simplified to a polyline (Douglas-Peucker: the rows where
//! it bends are anchors), and a row between two anchors takes the value interpolated along the
//! chord at its projection. Every stretch between two anchors is then checked at its middle row,
//! solved: when the interpolation there is off by more than the caller accepts, the middle row
//! becomes an anchor and both halves are checked in turn (the stretch is bisected until it
//! holds, or until every row of it is solved). The error of the result is thus measured on every
//! stretch, not on a sample.

/// Largest distance (a segment's bending, rad) of a row's configuration from the chord between
/// the anchors it is interpolated between.
pub const ANCHOR_DEVIATION_RAD: f64 = 0.01;

/// Largest change of a segment's bending (rad) between two anchors.
pub const ANCHOR_BENDING_RAD: f64 = 0.2;

/// Solves the points it is given (ascending) and returns their values (`None`: no value).
pub type Solver<'a, V> = dyn FnMut(&[usize]) -> Vec<Option<V>> + 'a;

/// A value that can be interpolated: a fixed number of reals, or as many as a caller needs.
pub trait Lerp: Clone {
    /// `a + t (b - a)`, component by component.
    fn lerp(a: &Self, b: &Self, t: f64) -> Self;
}

impl<const M: usize> Lerp for [f64; M] {
    fn lerp(a: &Self, b: &Self, t: f64) -> Self {
        std::array::from_fn(|j| a[j] + t * (b[j] - a[j]))
    }
}

impl Lerp for Vec<f64> {
    fn lerp(a: &Self, b: &Self, t: f64) -> Self {
        a.iter().zip(b).map(|(x, y)| x + t * (y - x)).collect()
    }
}

/// How a set of values was interpolated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct Interpolation {
    /// Rows solved as anchors of the polyline.
    pub anchors: usize,
    /// Middle rows solved to check a stretch.
    pub checked: usize,
    /// Checks the interpolation failed (the stretch was bisected).
    pub bisected: usize,
    /// Rows solved in all.
    pub solved: usize,
    /// Rows in all.
    pub rows: usize,
}

/// The projection of configuration `k` on the chord from `a` to `b` (0 at `a`, 1 at `b`,
/// clamped) and its largest distance from the chord (rad).
pub fn chord(a: &[f64; 3], b: &[f64; 3], k: &[f64; 3]) -> (f64, f64) {
    let d: [f64; 3] = std::array::from_fn(|l| b[l] - a[l]);
    let dd: f64 = d.iter().map(|v| v * v).sum();
    let t = if dd > 0.0 {
        ((0..3).map(|l| (k[l] - a[l]) * d[l]).sum::<f64>() / dd).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let dev = (0..3)
        .map(|l| (k[l] - a[l] - t * d[l]).abs())
        .fold(0.0, f64::max);
    (t, dev)
}

/// The anchors of the polyline through `cfg` (configurations in path order; `breaks[i]`: the
/// path is broken between point i-1 and i, as between two series): the first and last point
/// of every unbroken stretch, then, between consecutive anchors, the point farthest from the
/// chord, until every point is within [`ANCHOR_DEVIATION_RAD`] of its chord and no chord is
/// longer than [`ANCHOR_BENDING_RAD`].
pub fn anchors(cfg: &[[f64; 3]], breaks: &[bool]) -> Vec<bool> {
    let n = cfg.len();
    let mut anchor = vec![false; n];
    let mut stack: Vec<(usize, usize)> = Vec::new();
    let mut first = 0usize;
    for i in 0..n {
        if i + 1 == n || breaks[i + 1] {
            anchor[first] = true;
            anchor[i] = true;
            if i > first + 1 {
                stack.push((first, i));
            }
            first = i + 1;
        }
    }
    let bending =
        |a: &[f64; 3], b: &[f64; 3]| (0..3).map(|l| (a[l] - b[l]).abs()).fold(0.0, f64::max);
    while let Some((a, b)) = stack.pop() {
        let mut worst = (0.0f64, a);
        for i in a + 1..b {
            let (_, dev) = chord(&cfg[a], &cfg[b], &cfg[i]);
            if dev > worst.0 {
                worst = (dev, i);
            }
        }
        let split = if worst.0 > ANCHOR_DEVIATION_RAD {
            Some(worst.1)
        } else if bending(&cfg[a], &cfg[b]) > ANCHOR_BENDING_RAD {
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
    anchor
}

/// The values of every point of `cfg` (see [`anchors`] for `breaks`), solved by `solve` at the
/// anchors and at the middle of every stretch between them, interpolated elsewhere. `solve`
/// gets the points to solve in ascending order and returns their values (`None`: no value
/// there; a stretch with an end without a value is solved point by point). `within(interpolated,
/// solved)` says whether an interpolation is close enough; where it is not, the stretch is
/// bisected.
pub fn interpolate<V: Lerp>(
    cfg: &[[f64; 3]],
    breaks: &[bool],
    solve: &mut Solver<'_, V>,
    within: &dyn Fn(&V, &V) -> bool,
) -> (Vec<Option<V>>, Interpolation) {
    let n = cfg.len();
    let mut out: Vec<Option<V>> = vec![None; n];
    let mut done = vec![false; n];
    let anchor = anchors(cfg, breaks);
    let idx: Vec<usize> = (0..n).filter(|&i| anchor[i]).collect();
    let mut stats = Interpolation {
        anchors: idx.len(),
        rows: n,
        ..Interpolation::default()
    };
    for (&i, v) in idx.iter().zip(solve(&idx)) {
        out[i] = v;
        done[i] = true;
    }
    stats.solved += idx.len();
    // Stretches (a, b) between consecutive anchors of one unbroken path with rows between.
    let mut pending: Vec<(usize, usize)> = idx
        .windows(2)
        .filter(|w| w[1] > w[0] + 1 && !(w[0] + 1..=w[1]).any(|k| breaks[k]))
        .map(|w| (w[0], w[1]))
        .collect();
    let mut whole: Vec<(usize, usize)> = Vec::new();
    while !pending.is_empty() {
        pending.sort_unstable();
        let mids: Vec<usize> = pending.iter().map(|&(a, b)| (a + b) / 2).collect();
        let solved = solve(&mids);
        stats.solved += mids.len();
        stats.checked += mids.len();
        let mut next = Vec::new();
        for (&(a, b), (&m, v)) in pending.iter().zip(mids.iter().zip(solved)) {
            out[m] = v;
            done[m] = true;
            let (Some(va), Some(vb), Some(vm)) = (&out[a], &out[b], &out[m]) else {
                whole.push((a, b));
                continue;
            };
            let (va, vb) = (va.clone(), vb.clone());
            let (t, _) = chord(&cfg[a], &cfg[b], &cfg[m]);
            if within(&V::lerp(&va, &vb, t), vm) {
                for k in a + 1..b {
                    if !done[k] {
                        let (t, _) = chord(&cfg[a], &cfg[b], &cfg[k]);
                        out[k] = Some(V::lerp(&va, &vb, t));
                    }
                }
            } else {
                stats.bisected += 1;
                if m > a + 1 {
                    next.push((a, m));
                }
                if b > m + 1 {
                    next.push((m, b));
                }
            }
        }
        pending = next;
    }
    let rest: Vec<usize> = whole
        .iter()
        .flat_map(|&(a, b)| a + 1..b)
        .filter(|&k| !done[k])
        .collect();
    if !rest.is_empty() {
        for (&k, v) in rest.iter().zip(solve(&rest)) {
            out[k] = v;
        }
        stats.solved += rest.len();
    }
    (out, stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A path with a corner and a smooth nonlinear value along it.
    fn path() -> (Vec<[f64; 3]>, Vec<bool>) {
        let mut cfg = Vec::new();
        for k in 0..400 {
            let s = k as f64 / 400.0;
            cfg.push(if k < 200 {
                [0.4 * s, 0.1 * s, 0.0]
            } else {
                [0.08 + 0.2 * (s - 0.5), 0.05, 0.3 * (s - 0.5)]
            });
        }
        let mut breaks = vec![false; cfg.len()];
        breaks[300] = true;
        (cfg, breaks)
    }

    fn value(c: &[f64; 3]) -> [f64; 2] {
        [(3.0 * c[0]).sin() + c[2] * c[2] * 40.0, (c[1] * 7.0).exp()]
    }

    #[test]
    fn interpolated_values_are_within_the_tolerance_everywhere() {
        let (cfg, breaks) = path();
        let mut calls = 0;
        let tol = 1e-4;
        let (out, st) = interpolate::<[f64; 2]>(
            &cfg,
            &breaks,
            &mut |idx: &[usize]| {
                calls += 1;
                assert!(idx.windows(2).all(|w| w[0] < w[1]));
                idx.iter().map(|&i| Some(value(&cfg[i]))).collect()
            },
            &|a, b| (0..2).all(|j| (a[j] - b[j]).abs() <= tol),
        );
        assert_eq!(st.rows, 400);
        assert!(st.solved < 200, "{st:?}");
        assert!(st.bisected > 0, "{st:?}");
        for (k, v) in out.iter().enumerate() {
            let e = value(&cfg[k]);
            let v = v.unwrap();
            // A check at a stretch's middle bounds a smooth error over the stretch to about
            // the tolerance.
            assert!((0..2).all(|j| (v[j] - e[j]).abs() <= 3.0 * tol), "row {k}");
        }
        // Both ends of a break are anchors: nothing is interpolated across it.
        let a = anchors(&cfg, &breaks);
        assert!(a[299] && a[300] && a[0] && a[399]);
    }

    #[test]
    fn a_stretch_with_an_unsolved_end_is_solved_row_by_row() {
        let (cfg, breaks) = path();
        let (out, _) = interpolate::<[f64; 2]>(
            &cfg,
            &breaks,
            &mut |idx: &[usize]| {
                idx.iter()
                    .map(|&i| (!(100..=120).contains(&i)).then(|| value(&cfg[i])))
                    .collect()
            },
            &|a, b| (0..2).all(|j| (a[j] - b[j]).abs() <= 1e-4),
        );
        for (k, v) in out.iter().enumerate() {
            assert_eq!(v.is_none(), (100..=120).contains(&k), "row {k}");
        }
    }
}
