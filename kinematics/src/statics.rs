//! Kineto-static extension of the constant-curvature model (the paper's stated future work):
//! segments that bend under the link forces while the tendons hold their total bending, an
//! external wrench on the platform, and springs in the passive joints.
//!
//! Each segment is an inextensible planar rod (Kirchhoff elastica, large deflections) of bending
//! stiffness EI, clamped at B_i, loaded only by the force F at its tip (the link's force through
//! the rigid extension; a couple at the tip changes the tendon tension, never the shape). Along
//! the arc length: `theta' = w`, `w' = ((sin theta) F_x - (cos theta) F_y) / EI` (the internal
//! moment `EI w` changes by `-(t x F)_z`), `r' = (cos theta, sin theta)`. The tendons fix the total
//! bending `theta(l_C) - theta(0) = -kappa l_C`; the base curvature `w(0)` (the tendon tension's
//! share) is the segment's shooting unknown. The shape is integrated as its deviation from the
//! unloaded circular arc (`theta = theta_arc + delta`, classical RK4 with [`STEPS`] steps, the
//! arc's tangent tabulated exactly), so that without a load the joint M_i is the constant-curvature
//! model's exactly and the integration error scales with the deflection. The tip tangent is the
//! arc's (the bending is held), so the rigid extension carries the tip displacement to M_i.
//! [`Robot::tip_compliance`] is the small-load limit of this (linear beam theory along the arc).
//!
//! The links are two-force members unless the joints carry springs (torques
//! `tau_M = -k_M (gamma - gamma0)`, `tau_P = -k_P (zeta - zeta0)` on the link); the force on the
//! platform is `f_i = lambda_i u_i + ((tau_M + tau_P) / l_st) R(90 deg) u_i`, and the segment tip
//! carries -f_i. The springs' rest angles gamma0, zeta0 are those a physical robot has: the joint
//! angles of this model, springs off and unloaded, at the home motor positions (the nominal CC IK
//! of pose (0, 0, 0) rounded to whole steps, as the robot is homed; [`Robot::home_motor_steps`]),
//! through the model's tendon map.
//!
//! The 15 unknowns (pose, lambda, the three tip displacements, the three base curvatures) solve
//! the loop closures, the platform equilibrium `sum f_i + F = 0`,
//! `sum (P_i - E) x f_i + sum k_P (zeta_i - zeta0_i) + M = 0`, the segments' tip displacements
//! and their total bending together by Newton. The Jacobian is a finite difference of the
//! residual with every segment linearised about the current point (3 x 3 per segment, by finite
//! differences of the integration), which costs twelve segment integrations instead of
//! forty-five. A cold solve that fails from the rigid pose follows the loads up from zero.
//!
//! This model is independent of the plant's elastica shooting (`pcr-plant`): it shares only the
//! conventions of geometry.md and the physics of a loaded rod, and it is what the residual tools
//! fit when the data show compliance.

use crate::fk::FkError;
use crate::ik::IkError;
use crate::leg::Leg;
use crate::model::Robot;
use crate::pose::Pose;
use nalgebra::{SMatrix, SVector};
use pcr_robot::effects::Compliance;
use pcr_robot::{geometry as g, Vec2};

/// Quadrature intervals along a segment (the linear compliance).
const QUAD: usize = 96;

/// Classical Runge-Kutta steps along a segment of the elastica: on the nominal robot the pose
/// is within 1.5e-3 mm and 3e-4 deg of a 256-step integration for tip loads up to 16 N (four
/// times EI / l_C^2; the error falls with the fourth power of the step), far below what a motion
/// capture resolves; a test holds it.
pub const STEPS: usize = 8;

/// Unknowns of the loaded equilibrium: pose (x, y mm, phi rad), lambda_1..3 (N), the
/// displacements of M_1..3 from the unloaded arc (x, y mm, base frame), and the deviations of
/// the segments' base curvature from the arc's, times l_C (rad).
const N: usize = 15;
type VN = SVector<f64, N>;
type MN = SMatrix<f64, N, N>;

/// Loads on the robot and its stiffness.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Loads {
    /// Segment bending stiffness, N mm^2.
    pub ei: f64,
    /// External force on the platform centre, base frame, N.
    pub force: [f64; 2],
    /// External couple, N mm.
    pub couple: f64,
    /// Joint spring at M_i, N mm/rad.
    pub k_m: f64,
    /// Joint spring at P_i, N mm/rad.
    pub k_p: f64,
}

impl Loads {
    /// The loads of a robot file's `[effects.compliance]`.
    pub fn from_compliance(c: &Compliance) -> Loads {
        Loads {
            ei: c.ei_n_mm2,
            force: c.force_n,
            couple: c.couple_n_mm,
            k_m: c.k_m_n_mm_per_rad,
            k_p: c.k_p_n_mm_per_rad,
        }
    }

    /// Whether nothing loads the robot (the result is the rigid model's).
    pub fn is_unloaded(&self) -> bool {
        self.force == [0.0; 2] && self.couple == 0.0 && self.k_m == 0.0 && self.k_p == 0.0
    }

    /// Every load and spring times `s` (the continuation of a cold solve).
    fn scaled(&self, s: f64) -> Loads {
        Loads {
            ei: self.ei,
            force: [s * self.force[0], s * self.force[1]],
            couple: s * self.couple,
            k_m: s * self.k_m,
            k_p: s * self.k_p,
        }
    }
}

/// A kineto-static equilibrium.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Equilibrium {
    /// Platform pose.
    pub pose: Pose,
    /// Axial link forces (positive: the link pushes the platform away from M_i), N.
    pub lambda: [f64; 3],
    /// Passive joints M_i with the segments' deflection, mm.
    pub m: [Vec2; 3],
    /// Passive joint angles gamma_i, zeta_i, rad.
    pub angles: [(f64, f64); 3],
}

/// One segment of given curvature: its unloaded joint and tip tangent (base frame), and the
/// arc's tangent at the integration nodes.
#[derive(Clone)]
struct Segment {
    m0: Vec2,
    t: Vec2,
    /// Step along the arc, mm.
    h: f64,
    /// (cos, sin) of the arc's tangent angle pi/2 - kappa s in the leg's local frame at
    /// s = j h / 2, j = 0 ..= 2 STEPS.
    arc: [[f64; 2]; 2 * STEPS + 1],
}

impl Segment {
    fn new(leg: &Leg, kappa: f64) -> Segment {
        let h = leg.l_c / STEPS as f64;
        let (sd, cd) = (0.5 * kappa * h).sin_cos();
        let mut arc = [[0.0; 2]; 2 * STEPS + 1];
        // (cos, sin)(pi/2 - kappa s) = (sin kappa s, cos kappa s), by rotation recurrence.
        let (mut sk, mut ck) = (0.0f64, 1.0f64);
        for a in arc.iter_mut() {
            *a = [sk, ck];
            (sk, ck) = (sk * cd + ck * sd, ck * cd - sk * sd);
        }
        Segment {
            m0: leg.joint_m(kappa),
            t: leg.tangent(kappa),
            h,
            arc,
        }
    }

    /// The elastica under the tip force `f` (leg's local frame, N) with its base curvature
    /// `u0` (1/mm) above the arc's: the tip's displacement from the arc's tip (local frame, mm)
    /// and the change of the total bending theta(l_C) - theta(0) (rad). Bit for bit the lane of
    /// [`deflect3`] that integrates it (a test holds it): the solver integrates its segments
    /// three at a time, and this is the one-segment reference the tests hold them to.
    #[cfg(test)]
    fn deflect(&self, ei: f64, f: Vec2, u0: f64) -> [f64; 3] {
        let (fx, fy) = (f[0] / ei, f[1] / ei);
        // State: delta = theta - theta_arc, u = delta', and the displacement (which does not
        // feed back). (cos, sin) of delta are carried from step to step and turned by each
        // stage's increment of delta (short series: no transcendental call on the way).
        // The right-hand side at arc node `a` with (cos, sin) delta = `e`.
        let rhs = |a: [f64; 2], e: [f64; 2], u: f64| -> [f64; 4] {
            let c = a[0] * e[0] - a[1] * e[1];
            let s = a[1] * e[0] + a[0] * e[1];
            [u, s * fx - c * fy, c - a[0], s - a[1]]
        };
        let turn = |e: [f64; 2], x: f64| -> [f64; 2] {
            let (s, c) = sin_cos_small(x);
            [e[0] * c - e[1] * s, e[1] * c + e[0] * s]
        };
        let h = self.h;
        let (mut d, mut u, mut x, mut y) = (0.0, u0, 0.0, 0.0);
        let mut e = [1.0, 0.0];
        for j in 0..STEPS {
            let (a0, am, a1) = (self.arc[2 * j], self.arc[2 * j + 1], self.arc[2 * j + 2]);
            let k1 = rhs(a0, e, u);
            let k2 = rhs(am, turn(e, 0.5 * h * k1[0]), u + 0.5 * h * k1[1]);
            let k3 = rhs(am, turn(e, 0.5 * h * k2[0]), u + 0.5 * h * k2[1]);
            let k4 = rhs(a1, turn(e, h * k3[0]), u + h * k3[1]);
            let w = h / 6.0;
            let dd = w * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0]);
            d += dd;
            e = turn(e, dd);
            u += w * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1]);
            x += w * (k1[2] + 2.0 * (k2[2] + k3[2]) + k4[2]);
            y += w * (k1[3] + 2.0 * (k2[3] + k3[3]) + k4[3]);
        }
        [x, y, d]
    }
}

/// The elastica of the three segments under their tip forces `f` (leg's local frame, N) with
/// their base curvatures `u0` (1/mm) above the arcs': each tip's displacement from its arc's
/// tip (local frame, mm) and the change of its total bending theta(l_C) - theta(0) (rad). RK4
/// on delta = theta - theta_arc and u = delta' (the displacement does not feed back); (cos,
/// sin) of delta are carried from step to step and turned by each stage's increment (short
/// series: no transcendental call on the way). The three integrations run in lockstep
/// (independent chains the processor overlaps); the tests hold them bit for bit to one
/// segment's integration.
fn deflect3(seg: &[Segment; 3], ei: f64, f: [Vec2; 3], u0: [f64; 3]) -> [[f64; 3]; 3] {
    let fx = [f[0][0] / ei, f[1][0] / ei, f[2][0] / ei];
    let fy = [f[0][1] / ei, f[1][1] / ei, f[2][1] / ei];
    let h = [seg[0].h, seg[1].h, seg[2].h];
    let mut d = [0.0f64; 3];
    let mut u = u0;
    let mut x = [0.0f64; 3];
    let mut y = [0.0f64; 3];
    let mut e = [[1.0, 0.0]; 3];
    // The stages in plain loops over the lanes ([`rk_stage`]): built through
    // `std::array::from_fn` closures they were not inlined, and `core::array::try_from_fn`
    // took more cpu than the arithmetic (7 % of an analysis under joint springs against 4 %).
    for j in 0..STEPS {
        let k1 = rk_stage(seg, fx, fy, h, &e, &u, None, 2 * j, 0.0);
        let k2 = rk_stage(seg, fx, fy, h, &e, &u, Some(&k1), 2 * j + 1, 0.5);
        let k3 = rk_stage(seg, fx, fy, h, &e, &u, Some(&k2), 2 * j + 1, 0.5);
        let k4 = rk_stage(seg, fx, fy, h, &e, &u, Some(&k3), 2 * j + 2, 1.0);
        for i in 0..3 {
            let w = h[i] / 6.0;
            let (k1, k2, k3, k4) = (k1[i], k2[i], k3[i], k4[i]);
            let dd = w * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0]);
            d[i] += dd;
            e[i] = turn(e[i], dd);
            u[i] += w * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1]);
            x[i] += w * (k1[2] + 2.0 * (k2[2] + k3[2]) + k4[2]);
            y[i] += w * (k1[3] + 2.0 * (k2[3] + k3[3]) + k4[3]);
        }
    }
    [[x[0], y[0], d[0]], [x[1], y[1], d[1]], [x[2], y[2], d[2]]]
}

