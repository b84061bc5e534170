//! Values that are costly to solve at every row (a loaded equilibrium, its load responses),
//! solved at some rows and interpolated along the path of the configuration between them, with
//! every interpolated stretch checked.
//!
//! The configuration of a row is its segments' bending (curvature times arc length, rad). The
//! path of a recording through it is simplified to a polyline (Douglas-Peucker: the rows where
//! it bends are anchors), and a row between two anchors takes the value interpolated along the
//! chord at its projection (with the value's gradient where the solver gives it: cubic along
//! the chord, and first order across it, [`WithGradient`]). Every stretch between two anchors
//! is then checked at its middle row, solved: when the interpolation there is off by more than
//! the caller accepts, the middle row becomes an anchor and both halves are checked in turn
//! (the stretch is bisected until it holds, or until every row of it is solved). The error of
//! the result is thus measured on every stretch, not on a sample. Without gradients a row's
//! offset across the chord is not covered by that check (the motors step one at a time, so the
//! path is a staircase about its chords): a value steep across the chord is off there by the
//! offset times its slope.

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

    /// The value at a configuration `off` away from the chord's point at `t` (rad, the part
    /// of the row's configuration across the chord): by default the chord's value. A value
    /// that carries its own gradient in the configuration ([`WithGradient`]) adds the
    /// first-order change across the chord.
    fn lerp_off(a: &Self, b: &Self, t: f64, _span: &[f64; 3], _off: &[f64; 3]) -> Self {
        Self::lerp(a, b, t)
    }
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

/// A value of `M` reals, with its gradient in the configuration where the solver gives it
/// (`gradient[l][j]`: d value_j / d bending of segment l, per rad). With the gradients of both
/// ends, a row between them takes the cubic Hermite interpolation along the chord (the ends'
/// values and slopes along it) plus the interpolated gradient times the row's offset across the
/// chord; without, the chord's linear interpolation. Where the path moves one motor at a time
/// (a staircase about the chord, up to [`ANCHOR_DEVIATION_RAD`] off it) a value that changes
/// steeply (the deflection under joint springs, 10-15 mm per rad) is off by the offset times
/// its slope, and curves along the chord: linearly interpolated, 98 % of the stretches failed
/// their check on joint springs at 3x (off by up to 0.05 mm against 0.001); with the gradients,
/// 2 %.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WithGradient<const M: usize> {
    /// The value.
    pub value: [f64; M],
    /// Its derivatives per segment's bending (rad), if known.
    pub gradient: Option<[[f64; M]; 3]>,
}

impl<const M: usize> Lerp for WithGradient<M> {
    fn lerp(a: &Self, b: &Self, t: f64) -> Self {
        WithGradient {
            value: Lerp::lerp(&a.value, &b.value, t),
            gradient: a
                .gradient
                .zip(b.gradient)
                .map(|(ga, gb)| std::array::from_fn(|l| Lerp::lerp(&ga[l], &gb[l], t))),
        }
    }

