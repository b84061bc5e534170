//! Kineto-static equilibrium of the whole robot: three elastica segments, rigid extensions and
//! links, passive joint springs and friction, and the platform under an external wrench.
//!
//! Unknowns (12): the platform pose (x, y, phi), the tip load F_i of each segment (2 each; the
//! link force is f_i = f_fric,M_i - F_i, so lambda_i = f_i . u_i) and the shooting unknown
//! m_i(0). Equations (12): per leg the tendon constraint theta(l_C) - theta(0) = -phi_b,i, the
//! link length |P_i - M_i| = l_st and the link's moment balance (f_i . n_i = (tau_M + tau_P) /
//! l_st); the platform's force and moment balance. Newton with the segment Jacobians from the
//! variational equations and the cheap algebraic part differentiated numerically.

use crate::model::LegGeometry;
use crate::segment::{self, SegmentEnd, SegmentParams};
use nalgebra::{SMatrix, SVector};
use pcr_robot::geometry::{add, cross, dot, norm, perp, rot, scale, signed_angle, sub, Vec2};

/// A factorised Jacobian of the equilibrium equations, kept between solves.
#[derive(Debug, Clone)]
pub struct JacobianCache {
    /// Inverse Jacobian, kept current by Broyden updates between refreshes.
    inv: Mat,
    /// Sign of its determinant.
    pub det_sign: f64,
}

/// A quasi-Newton step must shrink the residual at least by this factor, else the Jacobian is
/// refreshed.
const CHORD_CONTRACTION: f64 = 0.5;

/// Number of unknowns.
pub const N: usize = 12;
type Mat = SMatrix<f64, N, N>;
type Vecn = SVector<f64, N>;

/// Which joint of a leg.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Joint {
    /// The passive joint M_i at the tip extension.
    M,
    /// The passive joint P_i on the platform.
    P,
}

impl std::fmt::Display for Joint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Joint::M => "M",
            Joint::P => "P",
        })
    }
}

/// Why no equilibrium was found. Legs are numbered 1..=3.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StaticsError {
    /// The commanded bending is outside the bending range.
    #[error(
        "leg {leg}: bending {bending_deg:.2} deg is outside the bending range +-{max_deg:.1} deg"
    )]
    BendingRange {
        /// Leg 1..=3.
        leg: usize,
        /// Requested bending, degrees.
        bending_deg: f64,
        /// Limit, degrees.
        max_deg: f64,
    },
    /// A passive joint angle of the equilibrium is outside the joint range.
    #[error("leg {leg}: joint {joint} angle {angle_deg:.2} deg is outside the joint range [{min_deg:.1}, {max_deg:.1}] deg")]
    JointRange {
        /// Leg 1..=3.
        leg: usize,
        /// Which joint.
        joint: Joint,
        /// Its angle, degrees.
        angle_deg: f64,
        /// Lower limit, degrees.
        min_deg: f64,
        /// Upper limit, degrees.
        max_deg: f64,
    },
    /// A segment under its tip load has passed its buckling (Jacobi conjugate point) limit.
    #[error("leg {leg}: the segment buckles under its tip load of {load_n:.3} N")]
    Buckling {
        /// Leg 1..=3.
        leg: usize,
        /// Magnitude of the tip load, N.
        load_n: f64,
    },
    /// The platform would pass a type-2 singularity (det A changes sign) and leave the robot's
    /// assembly mode.
    #[error("the platform reaches a singularity (det A changes sign from {from:+.3e} to {to:+.3e}): it would leave the robot's assembly mode")]
    AssemblyMode {
        /// det A before, mm^3-ish units of geometry.md.
        from: f64,
        /// det A after.
        to: f64,
    },
    /// The equilibrium loses its stability (the tangent stiffness of the whole robot changes
    /// sign: snap-through or buckling of the robot).
    #[error("the equilibrium loses its stability (snap-through or buckling of the robot)")]
    Unstable,
    /// The equilibrium path from home ends (a singularity or limit point of the whole robot).
    #[error("no equilibrium in the robot's assembly mode: the path from home passes a singularity at {fraction:.3} of the way")]
    Singular {
        /// Fraction of the continuation path where it happened.
        fraction: f64,
    },
    /// Newton did not converge.
    #[error(
        "static solve did not converge: residual {residual:.3e} after {iterations} iterations"
    )]
    NoConvergence {
        /// Iterations done.
        iterations: usize,
        /// Final scaled residual (mm / N).
        residual: f64,
    },
}

