//! Coulomb friction in the passive joints and in the joints' supports, as loads of the
//! small-load statics about the constant-curvature configuration.
//!
//! Each passive joint (M_i and P_i) can carry a friction couple between the bodies it joins,
//! and each joint's support (M_i on the segment's tip body, P_i on the platform) a friction
//! force against the base plate it slides on. Each is an elastic-perfectly-plastic (Jenkins)
//! element: a stiff spring from an anchor in series with a Coulomb slider. Its load is
//! `-k (x - a)` while `|k (x - a)|` stays within its limit (stick) and the limit along
//! `-(x - a)` beyond it (slip), where the anchor `a` follows so that the element sits at its
//! limit: the history of the path is in the anchors. `x` is the joint angle (gamma_i, zeta_i of
//! geometry.md) or the joint's position in the base frame; `k` is the limit over the
//! pre-sliding displacement (the element's travel from stick to slip, a property of the
//! contact rather than of its load, as in Dahl's model).
//!
//! The loads are small (a few N mm, a few tenths of N), so the structure answers them as a
//! linear elastic one about the configuration of the curvatures ([`SmallLoads`]): the links are
//! rigid, each segment's tip (and with it M_i, the tip tangent held by the tendons) moves by its
//! tip compliance times the force on it ([`Robot::tip_compliance`]), the platform is rigid. The
//! elastic unknowns are the three tips' displacements; the elements' coordinates and the pose
//! follow from them through the loop closures. Each row's equilibrium minimises the potential
//! energy of the segments and the elements (convex: a Newton iteration on six unknowns), so
//! that a stuck support holds its joint against the segment's compliance while a slipping one
//! pushes with its limit. Near the workspace's edge the platform turns easily and the first-order
//! answer misses by several per cent of the deflection: the structure's answer is taken at the
//! midpoint of the deflection (second order; the row before's, which changes little from row to
//! row; a test holds the midpoint rule against the large-deflection solver of
//! [`crate::statics`]).
//!
//! The model is this crate's own (the plant's friction, `pcr-plant`, is another model of the
//! same physics); it is what the residual tools fit when the data show friction.

use crate::model::Robot;
use crate::pose::Pose;
use nalgebra::{SMatrix, SVector};
use pcr_robot::geometry as g;

/// Friction elements: 6 joints (gamma_1..3, zeta_1..3: their couples on the link, N mm) and 6
/// supports (x, y of M_1..3, then of P_1..3: their forces on the tip bodies and the platform,
/// N): the coordinates `x` and the loads `L` of the elements, in this order.
pub const ELEMENTS: usize = 18;

/// Elastic degrees of freedom: the displacements of the segments' tips (x, y of M_1..3, base
/// frame, mm).
const DOF: usize = 6;

type VE = SVector<f64, ELEMENTS>;
type VD = SVector<f64, DOF>;
type MD = SMatrix<f64, DOF, DOF>;
/// d x / d d: the elements' coordinates per tip displacement.
type MT = SMatrix<f64, ELEMENTS, DOF>;

/// The friction of the joints and their supports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Friction {
    /// Coulomb couple of each passive joint, N mm.
    pub joint_torque: f64,
    /// A joint's rotation from stick to slip, rad.
    pub joint_presliding: f64,
    /// Coulomb force of each joint's support on the base plate, N.
    pub support_force: f64,
    /// A support's displacement from stick to slip, mm.
    pub support_presliding: f64,
    /// Segment bending stiffness, N mm^2.
    pub ei: f64,
}

impl Friction {
    /// The friction of a robot file's `[effects.friction]`.
    pub fn from_effect(f: &pcr_robot::effects::Friction) -> Friction {
        Friction {
            joint_torque: f.joint_torque_n_mm,
            joint_presliding: f.joint_presliding_rad,
            support_force: f.support_force_n,
            support_presliding: f.support_presliding_mm,
            ei: f.ei_n_mm2,
        }
    }

    /// Whether nothing rubs (every prediction is the rigid one).
    pub fn is_off(&self) -> bool {
        self.joint_torque == 0.0 && self.support_force == 0.0
    }

    /// Whether the joints' couple loads the structure ([`NEGLIGIBLE_COUPLE`]).
    fn joints_load(&self) -> bool {
        self.joint_torque > NEGLIGIBLE_COUPLE
    }
}

/// A joints' couple (N mm) at or below which the equilibrium leaves the joints out: their loads
/// move the tips by some 1e-10 mm and less. The joints' elements keep their history, and the
/// tangent's derivative by the couple is taken as at the couple's onset, from where each joint
/// sticks or slips. A fit that holds the couple at its bound of zero leaves it a little inside
/// (1e-25 to 1e-35 N mm beside the supports' friction): with the joints in, each configuration
/// of the path carried six more elements whose stick-slip pattern the Newton iteration had to
/// settle, for nothing (backlash + supports at 3x: 0.4 s of 9).
pub const NEGLIGIBLE_COUPLE: f64 = 1e-9;

/// The small-load statics at one configuration: the elastic degrees of freedom are the
/// segments' tip displacements `d` (the links and the platform rigid, the tip tangents held by
/// the tendons); the elements' coordinates are `x0 + t d`, the pose's change `h d`, and the
/// segments' stiffness `k` (block diagonal, the inverses of their tip compliances). Loads `L`
/// at the elements hold the tips where `k d = t^T L` (virtual work).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SmallLoads {
    /// The elements' coordinates without loads.
    pub x0: VE,
    /// d x / d d.
    pub t: MT,
    /// d pose / d d (x mm, y mm, phi rad).
    pub h: SMatrix<f64, 3, DOF>,
    /// The segments' tip stiffness, N/mm.
    pub k: MD,
}

impl SmallLoads {
    /// The tip displacements, the elements' coordinates and the pose's change (x mm, y mm, phi
    /// rad) under the loads `l` at the elements (the order of [`ELEMENTS`]).
    pub fn answer(&self, l: &[f64; ELEMENTS]) -> ([f64; DOF], [f64; ELEMENTS], [f64; 3]) {
        let q = self.t.tr_mul(&VE::from(*l));
        let d = self.k.cholesky().map_or(VD::zeros(), |c| c.solve(&q));
        let x = self.x0 + self.t * d;
        let p = self.h * d;
        (d.into(), x.into(), [p[0], p[1], p[2]])
    }
}

/// Where each friction element sticks: its history along the path.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FrictionState {
    /// Anchors of the element coordinates (a support's two share one 2-D anchor); `None`
    /// before the first row (the path starts with every element unloaded).
    anchors: Option<[f64; ELEMENTS]>,
    /// The tip displacements of the last row (the next row's Newton start).
    d: [f64; DOF],
    /// The last row's configuration (pose, curvatures) and its answer: a row at rest keeps it.
    last: Option<([f64; 3], [f64; 3], [f64; 3])>,
    /// [`Robot::friction_onset`]'s last answer to the supports (the joints' is in `d`).
    onset: [f64; 3],
    /// The structure the last row was answered with: what the configurations passed before the
    /// next row are answered with ([`Robot::friction_pass`]; its coordinates are the last
    /// configuration's).
    held: Option<SmallLoads>,
    /// Per leg and direction of its curvature's change (falling, rising): how the tips moved
    /// per unit of that change the last time that leg alone stepped that way (mm per 1/mm),
    /// the next Newton start's predictor ([`settle`]).
    per_step: [[Option<[f64; DOF]>; 2]; 3],
}

impl FrictionState {
    /// The displacements of the joints M_i (base frame, mm) by the friction at the last row
    /// [`Robot::friction_step`] answered: the segments' tips deflected by the loads.
    pub fn joints(&self) -> [[f64; 2]; 3] {
        std::array::from_fn(|i| [self.d[2 * i], self.d[2 * i + 1]])
    }

    /// How far the history `other` holds is from this one: the largest difference of an
    /// element's anchor (rad for a joint, mm for a support) or of a tip's displacement (mm);
    /// infinite where one of them has not started. What the rows after them are answered from
    /// (the rest of a state only starts the next equilibrium's iteration).
    pub fn difference(&self, other: &FrictionState) -> f64 {
        let (Some(a), Some(b)) = (self.anchors, other.anchors) else {
            return f64::INFINITY;
        };
        a.iter()
            .zip(&b)
            .chain(self.d.iter().zip(&other.d))
            .fold(0.0, |m: f64, (x, y)| m.max((x - y).abs()))
    }
}

/// The derivatives of a path's friction state by the fitted values (the joints' couple N mm, the
/// supports' force N, the joints' pre-sliding travel rad): of the tips' displacements, of the
/// anchors, and of the last row's answer ([`Robot::friction_step_tangent`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrictionTangent {
    d: SMatrix<f64, DOF, 3>,
    a: SMatrix<f64, ELEMENTS, 3>,
    pose: [[f64; 3]; 3],
}

impl Default for FrictionTangent {
    fn default() -> Self {
        FrictionTangent {
            d: SMatrix::zeros(),
            a: SMatrix::zeros(),
            pose: [[0.0; 3]; 3],
        }
    }
}

impl FrictionTangent {
    /// How far the derivatives `other` holds are from these: per fitted value (their scales
    /// differ: N mm, N, rad), the largest difference of a derivative of an anchor or of a tip's
    /// displacement by it relative to the largest such derivative of either; the largest of
    /// the three.
    pub fn difference(&self, other: &FrictionTangent) -> f64 {
        (0..3).fold(0.0, |m: f64, c| {
            let (d0, d1) = (self.d.column(c), other.d.column(c));
            let (a0, a1) = (self.a.column(c), other.a.column(c));
            let diff = (d0 - d1).amax().max((a0 - a1).amax());
            if diff == 0.0 {
                return m;
            }
            let scale = d0.amax().max(d1.amax()).max(a0.amax()).max(a1.amax());
            m.max(diff / scale)
        })
    }

