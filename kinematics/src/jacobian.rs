//! Differential kinematics: A = dh/dx_E, B = dh/dkappa (diagonal), J = -A^-1 B, the motor-step
//! Jacobian, and the singularity measure.
//!
//! Singularity measure (documented threshold `limits.singularity_threshold`, default 1e-3):
//! the smaller of
//! - the inverse condition number sigma_min / sigma_max of A with its orientation column scaled
//!   by a characteristic platform radius r (mean |P_i^E|), so that all columns are lengths
//!   (A-type, "parallel" singularity: det A = 0), and
//! - min_i |B_ii| / (2 l_st |dM_i/dkappa_i|), the cosine of the angle between link i and the
//!   direction in which M_i moves (B-type, "serial" singularity: det B = 0).
//!
//! Both are dimensionless, 1 for a perfectly conditioned leg or platform and 0 at a singularity.

use crate::model::Robot;
use crate::pose::Pose;
use nalgebra::{Matrix3, Vector3};
use pcr_robot::geometry as g;

impl Robot {
    /// A = dh/dx_E at (pose, kappa), with x_E = (x mm, y mm, phi rad).
    pub fn jacobian_a(&self, pose: &Pose, kappa: &[f64; 3]) -> Matrix3<f64> {
        let mut a = Matrix3::zeros();
        for i in 0..3 {
            let pe = g::rot(pose.phi, self.legs[i].p_e);
            let d = g::sub(g::add([pose.x, pose.y], pe), self.joint_m(i, kappa[i]));
            a[(i, 0)] = 2.0 * d[0];
            a[(i, 1)] = 2.0 * d[1];
            a[(i, 2)] = 2.0 * g::dot(d, g::perp(pe));
        }
        a
    }

    /// The diagonal of B = dh/dkappa at (pose, kappa), mm^3.
    pub fn jacobian_b(&self, pose: &Pose, kappa: &[f64; 3]) -> [f64; 3] {
        std::array::from_fn(|i| {
            let leg = &self.legs[i];
            let tip = leg.local_tip(kappa[i] * leg.l_c);
            let p = leg.to_local(g::sub(self.joint_p(i, pose), leg.b));
            -2.0 * g::dot(g::sub(p, tip.m), tip.dm) * leg.l_c
        })
    }

    /// J = dx_E/dkappa = -A^-1 B (rows x mm, y mm, phi rad; columns kappa_i in 1/mm), or None
    /// where A is singular.
    ///
    /// Bit for bit `-jacobian_a^-1 diag(jacobian_b)`, with each leg's tip and the platform's
    /// sin_cos computed once for both.
    pub fn jacobian(&self, pose: &Pose, kappa: &[f64; 3]) -> Option<Matrix3<f64>> {
        let (s, c) = pose.phi.sin_cos();
        let mut a = Matrix3::zeros();
        let mut b = [0.0; 3];
        for i in 0..3 {
            let leg = &self.legs[i];
            let v = leg.p_e;
            let pe = [c * v[0] - s * v[1], s * v[0] + c * v[1]];
            let tip = leg.local_tip(kappa[i] * leg.l_c);
            let jp = g::add([pose.x, pose.y], pe);
            let d = g::sub(jp, g::add(leg.b, leg.to_base(tip.m)));
            a[(i, 0)] = 2.0 * d[0];
            a[(i, 1)] = 2.0 * d[1];
            a[(i, 2)] = 2.0 * g::dot(d, g::perp(pe));
            let p = leg.to_local(g::sub(jp, leg.b));
            b[i] = -2.0 * g::dot(g::sub(p, tip.m), tip.dm) * leg.l_c;
        }
        let b = Matrix3::from_diagonal(&Vector3::from(b));
        crate::lu3::Lu3::new(&a).solve_matrix(&b).map(|m| -m)
    }

    /// dx_E/dq: the Jacobian with respect to motor steps at motor positions q (steps).
    pub fn jacobian_steps(
        &self,
        pose: &Pose,
        kappa: &[f64; 3],
        q: &[f64; 3],
    ) -> Option<Matrix3<f64>> {
        let j = self.jacobian(pose, kappa)?;
        let d = Matrix3::from_diagonal(&Vector3::from(std::array::from_fn::<f64, 3, _>(|i| {
            self.dkappa_dsteps(i, q[i])
        })));
        Some(j * d)
    }

    /// The singularity measure described in the module documentation (0 singular .. 1).
    pub fn conditioning(&self, pose: &Pose, kappa: &[f64; 3]) -> Conditioning {
        let mut a = self.jacobian_a(pose, kappa);
        for i in 0..3 {
            a[(i, 2)] /= self.r_char;
        }
        let sv = a.singular_values();
        let (mx, mn) = (sv.max(), sv.min());
        let a_measure = if mx > 0.0 { mn / mx } else { 0.0 };
        let b = self.jacobian_b(pose, kappa);
        let mut b_measure = f64::INFINITY;
        for (i, bi) in b.iter().enumerate() {
            let leg = &self.legs[i];
            let dm = leg.local_tip(kappa[i] * leg.l_c).dm;
            let scale = 2.0 * leg.l_st * g::norm(dm) * leg.l_c;
            b_measure = b_measure.min(if scale > 0.0 { bi.abs() / scale } else { 0.0 });
        }
        Conditioning {
            a: a_measure,
            b: b_measure,
        }
    }
}

/// Conditioning of a configuration (dimensionless, 0 at a singularity, 1 best).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Conditioning {
    /// Inverse condition number of the scaled A.
    pub a: f64,
    /// Smallest normalised |B_ii|.
    pub b: f64,
}

impl Conditioning {
    /// The smaller of the two measures.
    pub fn value(&self) -> f64 {
        self.a.min(self.b)
    }
}