/// Passive joint springs, relaxed at gamma0, zeta0 (rad).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Springs {
    /// Stiffness at M_i, N mm/rad.
    pub k_m: f64,
    /// Stiffness at P_i, N mm/rad.
    pub k_p: f64,
    /// Rest angles at M_i, rad.
    pub gamma0: [f64; 3],
    /// Rest angles at P_i, rad.
    pub zeta0: [f64; 3],
}

/// Friction parameters (Jenkins elements: stiff spring in series with a Coulomb slider).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrictionParams {
    /// Slip torque of a passive joint, N mm (0 = off).
    pub joint_torque: f64,
    /// Stick stiffness of a joint, N mm/rad.
    pub joint_stiffness: f64,
    /// Slip force of a support on the base plate, N (0 = off).
    pub support_force: f64,
    /// Stick stiffness of a support, N/mm.
    pub support_stiffness: f64,
}

/// Where each friction element sticks (its history).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrictionAnchors {
    /// Anchor angles of the joints at M_i, rad.
    pub gamma: [f64; 3],
    /// Anchor angles of the joints at P_i, rad.
    pub zeta: [f64; 3],
    /// Anchor points of the supports at M_i, mm.
    pub m: [Vec2; 3],
    /// Anchor points of the supports at P_i, mm.
    pub p: [Vec2; 3],
}

/// Everything the equilibrium depends on besides the robot.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Loads {
    /// Bending of each segment phi_b,i (rad), from the tendon map.
    pub phi_b: [f64; 3],
    /// External wrench at E: (Fx N, Fy N, Mz N mm), base frame.
    pub wrench: [f64; 3],
    /// Friction: parameters and anchors (None = no friction).
    pub friction: Option<(FrictionParams, FrictionAnchors)>,
}

/// The model the solver works on.
#[derive(Debug, Clone, PartialEq)]
pub struct Statics {
    /// True leg geometry.
    pub legs: [LegGeometry; 3],
    /// Bending stiffness, N mm^2.
    pub ei: f64,
    /// RK4 steps per segment.
    pub steps: usize,
    /// Joint springs.
    pub springs: Springs,
    /// Joint range, rad.
    pub joint_range: (f64, f64),
    /// Largest |bending|, rad.
    pub bending_max: f64,
    /// Convergence tolerance on the scaled residual (mm and N).
    pub tol: f64,
    /// Newton iteration limit per solve.
    pub max_iter: usize,
}

/// One solved equilibrium with every derived quantity.
#[derive(Debug, Clone, PartialEq)]
pub struct Equilibrium {
    /// The unknowns: x, y, phi, F_1..3 (x, y), m_1..3(0).
    pub z: [f64; N],
    /// Platform pose (x mm, y mm, phi rad).
    pub pose: [f64; 3],
    /// Segment tips, mm.
    pub tip: [Vec2; 3],
    /// Tip tangent angles, rad.
    pub tip_theta: [f64; 3],
    /// Passive joints M_i, mm.
    pub m: [Vec2; 3],
    /// Platform joints P_i, mm.
    pub p: [Vec2; 3],
    /// Joint angles gamma_i at M_i, rad.
    pub gamma: [f64; 3],
    /// Joint angles zeta_i at P_i, rad.
    pub zeta: [f64; 3],
    /// Link forces on the platform f_i, N.
    pub link_force: [Vec2; 3],
    /// Axial link forces lambda_i = f_i . u_i with u_i = (P_i - M_i)/l_st: the link pushes the
    /// platform away from M_i when positive (compression), N.
    pub lambda: [f64; 3],
    /// Tendon moment T_i = m_i(l_C) minus the tip couples, N mm.
    pub tendon_moment: [f64; 3],
    /// Segment tip loads F_i, N.
    pub tip_load: [Vec2; 3],
    /// Joint couples on the link at M_i and P_i (springs + friction), N mm.
    pub joint_torque: [[f64; 2]; 3],
    /// Friction forces of the supports at M_i and P_i, N.
    pub support_force: [[Vec2; 2]; 3],
    /// Final scaled residual.
    pub residual: f64,
    /// Newton iterations used.
    pub iterations: usize,
    /// Sign of det of the Jacobian (assembly-mode indicator along a path).
    pub det_sign: f64,
    /// det A of the platform's loop closure h_i = |P_i - M_i|^2 - l_st^2 with respect to the
    /// pose (x mm, y mm, phi rad) at the current M_i: its sign is the assembly mode (geometry.md:
    /// positive at home), zero at a type-2 singularity.
    pub det_a: f64,
    /// d theta(l_C) / d m(0) per segment (> 0: no conjugate point, no buckling), rad/(N mm).
    pub jacobi: [f64; 3],
}