    /// One row: the equilibrium `d` of `sl` with the anchors `a` (before they follow), its
    /// derivatives, and those of the anchors after the row.
    fn advance(&mut self, f: &Friction, sl: &SmallLoads, a: &VE, d: &VD, laws: AtEquilibrium) {
        // The elements' coordinates and tangent at `d`, as the equilibrium's iteration left
        // them where it evaluated them there.
        let (x, tan) = laws.unwrap_or_else(|| {
            let x = sl.x0 + sl.t * d;
            (x, element_laws(f, &x, a).1)
        });
        // dL/dtheta at fixed coordinates and anchors, and the elements' stiffness times the
        // anchors' derivatives (L depends on x - a: dL/da = D).
        let mut rhs = SMatrix::<f64, ELEMENTS, 3>::zeros();
        let (tj, fs) = (f.joint_torque, f.support_force);
        if tj > 0.0 {
            let p = f.joint_presliding;
            let load = f.joints_load();
            for e in 0..6 {
                let s = x[e] - a[e];
                // Left out of the equilibrium, a joint sticks within its pre-sliding travel.
                let stuck = if load {
                    tan.joints[e] != 0.0
                } else {
                    s.abs() <= p
                };
                if stuck {
                    // Stuck: L = -(tau / p) s.
                    rhs[(e, 0)] = -s / p;
                    rhs[(e, 2)] = tj * s / (p * p);
                } else {
                    rhs[(e, 0)] = -s.signum();
                }
                for c in 0..3 {
                    rhs[(e, c)] += tan.joints[e] * self.a[(e, c)];
                }
            }
        }
        if fs > 0.0 {
            let ps = f.support_presliding;
            for q in 0..6 {
                let (ix, iy) = (6 + 2 * q, 7 + 2 * q);
                let s = [x[ix] - a[ix], x[iy] - a[iy]];
                let n = (s[0] * s[0] + s[1] * s[1]).sqrt();
                let b = tan.supports[q];
                let (ux, uy) = if n * fs / ps <= fs || n == 0.0 {
                    (s[0] / ps, s[1] / ps)
                } else {
                    (s[0] / n, s[1] / n)
                };
                rhs[(ix, 1)] = -ux;
                rhs[(iy, 1)] = -uy;
                for c in 0..3 {
                    let (dax, day) = (self.a[(ix, c)], self.a[(iy, c)]);
                    rhs[(ix, c)] += b[0] * dax + b[1] * day;
                    rhs[(iy, c)] += b[1] * dax + b[2] * day;
                }
            }
        }
        let Some(ch) = Chol6::new(&hessian(sl, &tan)) else {
            return;
        };
        self.d = ch.solve_columns(&sl.t.tr_mul(&rhs));
        let dx = sl.t * self.d;
        // The anchors that slip follow their coordinates, a pre-sliding travel behind.
        let mut next = self.a;
        if tj > 0.0 {
            let p = f.joint_presliding;
            for e in 0..6 {
                let s = x[e] - a[e];
                if s.abs() > p {
                    for c in 0..3 {
                        next[(e, c)] = dx[(e, c)] - if c == 2 { s.signum() } else { 0.0 };
                    }
                }
            }
        }
        if fs > 0.0 {
            let ps = f.support_presliding;
            for q in 0..6 {
                let (ix, iy) = (6 + 2 * q, 7 + 2 * q);
                let s = [x[ix] - a[ix], x[iy] - a[iy]];
                let n = (s[0] * s[0] + s[1] * s[1]).sqrt();
                if n > ps {
                    let u = [s[0] / n, s[1] / n];
                    for c in 0..3 {
                        let ds = [dx[(ix, c)] - self.a[(ix, c)], dx[(iy, c)] - self.a[(iy, c)]];
                        // d(s/|s|) = (I - u u^T) ds / |s|.
                        let along = u[0] * ds[0] + u[1] * ds[1];
                        let du = [(ds[0] - u[0] * along) / n, (ds[1] - u[1] * along) / n];
                        next[(ix, c)] = dx[(ix, c)] - ps * du[0];
                        next[(iy, c)] = dx[(iy, c)] - ps * du[1];
                    }
                }
            }
        }
        self.a = next;
        let dp = sl.h * self.d;
        self.pose = std::array::from_fn(|c| [dp[(0, c)], dp[(1, c)], dp[(2, c)]]);
    }
}

/// Why a row's friction could not be found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrictionError {
    /// The links cannot carry the platform's loads (a singular configuration).
    #[error("friction: the links cannot balance the platform here (singular configuration)")]
    Singular,
    /// The iteration did not converge.
    #[error("friction: the stick-slip iteration did not converge")]
    NoConvergence,
}

/// A segment's axial compliance, as a share of its bending compliance (the trace of its tip
/// compliance): [`Robot::small_loads`].
const AXIAL: f64 = 1e-6;

/// The segments' tip stiffness (block diagonal, N/mm) of their tip compliances `c` (base
/// frame, mm/N): the inverses, each with a small axial compliance ([`AXIAL`]); `None` where one
/// is not positive definite.
fn stiffness_of(c: &[[[f64; 2]; 2]; 3]) -> Option<MD> {
    let mut k = MD::zeros();
    for (i, c) in c.iter().enumerate() {
        let mut c = *c;
        // A straight inextensible segment does not yield along its axis (its compliance is
        // singular there): a real one does, slightly. Its stiffness is taken as a million times
        // the bending's, which keeps the equilibrium's Hessian regular and moves nothing
        // measurably.
        let axial = AXIAL * (c[0][0] + c[1][1]);
        c[0][0] += axial;
        c[1][1] += axial;
        let det = c[0][0] * c[1][1] - c[0][1] * c[1][0];
        if det.is_nan() || det <= 0.0 {
            return None;
        }
        // Symmetrised (the quadrature's compliance is symmetric to rounding).
        let off = 0.5 * (c[0][1] + c[1][0]);
        k[(2 * i, 2 * i)] = c[1][1] / det;
        k[(2 * i + 1, 2 * i + 1)] = c[0][0] / det;
        k[(2 * i, 2 * i + 1)] = -off / det;
        k[(2 * i + 1, 2 * i)] = -off / det;
    }
    Some(k)
}

/// Nodes of the table of a segment's dimensionless tip compliance over its bending, +-180 deg.
const TABLE: usize = 4096;

/// A base-frame compliance (xx, xy, yy) of `leg` in the leg's frame.
fn local(leg: &crate::leg::Leg, c: [f64; 3]) -> [f64; 3] {
    let (cp, sp) = (leg.cos_psi, leg.sin_psi);
    let (a, b, d) = (c[0], c[1], c[2]);
    [
        cp * cp * a + 2.0 * cp * sp * b + sp * sp * d,
        -cp * sp * (a - d) + (cp * cp - sp * sp) * b,
        sp * sp * a - 2.0 * cp * sp * b + cp * cp * d,
    ]
}

/// The dimensionless tip compliance (xx, xy, yy in the leg's frame, times EI / l_C^3) of a
/// segment bent by `theta`, from the table; `None` beyond +-180 deg.
fn shape_compliance(theta: f64) -> Option<[f64; 3]> {
    static NODES: std::sync::OnceLock<Vec<[f64; 3]>> = std::sync::OnceLock::new();
    let pi = std::f64::consts::PI;
    if theta.is_nan() || theta.abs() > pi {
        return None;
    }
    let nodes = NODES.get_or_init(|| {
        let r = Robot::nominal();
        let leg = &r.legs[0];
        let (ei, l) = (1.0, leg.l_c);
        let s = ei / l.powi(3);
        (0..=TABLE)
            .map(|k| {
                let theta = -pi + 2.0 * pi * k as f64 / TABLE as f64;
                let c = r.tip_compliance(0, theta / l, ei);
                local(
                    leg,
                    [c[0][0] * s, 0.5 * (c[0][1] + c[1][0]) * s, c[1][1] * s],
                )
            })
            .collect()
    });
    let u = (theta + pi) / (2.0 * pi) * TABLE as f64;
    let k = (u.floor() as usize).min(TABLE - 1);
    let w = u - k as f64;
    let (a, b) = (nodes[k], nodes[k + 1]);
    Some(std::array::from_fn(|c| a[c] + w * (b[c] - a[c])))
}

/// Newton iterations of one row at most.
const ITERATIONS: usize = 50;

impl Robot {
    /// The small-load statics at the rigid pose `pose` of the curvatures `kappa`
    /// ([`SmallLoads`]); `None` at a singular configuration.
    pub fn small_loads(&self, pose: &Pose, kappa: &[f64; 3], ei: f64) -> Option<SmallLoads> {
        let k = self.tip_stiffness(kappa, ei)?;
        self.small_loads_displaced(pose, kappa, &[[0.0; 2]; 3], &k)
    }

    /// The segments' tip stiffness (block diagonal, N/mm): the inverses of their tip
    /// compliances, each with a small axial compliance ([`AXIAL`]); `None` where one is not
    /// positive definite.
    fn tip_stiffness(&self, kappa: &[f64; 3], ei: f64) -> Option<MD> {
        stiffness_of(&std::array::from_fn(|i| {
            self.tip_compliance_tabulated(i, kappa[i], ei)
        }))
    }

    /// [`Robot::tip_compliance`] from a table: the compliance of a segment whose tip tangent is
    /// held is `l_C^3 / EI` times a function of its bending `kappa l_C` alone (in the leg's
    /// frame), tabulated once over +-180 deg and interpolated linearly (within 1e-6 of the
    /// quadrature's: a test holds it).
    pub fn tip_compliance_tabulated(&self, i: usize, kappa: f64, ei: f64) -> [[f64; 2]; 2] {
        let leg = &self.legs[i];
        let theta = kappa * leg.l_c;
        let c = shape_compliance(theta).unwrap_or_else(|| {
            // Beyond the table (beyond the bending range): the quadrature itself.
            let k = self.tip_compliance(i, kappa, ei);
            let s = ei / leg.l_c.powi(3);
            local(
                leg,
                [k[0][0] * s, 0.5 * (k[0][1] + k[1][0]) * s, k[1][1] * s],
            )
        });
        let s = leg.l_c.powi(3) / ei;
        // R c R^T with R the leg's rotation.
        let (cp, sp) = (leg.cos_psi, leg.sin_psi);
        let (a, b, d) = (c[0] * s, c[1] * s, c[2] * s);
        let xx = cp * cp * a - 2.0 * cp * sp * b + sp * sp * d;
        let xy = cp * sp * (a - d) + (cp * cp - sp * sp) * b;
        let yy = sp * sp * a + 2.0 * cp * sp * b + cp * cp * d;
        [[xx, xy], [xy, yy]]
    }