/// The elastica's right-hand side at arc node `a` (its tangent's (cos, sin)) with (cos, sin)
/// of delta `e` and delta' `u`, the tip force over EI (`fx`, `fy`): (delta', u', x', y') and
/// the tangent's (cos, sin) there ([`deflect3`], [`deflect_jac3`]).
#[inline(always)]
fn rk_rhs(fx: f64, fy: f64, a: [f64; 2], e: [f64; 2], u: f64) -> ([f64; 4], f64, f64) {
    let c = a[0] * e[0] - a[1] * e[1];
    let s = a[1] * e[0] + a[0] * e[1];
    ([u, s * fx - c * fy, c - a[0], s - a[1]], c, s)
}

/// The RK4 stage of [`deflect3`]'s three lanes at arc node `node` (lane i's segment
/// `seg[i]`, tip force over EI `fx[i]`, `fy[i]`, step `h[i]`, state `e[i]`, `u[i]`), taken a
/// fraction `frac` of the step along the stage `prev` (`None`: the first stage, at the state).
/// A plain function, not a closure, so that it is inlined.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn rk_stage(
    seg: &[Segment; 3],
    fx: [f64; 3],
    fy: [f64; 3],
    h: [f64; 3],
    e: &[[f64; 2]; 3],
    u: &[f64; 3],
    prev: Option<&[[f64; 4]; 3]>,
    node: usize,
    frac: f64,
) -> [[f64; 4]; 3] {
    let mut out = [[0.0f64; 4]; 3];
    for i in 0..3 {
        let (ei, ui) = match prev {
            None => (e[i], u[i]),
            Some(k) => (
                turn(e[i], frac * h[i] * k[i][0]),
                u[i] + frac * h[i] * k[i][1],
            ),
        };
        out[i] = rk_rhs(fx[i], fy[i], seg[i].arc[node], ei, ui).0;
    }
    out
}

/// (cos, sin) `e` turned by the angle `x` ([`sin_cos_small`]).
#[inline(always)]
fn turn(e: [f64; 2], x: f64) -> [f64; 2] {
    let (s, c) = sin_cos_small(x);
    [e[0] * c - e[1] * s, e[1] * c + e[0] * s]
}

/// [`deflect3`] with its derivatives `jac[i][o][k] = d out_o / d (f_x, f_y, u0)_k` of segment
/// i: the variational equations integrated alongside, stage by stage, so that they are the
/// exact derivatives of the discrete integration (the outputs are bit for bit
/// [`deflect3`]'s).
#[allow(clippy::type_complexity)]
fn deflect_jac3(
    seg: &[Segment; 3],
    ei: f64,
    f: [Vec2; 3],
    u0: [f64; 3],
) -> ([[f64; 3]; 3], [[[f64; 3]; 3]; 3]) {
    let fx = [f[0][0] / ei, f[1][0] / ei, f[2][0] / ei];
    let fy = [f[0][1] / ei, f[1][1] / ei, f[2][1] / ei];
    let g = 1.0 / ei;
    let h = [seg[0].h, seg[1].h, seg[2].h];
    let mut d = [0.0f64; 3];
    let mut u = u0;
    let mut x = [0.0f64; 3];
    let mut y = [0.0f64; 3];
    let mut e = [[1.0, 0.0]; 3];
    let mut ts = [[[0.0f64; 2]; 3]; 3];
    for t in ts.iter_mut() {
        t[2][1] = 1.0;
    }
    let mut tp = [[[0.0f64; 2]; 3]; 3];
    // The stages as in [`deflect3`] ([`rk_var_stage`]).
    for j in 0..STEPS {
        let lanes = (seg, fx, fy, g, h);
        let s1 = rk_var_stage(lanes, &e, &u, &ts, None, 2 * j, 0.0);
        let s2 = rk_var_stage(lanes, &e, &u, &ts, Some(&s1), 2 * j + 1, 0.5);
        let s3 = rk_var_stage(lanes, &e, &u, &ts, Some(&s2), 2 * j + 1, 0.5);
        let s4 = rk_var_stage(lanes, &e, &u, &ts, Some(&s3), 2 * j + 2, 1.0);
        for i in 0..3 {
            let w = h[i] / 6.0;
            let (k1, k2, k3, k4) = (s1.0[i], s2.0[i], s3.0[i], s4.0[i]);
            let dd = w * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0]);
            d[i] += dd;
            e[i] = turn(e[i], dd);
            u[i] += w * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1]);
            x[i] += w * (k1[2] + 2.0 * (k2[2] + k3[2]) + k4[2]);
            y[i] += w * (k1[3] + 2.0 * (k2[3] + k3[3]) + k4[3]);
            let (v1, v2, v3, v4) = (&s1.1[i], &s2.1[i], &s3.1[i], &s4.1[i]);
            for q in 0..3 {
                let inc = |c: usize| w * (v1[q][c] + 2.0 * (v2[q][c] + v3[q][c]) + v4[q][c]);
                ts[i][q][0] += inc(0);
                ts[i][q][1] += inc(1);
                tp[i][q][0] += inc(2);
                tp[i][q][1] += inc(3);
            }
        }
    }
    let out = [[x[0], y[0], d[0]], [x[1], y[1], d[1]], [x[2], y[2], d[2]]];
    let jac = std::array::from_fn(|i| {
        let (ts, tp) = (&ts[i], &tp[i]);
        [
            [tp[0][0], tp[1][0], tp[2][0]],
            [tp[0][1], tp[1][1], tp[2][1]],
            [ts[0][0], ts[1][0], ts[2][0]],
        ]
    });
    (out, jac)
}

/// A stage of [`deflect_jac3`]: the derivatives of the three lanes and of their tangents (d
/// (delta, u) / d (f_x, f_y, u0)).
type VarStage = ([[f64; 4]; 3], [[[f64; 4]; 3]; 3]);

/// [`rk_stage`] with the variational equations: lane i's tangents `ts[i]` advanced as its state
/// is, and their right-hand side at the stage. `lanes`: the segments, the tip forces over EI,
/// 1 / EI and the steps.
#[allow(clippy::type_complexity)]
#[inline(always)]
fn rk_var_stage(
    lanes: (&[Segment; 3], [f64; 3], [f64; 3], f64, [f64; 3]),
    e: &[[f64; 2]; 3],
    u: &[f64; 3],
    ts: &[[[f64; 2]; 3]; 3],
    prev: Option<&VarStage>,
    node: usize,
    frac: f64,
) -> VarStage {
    let (seg, fx, fy, g, h) = lanes;
    let mut out: VarStage = ([[0.0; 4]; 3], [[[0.0; 4]; 3]; 3]);
    for i in 0..3 {
        let (r, t) = match prev {
            None => (rk_rhs(fx[i], fy[i], seg[i].arc[node], e[i], u[i]), ts[i]),
            Some((k, v)) => {
                let x = frac * h[i];
                let ei = turn(e[i], x * k[i][0]);
                let r = rk_rhs(fx[i], fy[i], seg[i].arc[node], ei, u[i] + x * k[i][1]);
                let adv = |q: usize| [ts[i][q][0] + x * v[i][q][0], ts[i][q][1] + x * v[i][q][1]];
                (r, [adv(0), adv(1), adv(2)])
            }
        };
        let (c, s) = (r.1, r.2);
        let m = c * fx[i] + s * fy[i];
        out.0[i] = r.0;
        out.1[i] = [
            [t[0][1], m * t[0][0] + s * g, -s * t[0][0], c * t[0][0]],
            [t[1][1], m * t[1][0] - c * g, -s * t[1][0], c * t[1][0]],
            [t[2][1], m * t[2][0], -s * t[2][0], c * t[2][0]],
        ];
    }
    out
}

/// (sin x, cos x): Taylor series, to x^6 for |x| <= 0.02, to x^10 for |x| <= 0.1, to x^14 for
/// |x| <= 0.5 (each with an error below 1e-17), the library's beyond.
#[inline]
fn sin_cos_small(x: f64) -> (f64, f64) {
    let ax = x.abs();
    if ax > 0.5 {
        return x.sin_cos();
    }
    let x2 = x * x;
    if ax <= 0.02 {
        let s = x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0)));
        let c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0)));
        return (s, c);
    }
    if ax <= 0.1 {
        let s = x
            * (1.0
                + x2 * (-1.0 / 6.0
                    + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362880.0)))));
        let c = 1.0
            + x2 * (-0.5
                + x2 * (1.0 / 24.0
                    + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40320.0 + x2 * (-1.0 / 3628800.0)))));
        return (s, c);
    }
    // Horner in x^2 with the Taylor coefficients 1/n!.
    const S: [f64; 7] = [
        1.0,
        -1.0 / 6.0,
        1.0 / 120.0,
        -1.0 / 5040.0,
        1.0 / 362880.0,
        -1.0 / 39916800.0,
        1.0 / 6227020800.0,
    ];
    const C: [f64; 8] = [
        1.0,
        -1.0 / 2.0,
        1.0 / 24.0,
        -1.0 / 720.0,
        1.0 / 40320.0,
        -1.0 / 3628800.0,
        1.0 / 479001600.0,
        -1.0 / 87178291200.0,
    ];
    let mut s = S[6];
    for k in (0..6).rev() {
        s = s * x2 + S[k];
    }
    let mut c = C[7];
    for k in (0..7).rev() {
        c = c * x2 + C[k];
    }
    let s = s * x;
    (s, c)
}

/// Whether an iteration whose last steps were `step` and `last` (largest component, mm, N, rad)
/// has converged: the error left after `step`, estimated from the contraction of the two
/// (linear convergence: step * rate / (1 - rate)), below 1e-9, or `step` itself below 1e-11
/// (`last` infinite: no rate known yet).
/// The solution is then `z + step`, with no further evaluation.
fn converged(step: f64, last: f64) -> bool {
    if step < 1e-11 {
        return true;
    }
    if !last.is_finite() {
        return false;
    }
    let rate = step / last;
    rate < 0.5 && step * rate / (1.0 - rate) < 1e-9
}

/// What the loaded equilibrium of given curvatures keeps fixed: the segments and the springs'
/// rest angles.
struct LoadedSetup {
    seg: [Segment; 3],
    rest: [(f64, f64); 3],
}

/// The segments at one point of the iteration: their inputs (tip force, local frame, N; base
/// curvature above the arc's, 1/mm), outputs ([`deflect3`]) and the outputs'
/// derivatives `lin[i][o][k] = d out_o / d input_k`.
#[derive(Clone, Copy)]
struct Segments {
    input: [[f64; 3]; 3],
    out: [[f64; 3]; 3],
    lin: [[[f64; 3]; 3]; 3],
}

impl Segments {
    /// Segment i's output for `input`, linearised.
    fn linear(&self, i: usize, input: &[f64; 3]) -> [f64; 3] {
        let dx = [
            input[0] - self.input[i][0],
            input[1] - self.input[i][1],
            input[2] - self.input[i][2],
        ];
        std::array::from_fn(|c| {
            let r = &self.lin[i][c];
            self.out[i][c] + r[0] * dx[0] + r[1] * dx[1] + r[2] * dx[2]
        })
    }
}

/// One leg's share of the loaded residual: its loop closure (mm), its force on the platform
/// (N) and moment about E (N mm, spring at P_i included), its segment's input and output.
#[derive(Clone, Copy)]
struct LegTerms {
    closure: f64,
    f: Vec2,
    moment: f64,
    input: [f64; 3],
    out: [f64; 3],
}

/// How the residual evaluates the segments: integrated, or linearised about a point.
#[derive(Clone, Copy)]
enum SegmentMode<'a> {
    Exact,
    /// Integrated, with the derivatives ([`deflect_jac3`]).
    Variational,
    Linear(&'a Segments),
}

/// A loaded equilibrium's pose and its first-order responses
/// ([`Robot::loaded_sensitivity_warm`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoadedSensitivity {
    /// The platform pose.
    pub pose: Pose,
    /// d(x mm, y mm, phi rad)/d kappa_i (1/mm), one column per leg.
    pub d_kappa: [[f64; 3]; 3],
    /// d(x mm, y mm, phi rad)/d(force x N, force y N, couple N mm, k_M, k_P N mm/rad).
    pub d_loads: [[f64; 3]; 5],
}

/// The first three rows of the inverse of a loaded Jacobian: the pose's first-order response
/// to a change of the residual. A response needs only the pose (x, y, phi) of the solution of
/// `J dz = -f`, so each is three dot products with these rows, where a solve through the
/// factored Jacobian costs two triangular solves of the whole system; the rows themselves
/// cost one factorisation (of `J` transposed) and three solves, and a linearisation is read
/// by about thirty responses (the curvatures, the loads, the calibration's directions). A
/// linearisation along a series ([`Robot::linearised_warm`]) takes them from the whole
/// inverse instead, which its state keeps as the next solve's chord.
struct PoseRows([VN; 3]);