/// How far (in units of limit / stiffness) a friction element stretches before it slips: the
/// element's force is `limit tanh(stiffness x / limit)`, smooth so that Newton converges, and the
/// anchor follows once `|x|` exceeds this many slip lengths (tanh(3) = 0.995).
pub const SLIP_STRETCH: f64 = 3.0;

/// Smoothed Jenkins element of a joint: couple on the link, N mm.
#[inline]
pub fn joint_friction(k: f64, limit: f64, angle: f64, anchor: f64) -> f64 {
    -limit * (k * (angle - anchor) / limit).tanh()
}

/// Smoothed Jenkins element of a support: force on the body, N.
#[inline]
pub fn support_friction(k: f64, limit: f64, p: Vec2, anchor: Vec2) -> Vec2 {
    let d = sub(p, anchor);
    let n = norm(d);
    if n * k < 1e-12 * limit {
        return scale(-k, d);
    }
    scale(-limit * (k * n / limit).tanh() / n, d)
}

/// The anchor of a joint friction element after the body moved to `angle` (slip).
pub fn joint_anchor_after(k: f64, limit: f64, angle: f64, anchor: f64) -> f64 {
    let max = SLIP_STRETCH * limit / k;
    let x = angle - anchor;
    if x.abs() > max {
        angle - x.signum() * max
    } else {
        anchor
    }
}

/// The anchor of a support friction element after the body moved to `p` (slip).
pub fn support_anchor_after(k: f64, limit: f64, p: Vec2, anchor: Vec2) -> Vec2 {
    let max = SLIP_STRETCH * limit / k;
    let d = sub(p, anchor);
    let n = norm(d);
    if n > max {
        sub(p, scale(max / n, d))
    } else {
        anchor
    }
}

/// Per-segment outputs the algebraic part uses: tip (x, y) relative to the base and theta(l_C).
type SegOut = [[f64; 3]; 3];

/// What one leg contributes to the residual.
struct LegTerms {
    /// Tendon constraint (mm), link length (mm), link moment balance (N).
    r: [f64; 3],
    /// Force on the platform (link + support friction at P), N.
    force: Vec2,
    /// Its moment about E plus the joint couple at P, N mm.
    moment: f64,
    tip: Vec2,
    m: Vec2,
    p: Vec2,
    gamma: f64,
    zeta: f64,
    f: Vec2,
    tau: [f64; 2],
    fs: [Vec2; 2],
}

struct Algebra {
    r: [f64; N],
    tip: [Vec2; 3],
    m: [Vec2; 3],
    p: [Vec2; 3],
    gamma: [f64; 3],
    zeta: [f64; 3],
    f: [Vec2; 3],
    tau: [[f64; 2]; 3],
    fs: [[Vec2; 2]; 3],
}

impl Statics {
    fn seg_params(&self, i: usize) -> SegmentParams {
        SegmentParams {
            theta0: self.legs[i].theta0,
            length: self.legs[i].l_c,
            ei: self.ei,
            steps: self.steps,
        }
    }

    fn segments(&self, z: &[f64; N]) -> [SegmentEnd; 3] {
        std::array::from_fn(|i| {
            segment::integrate(&self.seg_params(i), z[9 + i], [z[3 + 2 * i], z[4 + 2 * i]])
        })
    }