    fn lerp_off(a: &Self, b: &Self, t: f64, span: &[f64; 3], off: &[f64; 3]) -> Self {
        let mut v = Self::lerp(a, b, t);
        let (Some(ga), Some(gb), Some(g)) = (&a.gradient, &b.gradient, &v.gradient) else {
            return v;
        };
        let slope =
            |g: &[[f64; M]; 3], j: usize| -> f64 { (0..3).map(|l| g[l][j] * span[l]).sum() };
        let (t2, t3) = (t * t, t * t * t);
        let (h00, h10, h01, h11) = (
            2.0 * t3 - 3.0 * t2 + 1.0,
            t3 - 2.0 * t2 + t,
            -2.0 * t3 + 3.0 * t2,
            t3 - t2,
        );
        for j in 0..M {
            v.value[j] = h00 * a.value[j]
                + h10 * slope(ga, j)
                + h01 * b.value[j]
                + h11 * slope(gb, j)
                + (0..3).map(|l| g[l][j] * off[l]).sum::<f64>();
        }
        v
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
/// clamped) and its offset from the chord there, `k - (a + t (b - a))` (rad).
pub fn chord(a: &[f64; 3], b: &[f64; 3], k: &[f64; 3]) -> (f64, [f64; 3]) {
    let d: [f64; 3] = std::array::from_fn(|l| b[l] - a[l]);
    let dd: f64 = d.iter().map(|v| v * v).sum();
    let t = if dd > 0.0 {
        ((0..3).map(|l| (k[l] - a[l]) * d[l]).sum::<f64>() / dd).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (t, std::array::from_fn(|l| k[l] - a[l] - t * d[l]))
}

/// The largest component of an offset from a chord ([`chord`]): the distance the anchors are
/// chosen by (rad).
fn distance(off: &[f64; 3]) -> f64 {
    off.iter().map(|v| v.abs()).fold(0.0, f64::max)
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
            let dev = distance(&chord(&cfg[a], &cfg[b], &cfg[i]).1);
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
            let span: [f64; 3] = std::array::from_fn(|l| cfg[b][l] - cfg[a][l]);
            let at = |k: usize| {
                let (t, off) = chord(&cfg[a], &cfg[b], &cfg[k]);
                V::lerp_off(&va, &vb, t, &span, &off)
            };
            if within(&at(m), vm) {
                for k in a + 1..b {
                    if !done[k] {
                        out[k] = Some(at(k));
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

    /// A path that moves one coordinate at a time (a staircase about a diagonal, as the motors
    /// step), and a value steep across it.
    fn staircase() -> (Vec<[f64; 3]>, Vec<bool>) {
        let mut c = [0.2, 0.3, 0.4];
        let mut cfg = Vec::new();
        for k in 0..3000 {
            c[k % 3] += [0.0015, -0.001, 0.0005][k % 3] * (1.0 + 0.5 * (k as f64 * 0.003).sin());
            cfg.push(c);
        }
        let breaks = vec![false; cfg.len()];
        (cfg, breaks)
    }

    fn steep(c: &[f64; 3]) -> WithGradient<2> {
        let v = [
            12.0 * c[0] * c[1] + 3.0 * (2.0 * c[2]).sin(),
            -9.0 * c[1] * c[1] + 10.0 * c[0] * c[2],
        ];
        let g = [
            [12.0 * c[1], 10.0 * c[2]],
            [12.0 * c[0], -18.0 * c[1]],
            [6.0 * (2.0 * c[2]).cos(), 10.0 * c[0]],
        ];
        WithGradient {
            value: v,
            gradient: Some(g),
        }
    }

    #[test]
    fn values_with_their_gradients_interpolate_a_staircase_within_the_tolerance() {
        let (cfg, breaks) = staircase();
        let tol = 1e-3;
        let within = |a: &WithGradient<2>, b: &WithGradient<2>| {
            (0..2).all(|j| (a.value[j] - b.value[j]).abs() <= tol)
        };
        let run = |gradients: bool| {
            interpolate::<WithGradient<2>>(
                &cfg,
                &breaks,
                &mut |idx: &[usize]| {
                    idx.iter()
                        .map(|&i| {
                            let mut v = steep(&cfg[i]);
                            if !gradients {
                                v.gradient = None;
                            }
                            Some(v)
                        })
                        .collect()
                },
                &within,
            )
        };
        let (with, st) = run(true);
        let (without, st_linear) = run(false);
        let (with, without): (Vec<_>, Vec<_>) = (with, without);
        let worst = |out: &[Option<WithGradient<2>>]| {
            out.iter()
                .enumerate()
                .map(|(k, v)| {
                    let (v, e) = (v.unwrap().value, steep(&cfg[k]).value);
                    (v[0] - e[0]).abs().max((v[1] - e[1]).abs())
                })
                .fold(0.0, f64::max)
        };
        assert!(worst(&with) <= 3.0 * tol, "{}", worst(&with));
        // Linearly, a row between the checked ones is off by its offset across the chord
        // times the slope there, which no check at a stretch's middle bounds.
        assert!(worst(&without) > 3.0 * tol, "{}", worst(&without));
        // And most stretches fail their check and are bisected; with the gradients, hardly
        // any.
        assert!(st_linear.bisected > st_linear.checked / 2, "{st_linear:?}");
        assert!(st.bisected * 10 < st.checked, "{st:?}");
        assert!(2 * st.solved < st_linear.solved, "{st:?} {st_linear:?}");
    }

    #[test]
    fn without_gradients_the_interpolation_is_linear() {
        let a = WithGradient {
            value: [1.0, 2.0],
            gradient: Some([[5.0, 1.0], [0.0, 2.0], [1.0, 1.0]]),
        };
        let b = WithGradient {
            value: [3.0, -2.0],
            gradient: None,
        };
        let v = WithGradient::lerp_off(&a, &b, 0.25, &[0.1, 0.2, 0.3], &[0.01, 0.0, 0.0]);
        assert_eq!(v.value, [1.5, 1.0]);
        assert_eq!(v.gradient, None);
        // With both, the ends' values are met and the offset adds the gradient's share.
        let b = WithGradient {
            gradient: a.gradient,
            ..b
        };
        let at_a = WithGradient::lerp_off(&a, &b, 0.0, &[0.1, 0.2, 0.3], &[0.01, 0.0, 0.0]);
        assert!((at_a.value[0] - 1.05).abs() < 1e-12 && (at_a.value[1] - 2.01).abs() < 1e-12);
        let at_b = WithGradient::lerp_off(&a, &b, 1.0, &[0.1, 0.2, 0.3], &[0.0; 3]);
        assert_eq!(at_b.value, [3.0, -2.0]);
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
