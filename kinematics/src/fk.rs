//! Forward kinematics: the platform pose that closes all three loops for given curvatures, in
//! the robot's working and assembly mode.
//!
//! Warm start: Newton on h(x_E) = 0 with the analytic A from the previous pose; the result is
//! accepted only if it is in the home assembly mode (sign of det A) and the working mode (signs
//! of gamma_i). Cold start: continuation in curvature space from the home configuration, with a
//! tangent predictor (dx = J dkappa) and Newton corrector, halving the step whenever the
//! corrector fails or the mode would change; this follows the physical robot from home to the
//! requested curvatures without jumping to another assembly mode.

use crate::model::Robot;
use crate::pose::Pose;
use nalgebra::Vector3;
use pcr_robot::{geometry as g, Vec2};

/// Why FK found no pose.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum FkError {
    /// The curvatures are not finite.
    #[error("curvatures must be finite numbers")]
    NotFinite,
    /// No pose in the working and assembly mode closes the loops (the continuation from home
    /// met a singularity or the loops cannot close).
    #[error("no pose in the working and assembly mode closes the loops (continuation stopped at {reached:.3} of the way from home)")]
    NoSolution {
        /// Fraction of the path from home to the target that was followed.
        reached: f64,
    },
}

impl FkError {
    /// The status word used in CSV outputs.
    pub fn status(&self) -> &'static str {
        "unreachable"
    }
}

/// Tolerance on the Newton step, mm (and mm-equivalent for phi).
const STEP_TOL: f64 = 1e-11;

impl Robot {
    /// Newton on the loop closures with fixed joint positions M_i; returns the converged pose.
    fn fk_newton(&self, m: &[Vec2; 3], x0: Pose, max_iter: usize) -> Option<Pose> {
        let mut x = x0;
        let mut last = f64::INFINITY;
        for _ in 0..max_iter {
            let mut a = nalgebra::Matrix3::zeros();
            let mut h = Vector3::zeros();
            // One sin_cos of phi for the three legs (g::rot's arithmetic, bit for bit).
            let (s, c) = x.phi.sin_cos();
            for i in 0..3 {
                let v = self.legs[i].p_e;
                let pe = [c * v[0] - s * v[1], s * v[0] + c * v[1]];
                let d = g::sub(g::add([x.x, x.y], pe), m[i]);
                h[i] = g::dot(d, d) - self.legs[i].l_st * self.legs[i].l_st;
                a[(i, 0)] = 2.0 * d[0];
                a[(i, 1)] = 2.0 * d[1];
                a[(i, 2)] = 2.0 * g::dot(d, g::perp(pe));
            }
            let dx = crate::lu3::Lu3::new(&a).solve(&(-h))?;
            x.x += dx[0];
            x.y += dx[1];
            x.phi += dx[2];
            let size = dx[0]
                .abs()
                .max(dx[1].abs())
                .max((dx[2] * self.r_char).abs());
            if !size.is_finite() || size > 1e3 {
                return None;
            }
            if size < STEP_TOL {
                return Some(x);
            }
            // Once in the quadratic regime the step must shrink; a step that stops shrinking
            // at round-off level is converged.
            if size < 1e-8 && size >= last {
                return Some(x);
            }
            last = size;
        }
        None
    }