    /// The algebraic terms of leg `i` for the platform pose, the segment's tip load and its tip
    /// (x, y relative to the base, theta).
    fn leg_terms(
        &self,
        i: usize,
        loads: &Loads,
        pose: [f64; 3],
        load: Vec2,
        s: [f64; 3],
    ) -> LegTerms {
        let g = &self.legs[i];
        let sp = &self.springs;
        let tip = add(g.base, [s[0], s[1]]);
        let th = s[2];
        let t = [th.cos(), th.sin()];
        let m = add(tip, scale(g.l_ce, t));
        let pe = rot(pose[2], g.p_e);
        let p = add([pose[0], pose[1]], pe);
        let d = sub(p, m);
        let len = norm(d);
        let u = scale(1.0 / len, d);
        let n = perp(u);
        let gamma = signed_angle(t, u);
        let zeta = signed_angle(pe, scale(-1.0, u));
        let mut tau_m = -sp.k_m * (gamma - sp.gamma0[i]);
        let mut tau_p = -sp.k_p * (zeta - sp.zeta0[i]);
        let mut f_m = [0.0, 0.0];
        let mut f_p = [0.0, 0.0];
        if let Some((fp, an)) = &loads.friction {
            if fp.joint_torque > 0.0 {
                tau_m += joint_friction(fp.joint_stiffness, fp.joint_torque, gamma, an.gamma[i]);
                tau_p += joint_friction(fp.joint_stiffness, fp.joint_torque, zeta, an.zeta[i]);
            }
            if fp.support_force > 0.0 {
                f_m = support_friction(fp.support_stiffness, fp.support_force, m, an.m[i]);
                f_p = support_friction(fp.support_stiffness, fp.support_force, p, an.p[i]);
            }
        }
        let f = sub(f_m, load);
        let fp_total = add(f, f_p);
        LegTerms {
            r: [
                (th - g.theta0 + loads.phi_b[i]) * g.l_c,
                len - g.l_st,
                dot(f, n) - (tau_m + tau_p) / g.l_st,
            ],
            force: fp_total,
            moment: cross(pe, fp_total) - tau_p,
            tip,
            m,
            p,
            gamma,
            zeta,
            f,
            tau: [tau_m, tau_p],
            fs: [f_m, f_p],
        }
    }

    /// Scale of the platform's moment equation (N mm -> N).
    fn moment_scale(&self) -> f64 {
        1.0 / self.legs[0].p_e[0].hypot(self.legs[0].p_e[1]).max(1.0)
    }

    /// The algebraic part of the residual, given the segment outputs.
    fn algebra(&self, loads: &Loads, z: &[f64; N], s: &SegOut) -> Algebra {
        let mut a = Algebra {
            r: [0.0; N],
            tip: [[0.0; 2]; 3],
            m: [[0.0; 2]; 3],
            p: [[0.0; 2]; 3],
            gamma: [0.0; 3],
            zeta: [0.0; 3],
            f: [[0.0; 2]; 3],
            tau: [[0.0; 2]; 3],
            fs: [[[0.0; 2]; 2]; 3],
        };
        let pose = [z[0], z[1], z[2]];
        let mut fsum = [loads.wrench[0], loads.wrench[1]];
        let mut msum = loads.wrench[2];
        for i in 0..3 {
            let l = self.leg_terms(i, loads, pose, [z[3 + 2 * i], z[4 + 2 * i]], s[i]);
            a.r[i] = l.r[0];
            a.r[3 + i] = l.r[1];
            a.r[6 + i] = l.r[2];
            fsum = add(fsum, l.force);
            msum += l.moment;
            a.tip[i] = l.tip;
            a.m[i] = l.m;
            a.p[i] = l.p;
            a.gamma[i] = l.gamma;
            a.zeta[i] = l.zeta;
            a.f[i] = l.f;
            a.tau[i] = l.tau;
            a.fs[i] = l.fs;
        }
        a.r[9] = fsum[0];
        a.r[10] = fsum[1];
        a.r[11] = msum * self.moment_scale();
        a
    }

    fn seg_out(ends: &[SegmentEnd; 3]) -> SegOut {
        std::array::from_fn(|i| [ends[i].pos[0], ends[i].pos[1], ends[i].theta])
    }

    fn segments_light(&self, z: &[f64; N]) -> [SegmentEnd; 3] {
        std::array::from_fn(|i| {
            segment::integrate_light(&self.seg_params(i), z[9 + i], [z[3 + 2 * i], z[4 + 2 * i]])
        })
    }