impl PoseRows {
    /// The rows of `jac`'s inverse; `None` when it is singular.
    fn of(jac: &MN) -> Option<PoseRows> {
        let lu = jac.transpose().lu();
        let row = |k: usize| lu.solve(&VN::from_fn(|i, _| if i == k { 1.0 } else { 0.0 }));
        Some(PoseRows([row(0)?, row(1)?, row(2)?]))
    }

    /// The pose's change for the residual's change `df` (per unit of a parameter): the first
    /// three components of `-J^-1 df`.
    fn response(&self, df: &VN) -> [f64; 3] {
        std::array::from_fn(|k| -self.0[k].dot(df))
    }
}

/// A loaded equilibrium linearised ([`Robot::linearised_warm`]).
struct Linearised {
    rest: [(f64, f64); 3],
    st: LoadedSetup,
    z: VN,
    segs: Segments,
    f0: VN,
    /// The inverse Jacobian there (the state keeps it too), and the pose's rows of it.
    inv: MN,
    rows: PoseRows,
    /// The residual at `z` with the segments integrated, and the legs' shares it was assembled
    /// from: the integration that linearised the segments gives them (its outputs are
    /// [`deflect3`]'s bit for bit).
    exact: VN,
    terms: [LegTerms; 3],
}

/// Another robot for [`Robot::loaded_directions_warm`]: this one with one parameter of its
/// drawing or tendon map changed by `step`.
#[derive(Debug, Clone, Copy)]
pub struct Direction<'r> {
    /// The changed robot.
    pub robot: &'r Robot,
    /// Its curvatures at the row (the same tendon displacements through its map).
    pub kappa: [f64; 3],
    /// Its springs' rest angles ([`Robot::home_joint_angles`]).
    pub rest: [(f64, f64); 3],
    /// The change of the parameter.
    pub step: f64,
}

/// The state [`Robot::fk_loaded_warm`] carries from one call to the next along a series: the
/// last solution and the inverse Jacobian of the quasi-Newton iteration (kept current by
/// Broyden updates, or the exact one of a linearisation there), the solution's derivatives in
/// the curvatures where a linearisation gave them, and the springs' rest angles. One
/// `LoadedWarm` serves one robot.
#[derive(Debug, Clone, Default)]
pub struct LoadedWarm {
    rest: Option<[(f64, f64); 3]>,
    z: Option<VN>,
    rigid: [f64; 3],
    /// The solution before `z`, as offsets from its rigid pose (the pose's first three).
    before: Option<VN>,
    inv: Option<MN>,
    /// The solution's derivatives in the curvatures (d z / d kappa_i, one column per leg) and
    /// the curvatures it was solved at, where a linearisation gave them: the next solve starts
    /// at `z` moved along them (first order in the change of the curvatures).
    tangent: Option<([VN; 3], [f64; 3])>,
}

impl LoadedWarm {
    /// Starts the next solve from the solution and inverse Jacobian `other` holds (the same
    /// configuration solved for a nearby robot or nearby loads: an evaluation of a fit before
    /// this one), keeping this state's rest angles; nothing is extrapolated. Nothing changes
    /// when `other` holds no solution.
    pub fn resume_from(&mut self, other: &LoadedWarm) {
        if other.z.is_none() {
            return;
        }
        self.z = other.z;
        self.rigid = other.rigid;
        self.before = None;
        self.inv = other.inv;
        self.tangent = other.tangent;
    }
}

impl Robot {
    /// The 2x2 compliance of leg i's joint M_i to a small force at the segment tip (base frame,
    /// mm/N), for curvature `kappa` and bending stiffness `ei` (N mm^2), total bending held:
    /// linear beam theory along the arc, the small-load limit of the elastica the loaded model
    /// solves.
    pub fn tip_compliance(&self, i: usize, kappa: f64, ei: f64) -> [[f64; 2]; 2] {
        let leg = &self.legs[i];
        let n = QUAD;
        let h = leg.l_c / n as f64;
        // Local frame: start tangent +y, tangent angle pi/2 - kappa s: position r(s) and normal
        // n(s) = (-cos(kappa s), sin(kappa s)), by rotation recurrence (two trig calls).
        let (sd, cd) = (kappa * h).sin_cos();
        let mut r = [[0.0f64; 2]; QUAD + 1];
        let mut nrm = [[0.0f64; 2]; QUAD + 1];
        let (mut sk, mut ck) = (0.0f64, 1.0f64);
        for k in 0..=n {
            let s = k as f64 * h;
            let x = kappa * s;
            r[k] = if x.abs() < 1e-9 {
                [0.5 * kappa * s * s, s]
            } else {
                [(1.0 - ck) / kappa, sk / kappa]
            };
            nrm[k] = [-ck, sk];
            let (s2, c2) = (sk * cd + ck * sd, ck * cd - sk * sd);
            sk = s2;
            ck = c2;
        }
        let rl = r[n];
        // Forces along the base axes, rotated into the local frame.
        let fl = [leg.to_local([1.0, 0.0]), leg.to_local([0.0, 1.0])];
        // g(s) = ((r_L - r(s)) x F)_z for both forces.
        let mut gs = [[0.0f64; 2]; QUAD + 1];
        for (gk, p) in gs.iter_mut().zip(&r) {
            let d = g::sub(rl, *p);
            *gk = [g::cross(d, fl[0]), g::cross(d, fl[1])];
        }
        let mut mean = [0.0f64; 2];
        for k in 0..n {
            for c in 0..2 {
                mean[c] += 0.5 * (gs[k][c] + gs[k + 1][c]);
            }
        }
        let mean = [mean[0] / n as f64, mean[1] / n as f64];
        // d alpha(s) = integral of (g - mean)/EI; tip displacement = integral of d alpha n.
        let mut cols = [[0.0; 2]; 2];
        for (c, col) in cols.iter_mut().enumerate() {
            let mut da = 0.0;
            let mut dr = [0.0, 0.0];
            for k in 0..n {
                let da_next = da + h * 0.5 * ((gs[k][c] - mean[c]) + (gs[k + 1][c] - mean[c])) / ei;
                dr[0] += 0.5 * h * (da * nrm[k][0] + da_next * nrm[k + 1][0]);
                dr[1] += 0.5 * h * (da * nrm[k][1] + da_next * nrm[k + 1][1]);
                da = da_next;
            }
            *col = leg.to_base(dr);
        }
        // cols[c] is the displacement for a unit force along base axis c.
        [[cols[0][0], cols[1][0]], [cols[0][1], cols[1][1]]]
    }

    /// The motor positions the robot is homed at (steps): the constant-curvature IK of pose
    /// (0, 0, 0) of the nominal robot of geometry.md (the drawing the firmware homes by, not this
    /// model's calibrated geometry, which may bend it by whole steps) in the working mode, with
    /// the linear map kappa = dl / (a l_C) of this robot's actuation, rounded to whole steps
    /// (spec/plant.md; 176 per motor for the prototype).
    pub fn home_motor_steps(&self) -> [f64; 3] {
        static NOMINAL_HOME_BENDING: std::sync::OnceLock<[f64; 3]> = std::sync::OnceLock::new();
        let bending = NOMINAL_HOME_BENDING.get_or_init(|| {
            let r = Robot::nominal();
            std::array::from_fn(|i| r.home_kappa[i] * r.legs[i].l_c)
        });
        std::array::from_fn(|i| {
            let a = self.config().legs[i].actuation.tendon_offset_mm;
            (bending[i] * a / self.legs[i].mm_per_step).round()
        })
    }

    /// The passive joint angles (gamma_i, zeta_i) of this model, springs off and unloaded, at
    /// the home motor positions ([`Robot::home_motor_steps`], through the model's tendon map):
    /// the rest angles of the joint springs.
    pub fn home_joint_angles(&self) -> [(f64, f64); 3] {
        let q = self.home_motor_steps();
        let kappa: [f64; 3] = std::array::from_fn(|i| self.steps_to_kappa(i, q[i]));
        let Ok(pose) = self.fk_warm(&kappa, &Pose::default()) else {
            let home = Pose::default();
            return std::array::from_fn(|i| self.joint_angles(i, &home, self.home_kappa[i]));
        };
        std::array::from_fn(|i| self.joint_angles(i, &pose, kappa[i]))
    }

    /// Forward kinematics with loads: the equilibrium for curvatures `kappa` (the tendons' total
    /// bending), started at `guess` (e.g. the rigid FK).
    pub fn fk_loaded(
        &self,
        kappa: &[f64; 3],
        loads: &Loads,
        guess: &Pose,
    ) -> Result<Equilibrium, FkError> {
        let setup = self.loaded_setup(kappa);
        self.fk_loaded_in(&setup, kappa, loads, guess)
            .map(|z| self.equilibrium_of_z(&setup, &z))
    }

    /// The equilibrium unknowns for `setup`: Newton with a fresh Jacobian at every step, started
    /// at the rigid FK from `guess`; if that fails, along the loads scaled up from zero.
    fn fk_loaded_in(
        &self,
        setup: &LoadedSetup,
        kappa: &[f64; 3],
        loads: &Loads,
        guess: &Pose,
    ) -> Result<VN, FkError> {
        let rigid = self.fk_warm(kappa, guess)?;
        let mut z = VN::zeros();
        z[0] = rigid.x;
        z[1] = rigid.y;
        z[2] = rigid.phi;
        if loads.is_unloaded() {
            return Ok(z);
        }
        if let Ok(sol) = self.loaded_newton(setup, loads, z) {
            return Ok(sol);
        }
        let n = 8;
        for k in 1..=n {
            z = self.loaded_newton(setup, &loads.scaled(k as f64 / n as f64), z)?;
        }
        Ok(z)
    }

    /// Newton from `z` with the Jacobian refreshed at every step while the steps are large,
    /// quasi-Newton ([`Robot::quasi_newton`]) once they are small.
    fn loaded_newton(&self, setup: &LoadedSetup, loads: &Loads, z: VN) -> Result<VN, FkError> {
        let mut inv = None;
        self.quasi_newton(setup, loads, z, &mut inv, 1e-4, 40)
    }

    /// The iteration of both solves from `z`: steps with the inverse Jacobian `inv`, kept
    /// current by Broyden's (good) rank-one update after every step, recomputed when there is
    /// none, when a step is larger than `fresh_above` (damped to 20 mm), or when a step does not
    /// contract by 2x. Each step costs one integration per segment, a fresh Jacobian twelve.
    /// Converged as [`converged`] says.
    fn quasi_newton(
        &self,
        setup: &LoadedSetup,
        loads: &Loads,
        mut z: VN,
        inv: &mut Option<MN>,
        fresh_above: f64,
        max_iter: usize,
    ) -> Result<VN, FkError> {
        let fail = FkError::NoSolution { reached: 0.0 };
        let mut f = self.loaded_eval(setup, loads, &z, SegmentMode::Exact);
        let mut last = f64::INFINITY;
        for _ in 0..max_iter {
            if !f.iter().all(|v| v.is_finite()) {
                *inv = None;
                return Err(fail);
            }
            if inv.is_none() {
                let segs = self.segments_at(setup, loads, &z);
                *inv =
                    crate::inverse::try_inverse(&self.loaded_jacobian(setup, loads, &z, &segs, &f));
                last = f64::INFINITY;
            }
            let Some(h) = inv.as_mut() else {
                return Err(fail);
            };
            // In place (no copy of the 15 x 15 matrix): dz = -H f.
            let mut dz = VN::zeros();
            dz.gemv(-1.0, &*h, &f, 0.0);
            let step = dz.amax();
            if !step.is_finite() || step > 1e3 {
                *inv = None;
                return Err(fail);
            }
            // Damped where a step would move the pose or a joint by more than 20 mm.
            if step > 20.0 {
                dz *= 20.0 / step;
            }
            z += dz;
            if converged(step, last) {
                return Ok(z);
            }
            let f_new = self.loaded_eval(setup, loads, &z, SegmentMode::Exact);
            // Broyden: H += (s - H y) s^T H / (s^T H y), s the step, y the residual's change.
            let y = f_new - f;
            let mut hy = VN::zeros();
            hy.gemv(1.0, &*h, &y, 0.0);
            let denom = dz.dot(&hy);
            if denom.abs() > 1e-30 {
                // In place: H += (s - H y) (H^T s)^T / denom.
                let hts = h.tr_mul(&dz);
                h.ger(1.0 / denom, &(dz - hy), &hts, 1.0);
            }
            f = f_new;
            if step > fresh_above || step > 0.03 * last {
                *inv = None;
            }
            last = step;
        }
        *inv = None;
        Err(fail)
    }

