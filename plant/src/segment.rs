//! One continuum segment as a planar Kirchhoff elastica, integrated by fixed-step RK4 together
//! with its sensitivities (variational equations) to the shooting unknown and the tip load.
//!
//! State along the arc length s (mm), relative to the clamped base point:
//! `x' = cos theta`, `y' = sin theta`, `theta' = m / EI`, `m' = Fx sin theta - Fy cos theta`
//! (that is `m' = -(t x F)_z`, F the constant load at the tip). `m(0)` is the shooting unknown.

/// Parameters of one segment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentParams {
    /// Base tangent angle theta(0), rad.
    pub theta0: f64,
    /// Length l_C, mm.
    pub length: f64,
    /// Bending stiffness EI, N mm^2.
    pub ei: f64,
    /// Number of RK4 steps over the length.
    pub steps: usize,
}

/// The tip state and its derivatives.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SegmentEnd {
    /// Tip position relative to the base point, mm.
    pub pos: [f64; 2],
    /// Tip tangent angle theta(l_C), rad.
    pub theta: f64,
    /// Internal moment at the tip m(l_C), N mm.
    pub moment: f64,
    /// d(x, y, theta, m)(l_C) / d(m0, Fx, Fy): rows x, y, theta, m; columns m0, Fx, Fy.
    pub jac: [[f64; 3]; 4],
}

/// (sin, cos) of a small angle by its Taylor series (error below 1e-18 for |d| <= 0.1 rad),
/// falling back to `sin_cos` for larger angles. The integrators track (cos, sin) of theta from
/// step to step with it instead of calling `sin_cos` at every stage.
#[inline(always)]
fn small_sin_cos(d: f64) -> (f64, f64) {
    if d.abs() > 0.1 {
        return d.sin_cos();
    }
    let d2 = d * d;
    let s = d * (1.0 - d2 / 6.0 * (1.0 - d2 / 20.0 * (1.0 - d2 / 42.0 * (1.0 - d2 / 72.0))));
    let c = 1.0
        - d2 / 2.0 * (1.0 - d2 / 12.0 * (1.0 - d2 / 30.0 * (1.0 - d2 / 56.0 * (1.0 - d2 / 90.0))));
    (s, c)
}

/// (sin, cos) of theta0 + d from (s0, c0) of theta0.
#[inline(always)]
fn rotated(s0: f64, c0: f64, d: f64) -> (f64, f64) {
    let (sd, cd) = small_sin_cos(d);
    (s0 * cd + c0 * sd, c0 * cd - s0 * sd)
}

/// State plus the 4x3 sensitivity matrix, flattened: [x, y, th, m, S(4x3) row-major].
type State = [f64; 16];

#[inline(always)]
fn rhs(y: &State, sc: (f64, f64), inv_ei: f64, fx: f64, fy: f64) -> State {
    let (s, c) = sc;
    let mut d = [0.0; 16];
    d[0] = c;
    d[1] = s;
    d[2] = y[3] * inv_ei;
    d[3] = fx * s - fy * c;
    let k = fx * c + fy * s;
    // Sensitivity rows: 4 + 3*row + col.
    for j in 0..3 {
        let dth = y[4 + 6 + j];
        let dm = y[4 + 9 + j];
        d[4 + j] = -s * dth;
        d[4 + 3 + j] = c * dth;
        d[4 + 6 + j] = dm * inv_ei;
        d[4 + 9 + j] = k * dth;
    }
    d[4 + 9 + 1] += s;
    d[4 + 9 + 2] -= c;
    d
}

#[inline(always)]
fn axpy(y: &State, h: f64, k: &State) -> State {
    let mut o = *y;
    for i in 0..16 {
        o[i] += h * k[i];
    }
    o
}