    fn residual_light(&self, loads: &Loads, z: &[f64; N]) -> ([f64; N], [SegmentEnd; 3]) {
        let ends = self.segments_light(z);
        let a = self.algebra(loads, z, &Self::seg_out(&ends));
        (a.r, ends)
    }

    /// The inverted Jacobian at `z` (for [`Statics::solve_cached`]); None if singular.
    pub fn jacobian_at(&self, loads: &Loads, z: &[f64; N]) -> Option<JacobianCache> {
        let ends = self.segments(z);
        let lu = self.jacobian(loads, z, &ends).lu();
        let det_sign = lu.determinant().signum();
        Some(JacobianCache {
            inv: lu.try_inverse()?,
            det_sign,
        })
    }

    /// Quasi-Newton (Broyden) iteration with an inverse Jacobian kept from earlier solves
    /// (`cache`), refreshed only when a step stops contracting. Residual evaluations carry no
    /// sensitivities, so a warm solve costs a few cheap shots. Checks only convergence.
    pub fn solve_cached(
        &self,
        loads: &Loads,
        guess: &[f64; N],
        cache: &mut Option<JacobianCache>,
    ) -> Result<Equilibrium, StaticsError> {
        let mut z = *guess;
        let (mut r, mut ends) = self.residual_light(loads, &z);
        let mut nr = Self::norm_inf(&r);
        let mut it = 0;
        let mut fresh = false;
        let fail = |it, nr| StaticsError::NoConvergence {
            iterations: it,
            residual: nr,
        };
        while nr > self.tol {
            if it >= self.max_iter || !nr.is_finite() {
                return Err(fail(it, nr));
            }
            if cache.is_none() {
                *cache = self.jacobian_at(loads, &z);
                if cache.is_none() {
                    return Err(fail(it, nr));
                }
                fresh = true;
            }
            let c = cache.as_mut().expect("set above");
            let rv = Vecn::from_column_slice(&r);
            let dz = c.inv * rv;
            let n2 = Self::norm2(&r);
            let mut alpha = 1.0;
            let mut accepted = false;
            for _ in 0..if fresh { 12 } else { 1 } {
                let zt: [f64; N] = std::array::from_fn(|k| z[k] - alpha * dz[k]);
                let (rt, et) = self.residual_light(loads, &zt);
                let nt = Self::norm_inf(&rt);
                let n2t = Self::norm2(&rt);
                let good = if fresh {
                    n2t < n2
                } else {
                    n2t < CHORD_CONTRACTION * n2
                };
                if nt.is_finite() && (good || nt <= self.tol) {
                    // Broyden ("good") update of the inverse: s = step, y = residual change.
                    let sv = Vecn::from_fn(|k, _| zt[k] - z[k]);
                    let yv = Vecn::from_column_slice(&rt) - rv;
                    let hy = c.inv * yv;
                    let den = sv.dot(&hy);
                    if den.abs() > 1e-300 {
                        let sth = sv.transpose() * c.inv;
                        c.inv += (sv - hy) * sth / den;
                    }
                    z = zt;
                    r = rt;
                    ends = et;
                    nr = nt;
                    accepted = true;
                    break;
                }
                alpha *= 0.5;
            }
            it += 1;
            if !accepted {
                if fresh {
                    return Err(fail(it, nr));
                }
                // Slow contraction with an old Jacobian: refresh it here.
                *cache = None;
            } else {
                fresh = false;
            }
        }
        let det_sign = cache.as_ref().map_or(0.0, |c| c.det_sign);
        Ok(self.finish(loads, z, &ends, nr, it, det_sign))
    }

    fn residual(&self, loads: &Loads, z: &[f64; N]) -> ([f64; N], [SegmentEnd; 3]) {
        let ends = self.segments(z);
        let a = self.algebra(loads, z, &Self::seg_out(&ends));
        (a.r, ends)
    }

