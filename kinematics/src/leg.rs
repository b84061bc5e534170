//! One leg of the 3-FbRR: constant-curvature segment, tip extension and link (geometry.md eq. 4).
//!
//! Internally a leg works in its local frame, rotated by -psi about its base point B_i, where the
//! segment starts along +y and a positive bending angle theta = kappa l_C turns it towards +x.

use crate::tendon::TendonMap;
use pcr_robot::{geometry as g, LegConfig, Vec2};

/// Bending angles below this magnitude use the series expansion of the arc (rad).
const SERIES_THETA: f64 = 0.1;

/// The precomputed, immutable description of one leg.
#[derive(Debug, Clone)]
pub struct Leg {
    /// Base point B_i in the base frame, mm.
    pub b: Vec2,
    /// Orientation psi_i of the segment base, rad.
    pub psi: f64,
    pub(crate) cos_psi: f64,
    pub(crate) sin_psi: f64,
    /// Segment length l_C, mm.
    pub l_c: f64,
    /// Tip extension l_CE, mm.
    pub l_ce: f64,
    /// Link length l_st, mm.
    pub l_st: f64,
    /// Platform joint P_i in the platform frame, mm.
    pub p_e: Vec2,
    /// Tendon displacement per motor step, mm.
    pub mm_per_step: f64,
    /// Maximum step rate of the drive, steps/s.
    pub max_step_rate: f64,
    /// Robot-dependent model.
    pub map: TendonMap,
}

impl Leg {
    /// Whether `other` has the same drawing: every field the kinematics and statics read
    /// besides the tendon map and the drive (base point, orientation, lengths, platform joint),
    /// compared exactly. Two legs of the same drawing at the same curvature have the same
    /// segment, joint and tangent. Every field is named, so that a field added to `Leg` is
    /// placed on one side or the other before this compiles.
    pub fn same_drawing(&self, other: &Leg) -> bool {
        let Leg {
            b,
            psi,
            cos_psi,
            sin_psi,
            l_c,
            l_ce,
            l_st,
            p_e,
            mm_per_step: _,
            max_step_rate: _,
            map: _,
        } = self;
        *b == other.b
            && *psi == other.psi
            && *cos_psi == other.cos_psi
            && *sin_psi == other.sin_psi
            && *l_c == other.l_c
            && *l_ce == other.l_ce
            && *l_st == other.l_st
            && *p_e == other.p_e
    }
}

/// Position and first derivative of the joint M_i, with the tip tangent, in the leg's local frame.
#[derive(Debug, Clone, Copy)]
pub struct LocalTip {
    /// M_i - B_i rotated by -psi, mm.
    pub m: Vec2,
    /// d m / d theta, mm/rad.
    pub dm: Vec2,
    /// Tip tangent (unit), local frame.
    pub t: Vec2,
}

/// (1 - cos x)/x, sin(x)/x and their derivatives, stable at x = 0.
#[inline]
fn arc_functions(x: f64) -> (f64, f64, f64, f64) {
    let (s, c) = x.sin_cos();
    arc_functions_sc(x, s, c)
}

/// [`arc_functions`] with sin x and cos x already known.
#[inline]
fn arc_functions_sc(x: f64, s: f64, c: f64) -> (f64, f64, f64, f64) {
    if x.abs() < SERIES_THETA {
        let x2 = x * x;
        let f1 = x
            * (0.5
                + x2 * (-1.0 / 24.0 + x2 * (1.0 / 720.0 + x2 * (-1.0 / 40320.0 + x2 / 3628800.0))));
        let f2 = 1.0
            + x2 * (-1.0 / 6.0
                + x2 * (1.0 / 120.0
                    + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362880.0 - x2 / 39916800.0))));
        let d1 =
            0.5 + x2 * (-1.0 / 8.0 + x2 * (1.0 / 144.0 + x2 * (-1.0 / 5760.0 + x2 / 403200.0)));
        let d2 = x
            * (-1.0 / 3.0
                + x2 * (1.0 / 30.0 + x2 * (-1.0 / 840.0 + x2 * (1.0 / 45360.0 - x2 / 3991680.0))));
        (f1, f2, d1, d2)
    } else {
        let f1 = (1.0 - c) / x;
        let f2 = s / x;
        let d1 = (s - f1) / x;
        let d2 = (c - f2) / x;
        (f1, f2, d1, d2)
    }
}