/// Integrates the segment from its clamped base with `m(0) = m0` and tip load `f` (N, base frame).
pub fn integrate(p: &SegmentParams, m0: f64, f: [f64; 2]) -> SegmentEnd {
    let mut y: State = [0.0; 16];
    y[2] = p.theta0;
    y[3] = m0;
    y[4 + 9] = 1.0; // dm/dm0
    let n = p.steps.max(1);
    let h = p.length / n as f64;
    let inv_ei = 1.0 / p.ei;
    let (fx, fy) = (f[0], f[1]);
    let (mut s0, mut c0) = p.theta0.sin_cos();
    for _ in 0..n {
        let th = y[2];
        let k1 = rhs(&y, (s0, c0), inv_ei, fx, fy);
        let y2 = axpy(&y, 0.5 * h, &k1);
        let k2 = rhs(&y2, rotated(s0, c0, y2[2] - th), inv_ei, fx, fy);
        let y3 = axpy(&y, 0.5 * h, &k2);
        let k3 = rhs(&y3, rotated(s0, c0, y3[2] - th), inv_ei, fx, fy);
        let y4 = axpy(&y, h, &k3);
        let k4 = rhs(&y4, rotated(s0, c0, y4[2] - th), inv_ei, fx, fy);
        for i in 0..16 {
            y[i] += h / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
        }
        (s0, c0) = rotated(s0, c0, y[2] - th);
    }
    let mut jac = [[0.0; 3]; 4];
    for (r, row) in jac.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = y[4 + 3 * r + c];
        }
    }
    SegmentEnd {
        pos: [y[0], y[1]],
        theta: y[2],
        moment: y[3],
        jac,
    }
}

/// Integrates the segment like [`integrate`] but carries only the sensitivity to m(0) of theta
/// and m (the Jacobi field): `jac` holds d theta / d m0 in `jac[2][0]` and d m / d m0 in
/// `jac[3][0]`, every other entry is zero. About three times cheaper than [`integrate`].
pub fn integrate_light(p: &SegmentParams, m0: f64, f: [f64; 2]) -> SegmentEnd {
    let n = p.steps.max(1);
    let h = p.length / n as f64;
    let inv_ei = 1.0 / p.ei;
    let (fx, fy) = (f[0], f[1]);
    let g = |y: &[f64; 6], (s, c): (f64, f64)| -> [f64; 6] {
        [
            c,
            s,
            y[3] * inv_ei,
            fx * s - fy * c,
            y[5] * inv_ei,
            (fx * c + fy * s) * y[4],
        ]
    };
    let add = |y: &[f64; 6], a: f64, k: &[f64; 6]| -> [f64; 6] {
        std::array::from_fn(|i| y[i] + a * k[i])
    };
    let mut y = [0.0, 0.0, p.theta0, m0, 0.0, 1.0];
    let (mut s0, mut c0) = p.theta0.sin_cos();
    for _ in 0..n {
        let th = y[2];
        let k1 = g(&y, (s0, c0));
        let y2 = add(&y, 0.5 * h, &k1);
        let k2 = g(&y2, rotated(s0, c0, y2[2] - th));
        let y3 = add(&y, 0.5 * h, &k2);
        let k3 = g(&y3, rotated(s0, c0, y3[2] - th));
        let y4 = add(&y, h, &k3);
        let k4 = g(&y4, rotated(s0, c0, y4[2] - th));
        for i in 0..6 {
            y[i] += h / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
        }
        (s0, c0) = rotated(s0, c0, y[2] - th);
    }
    let mut jac = [[0.0; 3]; 4];
    jac[2][0] = y[4];
    jac[3][0] = y[5];
    SegmentEnd {
        pos: [y[0], y[1]],
        theta: y[2],
        moment: y[3],
        jac,
    }
}