    /// The Jacobian of the residual: per leg, the algebraic terms are differentiated by central
    /// differences in their 8 inputs (pose, tip load, segment tip) and chained with the segment's
    /// sensitivities from the variational equations.
    fn jacobian(&self, loads: &Loads, z: &[f64; N], ends: &[SegmentEnd; 3]) -> Mat {
        let mut j = Mat::zeros();
        let ms = self.moment_scale();
        for i in 0..3 {
            let x0 = [
                z[0],
                z[1],
                z[2],
                z[3 + 2 * i],
                z[4 + 2 * i],
                ends[i].pos[0],
                ends[i].pos[1],
                ends[i].theta,
            ];
            let eval = |x: &[f64; 8]| -> [f64; 6] {
                let l = self.leg_terms(
                    i,
                    loads,
                    [x[0], x[1], x[2]],
                    [x[3], x[4]],
                    [x[5], x[6], x[7]],
                );
                [
                    l.r[0],
                    l.r[1],
                    l.r[2],
                    l.force[0],
                    l.force[1],
                    l.moment * ms,
                ]
            };
            // d (leg outputs) / d (inputs), 6 x 8.
            let mut d = [[0.0; 8]; 6];
            for c in 0..8 {
                let h = if c == 2 || c == 7 {
                    1e-7
                } else {
                    1e-6 * (1.0 + x0[c].abs())
                };
                let mut xp = x0;
                let mut xm = x0;
                xp[c] += h;
                xm[c] -= h;
                let (op, om) = (eval(&xp), eval(&xm));
                for r in 0..6 {
                    d[r][c] = (op[r] - om[r]) / (2.0 * h);
                }
            }
            let rows = [i, 3 + i, 6 + i, 9, 10, 11];
            let seg_cols = [9 + i, 3 + 2 * i, 4 + 2 * i];
            for (r, &row) in rows.iter().enumerate() {
                for c in 0..3 {
                    j[(row, c)] += d[r][c];
                }
                j[(row, 3 + 2 * i)] += d[r][3];
                j[(row, 4 + 2 * i)] += d[r][4];
                for (q, &col) in seg_cols.iter().enumerate() {
                    let mut v = 0.0;
                    for k in 0..3 {
                        v += d[r][5 + k] * ends[i].jac[k][q];
                    }
                    j[(row, col)] += v;
                }
            }
        }
        j
    }

    fn norm_inf(r: &[f64; N]) -> f64 {
        r.iter().fold(0.0f64, |m, v| m.max(v.abs()))
    }

    fn norm2(r: &[f64; N]) -> f64 {
        r.iter().map(|v| v * v).sum::<f64>().sqrt()
    }

    /// Newton from `guess`. Checks only convergence (see [`Statics::check`] for the ranges).
    pub fn solve_from(&self, loads: &Loads, guess: &[f64; N]) -> Result<Equilibrium, StaticsError> {
        let mut z = *guess;
        let (mut r, mut ends) = self.residual(loads, &z);
        let mut nr = Self::norm_inf(&r);
        let mut it = 0;
        let mut det_sign = 0.0;
        let mut jac: Option<Mat> = None;
        while nr > self.tol || jac.is_none() {
            if it >= self.max_iter || !nr.is_finite() {
                return Err(StaticsError::NoConvergence {
                    iterations: it,
                    residual: nr,
                });
            }
            let j = self.jacobian(loads, &z, &ends);
            let lu = j.lu();
            let det = lu.determinant();
            det_sign = det.signum();
            jac = Some(j);
            if nr <= self.tol {
                break;
            }
            let dz = match lu.solve(&Vecn::from_column_slice(&r)) {
                Some(d) => d,
                None => {
                    return Err(StaticsError::NoConvergence {
                        iterations: it,
                        residual: nr,
                    })
                }
            };
            let mut alpha = 1.0;
            let mut accepted = false;
            for _ in 0..12 {
                let mut zt = z;
                for k in 0..N {
                    zt[k] -= alpha * dz[k];
                }
                let (rt, et) = self.residual(loads, &zt);
                let nt = Self::norm_inf(&rt);
                if nt.is_finite() && (Self::norm2(&rt) < Self::norm2(&r) || nt <= self.tol) {
                    z = zt;
                    r = rt;
                    ends = et;
                    nr = nt;
                    accepted = true;
                    break;
                }
                alpha *= 0.5;
            }
            it += 1;
            if !accepted {
                return Err(StaticsError::NoConvergence {
                    iterations: it,
                    residual: nr,
                });
            }
        }
        Ok(self.finish(loads, z, &ends, nr, it, det_sign))
    }