    /// Forward kinematics with loads along a series: as [`Robot::fk_loaded`], but started from
    /// the previous solution held in `warm` (its link forces, deflections and base curvatures,
    /// and the deflection of its pose from the rigid one; or, where a linearisation gave the
    /// solution's derivatives in the curvatures, that solution moved along them, off by the
    /// second order of the change: on springs + frame + backlash at 3x, 45,000 of the
    /// analysis's 155,000 solves of a sensitivity took a first step above 1 mm from the
    /// offsets, 700 from the derivatives) and iterated with the Jacobian `warm` carries,
    /// refreshed only when the iteration stops contracting (chord Newton). Converges to the
    /// same equilibrium as [`Robot::fk_loaded`] (to an estimated 1e-9), at a fraction of the
    /// cost where the configuration changes little from one call to the next.
    pub fn fk_loaded_warm(
        &self,
        kappa: &[f64; 3],
        loads: &Loads,
        guess: &Pose,
        warm: &mut LoadedWarm,
    ) -> Result<Equilibrium, FkError> {
        let rest = *warm.rest.get_or_insert_with(|| self.home_joint_angles());
        let setup = self.loaded_setup_at_rest(kappa, rest);
        let z = self.fk_loaded_warm_in(&setup, kappa, loads, guess, warm)?;
        Ok(self.equilibrium_of_z(&setup, &z))
    }

    /// [`Robot::fk_loaded_warm`]'s unknowns for `setup`.
    fn fk_loaded_warm_in(
        &self,
        setup: &LoadedSetup,
        kappa: &[f64; 3],
        loads: &Loads,
        guess: &Pose,
        warm: &mut LoadedWarm,
    ) -> Result<VN, FkError> {
        let rigid = self.fk_warm(kappa, guess)?;
        let mut z = VN::zeros();
        z[0] = rigid.x;
        z[1] = rigid.y;
        z[2] = rigid.phi;
        if loads.is_unloaded() {
            return Ok(z);
        }
        // The previous solution's offsets from its rigid pose, extrapolated linearly from the
        // one before it (rows along a path).
        let offsets = warm.z.map(|prev| {
            let mut o = prev;
            for k in 0..3 {
                o[k] -= warm.rigid[k];
            }
            o
        });
        if let (Some(prev), Some((t, at))) = (warm.z, warm.tangent.take()) {
            // Along the solution's derivatives from where it was solved.
            z = prev;
            for (c, (k, k0)) in t.iter().zip(kappa.iter().zip(at)) {
                z += c * (k - k0);
            }
        } else if let Some(o) = offsets {
            let mut start = o;
            if let Some(b) = warm.before {
                start += o - b;
            }
            for k in 0..3 {
                z[k] += start[k];
            }
            for k in 3..N {
                z[k] = start[k];
            }
        }
        let z = match self.quasi_newton(setup, loads, z, &mut warm.inv, f64::INFINITY, 60) {
            Ok(z) if z.iter().all(|v| v.is_finite()) => z,
            _ => {
                warm.inv = None;
                warm.z = None;
                warm.before = None;
                return Err(FkError::NoSolution { reached: 0.0 });
            }
        };
        warm.before = offsets;
        warm.z = Some(z);
        warm.rigid = [rigid.x, rigid.y, rigid.phi];
        Ok(z)
    }

    /// The segments integrated at `z`, with their derivatives (the variational equations
    /// integrated alongside).
    fn segments_at(&self, setup: &LoadedSetup, loads: &Loads, z: &VN) -> Segments {
        self.segments_and_terms_at(setup, loads, z).0
    }

    /// [`Robot::segments_at`] with the residual at `z` (the segments integrated) and the legs'
    /// shares it was assembled from.
    fn segments_and_terms_at(
        &self,
        setup: &LoadedSetup,
        loads: &Loads,
        z: &VN,
    ) -> (Segments, VN, [LegTerms; 3]) {
        let (res, terms, lin) = self.loaded_terms(setup, loads, z, SegmentMode::Variational);
        let segs = Segments {
            input: std::array::from_fn(|i| terms[i].input),
            out: std::array::from_fn(|i| terms[i].out),
            lin,
        };
        (segs, res, terms)
    }

    /// The finite-difference Jacobian of the loaded residual at `z` (`f` its value there), the
    /// segments linearised (`segs`, at `z`).
    fn loaded_jacobian(
        &self,
        setup: &LoadedSetup,
        loads: &Loads,
        z: &VN,
        segs: &Segments,
        f: &VN,
    ) -> MN {
        // Leg i reads the pose and its own lambda, joint displacement and base curvature: a
        // column of those moves only its share, the others' are those at `z` (the same
        // residual as a whole evaluation, bit for bit).
        let (sp, cp) = z[2].sin_cos();
        let base: [LegTerms; 3] = std::array::from_fn(|i| {
            let mut t = self.leg_terms(i, &setup.seg[i], setup.rest[i], loads, z, sp, cp);
            t.out = segs.linear(i, &t.input);
            t
        });
        let mut jac = MN::zeros();
        for k in 0..N {
            let h = 1e-7 * z[k].abs().max(if k == 2 { 1e-3 } else { 1.0 });
            let mut zp = *z;
            zp[k] += h;
            let leg = match k {
                0..=2 => None,
                3..=5 => Some(k - 3),
                6..=11 => Some((k - 6) / 2),
                _ => Some(k - 12),
            };
            let mut terms = base;
            let (sp, cp) = if k == 2 { zp[2].sin_cos() } else { (sp, cp) };
            for (i, t) in terms.iter_mut().enumerate() {
                if leg.is_none_or(|l| l == i) {
                    *t = self.leg_terms(i, &setup.seg[i], setup.rest[i], loads, &zp, sp, cp);
                    t.out = segs.linear(i, &t.input);
                }
            }
            let fp = self.assemble(loads, &zp, &terms);
            jac.set_column(k, &((fp - f) / h));
        }
        jac
    }

    /// The equilibrium of solved unknowns `z`.
    fn equilibrium_of_z(&self, setup: &LoadedSetup, z: &VN) -> Equilibrium {
        let pose = Pose::new(z[0], z[1], z[2]);
        let m: [Vec2; 3] = std::array::from_fn(|i| {
            [
                setup.seg[i].m0[0] + z[6 + 2 * i],
                setup.seg[i].m0[1] + z[7 + 2 * i],
            ]
        });
        let t: [Vec2; 3] = std::array::from_fn(|i| setup.seg[i].t);
        self.equilibrium_of(&pose, &m, &t, [z[3], z[4], z[5]])
    }

    fn loaded_setup(&self, kappa: &[f64; 3]) -> LoadedSetup {
        self.loaded_setup_at_rest(kappa, self.home_joint_angles())
    }

    /// [`Robot::loaded_setup`] with the springs' rest angles given (they depend on the robot
    /// only).
    fn loaded_setup_at_rest(&self, kappa: &[f64; 3], rest: [(f64, f64); 3]) -> LoadedSetup {
        LoadedSetup {
            seg: std::array::from_fn(|i| Segment::new(&self.legs[i], kappa[i])),
            rest,
        }
    }

    /// Residual of the loaded equilibrium: loop closures (mm), platform forces (N) and moment
    /// (N, divided by the characteristic radius), the joints' displacements (mm) and the
    /// segments' change of bending (rad times l_C, mm).
    fn loaded_eval(&self, st: &LoadedSetup, loads: &Loads, z: &VN, mode: SegmentMode) -> VN {
        self.loaded_terms(st, loads, z, mode).0
    }

    /// [`Robot::loaded_eval`]'s residual with the legs' shares it was assembled from and the
    /// segments' derivatives ([`SegmentMode::Variational`] only).
    #[allow(clippy::type_complexity)]
    fn loaded_terms(
        &self,
        st: &LoadedSetup,
        loads: &Loads,
        z: &VN,
        mode: SegmentMode,
    ) -> (VN, [LegTerms; 3], [[[f64; 3]; 3]; 3]) {
        let (sp, cp) = z[2].sin_cos();
        let mut terms: [LegTerms; 3] =
            std::array::from_fn(|i| self.leg_terms(i, &st.seg[i], st.rest[i], loads, z, sp, cp));
        let mut lins = [[[0.0; 3]; 3]; 3];
        match mode {
            SegmentMode::Exact => {
                let f = std::array::from_fn(|i| [terms[i].input[0], terms[i].input[1]]);
                let u0 = std::array::from_fn(|i| terms[i].input[2]);
                let outs = deflect3(&st.seg, loads.ei, f, u0);
                for (t, o) in terms.iter_mut().zip(outs) {
                    t.out = o;
                }
            }
            SegmentMode::Variational => {
                let f = std::array::from_fn(|i| [terms[i].input[0], terms[i].input[1]]);
                let u0 = std::array::from_fn(|i| terms[i].input[2]);
                let (outs, jacs) = deflect_jac3(&st.seg, loads.ei, f, u0);
                for (t, o) in terms.iter_mut().zip(outs) {
                    t.out = o;
                }
                lins = jacs;
            }
            SegmentMode::Linear(s) => {
                for (i, t) in terms.iter_mut().enumerate() {
                    t.out = s.linear(i, &t.input);
                }
            }
        }
        (self.assemble(loads, z, &terms), terms, lins)
    }

    /// Leg i's share of the residual at `z` (`sp`, `cp` the sine and cosine of its phi), its
    /// segment's output not yet filled in.
    #[allow(clippy::too_many_arguments)]
    fn leg_terms(
        &self,
        i: usize,
        sg: &Segment,
        rest: (f64, f64),
        loads: &Loads,
        z: &VN,
        sp: f64,
        cp: f64,
    ) -> LegTerms {
        let springs = loads.k_m != 0.0 || loads.k_p != 0.0;
        let leg = &self.legs[i];
        let m = [sg.m0[0] + z[6 + 2 * i], sg.m0[1] + z[7 + 2 * i]];
        // P_i - E and P_i (geometry.md eq. 5).
        let pe = [
            cp * leg.p_e[0] - sp * leg.p_e[1],
            sp * leg.p_e[0] + cp * leg.p_e[1],
        ];
        let p = [z[0] + pe[0], z[1] + pe[1]];
        let d = g::sub(p, m);
        let l = leg.l_st;
        let closure = (g::dot(d, d) - l * l) / (2.0 * l);
        let u = g::scale(1.0 / g::norm(d).max(1e-9), d);
        let (tau, zeta_k) = if springs {
            let gamma = g::signed_angle(sg.t, d);
            let zeta = g::signed_angle(pe, g::sub(m, p));
            let zk = loads.k_p * (zeta - rest.1);
            (-loads.k_m * (gamma - rest.0) - zk, zk)
        } else {
            (0.0, 0.0)
        };
        let f = g::add(g::scale(z[3 + i], u), g::scale(tau / l, g::perp(u)));
        // The segment tip carries -f.
        let fl = leg.to_local([-f[0], -f[1]]);
        LegTerms {
            closure,
            f,
            moment: g::cross(pe, f) + zeta_k,
            input: [fl[0], fl[1], z[12 + i] / leg.l_c],
            out: [0.0; 3],
        }
    }

    /// The residual from the legs' shares.
    fn assemble(&self, loads: &Loads, z: &VN, terms: &[LegTerms; 3]) -> VN {
        let mut out = VN::zeros();
        let mut sum_f = [loads.force[0], loads.force[1]];
        let mut sum_m = loads.couple;
        for (i, t) in terms.iter().enumerate() {
            out[i] = t.closure;
            sum_f = g::add(sum_f, t.f);
            sum_m += t.moment;
        }
        for (i, t) in terms.iter().enumerate() {
            let leg = &self.legs[i];
            let o = t.out;
            let disp = leg.to_base([o[0], o[1]]);
            out[6 + 2 * i] = z[6 + 2 * i] - disp[0];
            out[7 + 2 * i] = z[7 + 2 * i] - disp[1];
            out[12 + i] = o[2] * leg.l_c;
        }
        out[3] = sum_f[0];
        out[4] = sum_f[1];
        out[5] = sum_m / self.r_char;
        out
    }