    /// The elements' coordinates at the platform pose `pose`, the curvatures `kappa` and the
    /// joints M_i displaced by `dm` from the arcs'; `each` sees every leg's M_i and P_i.
    fn coordinates(
        &self,
        pose: &Pose,
        kappa: &[f64; 3],
        dm: &[[f64; 2]; 3],
        each: impl FnMut(usize, [f64; 2], [f64; 2]),
    ) -> VE {
        self.coordinates_of(pose, kappa, dm, true, each)
    }

    /// [`Robot::coordinates`], the joints' angles (the first six) left at zero without
    /// `angles`: what a structure needs of a configuration is the joints' places.
    fn coordinates_of(
        &self,
        pose: &Pose,
        kappa: &[f64; 3],
        dm: &[[f64; 2]; 3],
        angles: bool,
        mut each: impl FnMut(usize, [f64; 2], [f64; 2]),
    ) -> VE {
        let mut x0 = VE::zeros();
        for i in 0..3 {
            let m = g::add(self.joint_m(i, kappa[i]), dm[i]);
            let p = self.joint_p(i, pose);
            if angles {
                let t = self.legs[i].tangent(kappa[i]);
                let pe = g::sub(p, [pose.x, pose.y]);
                x0[i] = g::signed_angle(t, g::sub(p, m));
                x0[3 + i] = g::signed_angle(pe, g::sub(m, p));
            }
            x0[6 + 2 * i] = m[0];
            x0[7 + 2 * i] = m[1];
            x0[12 + 2 * i] = p[0];
            x0[13 + 2 * i] = p[1];
            each(i, m, p);
        }
        x0
    }

    /// [`Robot::small_loads`] at a configuration whose joints M_i are displaced by `dm` from
    /// the arcs' (the segments deflected, their tip tangents held) and whose platform is at
    /// `pose`, with the segments' tip stiffness `k`.
    fn small_loads_displaced(
        &self,
        pose: &Pose,
        kappa: &[f64; 3],
        dm: &[[f64; 2]; 3],
        k: &MD,
    ) -> Option<SmallLoads> {
        let mut sl = SmallLoads {
            x0: VE::zeros(),
            t: MT::zeros(),
            h: SMatrix::zeros(),
            k: *k,
        };
        self.small_loads_into(
            pose,
            kappa,
            dm,
            Some(&mut sl.x0),
            &mut sl.h,
            Some(&mut sl.t),
        )
        .then_some(sl)
    }

    /// The parts of [`Robot::small_loads_displaced`] asked for, written in place: the elements'
    /// coordinates `x0` (when given), the pose's change per tip displacement `h`, and `t` (when
    /// given); false at a singular configuration (`h` and `t` then as they were).
    fn small_loads_into(
        &self,
        pose: &Pose,
        kappa: &[f64; 3],
        dm: &[[f64; 2]; 3],
        x0_out: Option<&mut VE>,
        h: &mut SMatrix<f64, 3, DOF>,
        t_out: Option<&mut MT>,
    ) -> bool {
        let mut u = [[0.0; 2]; 3];
        let mut r = [[0.0; 2]; 3];
        let x0 = self.coordinates_of(pose, kappa, dm, x0_out.is_some(), |i, m, p| {
            u[i] = g::scale(1.0 / self.legs[i].l_st, g::sub(p, m));
            r[i] = g::sub(p, [pose.x, pose.y]);
        });
        if let Some(out) = x0_out {
            *out = x0;
        }
        // The rigid links keep their lengths: u_i . (dP_i - d_i) = 0 with dP_i = dp + dphi
        // R(90) r_i, the rows (u_i, r_i x u_i).
        let w = nalgebra::Matrix3::from_fn(|i, c| match c {
            0 => u[i][0],
            1 => u[i][1],
            _ => g::cross(r[i], u[i]),
        });
        let Some(wi) = w.try_inverse() else {
            return false;
        };
        for i in 0..3 {
            for c in 0..3 {
                h[(c, 2 * i)] = wi[(c, i)] * u[i][0];
                h[(c, 2 * i + 1)] = wi[(c, i)] * u[i][1];
            }
        }
        let Some(t) = t_out else {
            return true;
        };
        for i in 0..3 {
            let n = g::perp(u[i]);
            let pr = g::perp(r[i]);
            let l_st = self.legs[i].l_st;
            for col in 0..DOF {
                let dp = [
                    h[(0, col)] + h[(2, col)] * pr[0],
                    h[(1, col)] + h[(2, col)] * pr[1],
                ];
                let dm = [
                    if col == 2 * i { 1.0 } else { 0.0 },
                    if col == 2 * i + 1 { 1.0 } else { 0.0 },
                ];
                // The link turns by n . (dP - dM) / l_st; gamma with it (the tip tangent is
                // held), zeta with it less the platform's turn.
                let turn = g::dot(n, g::sub(dp, dm)) / l_st;
                t[(i, col)] = turn;
                t[(3 + i, col)] = turn - h[(2, col)];
                t[(6 + 2 * i, col)] = dm[0];
                t[(7 + 2 * i, col)] = dm[1];
                t[(12 + 2 * i, col)] = dp[0];
                t[(13 + 2 * i, col)] = dp[1];
            }
        }
        true
    }

    /// One row of a path through friction: the rigid pose `pose` of the curvatures `kappa`,
    /// the elements' anchors in `state` (updated: the elements that slipped follow). Returns
    /// the pose's change by the friction (x mm, y mm, phi rad). The first row of a path (a
    /// new `state`) starts every element unloaded at its place; a row at rest (the same pose
    /// and curvatures as the last) keeps the last row's answer.
    pub fn friction_step(
        &self,
        f: &Friction,
        pose: &Pose,
        kappa: &[f64; 3],
        state: &mut FrictionState,
    ) -> Result<[f64; 3], FrictionError> {
        self.friction_step_with(f, pose, kappa, state, None)
    }

    /// [`Robot::friction_step`], advancing `tangent` with it when given.
    fn friction_step_with(
        &self,
        f: &Friction,
        pose: &Pose,
        kappa: &[f64; 3],
        state: &mut FrictionState,
        tangent: Option<&mut FrictionTangent>,
    ) -> Result<[f64; 3], FrictionError> {
        let here = [pose.x, pose.y, pose.phi];
        if let Some((p, k, out)) = state.last {
            if p == here && k == *kappa {
                return Ok(out);
            }
        }
        let stiffness = self
            .tip_stiffness(kappa, f.ei)
            .ok_or(FrictionError::Singular)?;
        // The structure is built in place (it is a kilobyte and a half): first the rigid
        // configuration's coordinates and pose change, then the midpoint's structure.
        let mut x0 = VE::zeros();
        let mut h0 = SMatrix::<f64, 3, DOF>::zeros();
        if !self.small_loads_into(pose, kappa, &[[0.0; 2]; 3], Some(&mut x0), &mut h0, None) {
            return Err(FrictionError::Singular);
        }
        let (Some(anchors), false) = (state.anchors, f.is_off()) else {
            state.anchors = Some(x0.into());
            state.d = [0.0; DOF];
            state.last = Some((here, *kappa, [0.0; 3]));
            if let Some(tan) = tangent {
                *tan = FrictionTangent::default();
            }
            return Ok([0.0; 3]);
        };
        let a = VE::from(anchors);
        // Second order: the structure's answer taken at the midpoint of the deflection (the
        // platform and the joints M_i half-way), where the links' directions and levers are
        // those of half the loads. The midpoint is the row before's deflection halved: it
        // changes little from one row to the next, and one solve does (solving first at the
        // rigid configuration and again at the midpoint of that answer gave the same RMS
        // against the plant to 1e-3 mm and 0.004 deg on the sweep's recordings, from the
        // prototype's friction to ten times it, in twice the time). (The segments' own stiffening or softening under the link
        // forces, their tangent compliance at half the tip forces, changed nothing measurable
        // either, at twice the cost.)
        let d0 = VD::from(state.d);
        let p0 = h0 * d0;
        let half = Pose::new(
            pose.x + 0.5 * p0[0],
            pose.y + 0.5 * p0[1],
            pose.phi + 0.5 * p0[2],
        );
        let dm: [[f64; 2]; 3] = std::array::from_fn(|i| [0.5 * d0[2 * i], 0.5 * d0[2 * i + 1]]);
        let held = state.held.get_or_insert_with(|| SmallLoads {
            x0: VE::zeros(),
            t: MT::zeros(),
            h: SMatrix::zeros(),
            k: MD::zeros(),
        });
        held.x0 = x0;
        held.k = stiffness;
        if !self.small_loads_into(&half, kappa, &dm, None, &mut held.h, Some(&mut held.t)) {
            // The rigid configuration's structure where the midpoint's is singular.
            held.h = h0;
            self.small_loads_into(
                pose,
                kappa,
                &[[0.0; 2]; 3],
                None,
                &mut held.h,
                Some(&mut held.t),
            );
        }
        settle(f, &a, here, *kappa, state, tangent)
    }

    /// A configuration the path passes between two rows (a leg's step between two samples: the
    /// rigid pose `pose` of the curvatures `kappa`): the elements move with its rigid
    /// coordinates and those that slip take their anchors along, answered by the structure of
    /// the last row ([`Robot::friction_step`]; between two rows the links' directions and the
    /// segments' compliance change by a few steps' share, the elements' coordinates by their
    /// whole travel). `tangent`, when given, is advanced as by
    /// [`Robot::friction_step_tangent`]. Before the first row, it is that row.
    pub fn friction_pass(
        &self,
        f: &Friction,
        pose: &Pose,
        kappa: &[f64; 3],
        state: &mut FrictionState,
        tangent: Option<&mut FrictionTangent>,
    ) -> Result<[f64; 3], FrictionError> {
        let (Some(a), Some(sl), false) = (state.anchors, state.held.as_mut(), f.is_off()) else {
            return self.friction_step_with(f, pose, kappa, state, tangent);
        };
        sl.x0 = self.coordinates(pose, kappa, &[[0.0; 2]; 3], |_, _, _| {});
        let here = [pose.x, pose.y, pose.phi];
        settle(f, &VE::from(a), here, *kappa, state, tangent)
    }