impl Leg {
    /// Builds a leg from its configuration.
    pub fn from_config(c: &LegConfig) -> Leg {
        let psi = c.psi_deg.to_radians();
        Leg {
            b: c.base_point(),
            psi,
            cos_psi: psi.cos(),
            sin_psi: psi.sin(),
            l_c: c.l_c_mm,
            l_ce: c.l_ce_mm,
            l_st: c.l_st_mm,
            p_e: c.platform_point(),
            mm_per_step: c.actuation.mm_per_step(),
            max_step_rate: c.actuation.max_step_rate,
            map: TendonMap::from_leg(c),
        }
    }

    /// The tip in the local frame for bending angle `theta` = kappa l_C (rad).
    #[inline]
    pub fn local_tip(&self, theta: f64) -> LocalTip {
        let (s, c) = theta.sin_cos();
        self.local_tip_sc(theta, s, c)
    }

    /// [`Leg::local_tip`] with sin theta and cos theta already known.
    #[inline]
    pub fn local_tip_sc(&self, theta: f64, s: f64, c: f64) -> LocalTip {
        let (f1, f2, d1, d2) = arc_functions_sc(theta, s, c);
        LocalTip {
            m: [self.l_c * f1 + self.l_ce * s, self.l_c * f2 + self.l_ce * c],
            dm: [self.l_c * d1 + self.l_ce * c, self.l_c * d2 - self.l_ce * s],
            t: [s, c],
        }
    }

    /// Rotates a local vector into the base frame.
    #[inline]
    pub fn to_base(&self, v: Vec2) -> Vec2 {
        [
            self.cos_psi * v[0] - self.sin_psi * v[1],
            self.sin_psi * v[0] + self.cos_psi * v[1],
        ]
    }

    /// Rotates a base-frame vector into the local frame.
    #[inline]
    pub fn to_local(&self, v: Vec2) -> Vec2 {
        [
            self.cos_psi * v[0] + self.sin_psi * v[1],
            -self.sin_psi * v[0] + self.cos_psi * v[1],
        ]
    }

    /// Joint M_i in the base frame for curvature `kappa` (1/mm).
    pub fn joint_m(&self, kappa: f64) -> Vec2 {
        let tip = self.local_tip(kappa * self.l_c);
        g::add(self.b, self.to_base(tip.m))
    }

    /// Tip tangent t_i (unit) in the base frame for curvature `kappa`.
    pub fn tangent(&self, kappa: f64) -> Vec2 {
        self.to_base(self.local_tip(kappa * self.l_c).t)
    }

    /// Points along the segment (base frame, mm), `n` >= 2 of them from B_i to the segment tip,
    /// followed by M_i; for drawing.
    pub fn shape(&self, kappa: f64, n: usize) -> Vec<Vec2> {
        let mut pts: Vec<Vec2> = (0..n.max(2))
            .map(|k| {
                let s = self.l_c * k as f64 / (n.max(2) - 1) as f64;
                let (f1, f2, _, _) = arc_functions(kappa * s);
                g::add(self.b, self.to_base([s * f1, s * f2]))
            })
            .collect();
        pts.push(self.joint_m(kappa));
        pts
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn series_and_closed_form_agree_at_the_switch() {
        for x in [SERIES_THETA * 0.999, SERIES_THETA * 1.001] {
            let a = arc_functions(x);
            let (s, c) = x.sin_cos();
            assert!((a.0 - (1.0 - c) / x).abs() < 1e-15);
            assert!((a.1 - s / x).abs() < 1e-14);
        }
        let leg = Leg::from_config(&LegConfig::nominal(0));
        for th in [-1e-3, -1e-5, 0.0, 1e-7, 2e-3, 0.5, -2.5] {
            let t = leg.local_tip(th);
            let h = 1e-6;
            let (a, b) = (leg.local_tip(th + h).m, leg.local_tip(th - h).m);
            for k in 0..2 {
                let fd = (a[k] - b[k]) / (2.0 * h);
                assert!(
                    (fd - t.dm[k]).abs() < 1e-6,
                    "theta {th}: {fd} vs {}",
                    t.dm[k]
                );
            }
        }
    }

    #[test]
    fn straight_segment_points_along_the_base_tangent() {
        let leg = Leg::from_config(&LegConfig::nominal(1));
        let m = leg.joint_m(0.0);
        let dir = g::rot(leg.psi, [0.0, 1.0]);
        let expect = g::add(leg.b, g::scale(leg.l_c + leg.l_ce, dir));
        assert!(g::norm(g::sub(m, expect)) < 1e-12);
        // positive curvature turns the tangent clockwise
        let t = leg.tangent(0.01);
        assert!(g::cross(dir, t) < 0.0);
    }
}
