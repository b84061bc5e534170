//! The calibration parameters (the paper's step-1 and step-2 sets: per leg psi, l_C, the map
//! coefficients, r_p, theta_p) as nuisance columns: every candidate is fitted together with
//! them, so that an effect the calibration partly absorbed is estimated whole and no effect
//! gets the credit for a plain recalibration.

use crate::model::Prediction;
use pcr_kinematics::{Leg, Robot, TendonMap};
use pcr_robot::{geometry as g, RobotConfig, Vec2};
use rayon::prelude::*;

/// The calibration parameters (the paper's step-1 and step-2 sets) as nuisance columns:
/// per leg psi (deg), l_C (mm), the map coefficients, r_p (mm), theta_p (deg).
#[derive(Debug, Clone)]
pub struct Nuisance {
    cfg: Vec<pcr_robot::LegConfig>,
    /// Per leg: the leg as it is and perturbed in each geometric parameter, with P_i^E.
    legs: Vec<[(Leg, Vec2); 1 + GEO.len()]>,
    n_map: [usize; 3],
    /// Number of columns.
    pub n: usize,
    names: Vec<String>,
}

const GEO: [&str; 4] = ["psi_deg", "l_c_mm", "r_p_mm", "theta_p_deg"];
/// Finite-difference step of the geometric parameters (deg or mm).
const GEO_STEP: f64 = 1e-4;

impl Nuisance {
    /// The nuisance set of a robot file.
    pub fn of(config: &RobotConfig) -> Nuisance {
        let cfg = config.legs.clone();
        let n_map: [usize; 3] = std::array::from_fn(|i| cfg[i].tendon_map.form().n_coeffs());
        let legs = cfg
            .iter()
            .map(|c| {
                std::array::from_fn(|k| {
                    let mut p = c.clone();
                    match k {
                        1 => p.psi_deg += GEO_STEP,
                        2 => p.l_c_mm += GEO_STEP,
                        3 => p.r_p_mm += GEO_STEP,
                        4 => p.theta_p_deg += GEO_STEP,
                        _ => {}
                    }
                    (Leg::from_config(&p), p.platform_point())
                })
            })
            .collect();
        let mut names = Vec::new();
        for i in 0..3 {
            for gname in GEO {
                names.push(format!("{gname}[{}]", i + 1));
            }
            let form = cfg[i].tendon_map.form();
            for j in 0..n_map[i] {
                names.push(format!("{}[{}]", form.coeff_name(j), i + 1));
            }
        }
        Nuisance {
            legs,
            n: names.len(),
            names,
            cfg,
            n_map,
        }
    }

    /// Column names.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Offset of leg i's columns.
    fn offset(&self, i: usize) -> usize {
        (0..i).map(|l| GEO.len() + self.n_map[l]).sum()
    }

    /// The columns of a row predicted as `p` by the constant-curvature model `robot` (the
    /// change of its weighted pose per unit parameter; phi weighted by `w_phi`, mm/rad), written
    /// to the first [`Nuisance::n`] entries of `out`.
    pub fn columns(&self, robot: &Robot, p: &Prediction, w_phi: f64, out: &mut [[f64; 3]]) {
        for c in out.iter_mut().take(self.n) {
            *c = [0.0; 3];
        }
        let Some(pose) = p.pose else {
            return;
        };
        let x = pcr_kinematics::Pose::new(pose[0], pose[1], pose[2]);
        let a = robot.jacobian_a(&x, &p.kappa);
        let Some(ainv) = a.try_inverse() else {
            return;
        };
        let mut basis = [0.0; 13];
        for leg in 0..3 {
            let off = self.offset(leg);
            // dh_leg/d param by finite differences of the constraint alone.
            let h = |k: usize| {
                let (l, pe) = &self.legs[leg][k];
                let m = l.joint_m(p.kappa[leg]);
                let pe = g::rot(x.phi, *pe);
                let d = g::sub(g::add([x.x, x.y], pe), m);
                g::dot(d, d) - l.l_st * l.l_st
            };
            let h0 = h(0);
            for gk in 0..GEO.len() {
                // l_C changes the segment at a fixed curvature (theta = kappa l_C).
                let dh = (h(gk + 1) - h0) / GEO_STEP;
                out[off + gk] = [
                    -ainv[(0, leg)] * dh,
                    -ainv[(1, leg)] * dh,
                    -ainv[(2, leg)] * dh * w_phi,
                ];
            }
            // Map coefficients: d pose / d kappa_leg * basis_j(dl).
            let form = self.cfg[leg].tendon_map.form();
            TendonMap::flat_basis(form, p.dl_eff[leg], &mut basis);
            for j in 0..self.n_map[leg] {
                let b = basis[j];
                out[off + GEO.len() + j] = [
                    p.j_kappa[(0, leg)] * b,
                    p.j_kappa[(1, leg)] * b,
                    p.j_kappa[(2, leg)] * b * w_phi,
                ];
            }
        }
    }