    /// The first-order response of the platform pose to the five load parameters (force x, y in
    /// N, couple in N mm, k_M and k_P in N mm/rad) at the equilibrium of `loads`: columns of
    /// d(x mm, y mm, phi rad)/d(parameter). `guess` starts the equilibrium.
    pub fn load_response(
        &self,
        kappa: &[f64; 3],
        loads: &Loads,
        guess: &Pose,
    ) -> Result<[[f64; 3]; 5], FkError> {
        let st = self.loaded_setup(kappa);
        let z = self.fk_loaded_in(&st, kappa, loads, guess)?;
        self.load_response_at(&st, loads, &z)
    }

    /// [`Robot::load_response`] along a series: the equilibrium solved as
    /// [`Robot::fk_loaded_warm`] does, from the state `warm` carries (the same equilibrium, at a
    /// fraction of the cost where consecutive calls are near each other).
    pub fn load_response_warm(
        &self,
        kappa: &[f64; 3],
        loads: &Loads,
        guess: &Pose,
        warm: &mut LoadedWarm,
    ) -> Result<[[f64; 3]; 5], FkError> {
        let rest = *warm.rest.get_or_insert_with(|| self.home_joint_angles());
        let st = self.loaded_setup_at_rest(kappa, rest);
        let z = match self.fk_loaded_warm_in(&st, kappa, loads, guess, warm) {
            Ok(_) if !loads.is_unloaded() => warm.z.ok_or(FkError::NoSolution { reached: 0.0 })?,
            _ => self.fk_loaded_in(&st, kappa, loads, guess)?,
        };
        self.load_response_at(&st, loads, &z)
    }

    /// The loaded equilibrium along a series (solved as [`Robot::fk_loaded_warm`] does) with
    /// what its first-order responses need: the residual there with the segments linearised,
    /// and the pose's rows of the inverse Jacobian ([`PoseRows`]).
    fn linearised_warm(
        &self,
        kappa: &[f64; 3],
        loads: &Loads,
        guess: &Pose,
        warm: &mut LoadedWarm,
    ) -> Result<Linearised, FkError> {
        let rest = *warm.rest.get_or_insert_with(|| self.home_joint_angles());
        let st = self.loaded_setup_at_rest(kappa, rest);
        let z = match self.fk_loaded_warm_in(&st, kappa, loads, guess, warm) {
            Ok(z) => z,
            Err(_) => self.fk_loaded_in(&st, kappa, loads, guess)?,
        };
        let (segs, exact, terms) = self.segments_and_terms_at(&st, loads, &z);
        let f0 = self.loaded_eval(&st, loads, &z, SegmentMode::Linear(&segs));
        // The whole inverse: the pose's rows, and the next solve's chord (the state keeps it).
        let inv = crate::inverse::try_inverse(&self.loaded_jacobian(&st, loads, &z, &segs, &f0))
            .ok_or(FkError::NoSolution { reached: 0.0 })?;
        let rows = PoseRows(std::array::from_fn(|k| inv.row(k).transpose()));
        warm.inv = Some(inv);
        Ok(Linearised {
            rest,
            st,
            z,
            segs,
            f0,
            inv,
            rows,
            exact,
            terms,
        })
    }

    /// The loaded equilibrium along a series (solved as [`Robot::fk_loaded_warm`] does, from
    /// the state `warm` carries) with its first-order responses to the curvatures and to the
    /// five load parameters: what a least-squares fit of parameters that act through the
    /// curvatures or the loads needs of each row, without solving the equilibrium again per
    /// parameter.
    pub fn loaded_sensitivity_warm(
        &self,
        kappa: &[f64; 3],
        loads: &Loads,
        guess: &Pose,
        warm: &mut LoadedWarm,
    ) -> Result<LoadedSensitivity, FkError> {
        let Linearised {
            rest,
            st,
            z,
            segs,
            f0,
            inv,
            rows,
            exact,
            terms,
        } = self.linearised_warm(kappa, loads, guess, warm)?;
        let d_loads = self.load_columns(&st, loads, &z, &segs, &f0, &rows);
        // The curvatures change the segments themselves: their residual is integrated again
        // (the same fixed-step integration, smooth in the curvature). Leg i's curvature
        // changes its segment alone: the other legs' shares are those at `z`. The three
        // changed segments are integrated together, each bit for bit as alone.
        let (sp, cp) = z[2].sin_cos();
        let h: [f64; 3] = std::array::from_fn(|i| 1e-7 * kappa[i].abs().max(1e-3));
        let seg: [Segment; 3] =
            std::array::from_fn(|i| Segment::new(&self.legs[i], kappa[i] + h[i]));
        let moved: [LegTerms; 3] =
            std::array::from_fn(|i| self.leg_terms(i, &seg[i], rest[i], loads, &z, sp, cp));
        let outs = deflect3(
            &seg,
            loads.ei,
            std::array::from_fn(|i| [moved[i].input[0], moved[i].input[1]]),
            std::array::from_fn(|i| moved[i].input[2]),
        );
        let mut d_kappa = [[0.0; 3]; 3];
        let mut tangent = [VN::zeros(); 3];
        for (i, (col, tc)) in d_kappa.iter_mut().zip(tangent.iter_mut()).enumerate() {
            let mut t = terms;
            t[i] = LegTerms {
                out: outs[i],
                ..moved[i]
            };
            let df = (self.assemble(loads, &z, &t) - exact) / h[i];
            *col = rows.response(&df);
            tc.gemv(-1.0, &inv, &df, 0.0);
        }
        warm.tangent = Some((tangent, *kappa));
        Ok(LoadedSensitivity {
            pose: Pose::new(z[0], z[1], z[2]),
            d_kappa,
            d_loads,
        })
    }