    fn finish(
        &self,
        loads: &Loads,
        z: [f64; N],
        ends: &[SegmentEnd; 3],
        residual: f64,
        iterations: usize,
        det_sign: f64,
    ) -> Equilibrium {
        let a = self.algebra(loads, &z, &Self::seg_out(ends));
        let mut eq = Equilibrium {
            z,
            pose: [z[0], z[1], z[2]],
            tip: a.tip,
            tip_theta: std::array::from_fn(|i| ends[i].theta),
            m: a.m,
            p: a.p,
            gamma: a.gamma,
            zeta: a.zeta,
            link_force: a.f,
            lambda: [0.0; 3],
            tendon_moment: [0.0; 3],
            tip_load: std::array::from_fn(|i| [z[3 + 2 * i], z[4 + 2 * i]]),
            joint_torque: a.tau,
            support_force: a.fs,
            residual,
            iterations,
            det_sign,
            det_a: 0.0,
            jacobi: std::array::from_fn(|i| ends[i].jac[2][0]),
        };
        let rows: [[f64; 3]; 3] = std::array::from_fn(|i| {
            let d = sub(a.p[i], a.m[i]);
            let pe = sub(a.p[i], [z[0], z[1]]);
            [2.0 * d[0], 2.0 * d[1], 2.0 * dot(d, perp(pe))]
        });
        eq.det_a = rows[0][0] * (rows[1][1] * rows[2][2] - rows[1][2] * rows[2][1])
            - rows[0][1] * (rows[1][0] * rows[2][2] - rows[1][2] * rows[2][0])
            + rows[0][2] * (rows[1][0] * rows[2][1] - rows[1][1] * rows[2][0]);
        for (i, end) in ends.iter().enumerate() {
            let u = scale(1.0 / self.legs[i].l_st, sub(a.p[i], a.m[i]));
            eq.lambda[i] = dot(a.f[i], u);
            let lever = cross(sub(a.m[i], a.tip[i]), eq.tip_load[i]);
            // Couple of the joint at M on the tip body = -(couple on the link).
            eq.tendon_moment[i] = end.moment - lever + a.tau[i][0];
        }
        eq
    }

    /// Checks an equilibrium against the joint range and buckling; names the leg.
    pub fn check(&self, eq: &Equilibrium) -> Result<(), StaticsError> {
        let (lo, hi) = self.joint_range;
        for i in 0..3 {
            for (joint, a) in [(Joint::M, eq.gamma[i]), (Joint::P, eq.zeta[i])] {
                if a < lo || a > hi {
                    return Err(StaticsError::JointRange {
                        leg: i + 1,
                        joint,
                        angle_deg: a.to_degrees(),
                        min_deg: lo.to_degrees(),
                        max_deg: hi.to_degrees(),
                    });
                }
            }
            if eq.jacobi[i] <= 0.0 {
                return Err(StaticsError::Buckling {
                    leg: i + 1,
                    load_n: norm(eq.tip_load[i]),
                });
            }
        }
        Ok(())
    }

    /// Checks the commanded bending against the bending range.
    pub fn check_bending(&self, phi_b: &[f64; 3]) -> Result<(), StaticsError> {
        for (i, &b) in phi_b.iter().enumerate() {
            if b.is_nan() || b.abs() > self.bending_max {
                return Err(StaticsError::BendingRange {
                    leg: i + 1,
                    bending_deg: b.to_degrees(),
                    max_deg: self.bending_max.to_degrees(),
                });
            }
        }
        Ok(())
    }

    /// A starting point: unloaded arcs with the given bending and a pose guess.
    pub fn arc_guess(&self, phi_b: &[f64; 3], pose: [f64; 3]) -> [f64; N] {
        let mut z = [0.0; N];
        z[..3].copy_from_slice(&pose);
        for i in 0..3 {
            z[9 + i] = -self.ei * phi_b[i] / self.legs[i].l_c;
        }
        z
    }

    /// Warm-started solve with range checks.
    pub fn solve_warm(&self, loads: &Loads, guess: &[f64; N]) -> Result<Equilibrium, StaticsError> {
        self.check_bending(&loads.phi_b)?;
        let eq = self.solve_cached(loads, guess, &mut None)?;
        self.check(&eq)?;
        Ok(eq)
    }