    /// The prior of the nuisance parameters (1 / sigma^2, column order): the calibration has
    /// placed them, so one step moves the geometry by about a millimetre or a degree and a map
    /// coefficient by about 5 % of its value.
    pub fn prior(&self) -> Vec<f64> {
        let mut p = Vec::with_capacity(self.n);
        for leg in 0..3 {
            p.extend([1.0; GEO.len()]);
            let coeffs = self.cfg[leg].tendon_map.flat_coeffs();
            for j in 0..self.n_map[leg] {
                let c = coeffs.get(j).copied().unwrap_or(1e-3).abs().max(1e-6);
                p.push(1.0 / (0.05 * c).powi(2));
            }
        }
        p
    }

    /// Whether `config` has the same calibration parameters as this set (each leg's map of the
    /// same form), so that columns computed for one can stand for the other's.
    pub fn same_parameters(&self, config: &RobotConfig) -> bool {
        self.cfg
            .iter()
            .zip(&config.legs)
            .all(|(a, b)| a.tendon_map.form() == b.tendon_map.form())
            && config.legs.len() == self.cfg.len()
    }

    /// Applies parameter changes `dx` (in column order) to a robot configuration's legs.
    pub fn apply(&self, dx: &[f64], cfg: &mut RobotConfig) {
        for leg in 0..3 {
            let off = self.offset(leg);
            let l = &mut cfg.legs[leg];
            l.psi_deg += dx[off];
            l.l_c_mm += dx[off + 1];
            l.r_p_mm += dx[off + 2];
            l.theta_p_deg += dx[off + 3];
            if l.tendon_map.coeffs.is_empty() {
                // The nominal linear map written out: k0 = 1 / (a l_C) of the old length.
                l.tendon_map.coeffs =
                    vec![1.0 / (l.actuation.tendon_offset_mm * self.cfg[leg].l_c_mm)];
            }
            let mut flat = l.tendon_map.flat_coeffs();
            for j in 0..self.n_map[leg] {
                flat[j] += dx[off + GEO.len() + j];
            }
            l.tendon_map = pcr_robot::TendonMapSpec::from_flat(l.tendon_map.form(), &flat);
        }
    }
}

/// Why a leg's map of `robot` cannot be inverted over the tendon displacements the recordings
/// `series` command (`None` when every leg's can): strictly monotonic over each leg's range of
/// commanded displacements widened by 10 %, on its branch around dl = 0
/// ([`pcr_calibration::step1::displacement_coverage`]). A calibration refits the maps on the
/// static poses, a refinement on a few thousand rows: neither sees every displacement the paths
/// command, and a sixth-root map refitted so turned back just below dl = 0 (the prototype
/// plant's small loop: the extended circle stopped a motor at -1 step for -68).
pub(crate) fn map_refusal(robot: &RobotConfig, series: &[crate::series::Series]) -> Option<String> {
    let mut range = [[f64::INFINITY, f64::NEG_INFINITY]; 3];
    for x in series.iter().flat_map(|s| &s.samples) {
        for (r, q) in range.iter_mut().zip(x.q) {
            if q.is_finite() {
                r[0] = r[0].min(q);
                r[1] = r[1].max(q);
            }
        }
    }
    robot
        .legs
        .iter()
        .zip(range)
        .enumerate()
        .filter(|(_, (_, r))| r[0] <= r[1])
        .find_map(|(i, (leg, r))| {
            let mm = leg.actuation.mm_per_step();
            let map = pcr_kinematics::TendonMap::from_leg(leg);
            pcr_calibration::step1::displacement_coverage(&map, r[0] * mm, r[1] * mm)
                .err()
                .map(|e| format!("leg {}: {e}", i + 1))
        })
}

