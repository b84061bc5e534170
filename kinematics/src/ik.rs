//! Inverse kinematics: for a platform pose, the curvature of each leg that closes its loop.
//!
//! Each leg's constraint h_i(theta) = |p - m(theta)|^2 - l_st^2 is a scalar function of the
//! bending angle. Its roots are bracketed on a precomputed table of the local tip positions
//! (h is affine in the tabulated m_x, m_y, |m|^2, so the scan is a few multiply-adds per grid
//! point) and refined by safeguarded Newton on the exact model. A cell without a sign change but
//! with a turning point is searched for a pair of close roots, so that no root is lost away from
//! a tangency (a det B = 0 singularity).

use crate::model::{Robot, TABLE_N};
use crate::pose::Pose;
use pcr_robot::geometry as g;

/// Most roots one leg can have in the scanned range.
pub const MAX_ROOTS: usize = 4;

/// One root of a leg's loop-closure equation (an assembly branch of the joint M_i).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LegRoot {
    /// Curvature, 1/mm.
    pub kappa: f64,
    /// Bending angle kappa l_C, rad.
    pub theta: f64,
    /// Passive joint angle at M_i, rad.
    pub gamma: f64,
    /// Passive joint angle at P_i, rad.
    pub zeta: f64,
    /// |theta| is within the bending limit.
    pub bending_ok: bool,
    /// gamma is within the joint range.
    pub gamma_ok: bool,
    /// zeta is within the joint range.
    pub zeta_ok: bool,
}

impl LegRoot {
    /// The root respects every limit.
    pub fn valid(&self) -> bool {
        self.bending_ok && self.gamma_ok && self.zeta_ok
    }
}

/// All roots of one leg, ordered by bending angle.
#[derive(Debug, Clone, Copy, Default)]
pub struct LegRoots {
    roots: [LegRoot; MAX_ROOTS],
    n: usize,
}

impl LegRoots {
    /// The roots found.
    pub fn as_slice(&self) -> &[LegRoot] {
        &self.roots[..self.n]
    }
}

/// Why a pose has no IK solution in the working mode.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum IkError {
    /// Leg `leg` (1-based) cannot close its loop in the working mode's branch.
    #[error("leg {leg}: pose unreachable in the working mode")]
    Unreachable {
        /// 1-based leg number.
        leg: usize,
    },
    /// The branch exists but bends the segment beyond the bending limit.
    #[error("leg {leg}: bending {bending_deg:.2} deg beyond the limit")]
    BendingLimit {
        /// 1-based leg number.
        leg: usize,
        /// The bending angle needed, degrees.
        bending_deg: f64,
    },
    /// The branch exists but a passive joint is outside its range.
    #[error("leg {leg}: passive joint {joint} at {angle_deg:.2} deg outside its range")]
    JointLimit {
        /// 1-based leg number.
        leg: usize,
        /// "M" (gamma) or "P" (zeta).
        joint: char,
        /// The joint angle, degrees.
        angle_deg: f64,
    },
}

impl IkError {
    /// The status word used in CSV outputs.
    pub fn status(&self) -> &'static str {
        match self {
            IkError::Unreachable { .. } => "unreachable",
            IkError::BendingLimit { .. } => "bending_limit",
            IkError::JointLimit { .. } => "joint_limit",
        }
    }
}

/// The IK solution of a pose in the working mode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkSolution {
    /// Curvatures kappa_i, 1/mm.
    pub kappa: [f64; 3],
    /// Passive joint angles gamma_i at M_i, rad.
    pub gamma: [f64; 3],
    /// Passive joint angles zeta_i at P_i, rad.
    pub zeta: [f64; 3],
}

impl Robot {
    /// Every root of leg `i`'s loop closure for `pose` in the scanned bending range, whether in
    /// the working mode or not, with its joint angles and limit checks.
    pub fn leg_roots(&self, i: usize, pose: &Pose) -> LegRoots {
        self.roots_filtered(i, pose, None)
    }