    /// The loaded equilibrium along a series (solved as [`Robot::fk_loaded_warm`] does) and
    /// its first-order changes toward other robots: for each [`Direction`] (a robot that
    /// differs from this one by `step` in one parameter of its drawing or tendon map, with its
    /// curvatures at the row and its springs' rest angles), the change of the platform pose
    /// (x mm, y mm, phi rad) per unit of the parameter, by the implicit function theorem: the
    /// other robot's residual at this equilibrium, through the pose's rows of this one's
    /// inverse Jacobian. What a fit of calibration parameters around a loaded model needs of
    /// each row, without an equilibrium solved per parameter.
    ///
    /// The other robot's residual is assembled leg by leg: a leg with this one's drawing,
    /// curvature and rest angles keeps its share at `z`; a leg whose segment is this one's (the
    /// same length and curvature: the integration reads nothing else) but whose share changes
    /// (its base, its platform joint, or its rest angles, which move with every leg's drawing
    /// under springs) takes the segment's linearisation at `z` for its new tip load (exact to
    /// first order in the step, as the difference quotient itself is); only a leg whose length
    /// or curvature changes is integrated again. A direction of the drawing then integrates
    /// one segment or none, where it integrated three.
    pub fn loaded_directions_warm(
        &self,
        kappa: &[f64; 3],
        loads: &Loads,
        guess: &Pose,
        warm: &mut LoadedWarm,
        directions: &[Direction<'_>],
        out: &mut [[f64; 3]],
    ) -> Result<Pose, FkError> {
        let Linearised {
            rest,
            st,
            z,
            segs,
            rows,
            exact,
            terms,
            ..
        } = self.linearised_warm(kappa, loads, guess, warm)?;
        let (sp, cp) = z[2].sin_cos();
        // Without springs the rest angles are not read.
        let springs = loads.k_m != 0.0 || loads.k_p != 0.0;
        // Every direction's legs' shares; the segments to integrate again (direction, leg,
        // segment) are integrated three at a time afterwards, each bit for bit as alone.
        let mut shares: Vec<[LegTerms; 3]> = Vec::with_capacity(directions.len());
        let mut pending: Vec<(usize, usize, Segment)> = Vec::new();
        for (k, d) in directions.iter().enumerate() {
            let mut t = terms;
            for (i, ti) in t.iter_mut().enumerate() {
                let (leg, other) = (&self.legs[i], &d.robot.legs[i]);
                let drawing = leg.same_drawing(other);
                let curvature = d.kappa[i] == kappa[i];
                if drawing && curvature && (d.rest[i] == rest[i] || !springs) {
                    continue;
                }
                let seg = if drawing && curvature {
                    None
                } else {
                    Some(Segment::new(other, d.kappa[i]))
                };
                let sg = seg.as_ref().unwrap_or(&st.seg[i]);
                *ti = d.robot.leg_terms(i, sg, d.rest[i], loads, &z, sp, cp);
                // A changed length or curvature (a segment of its own) is integrated again.
                match seg {
                    Some(seg) if leg.l_c != other.l_c || !curvature => pending.push((k, i, seg)),
                    _ => ti.out = segs.linear(i, &ti.input),
                }
            }
            shares.push(t);
        }
        for batch in pending.chunks(3) {
            // A short batch is filled with its first segment (integrated, not read).
            let at = |j: usize| &batch[j.min(batch.len() - 1)];
            let seg: [Segment; 3] = std::array::from_fn(|j| at(j).2.clone());
            let input = |j: usize| shares[at(j).0][at(j).1].input;
            let outs = deflect3(
                &seg,
                loads.ei,
                std::array::from_fn(|j| [input(j)[0], input(j)[1]]),
                std::array::from_fn(|j| input(j)[2]),
            );
            for (&(k, i, _), o) in batch.iter().zip(outs) {
                shares[k][i].out = o;
            }
        }
        for ((d, t), o) in directions.iter().zip(&shares).zip(out.iter_mut()) {
            *o = rows.response(&((d.robot.assemble(loads, &z, t) - exact) / d.step));
        }
        Ok(Pose::new(z[0], z[1], z[2]))
    }

    /// The load response at the solved equilibrium `z`: the exact Jacobian there, and the
    /// residual's derivatives with respect to the five parameters.
    fn load_response_at(
        &self,
        st: &LoadedSetup,
        loads: &Loads,
        z: &VN,
    ) -> Result<[[f64; 3]; 5], FkError> {
        let segs = self.segments_at(st, loads, z);
        let f0 = self.loaded_eval(st, loads, z, SegmentMode::Linear(&segs));
        let rows = PoseRows::of(&self.loaded_jacobian(st, loads, z, &segs, &f0))
            .ok_or(FkError::NoSolution { reached: 0.0 })?;
        Ok(self.load_columns(st, loads, z, &segs, &f0, &rows))
    }

    /// The responses of the equilibrium `z` to the five load parameters, from the residual
    /// there (`f0`, segments linearised as `segs`) and the pose's rows of the inverse Jacobian.
    fn load_columns(
        &self,
        st: &LoadedSetup,
        loads: &Loads,
        z: &VN,
        segs: &Segments,
        f0: &VN,
        rows: &PoseRows,
    ) -> [[f64; 3]; 5] {
        let lin = SegmentMode::Linear(segs);
        let mut out = [[0.0; 3]; 5];
        for (j, o) in out.iter_mut().enumerate() {
            let mut l = *loads;
            let h = 1e-3;
            match j {
                0 => l.force[0] += h,
                1 => l.force[1] += h,
                2 => l.couple += h,
                3 => l.k_m += h,
                _ => l.k_p += h,
            }
            *o = rows.response(&((self.loaded_eval(st, &l, z, lin) - *f0) / h));
        }
        out
    }

    fn equilibrium_of(
        &self,
        pose: &Pose,
        m: &[Vec2; 3],
        t: &[Vec2; 3],
        lambda: [f64; 3],
    ) -> Equilibrium {
        let angles = std::array::from_fn(|i| {
            let p = self.joint_p(i, pose);
            let pe = g::sub(p, [pose.x, pose.y]);
            (
                g::signed_angle(t[i], g::sub(p, m[i])),
                g::signed_angle(pe, g::sub(m[i], p)),
            )
        });
        Equilibrium {
            pose: *pose,
            lambda,
            m: *m,
            angles,
        }
    }

    /// Inverse kinematics with loads: the curvatures whose loaded equilibrium is `pose`, by a
    /// fixed-point iteration on the rigid IK (the loads move the platform by a small amount).
    pub fn ik_loaded(&self, pose: &Pose, loads: &Loads) -> Result<[f64; 3], IkError> {
        let mut target = *pose;
        let mut kappa = self.ik(&target)?.kappa;
        if loads.is_unloaded() {
            return Ok(kappa);
        }
        for _ in 0..12 {
            let Ok(eq) = self.fk_loaded(&kappa, loads, &target) else {
                return Ok(kappa);
            };
            let e = [
                pose.x - eq.pose.x,
                pose.y - eq.pose.y,
                pose.phi - eq.pose.phi,
            ];
            if e[0].abs().max(e[1].abs()) < 1e-7 && e[2].abs() < 1e-9 {
                break;
            }
            target = Pose::new(target.x + e[0], target.y + e[1], target.phi + e[2]);
            kappa = self.ik(&target)?.kappa;
        }
        Ok(kappa)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // The reference integration of one segment with its derivatives the solver's lockstep one
    // (deflect_jac3) is held to, bit for bit: the same operations, one segment at a time
    // ([`Segment::deflect`] is the solver's own, for one segment).
    impl Segment {
        /// [`Segment::deflect`] with its derivatives `jac[o][k] = d out_o / d (f_x, f_y, u0)_k`: the
        /// variational equations of the elastica integrated alongside, stage by stage, so that they
        /// are the exact derivatives of the discrete integration (`out` is bit-for-bit
        /// [`Segment::deflect`]'s).
        fn deflect_jac(&self, ei: f64, f: Vec2, u0: f64) -> ([f64; 3], [[f64; 3]; 3]) {
            let (fx, fy) = (f[0] / ei, f[1] / ei);
            let g = 1.0 / ei;
            // The right-hand side at arc node `a` with (cos, sin) delta = `e`, and (cos, sin) of
            // the tangent angle there.
            let rhs = |a: [f64; 2], e: [f64; 2], u: f64| -> ([f64; 4], f64, f64) {
                let c = a[0] * e[0] - a[1] * e[1];
                let s = a[1] * e[0] + a[0] * e[1];
                ([u, s * fx - c * fy, c - a[0], s - a[1]], c, s)
            };
            // The tangent's right-hand side for each input k: (d delta, d u) = t[k], the tangent
            // angle (c, s) of the stage; the loads' own derivatives (1/EI along f_x, f_y).
            let var = |t: &[[f64; 2]; 3], c: f64, s: f64| -> [[f64; 4]; 3] {
                let m = c * fx + s * fy;
                [
                    [t[0][1], m * t[0][0] + s * g, -s * t[0][0], c * t[0][0]],
                    [t[1][1], m * t[1][0] - c * g, -s * t[1][0], c * t[1][0]],
                    [t[2][1], m * t[2][0], -s * t[2][0], c * t[2][0]],
                ]
            };
            let turn = |e: [f64; 2], x: f64| -> [f64; 2] {
                let (s, c) = sin_cos_small(x);
                [e[0] * c - e[1] * s, e[1] * c + e[0] * s]
            };
            let adv = |t: &[[f64; 2]; 3], k: &[[f64; 4]; 3], x: f64| -> [[f64; 2]; 3] {
                std::array::from_fn(|i| [t[i][0] + x * k[i][0], t[i][1] + x * k[i][1]])
            };
            let h = self.h;
            let (mut d, mut u, mut x, mut y) = (0.0, u0, 0.0, 0.0);
            let mut e = [1.0, 0.0];
            // Tangent state per input: d delta, d u, d x, d y.
            let mut ts = [[0.0f64; 2]; 3];
            ts[2][1] = 1.0;
            let mut tp = [[0.0f64; 2]; 3];
            for j in 0..STEPS {
                let (a0, am, a1) = (self.arc[2 * j], self.arc[2 * j + 1], self.arc[2 * j + 2]);
                let (k1, c1, s1) = rhs(a0, e, u);
                let v1 = var(&ts, c1, s1);
                let (k2, c2, s2) = rhs(am, turn(e, 0.5 * h * k1[0]), u + 0.5 * h * k1[1]);
                let v2 = var(&adv(&ts, &v1, 0.5 * h), c2, s2);
                let (k3, c3, s3) = rhs(am, turn(e, 0.5 * h * k2[0]), u + 0.5 * h * k2[1]);
                let v3 = var(&adv(&ts, &v2, 0.5 * h), c3, s3);
                let (k4, c4, s4) = rhs(a1, turn(e, h * k3[0]), u + h * k3[1]);
                let v4 = var(&adv(&ts, &v3, h), c4, s4);
                let w = h / 6.0;
                let dd = w * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0]);
                d += dd;
                e = turn(e, dd);
                u += w * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1]);
                x += w * (k1[2] + 2.0 * (k2[2] + k3[2]) + k4[2]);
                y += w * (k1[3] + 2.0 * (k2[3] + k3[3]) + k4[3]);
                for i in 0..3 {
                    let inc = |c: usize| w * (v1[i][c] + 2.0 * (v2[i][c] + v3[i][c]) + v4[i][c]);
                    ts[i][0] += inc(0);
                    ts[i][1] += inc(1);
                    tp[i][0] += inc(2);
                    tp[i][1] += inc(3);
                }
            }
            let jac = [
                [tp[0][0], tp[1][0], tp[2][0]],
                [tp[0][1], tp[1][1], tp[2][1]],
                [ts[0][0], ts[1][0], ts[2][0]],
            ];
            ([x, y, d], jac)
        }
    }

    /// The sweep's test strengths: a load of (0.4, -0.3) N and springs of 300 / 200 N mm/rad.
    fn springs_and_load() -> Loads {
        Loads {
            force: [0.4, -0.3],
            k_m: 300.0,
            k_p: 200.0,
            ..unloaded()
        }
    }

    fn unloaded() -> Loads {
        Loads {
            ei: 6.5e4,
            force: [0.0; 2],
            couple: 0.0,
            k_m: 0.0,
            k_p: 0.0,
        }
    }

    #[test]
    fn matches_the_independent_check_values_of_plant_md() {
        // Nominal robot at home, EI = 6.5e4 N mm^2: 1 N along +x moves the platform by
        // (+1.6602, -0.0085) mm and turns it by -0.0049 deg; +100 N mm turns it by +2.5132 deg.
        let r = Robot::nominal();
        let k = r.home_kappa;
        let home = Pose::default();
        let fx = r
            .fk_loaded(
                &k,
                &Loads {
                    force: [1.0, 0.0],
                    ..unloaded()
                },
                &home,
            )
            .unwrap();
        assert!((fx.pose.x - 1.6602).abs() < 0.01, "{:?}", fx.pose);
        assert!((fx.pose.y + 0.0085).abs() < 0.003, "{:?}", fx.pose);
        assert!((fx.pose.phi_deg() + 0.0049).abs() < 0.002, "{:?}", fx.pose);
        let mz = r
            .fk_loaded(
                &k,
                &Loads {
                    couple: 100.0,
                    ..unloaded()
                },
                &home,
            )
            .unwrap();
        assert!(
            (mz.pose.phi_deg() - 2.5132).abs() < 0.02,
            "{}",
            mz.pose.phi_deg()
        );
        assert!(
            mz.pose.x.abs() < 0.01 && mz.pose.y.abs() < 0.01,
            "{:?}",
            mz.pose
        );
        // Equal compliance along x and y (about 1.65 mm/N).
        let fy = r
            .fk_loaded(
                &k,
                &Loads {
                    force: [0.0, 1.0],
                    ..unloaded()
                },
                &home,
            )
            .unwrap();
        assert!((fy.pose.y - fx.pose.x).abs() < 0.01, "{:?}", fy.pose);
    }

    #[test]
    fn springs_are_relaxed_at_home_and_loaded_ik_inverts_loaded_fk() {
        let r = Robot::nominal();
        let springs = Loads {
            k_m: 200.0,
            k_p: 150.0,
            ..unloaded()
        };
        // Relaxed at the home motor positions (176 steps each: 22.098 deg, not the 22.050 deg
        // of the exact home pose), where the loaded model is the rigid one.
        assert_eq!(r.home_motor_steps(), [176.0; 3]);
        let kh: [f64; 3] = std::array::from_fn(|i| r.steps_to_kappa(i, 176.0));
        let rigid_home = r.fk(&kh).unwrap();
        let e = r.fk_loaded(&kh, &springs, &Pose::default()).unwrap();
        assert!(
            e.pose.position_distance(&rigid_home) < 1e-9
                && (e.pose.phi - rigid_home.phi).abs() < 1e-11,
            "{:?} vs {:?}",
            e.pose,
            rigid_home
        );
        assert!(e.lambda.iter().all(|l| l.abs() < 1e-9), "{:?}", e.lambda);
        let target = Pose::from_mm_deg(25.0, -15.0, 4.0);
        let loads = Loads {
            force: [0.3, -0.2],
            ..springs
        };
        let kappa = r.ik_loaded(&target, &loads).unwrap();
        let rigid = r.ik(&target).unwrap().kappa;
        assert!(
            (kappa[0] - rigid[0]).abs() > 1e-6,
            "the loads change the command"
        );
        let eq = r.fk_loaded(&kappa, &loads, &target).unwrap();
        assert!(eq.pose.position_distance(&target) < 1e-6, "{:?}", eq.pose);
        assert!((eq.pose.phi - target.phi).abs() < 1e-8);
        // Springs off and no load: the rigid model exactly.
        let eq0 = r.fk_loaded(&rigid, &unloaded(), &target).unwrap();
        assert!(eq0.pose.position_distance(&target) < 1e-9);
        assert_eq!(eq0.lambda, [0.0; 3]);
    }

    #[test]
    fn warm_started_loaded_fk_finds_the_cold_equilibrium_along_a_path() {
        let r = Robot::nominal();
        let loads = springs_and_load();
        let mut warm = LoadedWarm::default();
        for k in 0..=60 {
            // Along a line, back at the end (a reversal), then a jump across the workspace.
            let s = if k <= 40 {
                k as f64 / 40.0
            } else {
                (60 - k) as f64 / 20.0
            };
            let target = if k == 60 {
                Pose::from_mm_deg(-30.0, -20.0, 8.0)
            } else {
                Pose::from_mm_deg(-25.0 + 50.0 * s, 30.0 - 40.0 * s, -5.0 + 10.0 * s)
            };
            let kappa = r.ik(&target).unwrap().kappa;
            let cold = r.fk_loaded(&kappa, &loads, &target).unwrap();
            let hot = r
                .fk_loaded_warm(&kappa, &loads, &target, &mut warm)
                .unwrap();
            assert!(
                hot.pose.position_distance(&cold.pose) < 1e-8
                    && (hot.pose.phi - cold.pose.phi).abs() < 1e-9,
                "row {k}: {:?} vs {:?}",
                hot.pose,
                cold.pose
            );
            for i in 0..3 {
                assert!((hot.lambda[i] - cold.lambda[i]).abs() < 1e-7, "row {k}");
            }
        }
    }

    /// A solve resumed from the same configuration's state for nearby loads (a fit's
    /// evaluation after another) finds the cold equilibrium of the new loads.
    #[test]
    fn a_solve_resumed_from_nearby_loads_finds_the_cold_equilibrium() {
        let r = Robot::nominal();
        let loads = springs_and_load();
        let target = Pose::from_mm_deg(10.0, -5.0, 3.0);
        let kappa = r.ik(&target).unwrap().kappa;
        let mut first = LoadedWarm::default();
        r.fk_loaded_warm(&kappa, &loads, &target, &mut first)
            .unwrap();
        let nearby = Loads {
            force: [0.45, -0.28],
            k_m: 310.0,
            ..loads
        };
        // Another series' state (rest angles known), resumed from this row's.
        let mut warm = LoadedWarm::default();
        let other = Pose::from_mm_deg(-20.0, 15.0, -4.0);
        let k_other = r.ik(&other).unwrap().kappa;
        r.fk_loaded_warm(&k_other, &loads, &other, &mut warm)
            .unwrap();
        warm.resume_from(&first);
        let hot = r
            .fk_loaded_warm(&kappa, &nearby, &target, &mut warm)
            .unwrap();
        let cold = r.fk_loaded(&kappa, &nearby, &target).unwrap();
        assert!(hot.pose.position_distance(&cold.pose) < 1e-8);
        assert!((hot.pose.phi - cold.pose.phi).abs() < 1e-9);
        // Nothing to resume from: the state stays as it was.
        let before = warm.clone();
        warm.resume_from(&LoadedWarm::default());
        assert_eq!(warm.z, before.z);
    }

    #[test]
    fn load_response_is_the_derivative_of_the_loaded_pose() {
        let r = Robot::nominal();
        let target = Pose::from_mm_deg(-20.0, 30.0, -5.0);
        let kappa = r.ik(&target).unwrap().kappa;
        let base = Loads {
            force: [0.2, -0.1],
            k_m: 50.0,
            ..unloaded()
        };
        let resp = r.load_response(&kappa, &base, &target).unwrap();
        let p0 = r.fk_loaded(&kappa, &base, &target).unwrap().pose;
        for j in 0..5 {
            let mut l = base;
            let h = [1e-3, 1e-3, 1e-1, 1e-1, 1e-1][j];
            match j {
                0 => l.force[0] += h,
                1 => l.force[1] += h,
                2 => l.couple += h,
                3 => l.k_m += h,
                _ => l.k_p += h,
            }
            let p = r.fk_loaded(&kappa, &l, &target).unwrap().pose;
            let fd = [(p.x - p0.x) / h, (p.y - p0.y) / h, (p.phi - p0.phi) / h];
            for k in 0..3 {
                let tol = 1e-3 * fd[k].abs().max(resp[j][k].abs()) + 1e-9;
                assert!(
                    (fd[k] - resp[j][k]).abs() < tol.max(2e-6),
                    "param {j} comp {k}: {} vs {}",
                    resp[j][k],
                    fd[k]
                );
            }
        }
    }

    #[test]
    fn loaded_sensitivity_is_the_derivative_of_the_loaded_pose() {
        let r = Robot::nominal();
        let target = Pose::from_mm_deg(15.0, -25.0, 8.0);
        let kappa = r.ik(&target).unwrap().kappa;
        let base = Loads {
            force: [0.3, -0.2],
            couple: 5.0,
            k_m: 80.0,
            k_p: 40.0,
            ..unloaded()
        };
        let mut warm = LoadedWarm::default();
        let s = r
            .loaded_sensitivity_warm(&kappa, &base, &target, &mut warm)
            .unwrap();
        let p0 = r.fk_loaded(&kappa, &base, &target).unwrap().pose;
        assert!((s.pose.x - p0.x).abs() < 1e-7 && (s.pose.phi - p0.phi).abs() < 1e-9);
        let cold = r.load_response(&kappa, &base, &target).unwrap();
        for (a, b) in s.d_loads.iter().flatten().zip(cold.iter().flatten()) {
            assert!((a - b).abs() < 1e-5 * b.abs().max(1e-3), "{a} vs {b}");
        }
        for i in 0..3 {
            // Central differences of the cold solve: the derivative to second order.
            let h = 1e-6;
            let (mut kp, mut km) = (kappa, kappa);
            kp[i] += h;
            km[i] -= h;
            let pp = r.fk_loaded(&kp, &base, &target).unwrap().pose;
            let pm = r.fk_loaded(&km, &base, &target).unwrap().pose;
            let fd = [
                (pp.x - pm.x) / (2.0 * h),
                (pp.y - pm.y) / (2.0 * h),
                (pp.phi - pm.phi) / (2.0 * h),
            ];
            for k in 0..3 {
                let tol = 1e-4 * fd[k].abs().max(s.d_kappa[i][k].abs()) + 1e-6;
                assert!(
                    (fd[k] - s.d_kappa[i][k]).abs() < tol,
                    "leg {i} comp {k}: {} vs {}",
                    s.d_kappa[i][k],
                    fd[k]
                );
            }
        }
    }

    #[test]
    fn a_sensitivity_keeps_the_solutions_derivatives_and_the_next_solve_starts_along_them() {
        let (_, r, target, kappa) = nominal_at_target();
        let loads = Loads {
            force: [0.3, -0.2],
            k_m: 900.0,
            k_p: 600.0,
            ..unloaded()
        };
        let rest = r.home_joint_angles();
        let cold = |k: &[f64; 3]| {
            let st = r.loaded_setup_at_rest(k, rest);
            r.fk_loaded_in(&st, k, &loads, &target).unwrap()
        };
        let mut warm = LoadedWarm::default();
        r.loaded_sensitivity_warm(&kappa, &loads, &target, &mut warm)
            .unwrap();
        let (t, at) = warm.tangent.expect("a sensitivity keeps the derivatives");
        assert_eq!(at, kappa);
        // Every unknown's derivative (pose, link forces, joint displacements, base curvatures)
        // against central differences of the cold solve.
        for i in 0..3 {
            let h = 1e-6;
            let (mut kp, mut km) = (kappa, kappa);
            kp[i] += h;
            km[i] -= h;
            let fd = (cold(&kp) - cold(&km)) / (2.0 * h);
            let tol = 1e-4 * fd.amax() + 1e-6;
            assert!((fd - t[i]).amax() < tol, "leg {i}: {:?} vs {:?}", t[i], fd);
        }
        // A change of `b` rad of bending on each leg: how far the start along the derivatives
        // and the start from the old deflection (the new rigid pose plus the old offsets from
        // it, the rest unchanged) are from the new equilibrium, and how far that moved.
        let z0 = cold(&kappa);
        let starts = |b: f64| {
            let next: [f64; 3] = std::array::from_fn(|i| kappa[i] + b / r.legs[i].l_c);
            let z1 = cold(&next);
            let mut along = z0;
            for (c, (k, k0)) in t.iter().zip(next.iter().zip(kappa)) {
                along += c * (k - k0);
            }
            let (r0, r1) = (
                r.fk_warm(&kappa, &target).unwrap(),
                r.fk_warm(&next, &target).unwrap(),
            );
            let mut offsets = z0;
            offsets[0] += r1.x - r0.x;
            offsets[1] += r1.y - r0.y;
            offsets[2] += r1.phi - r0.phi;
            (
                next,
                z1,
                (z1 - along).amax(),
                (z1 - offsets).amax(),
                (z1 - z0).amax(),
            )
        };
        // A stretch between two anchors (0.1 rad): the joints move 4 mm under these springs,
        // the start along the derivatives is off by a tenth of that, the offsets' by all of
        // it; at a fifth of the change the error falls as its square.
        let (next, z1, off, off_offsets, moved) = starts(0.1);
        assert!(
            off < 0.15 * moved && off < 0.15 * off_offsets,
            "{off} {off_offsets} {moved}"
        );
        let (_, _, off_small, _, _) = starts(0.02);
        assert!(off_small < off / 15.0, "{off_small} against {off}");
        let e = r.fk_loaded_warm(&next, &loads, &target, &mut warm).unwrap();
        assert!((e.pose.x - z1[0]).abs() < 1e-7 && (e.pose.y - z1[1]).abs() < 1e-7);
        assert!((e.pose.phi - z1[2]).abs() < 1e-9);
    }

    /// The nominal robot at a pose off home, with its curvatures there: where the tests of the
    /// loaded directions linearise.
    fn nominal_at_target() -> (pcr_robot::RobotConfig, Robot, Pose, [f64; 3]) {
        let cfg = pcr_robot::RobotConfig::nominal();
        let r = Robot::new(&cfg).unwrap();
        let target = Pose::from_mm_deg(15.0, -25.0, 8.0);
        let kappa = r.ik(&target).unwrap().kappa;
        (cfg, r, target, kappa)
    }

    #[test]
    fn the_pose_rows_of_the_inverse_respond_as_a_solve_through_the_factored_jacobian() {
        // The responses read the first three components of -J^-1 df: the rows of the inverse
        // give them (other roundings), for the Jacobian of a loaded equilibrium with springs
        // and for random changes of the residual.
        let (_, r, target, kappa) = nominal_at_target();
        let loads = springs_and_load();
        let lin = r
            .linearised_warm(&kappa, &loads, &target, &mut LoadedWarm::default())
            .unwrap();
        let jac = r.loaded_jacobian(&lin.st, &loads, &lin.z, &lin.segs, &lin.f0);
        let lu = jac.lu();
        let mut seed = 0x2545_f491_4f6c_dd1d_u64;
        for _ in 0..50 {
            let df = VN::from_fn(|_, _| {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            });
            let dz = lu.solve(&(-df)).unwrap();
            let got = lin.rows.response(&df);
            for k in 0..3 {
                let scale = dz.amax().max(1e-300);
                assert!(
                    (got[k] - dz[k]).abs() <= 1e-10 * scale,
                    "component {k}: {} against {}",
                    got[k],
                    dz[k]
                );
            }
        }
        assert!(PoseRows::of(&MN::zeros()).is_none());
    }

    /// [`Robot::loaded_directions_warm`]'s columns as they were before its legs were assembled
    /// one by one: each direction's residual evaluated whole, its three segments integrated.
    fn whole_columns(
        r: &Robot,
        kappa: &[f64; 3],
        loads: &Loads,
        guess: &Pose,
        dirs: &[Direction<'_>],
        out: &mut [[f64; 3]],
    ) -> Pose {
        let lin = r
            .linearised_warm(kappa, loads, guess, &mut LoadedWarm::default())
            .unwrap();
        let exact = r.loaded_eval(&lin.st, loads, &lin.z, SegmentMode::Exact);
        for (d, o) in dirs.iter().zip(out.iter_mut()) {
            let st = d.robot.loaded_setup_at_rest(&d.kappa, d.rest);
            let res = d.robot.loaded_eval(&st, loads, &lin.z, SegmentMode::Exact);
            *o = lin.rows.response(&((res - exact) / d.step));
        }
        Pose::new(lin.z[0], lin.z[1], lin.z[2])
    }

    #[test]
    fn loaded_directions_assembled_leg_by_leg_are_the_whole_evaluations() {
        // Each kind of direction: a leg's base (its segment the same, linearised, and under
        // springs every leg's rest angles moved), a segment length (integrated again), a
        // platform joint, a map gain (a curvature), and no change at all.
        let (cfg, r, target, kappa) = nominal_at_target();
        type Change = fn(&mut pcr_robot::RobotConfig, f64);
        let changes: [Change; 5] = [
            |c, h| c.legs[0].psi_deg += h,
            |c, h| c.legs[0].l_c_mm += h,
            |c, h| c.legs[1].r_p_mm += h,
            |c, h| c.legs[2].r_base_mm += h,
            |_, _| {},
        ];
        let step = 1e-3;
        let others: Vec<Robot> = changes
            .iter()
            .map(|f| {
                let mut c = cfg.clone();
                f(&mut c, step);
                Robot::new(&c).unwrap()
            })
            .collect();
        for loads in [
            springs_and_load(),
            Loads {
                force: [0.6, -0.4],
                ..unloaded()
            },
        ] {
            let mut dirs: Vec<Direction> = others
                .iter()
                .map(|o| Direction {
                    robot: o,
                    kappa,
                    rest: o.home_joint_angles(),
                    step,
                })
                .collect();
            // A curvature: leg 2's map.
            dirs.push(Direction {
                robot: &r,
                kappa: [kappa[0], kappa[1] * (1.0 + step), kappa[2]],
                rest: r.home_joint_angles(),
                step,
            });
            let (mut a, mut b) = (vec![[0.0; 3]; dirs.len()], vec![[0.0; 3]; dirs.len()]);
            let pa = r
                .loaded_directions_warm(
                    &kappa,
                    &loads,
                    &target,
                    &mut LoadedWarm::default(),
                    &dirs,
                    &mut a,
                )
                .unwrap();
            let pb = whole_columns(&r, &kappa, &loads, &target, &dirs, &mut b);
            assert_eq!(pa, pb);
            // The unchanged robot's column is zero either way; a curvature's and a length's
            // (segments integrated again, the others' shares kept) are the whole evaluation's
            // to rounding; the linearised legs' to first order in the step (1e-8 of the
            // column at a step of 1e-3).
            assert_eq!(a[4], [0.0; 3]);
            assert_eq!(b[4], [0.0; 3]);
            for (k, (x, y)) in a.iter().zip(&b).enumerate() {
                let scale = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                for c in 0..3 {
                    assert!(
                        (x[c] - y[c]).abs() <= 1e-7 * scale + 1e-12,
                        "direction {k} comp {c}: {} vs {} (whole)",
                        x[c],
                        y[c]
                    );
                }
            }
        }
    }

    #[test]
    fn loaded_directions_are_the_derivatives_toward_other_robots() {
        // Strong springs and a load: a change of the drawing moves the loaded pose differently
        // from the rigid one (the springs' rest angles move with it), and a change of the map
        // moves the curvatures.
        let (cfg, r, target, kappa) = nominal_at_target();
        let loads = Loads {
            force: [0.6, -0.4],
            k_m: 900.0,
            k_p: 600.0,
            ..unloaded()
        };
        let dl: [f64; 3] = std::array::from_fn(|i| {
            let m = &r.legs[i].map;
            // The tendon displacement that gives kappa (bisection on the monotonic map).
            let (mut lo, mut hi) = (-60.0, 60.0);
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if (m.kappa(mid) - kappa[i]) * (m.kappa(hi) - m.kappa(lo)) > 0.0 {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            0.5 * (lo + hi)
        });
        type Change = fn(&mut pcr_robot::RobotConfig, f64);
        let changes: [(&str, Change); 5] = [
            ("psi[1]", |c, h| c.legs[0].psi_deg += h),
            ("l_c[1]", |c, h| c.legs[0].l_c_mm += h),
            ("r_p[2]", |c, h| c.legs[1].r_p_mm += h),
            ("theta_p[3]", |c, h| c.legs[2].theta_p_deg += h),
            ("map gain[2]", |c, h| {
                let k0 = 1.0 / (c.legs[1].actuation.tendon_offset_mm * c.legs[1].l_c_mm);
                let m = &mut c.legs[1].tendon_map;
                if m.coeffs.is_empty() {
                    m.coeffs = vec![k0];
                }
                m.coeffs[0] *= 1.0 + h;
            }),
        ];
        let robot_of = |f: Change, h: f64| {
            let mut c = cfg.clone();
            f(&mut c, h);
            Robot::new(&c).unwrap()
        };
        let step = 1e-5;
        let others: Vec<Robot> = changes.iter().map(|(_, f)| robot_of(*f, step)).collect();
        let dirs: Vec<Direction> = others
            .iter()
            .map(|o| Direction {
                robot: o,
                kappa: std::array::from_fn(|i| o.legs[i].map.kappa(dl[i])),
                rest: o.home_joint_angles(),
                step,
            })
            .collect();
        let mut out = vec![[0.0; 3]; dirs.len()];
        let mut warm = LoadedWarm::default();
        let pose = r
            .loaded_directions_warm(&kappa, &loads, &target, &mut warm, &dirs, &mut out)
            .unwrap();
        let p0 = r.fk_loaded(&kappa, &loads, &target).unwrap().pose;
        assert!((pose.x - p0.x).abs() < 1e-7 && (pose.phi - p0.phi).abs() < 1e-9);
        let mut differs_from_rigid = false;
        for (k, (name, f)) in changes.iter().enumerate() {
            // Central differences of the cold solves of the changed robots.
            let h = 1e-4;
            let solve = |h: f64| {
                let o = robot_of(*f, h);
                let kp: [f64; 3] = std::array::from_fn(|i| o.legs[i].map.kappa(dl[i]));
                o.fk_loaded(&kp, &loads, &target).unwrap().pose
            };
            let (pp, pm) = (solve(h), solve(-h));
            let fd = [
                (pp.x - pm.x) / (2.0 * h),
                (pp.y - pm.y) / (2.0 * h),
                (pp.phi - pm.phi) / (2.0 * h),
            ];
            let scale = fd.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            for c in 0..3 {
                assert!(
                    (fd[c] - out[k][c]).abs() < 2e-3 * scale + 1e-7,
                    "{name} comp {c}: {} vs {} (central differences)",
                    out[k][c],
                    fd[c]
                );
            }
            // The rigid model's change for the same parameter, at the same curvatures.
            let o = robot_of(*f, h);
            let kp: [f64; 3] = std::array::from_fn(|i| o.legs[i].map.kappa(dl[i]));
            let rp = o.fk_warm(&kp, &p0).unwrap();
            let rm = robot_of(*f, -h);
            let km: [f64; 3] = std::array::from_fn(|i| rm.legs[i].map.kappa(dl[i]));
            let rmp = rm.fk_warm(&km, &p0).unwrap();
            let rd = [(rp.x - rmp.x) / (2.0 * h), (rp.y - rmp.y) / (2.0 * h)];
            if (rd[0] - fd[0]).abs().max((rd[1] - fd[1]).abs()) > 0.1 * scale {
                differs_from_rigid = true;
            }
        }
        assert!(differs_from_rigid, "springs this strong change the columns");
    }

    #[test]
    fn variational_equations_are_the_derivatives_of_the_integration() {
        let r = Robot::nominal();
        let ei = 6.5e4;
        for (i, kappa, f, u0) in [
            (0, 0.00307872, [0.7, -0.4], 1e-4),
            (1, 0.012, [-3.0, 2.0], -2e-3),
            (2, -0.006, [12.0, 5.0], 5e-3),
        ] {
            let seg = Segment::new(&r.legs[i], kappa);
            let o = seg.deflect(ei, f, u0);
            let (oj, jac) = seg.deflect_jac(ei, f, u0);
            assert_eq!(o, oj);
            let segs = [
                Segment::new(&r.legs[0], kappa),
                Segment::new(&r.legs[1], -kappa),
                Segment::new(&r.legs[i], kappa),
            ];
            let three = deflect3(&segs, ei, [[0.1, 0.2], f, f], [1e-5, u0, u0]);
            assert_eq!(three[2], o);
            assert_eq!(three[1], segs[1].deflect(ei, f, u0));
            let (o3, j3) = deflect_jac3(&segs, ei, [[0.1, 0.2], f, f], [1e-5, u0, u0]);
            assert_eq!((o3[2], j3[2]), (o, jac));
            assert_eq!((o3[0], j3[0]), segs[0].deflect_jac(ei, [0.1, 0.2], 1e-5));
            for k in 0..3 {
                let h = if k < 2 { 1e-5 } else { 1e-8 };
                let mut p = [f[0], f[1], u0];
                let mut m = p;
                p[k] += h;
                m[k] -= h;
                let op = seg.deflect(ei, [p[0], p[1]], p[2]);
                let om = seg.deflect(ei, [m[0], m[1]], m[2]);
                for c in 0..3 {
                    let fd = (op[c] - om[c]) / (2.0 * h);
                    assert!(
                        (fd - jac[c][k]).abs() < 1e-6 * fd.abs().max(1e-3),
                        "seg {i} out {c} in {k}: {} vs {fd}",
                        jac[c][k]
                    );
                }
            }
        }
    }

    /// A straight segment whose total bending the tendons hold at zero, under a force across
    /// its tip, is a clamped-guided beam: two cantilevers of half its length, antisymmetric
    /// about the middle, each under the tip force. Their large deflection is the classical
    /// elastica of Bisshopp and Drucker (1945): at P (l/2)^2 / EI = 1 the half's tip moves
    /// 0.30172 across and 0.05643 along (of l/2), at 2 by 0.49346 and 0.16064 (linear theory:
    /// 1/3 and 2/3 across, nothing along).
    #[test]
    fn a_straight_segment_bends_as_the_classical_elastica() {
        let r = Robot::nominal();
        let leg = &r.legs[0];
        let seg = Segment::new(leg, 0.0);
        let ei = 6.5e4;
        let half = 0.5 * leg.l_c;
        for (alpha, across, along) in [(1.0, 0.30172, 0.05643), (2.0, 0.49346, 0.16064)] {
            let p = alpha * ei / (half * half);
            // The base curvature that keeps the total bending: Newton on delta(l_C), along the
            // load from zero.
            let mut u0 = 0.0;
            for k in 1..=10 {
                let pk = p * k as f64 / 10.0;
                for _ in 0..20 {
                    let d = seg.deflect(ei, [pk, 0.0], u0)[2];
                    let h = 1e-9;
                    let dd = (seg.deflect(ei, [pk, 0.0], u0 + h)[2] - d) / h;
                    u0 -= d / dd;
                }
            }
            let o = seg.deflect(ei, [p, 0.0], u0);
            assert!(o[2].abs() < 1e-9, "{:?}", o);
            let want = [2.0 * across * half, -2.0 * along * half];
            // Within 0.1 % of the deflection (eight RK4 steps; 0.01 mm at alpha = 2, where the
            // tip moves 62 mm across and 20 mm along).
            let tol = 1e-3 * g::norm(want);
            assert!(
                (o[0] - want[0]).abs() < tol && (o[1] - want[1]).abs() < tol,
                "alpha {alpha}: {:?} vs {want:?}",
                o
            );
        }
    }

    /// Large loads on the whole robot against equilibria the plant (`pcr-plant`, an independent
    /// elastica shooting with 50 RK4 steps per segment) computed for the nominal robot at whole
    /// motor steps: 10x the validation springs (tip loads up to 16 N, four times EI / l_C^2,
    /// the platform 30 mm from its rigid pose), 5x the validation wrench, and springs and
    /// wrench together. The springs are relaxed at the home motor positions (176 steps) in both.
    #[test]
    fn large_loads_match_the_elastica_of_the_plant() {
        let r = Robot::nominal();
        let cases = [
            (
                [436.0, -49.0, 327.0],
                Loads {
                    k_m: 3000.0,
                    k_p: 2000.0,
                    ..unloaded()
                },
                [1.83600, -48.07076, 6.15379],
            ),
            (
                [45.0, 167.0, 491.0],
                Loads {
                    force: [2.0, -1.5],
                    ..unloaded()
                },
                [-47.71539, -32.00819, 7.22937],
            ),
            (
                [267.0, 272.0, 168.0],
                Loads {
                    force: [1.2, -0.9],
                    k_m: 900.0,
                    k_p: 600.0,
                    ..unloaded()
                },
                [12.42124, 6.57216, 8.88855],
            ),
        ];
        for (q, loads, want) in cases {
            let kappa: [f64; 3] = std::array::from_fn(|i| r.steps_to_kappa(i, q[i]));
            let rigid = r.fk(&kappa).unwrap();
            let eq = r.fk_loaded(&kappa, &loads, &rigid).unwrap();
            let p = eq.pose;
            assert!(
                (p.x - want[0]).abs() < 5e-3
                    && (p.y - want[1]).abs() < 5e-3
                    && (p.phi_deg() - want[2]).abs() < 2e-3,
                "{q:?}: {p:?} vs {want:?}"
            );
            // The load moved the platform by millimetres: the check is not the rigid model's.
            assert!(p.position_distance(&rigid) > 2.0, "{q:?}");
            // Warm along a path to the same point gives the same equilibrium.
            let mut warm = LoadedWarm::default();
            for k in 0..=10 {
                let s = k as f64 / 10.0;
                let kk: [f64; 3] =
                    std::array::from_fn(|i| r.steps_to_kappa(i, 176.0 + s * (q[i] - 176.0)));
                let g = r.fk(&kk).unwrap();
                let hot = r.fk_loaded_warm(&kk, &loads, &g, &mut warm).unwrap();
                if k == 10 {
                    assert!(hot.pose.position_distance(&p) < 1e-7, "{q:?}");
                }
            }
        }
    }

    /// The elastica's small-load limit is the linear compliance of beam theory along the arc
    /// ([`Robot::tip_compliance`]), and the integration converges: 8 steps against 64.
    #[test]
    fn small_loads_give_the_linear_compliance() {
        let r = Robot::nominal();
        let ei = 6.5e4;
        for (i, kappa) in [(0, 0.00307872), (1, 0.012), (2, -0.006)] {
            let leg = &r.legs[i];
            let seg = Segment::new(leg, kappa);
            let c = r.tip_compliance(i, kappa, ei);
            for (axis, f) in [[1e-4, 0.0], [0.0, 1e-4]].iter().enumerate() {
                let fl = leg.to_local(*f);
                let mut u0 = 0.0;
                for _ in 0..10 {
                    let d = seg.deflect(ei, fl, u0)[2];
                    let h = 1e-10;
                    u0 -= d / ((seg.deflect(ei, fl, u0 + h)[2] - d) / h);
                }
                let o = seg.deflect(ei, fl, u0);
                let disp = leg.to_base([o[0], o[1]]);
                for k in 0..2 {
                    let lin = c[k][axis] * 1e-4;
                    assert!(
                        (disp[k] - lin).abs() < 2e-3 * c[0][0].abs().max(c[1][1].abs()) * 1e-4,
                        "leg {i} axis {axis}: {disp:?} vs {lin}"
                    );
                }
            }
        }
    }
}
