//! Kineto-static extension of the constant-curvature model (the paper's stated future work):
//! segments that bend under the link forces while the tendons hold their total bending, an
//! external wrench on the platform, and springs in the passive joints.
//!
//! Each segment is the unloaded circular arc plus the small-load change of shape under the force
//! F at its tip (linear beam theory along the arc): the internal moment gains
//! `g(s) = ((r_L - r(s)) x F)_z`; the tendons keep the total bending, so the curvature changes by
//! `(g(s) - mean g) / EI` (the tendon tension takes the mean); the tip moves by
//! `integral of d alpha(s) n(s) ds` with `d alpha` the change of the tangent angle and `n` the
//! normal. The tip tangent does not turn, so the rigid extension carries the displacement to
//! M_i unchanged. This gives a 2x2 compliance C_i(kappa_i) per leg, computed by quadrature.
//!
//! The links are two-force members unless the joints carry springs (torques
//! `tau_M = -k_M (gamma - gamma0)`, `tau_P = -k_P (zeta - zeta0)` on the link, relaxed at the home
//! pose of this model); the force on the platform is
//! `f_i = lambda_i u_i + ((tau_M + tau_P) / l_st) R(90 deg) u_i`, and the segment tip carries -f_i.
//! The unknowns (pose, lambda, the three tip displacements) solve the loop closures, the
//! platform equilibrium `sum f_i + F = 0`, `sum (P_i - E) x f_i + sum k_P (zeta_i - zeta0_i) + M = 0`
//! and the compliance relations together by Newton.
//!
//! This model is independent of the plant's elastica shooting (`pcr-plant`): it shares only the
//! conventions of geometry.md and the physics of a loaded rod, and it is what the residual tools
//! fit when the data show compliance.

use crate::fk::FkError;
use crate::ik::IkError;
use crate::model::Robot;
use crate::pose::Pose;
use nalgebra::{SMatrix, SVector};
use pcr_robot::effects::Compliance;
use pcr_robot::{geometry as g, Vec2};

/// Quadrature intervals along a segment.
const QUAD: usize = 96;

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

type V12 = SVector<f64, 12>;

/// What the loaded equilibrium of given curvatures keeps fixed: the unloaded joints and tip
/// tangents, the tip compliances and the springs' rest angles.
struct LoadedSetup {
    m0: [Vec2; 3],
    t: [Vec2; 3],
    c: [[[f64; 2]; 2]; 3],
    rest: [(f64, f64); 3],
}
type M12 = SMatrix<f64, 12, 12>;

/// The state [`Robot::fk_loaded_warm`] carries from one call to the next along a series: the
/// last solution and the factorised Jacobian of the chord iteration, and the springs' rest
/// angles. One `LoadedWarm` serves one robot.
#[derive(Debug, Clone, Default)]
pub struct LoadedWarm {
    rest: Option<[(f64, f64); 3]>,
    z: Option<V12>,
    rigid: [f64; 3],
    lu: Option<nalgebra::LU<f64, nalgebra::Const<12>, nalgebra::Const<12>>>,
}

impl Robot {
    /// The 2x2 compliance of leg i's joint M_i to a force at the segment tip (base frame,
    /// mm/N), for curvature `kappa` and bending stiffness `ei` (N mm^2), total bending held.
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

    /// The passive joint angles (gamma_i, zeta_i) of this model at its home configuration: the
    /// rest angles of the joint springs.
    pub fn home_joint_angles(&self) -> [(f64, f64); 3] {
        let home = Pose::default();
        std::array::from_fn(|i| self.joint_angles(i, &home, self.home_kappa[i]))
    }

    /// Forward kinematics with loads: the equilibrium for curvatures `kappa` (the tendons' total
    /// bending), started at `guess` (e.g. the rigid FK).
    pub fn fk_loaded(
        &self,
        kappa: &[f64; 3],
        loads: &Loads,
        guess: &Pose,
    ) -> Result<Equilibrium, FkError> {
        let setup = self.loaded_setup(kappa, loads.ei);
        self.fk_loaded_in(&setup, kappa, loads, guess)
            .map(|z| self.equilibrium_of_z(&setup, &z))
    }