    /// [`Robot::friction_onset`] at a configuration passed between two rows
    /// ([`Robot::friction_pass`]): the anchors follow the elements' rigid coordinates.
    pub fn friction_onset_pass(
        &self,
        f: &Friction,
        pose: &Pose,
        kappa: &[f64; 3],
        state: &mut FrictionState,
    ) -> Result<(), FrictionError> {
        let Some(anchors) = state.anchors else {
            return self.friction_onset(f, pose, kappa, state).map(|_| ());
        };
        let unit = Friction {
            joint_torque: 1.0,
            support_force: 1.0,
            ..*f
        };
        let x0 = self.coordinates(pose, kappa, &[[0.0; 2]; 3], |_, _, _| {});
        state.anchors = Some(slipped(&unit, &x0, &VE::from(anchors)).into());
        state.last = None;
        Ok(())
    }

    /// [`Robot::friction_step`] with the answer's derivatives by the friction's fitted values
    /// (the joints' couple N mm, the supports' force N, the joints' pre-sliding travel rad;
    /// columns of x mm, y mm, phi rad), carried along the path in `tangent` (a new one with a
    /// new `state`): the equilibrium's derivatives by implicit differentiation, the anchors'
    /// through the elements that slipped. The midpoint the structure is linearised at is held
    /// for them (its own dependence on the values is of second order). One pass gives what
    /// forward differences of three more passes would.
    pub fn friction_step_tangent(
        &self,
        f: &Friction,
        pose: &Pose,
        kappa: &[f64; 3],
        state: &mut FrictionState,
        tangent: &mut FrictionTangent,
    ) -> Result<([f64; 3], [[f64; 3]; 3]), FrictionError> {
        let out = self.friction_step_with(f, pose, kappa, state, Some(tangent))?;
        Ok((out, tangent.pose))
    }

    /// The derivatives of [`Robot::friction_step`]'s answer with respect to the joints' and the
    /// supports' limits where both are zero (x mm, y mm, phi rad per N mm of joint couple, and
    /// per N of support force): with vanishing loads the structure no longer moves the
    /// elements, each element's load is its limit times the stop operator of its pre-sliding
    /// travel on its rigid coordinate (`f`'s limits are not read), and the structure answers
    /// those loads. `state` carries the anchors (a state of its own, not one of
    /// [`Robot::friction_step`]'s).
    pub fn friction_onset(
        &self,
        f: &Friction,
        pose: &Pose,
        kappa: &[f64; 3],
        state: &mut FrictionState,
    ) -> Result<[[f64; 3]; 2], FrictionError> {
        let here = [pose.x, pose.y, pose.phi];
        if let Some((p, k, _)) = state.last {
            if p == here && k == *kappa {
                let (dj, ds) = (state.d, state.onset);
                return Ok([[dj[0], dj[1], dj[2]], ds]);
            }
        }
        let stiffness = self
            .tip_stiffness(kappa, f.ei)
            .ok_or(FrictionError::Singular)?;
        let sl = self
            .small_loads_displaced(pose, kappa, &[[0.0; 2]; 3], &stiffness)
            .ok_or(FrictionError::Singular)?;
        let unit = Friction {
            joint_torque: 1.0,
            support_force: 1.0,
            ..*f
        };
        let a = VE::from(state.anchors.unwrap_or(sl.x0.into()));
        let (l, _) = element_laws(&unit, &sl.x0, &a);
        let ch = Chol6::new(&sl.k).ok_or(FrictionError::Singular)?;
        let answer = |l: VE| -> [f64; 3] {
            let p = sl.h * ch.solve(&sl.t.tr_mul(&l));
            [p[0], p[1], p[2]]
        };
        let mut lj = l;
        let mut ls = l;
        lj.rows_mut(6, 12).fill(0.0);
        ls.rows_mut(0, 6).fill(0.0);
        let (dj, ds) = (answer(lj), answer(ls));
        state.anchors = Some(slipped(&unit, &sl.x0, &a).into());
        state.d = [dj[0], dj[1], dj[2], 0.0, 0.0, 0.0];
        state.onset = ds;
        state.last = Some((here, *kappa, [0.0; 3]));
        Ok([dj, ds])
    }
}

/// The equilibrium of the structure `state` holds with the anchors `a`, from the last tip
/// displacements in `state`; the anchors of the elements that slipped follow, and `state` keeps
/// the answer (the pose's change) as that of the configuration `here`, `kappa`.
fn settle(
    f: &Friction,
    a: &VE,
    here: [f64; 3],
    kappa: [f64; 3],
    state: &mut FrictionState,
    tangent: Option<&mut FrictionTangent>,
) -> Result<[f64; 3], FrictionError> {
    // Every caller has just set the structure.
    let Some(sl) = state.held.as_ref() else {
        return Err(FrictionError::Singular);
    };
    // The Newton start: the last tips' displacement, moved by what each leg's step did the
    // last time that leg alone stepped the same way. Between two rows the legs step in turn,
    // and each step of a leg moves the tips about as its last one did, while one leg's step
    // and the next leg's move them differently (the platform turns the supports' slip one way
    // and then the other): along the path the tips zigzag by some hundredths of a mm, so that
    // the last configuration's answer starts Newton a zigzag away, and this a few thousandths
    // (on friction at 3x, 3.6 Newton steps instead of 5.0 per configuration).
    let last = VD::from(state.d);
    let change: Option<[f64; 3]> = state
        .last
        .map(|(_, k, _)| std::array::from_fn(|l| kappa[l] - k[l]));
    let mut start = last;
    for (l, &dk) in change.iter().flatten().enumerate() {
        if let Some(g) = state.per_step[l][usize::from(dk > 0.0)].filter(|_| dk != 0.0) {
            start += VD::from(g) * dk;
        }
    }
    let (d, laws) = equilibrium_and_laws(f, sl, a, start, QUADRATIC)?;
    if let Some(dk) = change {
        let mut moved = (0..3).filter(|&l| dk[l] != 0.0);
        if let (Some(l), None) = (moved.next(), moved.next()) {
            state.per_step[l][usize::from(dk[l] > 0.0)] = Some(((d - last) / dk[l]).into());
        }
    }
    // The elements' coordinates at the answer (the iteration's own where it evaluated them).
    let x = laws.as_ref().map_or_else(|| sl.x0 + sl.t * d, |(x, _)| *x);
    if let Some(tan) = tangent {
        tan.advance(f, sl, a, &d, laws);
    }
    // The elements that slipped take their anchors along.
    let next = slipped(f, &x, a);
    let p = sl.h * d;
    let out = [p[0], p[1], p[2]];
    state.anchors = Some(next.into());
    state.d = d.into();
    state.last = Some((here, kappa, out));
    Ok(out)
}

/// The anchors `a` after the elements moved to `x`: those that slipped follow, each to its
/// pre-sliding travel behind its coordinate. A class of elements without friction keeps no
/// history: its anchors are its coordinates. (Left where the path started, they told two
/// pieces of one pass apart for ever ([`FrictionState::difference`]), and a pass of the
/// supports alone answered five of its six pieces twice.)
fn slipped(f: &Friction, x: &VE, a: &VE) -> VE {
    let mut next = *a;
    if f.joint_torque > 0.0 {
        let lim = f.joint_presliding;
        for e in 0..6 {
            let s = x[e] - a[e];
            if s.abs() > lim {
                next[e] = x[e] - s.signum() * lim;
            }
        }
    } else {
        next.rows_mut(0, 6).copy_from(&x.rows(0, 6));
    }
    if f.support_force <= 0.0 {
        next.rows_mut(6, 12).copy_from(&x.rows(6, 12));
    } else {
        let lim = f.support_presliding;
        for p in 0..6 {
            let (ix, iy) = (6 + 2 * p, 7 + 2 * p);
            let s = [x[ix] - a[ix], x[iy] - a[iy]];
            let n = (s[0] * s[0] + s[1] * s[1]).sqrt();
            if n > lim {
                next[ix] = x[ix] - s[0] * lim / n;
                next[iy] = x[iy] - s[1] * lim / n;
            }
        }
    }
    next
}

/// A Newton step of the equilibrium below this (mm), taken whole with every element sticking or
/// slipping as where it started, ends the iteration: within one pattern only the slipping
/// supports' energy is not quadratic (its curvature turns over their pre-sliding travel), so
/// that Newton converges quadratically and the step leaves the solution a few thousand times
/// `|step|^2` (mm) away: 0.3e-6 to 8e-6 mm along a path at 1x to 10x the prototype's friction
/// (a test holds it within 1e-5 mm), against a capture noise of some 0.07 mm. At 1e-4 that was
/// 2e-5 mm, at 1e-5 0.04e-6 mm; the friction at 3x took 9.1 M Newton steps at 5e-5 against
/// 9.6 M at 1e-5 and 8.9 M at 1e-4.
const QUADRATIC: f64 = 5e-5;

/// The tip displacements of the equilibrium of the small-load statics `sl` with the elements
/// anchored at `a`, from `d`: the minimum of the potential energy of the segments and the
/// elements, `1/2 d^T k d + sum_e phi_e(x_e(d) - a_e)` (convex, once differentiable), by
/// Newton's method with a line search on the energy's slope along the step (its gradient's
/// projection, which rounding does not blur as it does the energy's values, whose segments'
/// stiff axial terms cancel). A whole step whose slope at its end is within a tenth of the
/// start's is taken (the line search's own stop, the strong Wolfe condition), and one below
/// `quadratic` that keeps the elements' pattern ends the iteration ([`QUADRATIC`]; 0: run to
/// rounding).
#[cfg(test)]
fn equilibrium(
    f: &Friction,
    sl: &SmallLoads,
    a: &VE,
    d: VD,
    quadratic: f64,
) -> Result<VD, FrictionError> {
    equilibrium_and_laws(f, sl, a, d, quadratic).map(|(d, _)| d)
}

/// The elements' coordinates at an equilibrium and their tangent there, where the iteration
/// evaluated them ([`equilibrium_and_laws`]).
type AtEquilibrium = Option<(VE, Tangent)>;