/// Points of the centre line (relative to the base point, mm), `p.steps + 1` of them, with the
/// tangent angle at each (rad). Same integrator as [`integrate`], state only.
pub fn shape(p: &SegmentParams, m0: f64, f: [f64; 2]) -> Vec<([f64; 2], f64)> {
    let n = p.steps.max(1);
    let h = p.length / n as f64;
    let inv_ei = 1.0 / p.ei;
    let g = |y: [f64; 4]| -> [f64; 4] {
        let (s, c) = y[2].sin_cos();
        [c, s, y[3] * inv_ei, f[0] * s - f[1] * c]
    };
    let add = |y: [f64; 4], a: f64, k: [f64; 4]| -> [f64; 4] {
        [
            y[0] + a * k[0],
            y[1] + a * k[1],
            y[2] + a * k[2],
            y[3] + a * k[3],
        ]
    };
    let mut y = [0.0, 0.0, p.theta0, m0];
    let mut out = Vec::with_capacity(n + 1);
    out.push(([y[0], y[1]], y[2]));
    for _ in 0..n {
        let k1 = g(y);
        let k2 = g(add(y, 0.5 * h, k1));
        let k3 = g(add(y, 0.5 * h, k2));
        let k4 = g(add(y, h, k3));
        for i in 0..4 {
            y[i] += h / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
        }
        out.push(([y[0], y[1]], y[2]));
    }
    out
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests {
    use super::*;

    fn params(steps: usize) -> SegmentParams {
        SegmentParams {
            theta0: std::f64::consts::FRAC_PI_2,
            length: 125.0,
            ei: 6.5e4,
            steps,
        }
    }

    #[test]
    fn unloaded_segment_is_a_circular_arc() {
        // 50 steps: the default of the plant configurations.
        let p = params(50);
        for &kappa in &[
            0.0,
            1e-4,
            0.00307872,
            0.0224255,
            std::f64::consts::PI / 125.0,
        ] {
            // theta' = -kappa (positive curvature turns clockwise).
            let e = integrate(&p, -kappa * p.ei, [0.0, 0.0]);
            let (xa, ya) = if kappa == 0.0 {
                (0.0, p.length)
            } else {
                let kl = kappa * p.length;
                ((1.0 - kl.cos()) / kappa, kl.sin() / kappa)
            };
            assert!(
                (e.pos[0] - xa).abs() < 1e-6,
                "{kappa}: {} vs {xa}",
                e.pos[0]
            );
            assert!(
                (e.pos[1] - ya).abs() < 1e-6,
                "{kappa}: {} vs {ya}",
                e.pos[1]
            );
        }
    }

    #[test]
    fn small_angle_sin_cos_is_exact() {
        for k in -200..=200 {
            let d = k as f64 * 0.0005;
            let (s, c) = small_sin_cos(d);
            assert!(
                (s - d.sin()).abs() < 1e-16 && (c - d.cos()).abs() < 2e-16,
                "{d}"
            );
        }
    }

    #[test]
    fn light_integration_agrees_with_the_full_one() {
        let p = params(100);
        let a = integrate(&p, -150.0, [0.7, -1.3]);
        let b = integrate_light(&p, -150.0, [0.7, -1.3]);
        assert_eq!((a.pos, a.theta, a.moment), (b.pos, b.theta, b.moment));
        assert!((a.jac[2][0] - b.jac[2][0]).abs() < 1e-15);
        assert!((a.jac[3][0] - b.jac[3][0]).abs() < 1e-12);
    }

    #[test]
    fn sensitivities_match_finite_differences() {
        let p = params(100);
        let (m0, f) = (-150.0, [0.7, -1.3]);
        let e = integrate(&p, m0, f);
        let h = [1e-3, 1e-5, 1e-5];
        for c in 0..3 {
            let mut a = (m0, f);
            let mut b = (m0, f);
            match c {
                0 => {
                    a.0 += h[0];
                    b.0 -= h[0];
                }
                1 => {
                    a.1[0] += h[1];
                    b.1[0] -= h[1];
                }
                _ => {
                    a.1[1] += h[2];
                    b.1[1] -= h[2];
                }
            }
            let ea = integrate(&p, a.0, a.1);
            let eb = integrate(&p, b.0, b.1);
            let fd = [
                (ea.pos[0] - eb.pos[0]) / (2.0 * h[c]),
                (ea.pos[1] - eb.pos[1]) / (2.0 * h[c]),
                (ea.theta - eb.theta) / (2.0 * h[c]),
                (ea.moment - eb.moment) / (2.0 * h[c]),
            ];
            for r in 0..4 {
                let tol = 1e-6 * (1.0 + fd[r].abs());
                assert!(
                    (e.jac[r][c] - fd[r]).abs() < tol,
                    "{r},{c}: {} vs {}",
                    e.jac[r][c],
                    fd[r]
                );
            }
        }
    }
}