    /// The roots of leg `i`; with `branch = Some(s)`, brackets whose gamma has clearly the
    /// other sign than `s` at both ends are skipped (they cannot be the working mode's root).
    fn roots_filtered(&self, i: usize, pose: &Pose, branch: Option<f64>) -> LegRoots {
        let leg = &self.legs[i];
        let tab = &self.tables[i];
        let pe = g::rot(pose.phi, leg.p_e);
        let pb = g::add([pose.x, pose.y], pe);
        let p = leg.to_local(g::sub(pb, leg.b));
        let c0 = p[0] * p[0] + p[1] * p[1] - leg.l_st * leg.l_st;
        let (px2, py2) = (2.0 * p[0], 2.0 * p[1]);
        // h and dh/dtheta = -2 (p - m) . dm on the whole table (straight-line, vectorisable).
        let mut hv = [0.0; TABLE_N];
        let mut dhv = [0.0; TABLE_N];
        for k in 0..TABLE_N {
            hv[k] = c0 + tab.nn[k] - px2 * tab.mx[k] - py2 * tab.my[k];
            dhv[k] = 2.0 * tab.mdm[k] - px2 * tab.dmx[k] - py2 * tab.dmy[k];
        }
        let h = |k: usize| hv[k];
        let dh = |k: usize| dhv[k];
        // Exact h and dh/dtheta; sin and cos from the cell's tabulated values rotated by the
        // small offset (a short series), which is exact to round-off and avoids libm.
        let eval_near = |theta: f64, k: usize| {
            let (s, c) = sin_cos_near(
                theta,
                tab.theta0 + tab.dtheta * k as f64,
                tab.st[k],
                tab.ct[k],
            );
            let t = leg.local_tip_sc(theta, s, c);
            let d = g::sub(p, t.m);
            (g::dot(d, d) - leg.l_st * leg.l_st, -2.0 * g::dot(d, t.dm))
        };
        let mut out = LegRoots::default();
        let mut push = |theta: f64| {
            if out.n < MAX_ROOTS {
                out.roots[out.n].theta = theta;
                out.n += 1;
            }
        };
        let mut h_prev = h(0);
        for k in 1..TABLE_N {
            let eval = |theta: f64| eval_near(theta, k - 1);
            let h_k = h(k);
            // Most cells have no root and no turning point towards zero: skip them first.
            if h_prev * h_k > 0.0 {
                let (da, db) = (dh(k - 1), dh(k));
                if da * db >= 0.0 || (h_prev > 0.0) == (da > 0.0) {
                    h_prev = h_k;
                    continue;
                }
            }
            let (a, b) = (
                tab.theta0 + tab.dtheta * (k - 1) as f64,
                tab.theta0 + tab.dtheta * k as f64,
            );
            if h_prev == 0.0 {
                push(a);
            } else if h_prev * h_k < 0.0 {
                // sign of gamma ~ sign of t x (p - m) at the bracket ends
                let skip = branch.is_some_and(|s| {
                    let gs = |k: usize| {
                        let (st, ct) = (tab.st[k], tab.ct[k]);
                        st * (p[1] - tab.my[k]) - ct * (p[0] - tab.mx[k])
                    };
                    gs(k - 1) * s < 0.0 && gs(k) * s < 0.0
                });
                if !skip {
                    let start = a + (b - a) * h_prev / (h_prev - h_k);
                    push(refine(&eval, a, b, h_prev, start));
                }
            } else if h_k != 0.0 {
                // Same sign at both ends: a pair of roots hides only where h turns back.
                let (da, db) = (dh(k - 1), dh(k));
                let towards_zero = if h_prev > 0.0 { da < 0.0 } else { da > 0.0 };
                // Cheap screen: the cubic Hermite interpolant of the cell; only where it comes
                // close to zero is the exact extremum searched.
                let close = || {
                    let dt = b - a;
                    let mut m = f64::INFINITY;
                    for s in 1..8 {
                        let t = s as f64 / 8.0;
                        let (t2, t3) = (t * t, t * t * t);
                        let v = (2.0 * t3 - 3.0 * t2 + 1.0) * h_prev
                            + (t3 - 2.0 * t2 + t) * dt * da
                            + (-2.0 * t3 + 3.0 * t2) * h_k
                            + (t3 - t2) * dt * db;
                        m = m.min(v * h_prev.signum());
                    }
                    m < 0.1 * (h_prev.abs() + h_k.abs())
                };
                if da * db < 0.0 && towards_zero && close() {
                    // Locate the extremum by bisection on dh, then test its sign.
                    let (mut lo, mut hi) = (a, b);
                    for _ in 0..60 {
                        let mid = 0.5 * (lo + hi);
                        let (_, dm) = eval(mid);
                        if dm * da > 0.0 {
                            lo = mid;
                        } else {
                            hi = mid;
                        }
                    }
                    let ext = 0.5 * (lo + hi);
                    let (he, _) = eval(ext);
                    if he * h_prev <= 0.0 {
                        push(refine(&eval, a, ext, h_prev, 0.5 * (a + ext)));
                        push(refine(&eval, ext, b, he, 0.5 * (ext + b)));
                    }
                }
            }
            h_prev = h_k;
        }
        if h_prev == 0.0 {
            push(tab.theta0 + tab.dtheta * (TABLE_N - 1) as f64);
        }
        let lim = &self.limits;
        for r in out.roots[..out.n].iter_mut() {
            r.kappa = r.theta / leg.l_c;
            let tip = leg.local_tip(r.theta);
            let d = g::sub(p, tip.m);
            let gamma = g::signed_angle(tip.t, d);
            let zeta = g::signed_angle(pe, leg.to_base(g::scale(-1.0, d)));
            r.gamma = gamma;
            r.zeta = zeta;
            r.bending_ok = r.theta.abs() <= lim.bending_max;
            r.gamma_ok = gamma >= lim.joint_min && gamma <= lim.joint_max;
            r.zeta_ok = zeta >= lim.joint_min && zeta <= lim.joint_max;
        }
        out
    }