/// [`equilibrium`] with the elements' coordinates and tangent at the answer where the
/// iteration ended on an evaluation there (what [`FrictionTangent::advance`] takes up).
fn equilibrium_and_laws(
    f: &Friction,
    sl: &SmallLoads,
    a: &VE,
    mut d: VD,
    quadratic: f64,
) -> Result<(VD, AtEquilibrium), FrictionError> {
    // The gradient and the elements' tangent at d (k d - t^T L), written in place: two of each
    // are kept, the current iterate's and the trial's (they were moved from one to the other,
    // a fifth of a kilobyte each time).
    let gradient = |d: &VD, g: &mut VD, tan: &mut Tangent, x: &mut VE| {
        *x = sl.x0 + sl.t * d;
        let mut l = VE::zeros();
        element_laws_into(f, x, a, &mut l, tan);
        *g = sl.k * d - sl.t.tr_mul(&l);
    };
    let mut grads = [VD::zeros(); 2];
    let mut tans = [Tangent::ZERO; 2];
    let mut xs = [VE::zeros(); 2];
    let mut cur = 0;
    gradient(&d, &mut grads[0], &mut tans[0], &mut xs[0]);
    for _ in 0..ITERATIONS {
        let hess = hessian(sl, &tans[cur]);
        let Some(ch) = Chol6::new(&hess) else {
            break;
        };
        let step = -ch.solve(&grads[cur]);
        // The full step says how far the solution is.
        if step.amax() < 1e-8 {
            return Ok((d + step, None));
        }
        // The slope along the step at s: negative at 0, increasing (convexity). The whole step
        // where the slope is still not positive at its end; otherwise the slope's zero by
        // regula falsi (Illinois) on [0, 1].
        let slope0 = grads[cur].dot(&step);
        let trial = 1 - cur;
        let (g1, dl1, x1) = {
            let [g0, g1] = &mut grads;
            let [t0, t1] = &mut tans;
            let [x0, x1] = &mut xs;
            if trial == 1 {
                (g1, t1, x1)
            } else {
                (g0, t0, x0)
            }
        };
        gradient(&(d + step), g1, dl1, x1);
        let slope1 = g1.dot(&step);
        if slope1 <= 0.1 * slope0.abs() || !slope0.is_finite() {
            d += step;
            if step.amax() < quadratic && tans[trial].stuck == tans[cur].stuck {
                return Ok((d, Some((xs[trial], tans[trial]))));
            }
            cur = trial;
            // The tips' forces balance to a nanonewton: within 1e-8 mm of the solution for
            // segments of 0.1 N/mm and more.
            if grads[cur].amax() < 1e-9 {
                return Ok((d, Some((xs[cur], tans[cur]))));
            }
            continue;
        }
        let (mut lo, mut flo, mut hi, mut fhi) = (0.0, slope0, 1.0, slope1);
        let mut side = 0;
        let mut best = 0.5;
        for _ in 0..12 {
            let s = (lo * fhi - hi * flo) / (fhi - flo);
            gradient(
                &(d + step * s),
                &mut grads[trial],
                &mut tans[trial],
                &mut xs[trial],
            );
            let fs = grads[trial].dot(&step);
            best = s;
            if fs.abs() <= 0.1 * slope0.abs() {
                break;
            }
            if fs < 0.0 {
                (lo, flo) = (s, fs);
                if side == -1 {
                    fhi *= 0.5;
                }
                side = -1;
            } else {
                (hi, fhi) = (s, fs);
                if side == 1 {
                    flo *= 0.5;
                }
                side = 1;
            }
        }
        // The trial's gradient is the last point the line search took.
        d += step * best;
        cur = trial;
    }
    Err(FrictionError::NoConvergence)
}

/// The elements' stiffness where they stick or slip (the negative of d L / d x): a number
/// per joint, a symmetric 2x2 block (xx, xy, yy) per support.
#[derive(Clone, Copy)]
struct Tangent {
    joints: [f64; 6],
    supports: [[f64; 3]; 6],
    /// Bit e set where joint e sticks, bit 6 + q where support q does.
    stuck: u32,
}

impl Tangent {
    /// Every element free (no stiffness).
    const ZERO: Tangent = Tangent {
        joints: [0.0; 6],
        supports: [[0.0; 3]; 6],
        stuck: 0,
    };
}

/// The elements' loads for their coordinates `x` and anchors `a`, and their tangent stiffness.
fn element_laws(f: &Friction, x: &VE, a: &VE) -> (VE, Tangent) {
    let mut l = VE::zeros();
    let mut t = Tangent::ZERO;
    element_laws_into(f, x, a, &mut l, &mut t);
    (l, t)
}

/// [`element_laws`] written into `l` (zero on entry) and `t` (reset here); the joints' none
/// where their couple is negligible ([`NEGLIGIBLE_COUPLE`]).
fn element_laws_into(f: &Friction, x: &VE, a: &VE, l: &mut VE, t: &mut Tangent) {
    *t = Tangent::ZERO;
    let (tj, fs) = (f.joint_torque, f.support_force);
    if f.joints_load() {
        let kj = tj / f.joint_presliding;
        for e in 0..6 {
            let v = kj * (x[e] - a[e]);
            if v.abs() <= tj {
                l[e] = -v;
                t.joints[e] = kj;
                t.stuck |= 1 << e;
            } else {
                l[e] = -tj * v.signum();
            }
        }
    }
    if fs > 0.0 {
        let ks = fs / f.support_presliding;
        for p in 0..6 {
            let (ix, iy) = (6 + 2 * p, 7 + 2 * p);
            let v = [ks * (x[ix] - a[ix]), ks * (x[iy] - a[iy])];
            let n = (v[0] * v[0] + v[1] * v[1]).sqrt();
            if n <= fs {
                l[ix] = -v[0];
                l[iy] = -v[1];
                t.supports[p] = [ks, 0.0, ks];
                t.stuck |= 1 << (6 + p);
            } else {
                let u = [v[0] / n, v[1] / n];
                l[ix] = -fs * u[0];
                l[iy] = -fs * u[1];
                // -d(-fs v/|v|)/dx = (fs ks / |v|) (I - u u^T).
                let s = fs * ks / n;
                t.supports[p] = [
                    s * (1.0 - u[0] * u[0]),
                    -s * u[0] * u[1],
                    s * (1.0 - u[1] * u[1]),
                ];
            }
        }
    }
}

/// The Hessian of the potential energy: `k + t^T D t`, D the elements' tangent stiffness
/// (block diagonal: the sums run over the elements' rows of `t`), the upper triangle summed
/// element by element and mirrored.
fn hessian(sl: &SmallLoads, tan: &Tangent) -> MD {
    let mut h = [[0.0f64; DOF]; DOF];
    let row = |e: usize| -> [f64; DOF] { std::array::from_fn(|c| sl.t[(e, c)]) };
    for (e, &kj) in tan.joints.iter().enumerate() {
        if kj != 0.0 {
            let r = row(e);
            for i in 0..DOF {
                let w = kj * r[i];
                for j in i..DOF {
                    h[i][j] += w * r[j];
                }
            }
        }
    }
    for (p, b) in tan.supports.iter().enumerate() {
        if p < 3 {
            // M_p's support: its coordinates are M_p's tip displacement itself (unit rows of
            // `t`, `Robot::small_loads_displaced`), its block B on the diagonal.
            h[2 * p][2 * p] += b[0];
            h[2 * p][2 * p + 1] += b[1];
            h[2 * p + 1][2 * p + 1] += b[2];
        } else if b[0] != 0.0 || b[2] != 0.0 {
            let (rx, ry) = (row(6 + 2 * p), row(7 + 2 * p));
            // (rx, ry)^T B (rx, ry) with B = [[b0, b1], [b1, b2]].
            for i in 0..DOF {
                let (wx, wy) = (b[0] * rx[i] + b[1] * ry[i], b[1] * rx[i] + b[2] * ry[i]);
                for j in i..DOF {
                    h[i][j] += wx * rx[j] + wy * ry[j];
                }
            }
        }
    }
    MD::from_fn(|i, j| {
        let v = if i <= j { h[i][j] } else { h[j][i] };
        sl.k[(i, j)] + v
    })
}

/// A symmetric positive definite 6x6 matrix decomposed as L L^T (Cholesky), written out for
/// the equilibrium's Newton steps: nalgebra's generic `Cholesky` and its triangular solves took
/// about a tenth of a friction case's time under `perf`.
#[derive(Debug, Clone, Copy)]
struct Chol6 {
    /// Row-major, L on and below the diagonal.
    l: [[f64; DOF]; DOF],
}

impl Chol6 {
    /// The decomposition of `a` (its lower triangle read); `None` where a pivot is not
    /// positive (or not a number).
    fn new(a: &MD) -> Option<Chol6> {
        let mut l = [[0.0f64; DOF]; DOF];
        for j in 0..DOF {
            let mut s = a[(j, j)];
            for k in 0..j {
                s -= l[j][k] * l[j][k];
            }
            if s.is_nan() || s <= 0.0 {
                return None;
            }
            let d = s.sqrt();
            l[j][j] = d;
            for i in j + 1..DOF {
                let mut s = a[(i, j)];
                for k in 0..j {
                    s -= l[i][k] * l[j][k];
                }
                l[i][j] = s / d;
            }
        }
        Some(Chol6 { l })
    }

    /// The solution x of `L L^T x = b`.
    fn solve(&self, b: &VD) -> VD {
        let l = &self.l;
        let mut y = [0.0f64; DOF];
        for i in 0..DOF {
            let mut s = b[i];
            for k in 0..i {
                s -= l[i][k] * y[k];
            }
            y[i] = s / l[i][i];
        }
        for i in (0..DOF).rev() {
            let mut s = y[i];
            for k in i + 1..DOF {
                s -= l[k][i] * y[k];
            }
            y[i] = s / l[i][i];
        }
        VD::from(y)
    }