    /// The equilibrium unknowns (pose, lambda, tip displacements) for `setup`: Newton with a
    /// fresh finite-difference Jacobian at every step, started at the rigid FK from `guess`.
    fn fk_loaded_in(
        &self,
        setup: &LoadedSetup,
        kappa: &[f64; 3],
        loads: &Loads,
        guess: &Pose,
    ) -> Result<V12, FkError> {
        let rigid = self.fk_warm(kappa, guess)?;
        let mut z = V12::zeros();
        z[0] = rigid.x;
        z[1] = rigid.y;
        z[2] = rigid.phi;
        if loads.is_unloaded() {
            return Ok(z);
        }
        let residual = |z: &V12| self.loaded_residual(setup, loads, z);
        let mut f = residual(&z);
        for _ in 0..40 {
            let jac = self.loaded_jacobian(setup, loads, &z, &f);
            let Some(dz) = jac.lu().solve(&(-f)) else {
                return Err(FkError::NoSolution { reached: 0.0 });
            };
            z += dz;
            f = residual(&z);
            if !z.iter().all(|v| v.is_finite()) || dz[0].abs() > 1e3 {
                return Err(FkError::NoSolution { reached: 0.0 });
            }
            if dz.amax() < 1e-10 {
                break;
            }
        }
        if f.amax() > 1e-6 {
            return Err(FkError::NoSolution { reached: 0.0 });
        }
        Ok(z)
    }

    /// Forward kinematics with loads along a series: as [`Robot::fk_loaded`], but started from
    /// the previous solution held in `warm` (its link forces and deflections, and the deflection
    /// of its pose from the rigid one) and iterated with the Jacobian `warm` carries, refreshed
    /// only when the iteration stops contracting (chord Newton). Converges to the same
    /// equilibrium as [`Robot::fk_loaded`] (steps below 1e-10), at a fraction of the cost where
    /// the configuration changes little from one call to the next.
    pub fn fk_loaded_warm(
        &self,
        kappa: &[f64; 3],
        loads: &Loads,
        guess: &Pose,
        warm: &mut LoadedWarm,
    ) -> Result<Equilibrium, FkError> {
        let rest = *warm.rest.get_or_insert_with(|| self.home_joint_angles());
        let setup = self.loaded_setup_at_rest(kappa, loads.ei, rest);
        let rigid = self.fk_warm(kappa, guess)?;
        let mut z = V12::zeros();
        z[0] = rigid.x;
        z[1] = rigid.y;
        z[2] = rigid.phi;
        if loads.is_unloaded() {
            return Ok(self.equilibrium_of_z(&setup, &z));
        }
        if let Some(prev) = &warm.z {
            for k in 0..3 {
                z[k] += prev[k] - warm.rigid[k];
            }
            for k in 3..12 {
                z[k] = prev[k];
            }
        }
        let residual = |z: &V12| self.loaded_residual(&setup, loads, z);
        let mut f = residual(&z);
        let mut last = f64::INFINITY;
        let mut converged = false;
        for it in 0..60 {
            if warm.lu.is_none() || it == 40 {
                warm.lu = Some(self.loaded_jacobian(&setup, loads, &z, &f).lu());
                last = f64::INFINITY;
            }
            let Some(dz) = warm.lu.as_ref().and_then(|lu| lu.solve(&(-f))) else {
                warm.lu = None;
                return Err(FkError::NoSolution { reached: 0.0 });
            };
            let step = dz.amax();
            if !step.is_finite() || step > 1e3 {
                warm.lu = None;
                warm.z = None;
                return Err(FkError::NoSolution { reached: 0.0 });
            }
            z += dz;
            f = residual(&z);
            if step < 1e-10 {
                converged = true;
                break;
            }
            // A chord step that contracts poorly: a fresh Jacobian for the next one.
            if step > 0.25 * last {
                warm.lu = None;
            }
            last = step;
        }
        if !converged || f.amax() > 1e-6 || !z.iter().all(|v| v.is_finite()) {
            warm.lu = None;
            warm.z = None;
            return Err(FkError::NoSolution { reached: 0.0 });
        }
        warm.z = Some(z);
        warm.rigid = [rigid.x, rigid.y, rigid.phi];
        Ok(self.equilibrium_of_z(&setup, &z))
    }

    /// The finite-difference Jacobian of the loaded residual at `z` (`f` its value there).
    fn loaded_jacobian(&self, setup: &LoadedSetup, loads: &Loads, z: &V12, f: &V12) -> M12 {
        let mut jac = M12::zeros();
        for k in 0..12 {
            let h = 1e-7 * z[k].abs().max(if k == 2 { 1e-3 } else { 1.0 });
            let mut zp = *z;
            zp[k] += h;
            let fp = self.loaded_residual(setup, loads, &zp);
            jac.set_column(k, &((fp - f) / h));
        }
        jac
    }