    /// IK of one leg in the working mode's branch.
    pub fn leg_ik(&self, i: usize, pose: &Pose) -> Result<LegRoot, IkError> {
        let sign = self.mode[i].sign();
        let roots = self.roots_filtered(i, pose, Some(sign));
        let mut best: Option<LegRoot> = None;
        for r in roots.as_slice().iter().filter(|r| r.gamma * sign > 0.0) {
            let better = match &best {
                None => true,
                Some(b) => {
                    (r.valid() && !b.valid())
                        || (r.valid() == b.valid() && r.theta.abs() < b.theta.abs())
                }
            };
            if better {
                best = Some(*r);
            }
        }
        let leg = i + 1;
        match best {
            None => Err(IkError::Unreachable { leg }),
            Some(r) if !r.bending_ok => Err(IkError::BendingLimit {
                leg,
                bending_deg: r.theta.to_degrees(),
            }),
            Some(r) if !r.gamma_ok => Err(IkError::JointLimit {
                leg,
                joint: 'M',
                angle_deg: r.gamma.to_degrees(),
            }),
            Some(r) if !r.zeta_ok => Err(IkError::JointLimit {
                leg,
                joint: 'P',
                angle_deg: r.zeta.to_degrees(),
            }),
            Some(r) => Ok(r),
        }
    }

    /// IK of a pose in the working mode: the curvatures and joint angles, or the first leg's
    /// reason why not. Singularity is not checked here (see [`Robot::conditioning`]).
    pub fn ik(&self, pose: &Pose) -> Result<IkSolution, IkError> {
        let mut s = IkSolution {
            kappa: [0.0; 3],
            gamma: [0.0; 3],
            zeta: [0.0; 3],
        };
        for i in 0..3 {
            let r = self.leg_ik(i, pose)?;
            s.kappa[i] = r.kappa;
            s.gamma[i] = r.gamma;
            s.zeta[i] = r.zeta;
        }
        Ok(s)
    }
}

/// sin and cos of `theta` from those of a nearby `theta0` (|theta - theta0| <= 0.3 rad: an
/// addition theorem with 14th-order series of the offset, accurate to round-off).
#[inline]
fn sin_cos_near(theta: f64, theta0: f64, s0: f64, c0: f64) -> (f64, f64) {
    let d = theta - theta0;
    if d.abs() > 0.3 {
        return theta.sin_cos();
    }
    let d2 = d * d;
    let sd = d
        * (1.0
            + d2 * (-1.0 / 6.0
                + d2 * (1.0 / 120.0
                    + d2 * (-1.0 / 5040.0
                        + d2 * (1.0 / 362_880.0
                            + d2 * (-1.0 / 39_916_800.0 + d2 / 6_227_020_800.0))))));
    let cd = 1.0
        + d2 * (-0.5
            + d2 * (1.0 / 24.0
                + d2 * (-1.0 / 720.0
                    + d2 * (1.0 / 40_320.0
                        + d2 * (-1.0 / 3_628_800.0
                            + d2 * (1.0 / 479_001_600.0 - d2 / 87_178_291_200.0))))));
    (s0 * cd + c0 * sd, c0 * cd - s0 * sd)
}

/// Safeguarded Newton in [a, b], where h(a) has sign of `ha` and h(b) the opposite.
fn refine(eval: &impl Fn(f64) -> (f64, f64), a: f64, b: f64, ha: f64, start: f64) -> f64 {
    let (mut lo, mut hi) = (a, b); // h(lo) has the sign of ha
    let mut x = start;
    for _ in 0..100 {
        let (h, dh) = eval(x);
        if h == 0.0 {
            return x;
        }
        if (h > 0.0) == (ha > 0.0) {
            lo = x;
        } else {
            hi = x;
        }
        let newton = x - h / dh;
        let inside = if lo < hi {
            newton > lo && newton < hi
        } else {
            newton > hi && newton < lo
        };
        let next = if inside && dh != 0.0 {
            newton
        } else {
            0.5 * (lo + hi)
        };
        // Newton converges quadratically: after a step below 1e-10 rad the error is at
        // round-off level.
        if (next - x).abs() <= 1e-10 {
            return next;
        }
        x = next;
    }
    x
}