    /// [`Chol6::solve`] for each column of `b`.
    fn solve_columns<const C: usize>(&self, b: &SMatrix<f64, DOF, C>) -> SMatrix<f64, DOF, C> {
        let mut x = SMatrix::<f64, DOF, C>::zeros();
        for c in 0..C {
            x.set_column(c, &self.solve(&b.column(c).into_owned()));
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::statics::Loads;

    fn at(pose: Pose) -> (Robot, Pose, [f64; 3]) {
        let r = Robot::nominal();
        let kappa = r.ik(&pose).unwrap().kappa;
        (r, pose, kappa)
    }

    const EI: f64 = 6.5e4;

    fn unloaded(ei: f64) -> Loads {
        Loads {
            ei,
            force: [0.0; 2],
            couple: 0.0,
            k_m: 0.0,
            k_p: 0.0,
        }
    }

    /// A force at P_1 on the platform answers as the large-deflection solver's force at E with
    /// the couple of its lever: the platform's equilibrium and the segments' compliance agree
    /// with [`crate::statics`] to first order.
    #[test]
    fn a_support_force_at_p_moves_the_platform_as_the_loaded_solver_says() {
        for pose in [
            Pose::default(),
            Pose::from_mm_deg(20.0, -10.0, 5.0),
            Pose::from_mm_deg(-30.0, 20.0, -8.0),
        ] {
            let (r, pose, kappa) = at(pose);
            let sl = r.small_loads(&pose, &kappa, EI).unwrap();
            for (fx, fy) in [(0.02, 0.0), (0.0, -0.02)] {
                let mut l = [0.0; ELEMENTS];
                l[12] = fx;
                l[13] = fy;
                let (_, _, lin) = sl.answer(&l);
                let p1 = r.joint_p(0, &pose);
                let rr = g::sub(p1, [pose.x, pose.y]);
                let loads = Loads {
                    force: [fx, fy],
                    couple: g::cross(rr, [fx, fy]),
                    ..unloaded(EI)
                };
                let eq = r.fk_loaded(&kappa, &loads, &pose).unwrap();
                let big = [
                    eq.pose.x - pose.x,
                    eq.pose.y - pose.y,
                    eq.pose.phi - pose.phi,
                ];
                for c in 0..3 {
                    let scale = if c == 2 { 1e-4 } else { 0.02 };
                    assert!(
                        (lin[c] - big[c]).abs() < 0.01 * big[c].abs().max(scale),
                        "pose {pose:?} component {c}: small-load {} against {}",
                        lin[c],
                        big[c]
                    );
                }
            }
        }
    }

    /// Couples in the joints answer as weak joint springs do in the loaded solver (a spring is
    /// a couple -k (angle - rest) at the configuration; a weak one barely moves it).
    #[test]
    fn joint_couples_move_the_platform_as_weak_springs_do() {
        let (r, pose, kappa) = at(Pose::from_mm_deg(25.0, 15.0, 6.0));
        let rest = r.home_joint_angles();
        let sl = r.small_loads(&pose, &kappa, EI).unwrap();
        for (k_m, k_p) in [(0.5, 0.0), (0.0, 0.5)] {
            let mut l = [0.0; ELEMENTS];
            for i in 0..3 {
                let (gamma, zeta) = r.joint_angles(i, &pose, kappa[i]);
                l[i] = -k_m * (gamma - rest[i].0);
                l[3 + i] = -k_p * (zeta - rest[i].1);
            }
            let (_, _, lin) = sl.answer(&l);
            let loads = Loads {
                k_m,
                k_p,
                ..unloaded(EI)
            };
            let eq = r.fk_loaded(&kappa, &loads, &pose).unwrap();
            let big = [
                eq.pose.x - pose.x,
                eq.pose.y - pose.y,
                eq.pose.phi - pose.phi,
            ];
            assert!(
                big[0].abs() + big[1].abs() > 1e-3,
                "the springs move the platform: {big:?}"
            );
            for c in 0..3 {
                let scale = if c == 2 { 1e-5 } else { 1e-3 };
                assert!(
                    (lin[c] - big[c]).abs() < 0.02 * big[c].abs().max(scale),
                    "k_M {k_m}, k_P {k_p}, component {c}: small-load {} against {}",
                    lin[c],
                    big[c]
                );
            }
        }
    }

    /// The loads do work on the elements' coordinates only through the segments (Maxwell-Betti):
    /// the compliance of the coordinates, t k^-1 t^T, is symmetric and positive semi-definite.
    #[test]
    fn the_compliance_of_the_elements_is_symmetric() {
        let (r, pose, kappa) = at(Pose::from_mm_deg(-20.0, 10.0, -4.0));
        let sl = r.small_loads(&pose, &kappa, EI).unwrap();
        let c = sl.t * sl.k.try_inverse().unwrap() * sl.t.transpose();
        let asym = (c - c.transpose()).amax();
        assert!(asym < 1e-9 * c.amax(), "asymmetry {asym}");
        let eig = c.symmetric_eigenvalues();
        assert!(eig.min() > -1e-9 * c.amax());
    }

    /// Near the workspace's edge the platform turns easily, and a load's second-order answer
    /// shows: at phi = -10 deg, 0.3 N at P_1 turns the platform 5 % more or less than the first
    /// order says, with either sign of the force. The answer taken again at the midpoint of the
    /// deflection keeps within a third of the first order's miss (and within 2 % of the turn).
    #[test]
    fn the_midpoint_answer_follows_the_large_deflection_solver() {
        let r = Robot::nominal();
        for pose in [
            Pose::from_mm_deg(0.0, 0.0, -10.0),
            Pose::from_mm_deg(0.0, 40.0, -10.0),
        ] {
            let kappa = r.ik(&pose).unwrap().kappa;
            let k = r.tip_stiffness(&kappa, EI).unwrap();
            let sl = r
                .small_loads_displaced(&pose, &kappa, &[[0.0; 2]; 3], &k)
                .unwrap();
            for fy in [0.3, -0.3] {
                let mut l = [0.0; ELEMENTS];
                l[13] = fy;
                let (d1, _, p1) = sl.answer(&l);
                let half = Pose::new(
                    pose.x + 0.5 * p1[0],
                    pose.y + 0.5 * p1[1],
                    pose.phi + 0.5 * p1[2],
                );
                let dm: [[f64; 2]; 3] =
                    std::array::from_fn(|i| [0.5 * d1[2 * i], 0.5 * d1[2 * i + 1]]);
                let mid = r.small_loads_displaced(&half, &kappa, &dm, &k).unwrap();
                let (_, _, p2) = mid.answer(&l);
                let rr = g::sub(r.joint_p(0, &pose), [pose.x, pose.y]);
                let loads = Loads {
                    force: [0.0, fy],
                    couple: g::cross(rr, [0.0, fy]),
                    ..unloaded(EI)
                };
                let big = r.fk_loaded(&kappa, &loads, &pose).unwrap().pose.phi - pose.phi;
                let (e1, e2) = ((p1[2] - big).abs(), (p2[2] - big).abs());
                assert!(
                    e1 > 0.03 * big.abs(),
                    "the first order misses: {e1} of {big}"
                );
                assert!(
                    e2 < e1 / 3.0 && e2 < 0.02 * big.abs(),
                    "{pose:?} {fy}: midpoint {} first {} solver {}",
                    p2[2],
                    p1[2],
                    big
                );
            }
        }
    }

    fn path(r: &Robot, poses: &[Pose], f: &Friction) -> Vec<[f64; 3]> {
        let mut st = FrictionState::default();
        poses
            .iter()
            .map(|p| {
                let kappa = r.ik(p).unwrap().kappa;
                r.friction_step(f, p, &kappa, &mut st).unwrap()
            })
            .collect()
    }

    fn line(from: Pose, to: Pose, n: usize) -> Vec<Pose> {
        (0..=n)
            .map(|k| {
                let s = k as f64 / n as f64;
                Pose::new(
                    from.x + s * (to.x - from.x),
                    from.y + s * (to.y - from.y),
                    from.phi + s * (to.phi - from.phi),
                )
            })
            .collect()
    }

    fn prototype() -> Friction {
        Friction {
            joint_torque: 2.0,
            joint_presliding: 1e-3,
            support_force: 0.04,
            support_presliding: 5e-3,
            ei: EI,
        }
    }

    /// Three times the prototype's friction.
    fn three_times() -> Friction {
        Friction {
            joint_torque: 6.0,
            support_force: 0.12,
            ..prototype()
        }
    }

    /// `n` poses of a Lissajous path that reverses (30 mm, 5 deg), `dt` apart in its parameter.
    fn lissajous(n: usize, dt: f64) -> Vec<Pose> {
        (0..n)
            .map(|k| {
                let t = k as f64 * dt;
                Pose::from_mm_deg(
                    30.0 * (1.1 * t).cos(),
                    30.0 * (1.7 * t).sin(),
                    5.0 * (1.3 * t).sin(),
                )
            })
            .collect()
    }

    /// Friction makes the pose depend on the way to it: the same pose reached from either side
    /// is off by opposite deflections (the hysteresis), a path back over the same poses does
    /// not retrace the way out, and a row at rest keeps its deflection.
    #[test]
    fn the_pose_depends_on_the_way_to_it() {
        let r = Robot::nominal();
        let f = prototype();
        let (a, b, c) = (
            Pose::from_mm_deg(-20.0, 0.0, 0.0),
            Pose::from_mm_deg(0.0, 0.0, 0.0),
            Pose::from_mm_deg(20.0, 0.0, 0.0),
        );
        let mut from_left = line(a, b, 40);
        from_left.extend(line(b, b, 5));
        let mut from_right = line(c, b, 40);
        from_right.extend(line(b, b, 5));
        let (l, rr) = (path(&r, &from_left, &f), path(&r, &from_right, &f));
        let (dl, dr) = (l[l.len() - 1], rr[rr.len() - 1]);
        // Along x the friction holds the platform back: it arrives short of the pose.
        assert!(dl[0] < -0.05 && dr[0] > 0.05, "{dl:?} {dr:?}");
        assert!(
            (dl[0] + dr[0]).abs() < 0.2 * dl[0].abs(),
            "nearly symmetric: {dl:?} {dr:?}"
        );
        // At rest the deflection stays.
        assert_eq!(l[l.len() - 1], l[l.len() - 5]);
        // Out and back over the same poses: the way back is not the way out.
        let mut there_and_back = line(a, c, 40);
        there_and_back.extend(line(c, a, 40));
        let d = path(&r, &there_and_back, &f);
        let (out, back) = (d[20], d[60]);
        assert!((out[0] - back[0]).abs() > 0.1, "{out:?} {back:?}");
        // No friction, no deflection; twice the friction, about twice the deflection.
        let off = Friction {
            joint_torque: 0.0,
            support_force: 0.0,
            ..f
        };
        assert!(path(&r, &from_left, &off).iter().all(|d| *d == [0.0; 3]));
        let double = Friction {
            joint_torque: 4.0,
            support_force: 0.08,
            ..f
        };
        let d2 = path(&r, &from_left, &double);
        let ratio = d2[d2.len() - 1][0] / dl[0];
        assert!((1.8..2.2).contains(&ratio), "{ratio}");
    }

    /// A history started later, from every element unloaded, becomes the history from the
    /// start once the path has made every element slip: the elements forget what came before
    /// ([`FrictionState::difference`], and the derivatives' [`FrictionTangent::difference`]).
    /// Right after the later start, the two are far apart; a state has no difference with
    /// itself, and one not started is infinitely far from any.
    #[test]
    fn a_history_started_later_forgets_that_it_did() {
        let r = Robot::nominal();
        let f = three_times();
        let poses = lissajous(900, 0.02);
        let step = |st: &mut FrictionState, tan: &mut FrictionTangent, p: &Pose| {
            let kappa = r.ik(p).unwrap().kappa;
            r.friction_step_tangent(&f, p, &kappa, st, tan).unwrap();
        };
        let (mut whole, mut whole_tan) = (FrictionState::default(), FrictionTangent::default());
        let (mut late, mut late_tan) = (FrictionState::default(), FrictionTangent::default());
        assert_eq!(whole.difference(&late), f64::INFINITY);
        let mut after = Vec::new();
        for (k, p) in poses.iter().enumerate() {
            step(&mut whole, &mut whole_tan, p);
            if k >= 300 {
                step(&mut late, &mut late_tan, p);
                after.push((whole.difference(&late), whole_tan.difference(&late_tan)));
            }
        }
        assert_eq!(whole.difference(&whole), 0.0);
        assert_eq!(whole_tan.difference(&whole_tan), 0.0);
        let (first, last) = (after[0], after[after.len() - 1]);
        assert!(first.0 > 1e-3 && first.1 > 1e-2, "{first:?}");
        assert!(last.0 < 1e-9 && last.1 < 1e-6, "{last:?}");
    }

    /// The table of the segments' compliance is the quadrature's, on every leg, across the
    /// bending range.
    #[test]
    fn the_tabulated_tip_compliance_is_the_quadrature() {
        let mut cfg = pcr_robot::RobotConfig::nominal();
        cfg.legs[1].l_c_mm = 118.0;
        let r = Robot::new(&cfg).unwrap();
        for i in 0..3 {
            for k in -60..=60 {
                let kappa = k as f64 * 0.0004;
                let (a, b) = (
                    r.tip_compliance(i, kappa, EI),
                    r.tip_compliance_tabulated(i, kappa, EI),
                );
                let scale = a[0][0].abs() + a[1][1].abs();
                for (ra, rb) in a.iter().zip(&b) {
                    for (x, y) in ra.iter().zip(rb) {
                        assert!(
                            (x - y).abs() < 1e-6 * scale,
                            "leg {i} kappa {kappa}: {a:?} {b:?}"
                        );
                    }
                }
            }
        }
    }

    /// The onset columns are the derivatives of the answer at zero friction: a path with a
    /// millionth of the prototype's limits answers a millionth of them, joints and supports
    /// apart (at a ten-thousandth the stuck supports' coupling through the segments' compliance,
    /// about 10 mm/N at the tip, already shows by 1 % after a reversal).
    #[test]
    fn the_onset_is_the_derivative_at_zero_friction() {
        let r = Robot::nominal();
        let mut poses = line(
            Pose::from_mm_deg(-20.0, 5.0, 2.0),
            Pose::from_mm_deg(15.0, -5.0, -3.0),
            30,
        );
        poses.extend(line(
            Pose::from_mm_deg(15.0, -5.0, -3.0),
            Pose::from_mm_deg(0.0, 10.0, 0.0),
            30,
        ));
        let p = prototype();
        let s = 1e-6;
        let joints = Friction {
            support_force: 0.0,
            joint_torque: s * p.joint_torque,
            ..p
        };
        let supports = Friction {
            joint_torque: 0.0,
            support_force: s * p.support_force,
            ..p
        };
        let (dj, ds) = (path(&r, &poses, &joints), path(&r, &poses, &supports));
        let mut st = FrictionState::default();
        for (k, pose) in poses.iter().enumerate() {
            let kappa = r.ik(pose).unwrap().kappa;
            let [oj, os] = r.friction_onset(&p, pose, &kappa, &mut st).unwrap();
            for c in 0..3 {
                let (ej, es) = (oj[c] * s * p.joint_torque, os[c] * s * p.support_force);
                let tol = |e: f64| 0.005 * e.abs() + 1e-13;
                assert!(
                    (ej - dj[k][c]).abs() < tol(ej),
                    "row {k} joints {c}: {ej} {}",
                    dj[k][c]
                );
                assert!(
                    (es - ds[k][c]).abs() < tol(es),
                    "row {k} supports {c}: {es} {}",
                    ds[k][c]
                );
            }
        }
        assert!(
            dj[60][0].abs() > 1e-9 && ds[60][0].abs() > 1e-9,
            "{:?} {:?}",
            dj[60],
            ds[60]
        );
    }

    /// The midpoint taken from the row before's deflection (one solve a row) gives the poses of
    /// the midpoint of the row's own first-order answer (two solves a row), along a path that
    /// reverses, at three times the prototype's friction.
    #[test]
    fn the_row_before_s_midpoint_is_the_row_s_own() {
        let r = Robot::nominal();
        let f = three_times();
        let poses = lissajous(400, 0.02);
        let one = path(&r, &poses, &f);
        // Two solves a row: at the rigid configuration, then at the midpoint of that answer.
        let mut anchors: Option<VE> = None;
        let mut d = VD::zeros();
        let mut worst = [0.0f64; 2];
        for (k, pose) in poses.iter().enumerate() {
            let kappa = r.ik(pose).unwrap().kappa;
            let st = r.tip_stiffness(&kappa, f.ei).unwrap();
            let sl = r
                .small_loads_displaced(pose, &kappa, &[[0.0; 2]; 3], &st)
                .unwrap();
            let Some(a) = anchors else {
                anchors = Some(sl.x0);
                continue;
            };
            let d1 = equilibrium(&f, &sl, &a, d, QUADRATIC).unwrap();
            let p1 = sl.h * d1;
            let half = Pose::new(
                pose.x + 0.5 * p1[0],
                pose.y + 0.5 * p1[1],
                pose.phi + 0.5 * p1[2],
            );
            let dm: [[f64; 2]; 3] = std::array::from_fn(|i| [0.5 * d1[2 * i], 0.5 * d1[2 * i + 1]]);
            let mid = r.small_loads_displaced(&half, &kappa, &dm, &st).unwrap();
            let mid = SmallLoads { x0: sl.x0, ..mid };
            d = equilibrium(&f, &mid, &a, d1, QUADRATIC).unwrap();
            anchors = Some(slipped(&f, &(mid.x0 + mid.t * d), &a));
            let p = mid.h * d;
            worst[0] = worst[0].max((p[0] - one[k][0]).hypot(p[1] - one[k][1]));
            worst[1] = worst[1].max((p[2] - one[k][2]).abs());
        }
        assert!(worst[0] < 2e-3 && worst[1] < 7e-5, "{worst:?}");
    }

    /// The tangent pass gives the derivatives of the whole path's answers by the fitted values
    /// that central differences of the whole path give, within 2 % over the path (0.4-0.8 % at
    /// the time of writing; the differences have their own error at the elements' kinks).
    #[test]
    fn the_tangent_is_the_derivative_along_the_path() {
        let r = Robot::nominal();
        let f = three_times();
        let poses = lissajous(300, 0.01);
        let kappas: Vec<[f64; 3]> = poses.iter().map(|p| r.ik(p).unwrap().kappa).collect();
        let mut st = FrictionState::default();
        let mut tan = FrictionTangent::default();
        let with: Vec<([f64; 3], [[f64; 3]; 3])> = poses
            .iter()
            .zip(&kappas)
            .map(|(p, k)| {
                r.friction_step_tangent(&f, p, k, &mut st, &mut tan)
                    .unwrap()
            })
            .collect();
        let moved = |j: usize, h: f64| {
            let mut g = f;
            match j {
                0 => g.joint_torque += h,
                1 => g.support_force += h,
                _ => g.joint_presliding += h,
            }
            path(&r, &poses, &g)
        };
        let hs = [6e-3, 1.2e-4, 1e-6];
        let mut err = [0.0f64; 3];
        let mut size = [0.0f64; 3];
        for j in 0..3 {
            let (up, down) = (moved(j, hs[j]), moved(j, -hs[j]));
            for k in 0..poses.len() {
                for c in 0..3 {
                    let fd = (up[k][c] - down[k][c]) / (2.0 * hs[j]);
                    err[j] += (with[k].1[j][c] - fd).powi(2);
                    size[j] += fd.powi(2);
                }
            }
        }
        for j in 0..3 {
            assert!(size[j] > 0.0);
            assert!(
                err[j].sqrt() < 0.02 * size[j].sqrt(),
                "value {j}: {} of {}",
                err[j].sqrt(),
                size[j].sqrt()
            );
        }
        // The answers are friction_step's.
        let plain = path(&r, &poses, &f);
        assert!(with.iter().zip(&plain).all(|(a, b)| a.0 == *b));
    }

    /// A joints' couple below [`NEGLIGIBLE_COUPLE`] beside the supports' friction (what a fit
    /// holding it at zero leaves) answers as the joints in the equilibrium do at a couple just
    /// above it, and its derivatives by the fitted values are theirs: the couple's from where
    /// each joint sticks or slips. Its answers are those of no couple at all.
    #[test]
    fn a_negligible_couple_answers_as_the_joints_in_the_equilibrium_do() {
        let r = Robot::nominal();
        let poses = lissajous(300, 0.01);
        let run = |tj: f64| {
            let f = Friction {
                joint_torque: tj,
                ..three_times()
            };
            let mut st = FrictionState::default();
            let mut tan = FrictionTangent::default();
            poses
                .iter()
                .map(|p| {
                    let k = r.ik(p).unwrap().kappa;
                    r.friction_step_tangent(&f, p, &k, &mut st, &mut tan)
                        .unwrap()
                })
                .collect::<Vec<_>>()
        };
        let (out, within) = (run(1e-25), run(1e-8));
        // At no couple at all the answers and the derivatives by the supports' force are the
        // same to the bit (a pass at a negligible couple serves one asked at zero).
        let none = run(0.0);
        assert!(out
            .iter()
            .zip(&none)
            .all(|(a, b)| a.0 == b.0 && a.1[1] == b.1[1]));
        assert!(!Friction {
            joint_torque: 1e-25,
            ..three_times()
        }
        .joints_load());
        assert!(Friction {
            joint_torque: 1e-8,
            ..three_times()
        }
        .joints_load());
        let mut worst = [0.0f64; 4];
        let mut size = [0.0f64; 4];
        for (a, b) in out.iter().zip(&within) {
            for c in 0..3 {
                worst[0] = worst[0].max((a.0[c] - b.0[c]).abs());
                size[0] = size[0].max(b.0[c].abs());
                for j in 0..3 {
                    worst[1 + j] = worst[1 + j].max((a.1[j][c] - b.1[j][c]).abs());
                    size[1 + j] = size[1 + j].max(b.1[j][c].abs());
                }
            }
        }
        // The answers (up to 1 mm) within 1e-8 mm, the derivatives by the couple and the
        // supports' force within a millionth of their largest (7e-10 mm, 7e-9 and 6e-10 at the
        // time of writing).
        assert!(size[0] > 0.5 && worst[0] < 1e-8, "{worst:?} of {size:?}");
        for j in 0..2 {
            assert!(
                size[1 + j] > 0.0 && worst[1 + j] < 1e-6 * size[1 + j],
                "{worst:?} of {size:?}"
            );
        }
    }

    /// The configurations passed between two rows answered with the row before's structure
    /// (`friction_pass`) leave the rows' answers and their tangents as a full step at each
    /// configuration leaves them, to a small share (0.07 %, 0.13 % and 0.36 % of the largest
    /// deflection at 1x, 3x and 10x the prototype's friction; of the tangent 0.4 %, 0.8 % and
    /// 2.7 % at the time of writing), and the onset's exactly: five configurations between rows
    /// about 0.5 mm apart.
    #[test]
    fn a_pass_between_rows_answers_as_a_step_there_does() {
        let r = Robot::nominal();
        let rows = lissajous(300, 0.01);
        let between = |k: usize| -> Vec<Pose> {
            let mut l = line(rows[k - 1], rows[k], 6);
            l.remove(0);
            l.pop();
            l
        };
        for scale in [1.0, 3.0, 10.0] {
            let f = Friction {
                joint_torque: 2.0 * scale,
                support_force: 0.04 * scale,
                ..prototype()
            };
            let (mut full, mut pass) = (FrictionState::default(), FrictionState::default());
            let (mut tf, mut tp) = (FrictionTangent::default(), FrictionTangent::default());
            let (mut of, mut op) = (FrictionState::default(), FrictionState::default());
            let (mut err, mut size, mut terr, mut tsize, mut oerr) =
                (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
            for k in 0..rows.len() {
                if k > 0 {
                    for q in between(k) {
                        let kq = r.ik(&q).unwrap().kappa;
                        r.friction_step_tangent(&f, &q, &kq, &mut full, &mut tf)
                            .unwrap();
                        r.friction_pass(&f, &q, &kq, &mut pass, Some(&mut tp))
                            .unwrap();
                        r.friction_onset(&f, &q, &kq, &mut of).unwrap();
                        r.friction_onset_pass(&f, &q, &kq, &mut op).unwrap();
                    }
                }
                let kappa = r.ik(&rows[k]).unwrap().kappa;
                let (a, ta) = r
                    .friction_step_tangent(&f, &rows[k], &kappa, &mut full, &mut tf)
                    .unwrap();
                let (b, tb) = r
                    .friction_step_tangent(&f, &rows[k], &kappa, &mut pass, &mut tp)
                    .unwrap();
                let oa = r.friction_onset(&f, &rows[k], &kappa, &mut of).unwrap();
                let ob = r.friction_onset(&f, &rows[k], &kappa, &mut op).unwrap();
                for c in 0..3 {
                    err = err.max((a[c] - b[c]).abs());
                    size = size.max(a[c].abs());
                    for j in 0..3 {
                        // Per N mm, per 0.05 N and per mrad.
                        let unit = [1.0, 20.0, 1000.0][j];
                        terr = terr.max((ta[j][c] - tb[j][c]).abs() / unit);
                        tsize = tsize.max(ta[j][c].abs() / unit);
                    }
                    for j in 0..2 {
                        oerr = oerr.max((oa[j][c] - ob[j][c]).abs());
                    }
                }
            }
            assert!(size > 0.0 && tsize > 0.0);
            assert!(err < 0.005 * size, "{scale}x: {err} of {size}");
            assert!(terr < 0.05 * tsize, "{scale}x: {terr} of {tsize}");
            assert_eq!(oerr, 0.0, "{scale}x");
        }
    }

    /// Along a path whose legs step in turn between rows (four, three and two steps of each a
    /// cycle, as the firmware spreads them), reversing, every configuration's equilibrium (the
    /// predicted Newton start, the whole steps and the quadratic stop) is within 1e-5 mm of the
    /// one run to rounding from no displacement, at 1x, 3x and 10x the prototype's friction.
    #[test]
    fn the_equilibrium_is_the_one_run_to_rounding_whatever_its_start() {
        let r = Robot::nominal();
        let rows: Vec<[f64; 3]> = lissajous(200, 0.02)
            .iter()
            .map(|p| r.ik(p).unwrap().kappa)
            .collect();
        let rates = [4usize, 3, 2];
        let mut times: Vec<(usize, usize)> = (0..3)
            .flat_map(|l| (1..rates[l]).map(move |j| (j, l)))
            .collect();
        times.sort_by(|a, b| (a.0 * rates[b.1]).cmp(&(b.0 * rates[a.1])));
        for scale in [1.0, 3.0, 10.0] {
            let f = Friction {
                joint_torque: 2.0 * scale,
                support_force: 0.04 * scale,
                ..prototype()
            };
            let mut state = FrictionState::default();
            let mut pose = r.fk(&rows[0]).unwrap();
            let (mut worst, mut size, mut solved) = (0.0f64, 0.0f64, 0);
            for k in 0..rows.len() {
                // The configurations after each step between the row before and this one (each
                // leg at its own even rate), then the row.
                let mut stair = Vec::new();
                if k > 0 {
                    let mut kappa = rows[k - 1];
                    for &(j, l) in &times {
                        let (a, b) = (rows[k - 1][l], rows[k][l]);
                        kappa[l] = a + (b - a) * j as f64 / rates[l] as f64;
                        stair.push((kappa, Passing::Between));
                    }
                }
                stair.push((rows[k], Passing::Row));
                for (kappa, at) in stair {
                    pose = r.fk_warm(&kappa, &pose).unwrap();
                    let anchors = state.anchors;
                    match at {
                        Passing::Between => r.friction_pass(&f, &pose, &kappa, &mut state, None),
                        Passing::Row => r.friction_step(&f, &pose, &kappa, &mut state),
                    }
                    .unwrap();
                    let (Some(a), Some(sl)) = (anchors, state.held.as_ref()) else {
                        continue;
                    };
                    let tight = equilibrium(&f, sl, &VE::from(a), VD::zeros(), 0.0).unwrap();
                    let d = VD::from(state.d);
                    worst = worst.max((d - tight).amax());
                    size = size.max(tight.amax());
                    solved += 1;
                }
            }
            assert!(solved > 1000 && size > 0.05, "{scale}x: {solved} {size}");
            assert!(worst < 1e-5, "{scale}x: {worst} mm of {size}");
        }
    }

    /// Where [`the_equilibrium_is_the_one_run_to_rounding_whatever_its_start`] is: between two
    /// rows or at one.
    #[derive(Clone, Copy)]
    enum Passing {
        Between,
        Row,
    }

    /// The written-out Hessian and Cholesky are nalgebra's sums and decomposition to rounding,
    /// and the Cholesky refuses what nalgebra's refuses.
    #[test]
    fn the_hessian_and_its_cholesky_are_the_plain_sums_and_nalgebra_s() {
        let r = Robot::nominal();
        let f = three_times();
        let poses = lissajous(60, 0.05);
        let mut st = FrictionState::default();
        for p in &poses {
            let kappa = r.ik(p).unwrap().kappa;
            let k = r.tip_stiffness(&kappa, f.ei).unwrap();
            let sl = r
                .small_loads_displaced(p, &kappa, &[[0.0; 2]; 3], &k)
                .unwrap();
            let a = VE::from(st.anchors.unwrap_or(sl.x0.into()));
            let x = sl.x0 + sl.t * VD::from(st.d) + VE::from_element(2e-4);
            let (_, tan) = element_laws(&f, &x, &a);
            let mut plain = sl.k;
            for (e, &kj) in tan.joints.iter().enumerate() {
                let re = sl.t.row(e);
                plain += (re.transpose() * re) * kj;
            }
            for (q, b) in tan.supports.iter().enumerate() {
                let (rx, ry) = (sl.t.row(6 + 2 * q), sl.t.row(7 + 2 * q));
                plain += (rx.transpose() * rx) * b[0]
                    + (rx.transpose() * ry + ry.transpose() * rx) * b[1]
                    + (ry.transpose() * ry) * b[2];
            }
            let h = hessian(&sl, &tan);
            assert!((h - plain).amax() <= 1e-12 * plain.amax());
            let b = VD::from_fn(|i, _| (i as f64 + 1.0).sin());
            let ours = Chol6::new(&h).unwrap().solve(&b);
            let theirs = h.cholesky().unwrap().solve(&b);
            assert!((ours - theirs).amax() <= 1e-10 * theirs.amax());
            r.friction_step(&f, p, &kappa, &mut st).unwrap();
        }
        let mut bad = MD::identity();
        bad[(3, 3)] = -1.0;
        assert!(Chol6::new(&bad).is_none() && bad.cholesky().is_none());
        bad[(3, 3)] = f64::NAN;
        assert!(Chol6::new(&bad).is_none());
    }
}