    /// The equilibrium of solved unknowns `z`.
    fn equilibrium_of_z(&self, setup: &LoadedSetup, z: &V12) -> Equilibrium {
        let pose = Pose::new(z[0], z[1], z[2]);
        let m: [Vec2; 3] =
            std::array::from_fn(|i| [setup.m0[i][0] + z[6 + 2 * i], setup.m0[i][1] + z[7 + 2 * i]]);
        self.equilibrium_of(&pose, &m, &setup.t, [z[3], z[4], z[5]])
    }

    fn loaded_setup(&self, kappa: &[f64; 3], ei: f64) -> LoadedSetup {
        self.loaded_setup_at_rest(kappa, ei, self.home_joint_angles())
    }

    /// [`Robot::loaded_setup`] with the springs' rest angles given (they depend on the robot
    /// only).
    fn loaded_setup_at_rest(
        &self,
        kappa: &[f64; 3],
        ei: f64,
        rest: [(f64, f64); 3],
    ) -> LoadedSetup {
        LoadedSetup {
            m0: std::array::from_fn(|i| self.joint_m(i, kappa[i])),
            t: std::array::from_fn(|i| self.legs[i].tangent(kappa[i])),
            c: std::array::from_fn(|i| self.tip_compliance(i, kappa[i], ei)),
            rest,
        }
    }

    /// Residual of the loaded equilibrium: loop closures (mm), platform forces (N) and moment
    /// (N, divided by the characteristic radius), compliance relations (mm).
    fn loaded_residual(&self, st: &LoadedSetup, loads: &Loads, z: &V12) -> V12 {
        let pose = Pose::new(z[0], z[1], z[2]);
        let mut out = V12::zeros();
        let mut sum_f = [loads.force[0], loads.force[1]];
        let mut sum_m = loads.couple;
        for i in 0..3 {
            let m = [st.m0[i][0] + z[6 + 2 * i], st.m0[i][1] + z[7 + 2 * i]];
            let p = self.joint_p(i, &pose);
            let d = g::sub(p, m);
            let l = self.legs[i].l_st;
            out[i] = (g::dot(d, d) - l * l) / (2.0 * l);
            let u = g::scale(1.0 / g::norm(d).max(1e-9), d);
            let gamma = g::signed_angle(st.t[i], d);
            let pe = g::sub(p, [pose.x, pose.y]);
            let zeta = g::signed_angle(pe, g::sub(m, p));
            let tau = -loads.k_m * (gamma - st.rest[i].0) - loads.k_p * (zeta - st.rest[i].1);
            let f = g::add(g::scale(z[3 + i], u), g::scale(tau / l, g::perp(u)));
            sum_f = g::add(sum_f, f);
            sum_m += g::cross(pe, f) + loads.k_p * (zeta - st.rest[i].1);
            // Compliance: the tip carries -f.
            let c = &st.c[i];
            out[6 + 2 * i] = z[6 + 2 * i] + (c[0][0] * f[0] + c[0][1] * f[1]);
            out[7 + 2 * i] = z[7 + 2 * i] + (c[1][0] * f[0] + c[1][1] * f[1]);
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
        let st = self.loaded_setup(kappa, loads.ei);
        let z = self.fk_loaded_in(&st, kappa, loads, guess)?;
        let f0 = self.loaded_residual(&st, loads, &z);
        let lu = self.loaded_jacobian(&st, loads, &z, &f0).lu();
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
            let ft = (self.loaded_residual(&st, &l, &z) - f0) / h;
            let dz = lu
                .solve(&(-ft))
                .ok_or(FkError::NoSolution { reached: 0.0 })?;
            *o = [dz[0], dz[1], dz[2]];
        }
        Ok(out)
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
        let e = r
            .fk_loaded(&r.home_kappa, &springs, &Pose::default())
            .unwrap();
        assert!(
            e.pose.x.abs() < 1e-9 && e.pose.y.abs() < 1e-9,
            "{:?}",
            e.pose
        );
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
        let loads = Loads {
            force: [0.4, -0.3],
            k_m: 300.0,
            k_p: 200.0,
            ..unloaded()
        };
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
}