    /// Warm-started solve with range checks, reusing (and updating) a Jacobian cache.
    pub fn solve_warm_cached(
        &self,
        loads: &Loads,
        guess: &[f64; N],
        cache: &mut Option<JacobianCache>,
    ) -> Result<Equilibrium, StaticsError> {
        self.check_bending(&loads.phi_b)?;
        let eq = self.solve_cached(loads, guess, cache)?;
        self.check(&eq)?;
        Ok(eq)
    }

    /// Stateless solve: continuation from a known equilibrium `start` (e.g. home, unloaded) to
    /// `target`, in the bending and the wrench, so that the result is the equilibrium the
    /// physical robot reaches (same working and assembly mode).
    pub fn solve_path(
        &self,
        start_loads: &Loads,
        start: &Equilibrium,
        target: &Loads,
    ) -> Result<Equilibrium, StaticsError> {
        self.check_bending(&target.phi_b)?;
        let max_dphi = 4f64.to_radians();
        let max_dw = [0.5, 0.5, 30.0];
        let mut span: f64 = 0.0;
        for (i, dw) in max_dw.iter().enumerate() {
            span = span.max((target.phi_b[i] - start_loads.phi_b[i]).abs() / max_dphi);
            span = span.max((target.wrench[i] - start_loads.wrench[i]).abs() / dw);
        }
        let mut ds = 1.0 / span.ceil().max(1.0);
        let lerp = |s: f64| -> Loads {
            let mut l = *target;
            for i in 0..3 {
                l.phi_b[i] = start_loads.phi_b[i] + s * (target.phi_b[i] - start_loads.phi_b[i]);
                l.wrench[i] =
                    start_loads.wrench[i] + s * (target.wrench[i] - start_loads.wrench[i]);
            }
            l
        };
        let mut s = 0.0;
        let mut prev: Option<(f64, [f64; N])> = None;
        // The assembly-mode indicator of this path's model at its start (friction or a wrench
        // change the model, and with it the sign of the Jacobian's determinant).
        let cur0 = self.solve_from(&lerp(0.0), &start.z)?;
        let sign0 = cur0.det_sign;
        let sign_a = cur0.det_a.signum();
        // Without friction the whole structure's tangent stiffness (det of the Jacobian) must
        // keep its sign too (limit points); the platform's det A must in any case.
        let same_mode = |eq: &Equilibrium| {
            eq.det_a.signum() == sign_a
                && (target.friction.is_some() || eq.det_sign == sign0 || eq.det_sign == 0.0)
        };
        let mut cur = cur0;
        while s < 1.0 {
            let s1 = (s + ds).min(1.0);
            // Secant predictor.
            let mut guess = cur.z;
            if let Some((sp, zp)) = prev {
                let w = (s1 - s) / (s - sp);
                for k in 0..N {
                    guess[k] = cur.z[k] + w * (cur.z[k] - zp[k]);
                }
            }
            let loads = lerp(s1);
            match self.solve_from(&loads, &guess) {
                Ok(eq) if same_mode(&eq) => {
                    let step_ok = (0..3).all(|i| {
                        (eq.pose[i] - cur.pose[i]).abs() < if i == 2 { 0.05 } else { 5.0 }
                    });
                    if step_ok {
                        prev = Some((s, cur.z));
                        cur = eq;
                        s = s1;
                        ds = (ds * 1.5).min(1.0);
                        continue;
                    }
                    ds *= 0.5;
                }
                Ok(_) => {
                    if ds < 1e-4 {
                        return Err(StaticsError::Singular { fraction: s });
                    }
                    ds *= 0.5;
                }
                Err(e) => {
                    if ds < 1e-4 {
                        // Name the leg if a segment is buckling, else report the failure.
                        self.check(&cur)?;
                        return Err(match e {
                            StaticsError::NoConvergence { .. } => {
                                StaticsError::Singular { fraction: s }
                            }
                            other => other,
                        });
                    }
                    ds *= 0.5;
                }
            }
            if ds < 1e-5 {
                return Err(StaticsError::Singular { fraction: s });
            }
        }
        self.check(&cur)?;
        Ok(cur)
    }
}