/// The calibration parameters' changes of a loaded model: the robot changed by a small step in
/// each parameter (through [`Nuisance::apply`], as a fit applies it), with its springs' rest
/// angles. Under loads the rigid columns of [`Nuisance::columns`] are wrong: springs stiffen
/// the mechanism against a change of the drawing (a segment length moves a loaded platform by
/// half what it moves the rigid one, at springs three times the sweep's test strength), and
/// their rest angles move with the drawing and the map. The columns are then the derivatives
/// of the loaded equilibrium toward those robots
/// ([`pcr_kinematics::Robot::loaded_directions_warm`]).
#[derive(Debug)]
pub struct LoadedChanges {
    /// The model's robot and loads.
    robot: Robot,
    loads: pcr_kinematics::statics::Loads,
    robots: Vec<Robot>,
    rest: Vec<[(f64, f64); 3]>,
    steps: Vec<f64>,
}

/// Relative finite-difference step of the loaded columns: a thousandth of a parameter's prior
/// standard deviation (1e-3 mm or deg of the drawing, 5e-5 of a map coefficient).
const LOADED_STEP: f64 = 1e-3;

impl Nuisance {
    /// The changed robots of the loaded columns around `config` (whose nuisance set this is,
    /// the model's `robot` under `loads`); `None` when one of them is not a valid robot.
    pub fn loaded_changes(
        &self,
        config: &RobotConfig,
        robot: &Robot,
        loads: pcr_kinematics::statics::Loads,
    ) -> Option<LoadedChanges> {
        let prior = self.prior();
        let mut robots = Vec::with_capacity(self.n);
        let mut rest = Vec::with_capacity(self.n);
        let mut steps = Vec::with_capacity(self.n);
        for (j, p) in prior.iter().enumerate() {
            let h = LOADED_STEP / p.sqrt();
            let mut dx = vec![0.0; self.n];
            dx[j] = h;
            let mut c = config.clone();
            self.apply(&dx, &mut c);
            let r = Robot::new(&c).ok()?;
            rest.push(r.home_joint_angles());
            robots.push(r);
            steps.push(h);
        }
        Some(LoadedChanges {
            robot: robot.clone(),
            loads,
            robots,
            rest,
            steps,
        })
    }

    /// The columns of a row predicted as `p` by the loaded model of `changes`
    /// ([`LoadedChanges`]), warm-started along a series by `warm`; `false` (columns zero) when
    /// the equilibrium is not found.
    pub fn loaded_columns(
        &self,
        changes: &LoadedChanges,
        p: &Prediction,
        w_phi: f64,
        warm: &mut pcr_kinematics::statics::LoadedWarm,
        out: &mut [[f64; 3]],
    ) -> bool {
        for c in out.iter_mut().take(self.n) {
            *c = [0.0; 3];
        }
        let Some(pose) = p.pose else {
            return false;
        };
        let dirs: Vec<pcr_kinematics::statics::Direction> = changes
            .robots
            .iter()
            .zip(&changes.rest)
            .zip(&changes.steps)
            .map(|((r, rest), step)| pcr_kinematics::statics::Direction {
                robot: r,
                kappa: std::array::from_fn(|i| r.legs[i].map.kappa(p.dl_eff[i])),
                rest: *rest,
                step: *step,
            })
            .collect();
        let guess = pcr_kinematics::Pose::new(pose[0], pose[1], pose[2]);
        let ok = changes
            .robot
            .loaded_directions_warm(
                &p.kappa,
                &changes.loads,
                &guess,
                warm,
                &dirs,
                &mut out[..self.n],
            )
            .is_ok();
        if ok {
            for c in out.iter_mut().take(self.n) {
                c[2] *= w_phi;
            }
        } else {
            for c in out.iter_mut().take(self.n) {
                *c = [0.0; 3];
            }
        }
        ok
    }
}

/// The per-block normal equations' product of the nuisance's columns with themselves
/// (`G_b^T G_b`, symmetric, in block order) over the rows `idx`: the part of a joint fit every
/// candidate of a round shares, computed once per context and set of rows.
pub type NuisanceGram = Vec<(usize, nalgebra::DMatrix<f64>)>;