    /// Whether a pose with these curvatures is in the working mode and home assembly mode.
    ///
    /// Bit for bit `jacobian_a(pose, kappa).determinant()`'s sign and `joint_angles(..).0`'s
    /// sign, with each leg's tip and the platform's sin_cos computed once (it runs after every
    /// warm FK: 18 sin_cos and 6 atan2 calls before, 4 and at most 3 now).
    pub fn in_mode(&self, pose: &Pose, kappa: &[f64; 3]) -> bool {
        let (s, c) = pose.phi.sin_cos();
        let mut a = nalgebra::Matrix3::zeros();
        let mut d_of = [[0.0; 2]; 3];
        let mut t_of = [[0.0; 2]; 3];
        for i in 0..3 {
            let leg = &self.legs[i];
            let v = leg.p_e;
            let pe = [c * v[0] - s * v[1], s * v[0] + c * v[1]];
            let tip = leg.local_tip(kappa[i] * leg.l_c);
            let m = g::add(leg.b, leg.to_base(tip.m));
            let p = g::add([pose.x, pose.y], pe);
            let d = g::sub(p, m);
            a[(i, 0)] = 2.0 * d[0];
            a[(i, 1)] = 2.0 * d[1];
            a[(i, 2)] = 2.0 * g::dot(d, g::perp(pe));
            d_of[i] = d;
            t_of[i] = leg.to_base(tip.t);
        }
        if a.determinant().signum() != self.home_det_sign {
            return false;
        }
        (0..3).all(|i| {
            let (y, x) = (g::cross(t_of[i], d_of[i]), g::dot(t_of[i], d_of[i]));
            let sign = self.mode[i].sign();
            // atan2(y, x) has the sign of y wherever y is not zero (NaN: false either way).
            if y != 0.0 {
                y * sign > 0.0
            } else {
                y.atan2(x) * sign > 0.0
            }
        })
    }

    /// FK warm-started at `guess`: Newton from there; if it fails or leaves the mode, the cold
    /// (continuation) FK.
    pub fn fk_warm(&self, kappa: &[f64; 3], guess: &Pose) -> Result<Pose, FkError> {
        if kappa.iter().any(|k| !k.is_finite()) {
            return Err(FkError::NotFinite);
        }
        let m: [Vec2; 3] = std::array::from_fn(|i| self.joint_m(i, kappa[i]));
        if let Some(x) = self.fk_newton(&m, *guess, 30) {
            if self.in_mode(&x, kappa) {
                return Ok(x);
            }
        }
        self.fk(kappa)
    }

    /// Cold FK by continuation from the home configuration.
    pub fn fk(&self, kappa: &[f64; 3]) -> Result<Pose, FkError> {
        if kappa.iter().any(|k| !k.is_finite()) {
            return Err(FkError::NotFinite);
        }
        let k0 = self.home_kappa;
        let mut s = 0.0f64;
        let mut ds = 1.0f64;
        let mut x = Pose::default();
        let kappa_at =
            |s: f64| -> [f64; 3] { std::array::from_fn(|i| k0[i] + s * (kappa[i] - k0[i])) };
        while s < 1.0 {
            let s1 = (s + ds).min(1.0);
            let ka = kappa_at(s);
            let kb = kappa_at(s1);
            // Tangent predictor.
            let mut guess = x;
            if let Some(j) = self.jacobian(&x, &ka) {
                let dk = Vector3::new(kb[0] - ka[0], kb[1] - ka[1], kb[2] - ka[2]);
                let dx = j * dk;
                guess = Pose::new(x.x + dx[0], x.y + dx[1], x.phi + dx[2]);
            }
            let m: [Vec2; 3] = std::array::from_fn(|i| self.joint_m(i, kb[i]));
            let ok = self
                .fk_newton(&m, guess, 12)
                .filter(|p| self.in_mode(p, &kb) && p.position_distance(&x) < 1e3);
            match ok {
                Some(p) => {
                    x = p;
                    s = s1;
                    ds = (ds * 2.0).min(1.0);
                }
                None => {
                    ds *= 0.5;
                    if ds < 1e-4 {
                        return Err(FkError::NoSolution { reached: s });
                    }
                }
            }
        }
        Ok(x)
    }

    /// FK from motor positions (steps) through the tendon maps; cold start.
    pub fn fk_steps(&self, q: &[f64; 3]) -> Result<Pose, FkError> {
        let kappa = std::array::from_fn(|i| self.steps_to_kappa(i, q[i]));
        self.fk(&kappa)
    }
}