/// The nuisance parameters and their columns for every row of a context.
#[derive(Debug)]
pub struct NuisanceTable {
    /// The parameters.
    pub nui: Nuisance,
    /// Columns per row (the context's rows, in order).
    pub cols: Vec<Vec<[f64; 3]>>,
    /// The per-block products of the columns with themselves, per set of rows (keyed by a hash
    /// of the rows), computed on first use ([`NuisanceTable::gram`]).
    pub grams: std::sync::Mutex<std::collections::HashMap<u64, std::sync::Arc<NuisanceGram>>>,
}

impl NuisanceTable {
    /// The table of `nui` with the columns `cols`.
    pub fn new(nui: Nuisance, cols: Vec<Vec<[f64; 3]>>) -> NuisanceTable {
        NuisanceTable {
            nui,
            cols,
            grams: Default::default(),
        }
    }

    /// The per-block `G_b^T G_b` over the rows `idx` of the context whose table this is (`block`:
    /// the block of each of its rows), in block order; cached.
    pub fn gram(
        &self,
        block: &dyn Fn(usize) -> usize,
        idx: &[usize],
    ) -> std::sync::Arc<NuisanceGram> {
        use std::hash::{Hash, Hasher};
        let mut h = std::collections::hash_map::DefaultHasher::new();
        idx.hash(&mut h);
        let key = h.finish();
        if let Some(g) = self.grams.lock().ok().and_then(|m| m.get(&key).cloned()) {
            return g;
        }
        let n = self.nui.n;
        let nb = idx.iter().map(|&i| block(i) + 1).max().unwrap_or(1);
        // Each block's upper triangle, row by row in a flat vector (the same sums in the same
        // order as into a matrix, without its indexing).
        // The blocks in parallel, each over its rows in their order.
        let mut members: Vec<Vec<usize>> = vec![Vec::new(); nb];
        for &i in idx {
            members[block(i)].push(i);
        }
        let per: Vec<Option<Vec<f64>>> = members
            .par_iter()
            .map(|rows| {
                (!rows.is_empty()).then(|| {
                    let mut m = vec![0.0; n * (n + 1) / 2];
                    for &i in rows {
                        let g = &self.cols[i][..n];
                        let mut at = 0;
                        for (a, ga) in g.iter().enumerate() {
                            for (v, gb) in m[at..at + n - a].iter_mut().zip(&g[a..]) {
                                *v += ga[0] * gb[0] + ga[1] * gb[1] + ga[2] * gb[2];
                            }
                            at += n - a;
                        }
                    }
                    m
                })
            })
            .collect();
        let out: NuisanceGram = per
            .into_iter()
            .enumerate()
            .filter_map(|(b, m)| {
                m.map(|m| {
                    let mut full = nalgebra::DMatrix::zeros(n, n);
                    let mut at = 0;
                    for a in 0..n {
                        for c in a..n {
                            full[(a, c)] = m[at];
                            full[(c, a)] = m[at];
                            at += 1;
                        }
                    }
                    (b, full)
                })
            })
            .collect();
        let out = std::sync::Arc::new(out);
        if let Ok(mut m) = self.grams.lock() {
            m.insert(key, out.clone());
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pcr_robot::{MapForm, TendonMapKind, TendonMapSpec};

    /// The pose (x mm, y mm, phi rad) and curvatures of the robot `cfg` at motor positions `q`.
    fn pose_at(cfg: &RobotConfig, q: [f64; 3]) -> ([f64; 3], [f64; 3]) {
        let robot = Robot::new(cfg).unwrap();
        let kappa: [f64; 3] = std::array::from_fn(|i| {
            robot.legs[i]
                .map
                .kappa(q[i] * cfg.legs[i].actuation.mm_per_step())
        });
        let p = robot.fk(&kappa).unwrap();
        ([p.x, p.y, p.phi], kappa)
    }

    /// A map that turns back within the displacements the recordings command is refused, and
    /// says which leg; the same map over displacements short of its turn is not.
    #[test]
    fn a_map_that_turns_back_within_the_commanded_displacements_is_refused() {
        use crate::series::{Sample, Series};
        let series = |q1: [f64; 2]| Series {
            origin: "t".into(),
            samples: q1
                .iter()
                .enumerate()
                .map(|(k, &q)| Sample {
                    t_s: 0.02 * k as f64,
                    q: [q, 100.0, 100.0],
                    pose: None,
                    planned: None,
                    settled: false,
                    pose_id: None,
                })
                .collect(),
            row_noise: None,
            period_s: 0.02,
            declared_delay_s: 0.0,
            delay_declared: false,
            delay_s: 0.0,
        };
        let nominal = RobotConfig::nominal();
        assert_eq!(map_refusal(&nominal, &[series([-100.0, 500.0])]), None);
        // Leg 1 a cubic whose slope k1 + 3 k3 dl^2 turns at dl = +-3 mm (196 steps).
        let k1 = 1.0 / (7.0 * 125.0);
        let mut bent = nominal.clone();
        bent.legs[0].tendon_map =
            TendonMapSpec::symmetric(TendonMapKind::Poly3, vec![0.0, k1, 0.0, -k1 / 27.0]);
        let why = map_refusal(&bent, &[series([-100.0, 500.0])]).expect("refused");
        assert!(why.starts_with("leg 1: the map turns back"), "{why}");
        assert_eq!(map_refusal(&bent, &[series([-100.0, 150.0])]), None);
    }

    /// Every column is what the fits assume it is: the change of the pose when the parameter is
    /// changed as [`Nuisance::apply`] changes it, the robot solved again (checked against
    /// forward differences on a robot with a nonlinear map on one leg). The analysis's
    /// linearised calibration, every candidate's fit and the joint refinement rest on it.
    #[test]
    fn the_columns_are_the_poses_change_as_apply_makes_it() {
        let mut cfg = RobotConfig::nominal();
        // The nominal maps written out, then leg 1 bending by a cubic.
        let written = Nuisance::of(&cfg);
        written.apply(&vec![0.0; written.n], &mut cfg);
        let s = cfg.legs[0].tendon_map.flat_coeffs()[0];
        cfg.legs[0].tendon_map = TendonMapSpec::from_flat(
            MapForm::symmetric(TendonMapKind::Poly3),
            &[1e-4, s, 0.02 * s, 1e-3 * s],
        );
        let nui = Nuisance::of(&cfg);
        assert_eq!(nui.n, 3 * 4 + 4 + 2);
        let robot = Robot::new(&cfg).unwrap();
        let home = robot.home_motor_steps();
        for dq in [[40.0, -30.0, 10.0], [-25.0, 35.0, -40.0]] {
            let q: [f64; 3] = std::array::from_fn(|i| home[i] + dq[i]);
            let (p0, kappa) = pose_at(&cfg, q);
            let mmps: [f64; 3] = std::array::from_fn(|i| cfg.legs[i].actuation.mm_per_step());
            let mut j_kappa = nalgebra::Matrix3::zeros();
            let h = 1e-7;
            for l in 0..3 {
                let mut k = kappa;
                k[l] += h;
                let p = robot.fk(&k).unwrap();
                j_kappa[(0, l)] = (p.x - p0[0]) / h;
                j_kappa[(1, l)] = (p.y - p0[1]) / h;
                j_kappa[(2, l)] = (p.phi - p0[2]) / h;
            }
            let pred = crate::model::Prediction {
                pose: Some(p0),
                q_eff: q,
                dl_eff: std::array::from_fn(|i| q[i] * mmps[i]),
                kappa,
                j_q: nalgebra::Matrix3::zeros(),
                j_kappa,
                friction: None,
            };
            let mut cols = vec![[0.0; 3]; nui.n];
            nui.columns(&robot, &pred, 1.0, &mut cols);
            let flat: Vec<f64> = cfg
                .legs
                .iter()
                .flat_map(|l| {
                    let mut v = vec![1.0; GEO.len()];
                    v.extend(l.tendon_map.flat_coeffs().iter().map(|c| c.abs().max(1e-4)));
                    v
                })
                .collect();
            for j in 0..nui.n {
                let step = 1e-5 * flat[j];
                let mut dx = vec![0.0; nui.n];
                dx[j] = step;
                let mut c = cfg.clone();
                nui.apply(&dx, &mut c);
                let (p1, _) = pose_at(&c, q);
                let norm = cols[j].iter().map(|v| v * v).sum::<f64>().sqrt();
                for a in 0..3 {
                    let fd = (p1[a] - p0[a]) / step;
                    assert!(
                        (fd - cols[j][a]).abs() <= 1e-3 * norm + 1e-9,
                        "{} at q {q:?}, coordinate {a}: column {:e}, forward difference {fd:e}",
                        nui.names()[j],
                        cols[j][a]
                    );
                }
            }
        }
    }
}
