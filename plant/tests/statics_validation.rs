//! Validation of the static truth model against closed forms, independent computations and the
//! reference values of shared/spec/plant.md.

#![allow(clippy::needless_range_loop)] // index loops over legs and matrix entries read best here

use pcr_plant::model::{cc_ik_bending, LegGeometry};
use pcr_plant::segment::{integrate, SegmentParams};
use pcr_plant::statics::{Equilibrium, Loads, StaticsError};
use pcr_plant::{PlantConfig, TruthModel};
use pcr_robot::geometry::{norm, sub};
use pcr_robot::RobotConfig;

fn ideal() -> TruthModel {
    TruthModel::new(&RobotConfig::nominal(), &PlantConfig::ideal()).unwrap()
}

/// Unloaded equilibrium at the exact home bending (22.0497 deg per leg).
fn exact_home(t: &TruthModel) -> (Loads, Equilibrium) {
    let robot = RobotConfig::nominal();
    let phi: [f64; 3] =
        std::array::from_fn(|i| cc_ik_bending(&robot.legs[i], [0.0, 0.0, 0.0]).unwrap());
    let loads = Loads {
        phi_b: phi,
        wrench: [0.0; 3],
        friction: None,
    };
    let eq = t
        .statics
        .solve_warm(&loads, &t.statics.arc_guess(&phi, [0.0; 3]))
        .unwrap();
    (loads, eq)
}

fn loaded(t: &TruthModel, wrench: [f64; 3]) -> Equilibrium {
    let (l0, e0) = exact_home(t);
    let mut l = l0;
    l.wrench = wrench;
    t.statics.solve_path(&l0, &e0, &l).unwrap()
}

#[test]
fn springs_off_unloaded_equals_cc_arcs() {
    let t = ideal();
    let robot = RobotConfig::nominal();
    let poses = [
        [0.0, 0.0, 0.0],
        [20.0, -10.0, 5f64.to_radians()],
        [-40.0, 30.0, -10f64.to_radians()],
        [60.0, 40.0, 8f64.to_radians()],
        [-70.0, -50.0, 0.0],
    ];
    let mut worst: f64 = 0.0;
    for pose in poses {
        let phi: [f64; 3] = std::array::from_fn(|i| cc_ik_bending(&robot.legs[i], pose).unwrap());
        let eq = t
            .solve_loads(&Loads {
                phi_b: phi,
                wrench: [0.0; 3],
                friction: None,
            })
            .unwrap();
        for i in 0..3 {
            let g = LegGeometry::from_leg(&robot.legs[i]);
            let (m, th) = g.arc_tip(phi[i]);
            worst = worst.max(norm(sub(eq.m[i], m)));
            assert!((eq.tip_theta[i] - th).abs() < 1e-9);
            assert!(eq.lambda[i].abs() < 1e-7, "lambda {}", eq.lambda[i]);
        }
        for k in 0..2 {
            worst = worst.max((eq.pose[k] - pose[k]).abs());
        }
        assert!((eq.pose[2] - pose[2]).abs() < 1e-8);
    }
    assert!(
        worst < 1e-6,
        "largest difference to the CC model {worst:e} mm"
    );
    eprintln!("springs off, unloaded: largest |plant - CC| = {worst:.3e} mm");
}

#[test]
fn home_reference_joint_angles() {
    let t = ideal();
    let (_, eq) = exact_home(&t);
    assert!((eq.gamma[0].to_degrees() + 82.899).abs() < 2e-3);
    assert!((eq.zeta[0].to_degrees() + 44.949).abs() < 2e-3);
    assert!(eq.pose.iter().all(|v| v.abs() < 1e-9));
}

/// Clamped segment, tendon holding the tip rotation (theta(l) = theta(0)), small transverse
/// tip force: deflection F L^3 / (12 EI). Free tip (m(l) = 0): F L^3 / (3 EI).
#[test]
fn clamped_segment_small_load_closed_forms() {
    let p = SegmentParams {
        theta0: std::f64::consts::FRAC_PI_2,
        length: 125.0,
        ei: 6.5e4,
        steps: 200,
    };
    let f = 1e-3; // N along +x, transverse to the straight segment (along +y)
    let shoot = |target: &dyn Fn(&pcr_plant::segment::SegmentEnd) -> (f64, f64)| {
        let mut m0 = 0.0;
        for _ in 0..20 {
            let e = integrate(&p, m0, [f, 0.0]);
            let (r, d) = target(&e);
            m0 -= r / d;
        }
        integrate(&p, m0, [f, 0.0])
    };
    let guided = shoot(&|e| (e.theta - p.theta0, e.jac[2][0]));
    let free = shoot(&|e| (e.moment, e.jac[3][0]));
    let l3 = p.length.powi(3);
    let want_guided = f * l3 / (12.0 * p.ei);
    let want_free = f * l3 / (3.0 * p.ei);
    // Geometric nonlinearity is O(F^3): relative 1e-6 at this load.
    assert!(
        (guided.pos[0] - want_guided).abs() < 1e-6 * want_guided,
        "{} vs {want_guided}",
        guided.pos[0]
    );
    assert!(
        (free.pos[0] - want_free).abs() < 1e-6 * want_free,
        "{} vs {want_free}",
        free.pos[0]
    );
}

/// Large deflection of a free-tip cantilever under a transverse end load against the elastica
/// first integral (independent quadrature): with alpha = P L^2 / EI and tip angle b,
/// sqrt(2 alpha) = int_0^b dth / sqrt(sin b - sin th), transverse deflection
/// = L / sqrt(2 alpha) int_0^b sin th / sqrt(sin b - sin th) dth, axial = L sqrt(2 sin b / alpha).
#[test]
fn cantilever_large_deflection_matches_elastica_integral() {
    let (l, ei) = (125.0, 6.5e4);
    let alpha: f64 = 2.0;
    let load = alpha * ei / (l * l);
    // Quadrature with th = b - v^2 (removes the end singularity), composite Gauss-Legendre.
    let integral = |b: f64, g: &dyn Fn(f64) -> f64| -> f64 {
        let xs = [
            -0.906_179_845_938_664,
            -0.538_469_310_105_683,
            0.0,
            0.538_469_310_105_683,
            0.906_179_845_938_664,
        ];
        let ws = [
            0.236_926_885_056_189,
            0.478_628_670_499_366,
            0.568_888_888_888_889,
            0.478_628_670_499_366,
            0.236_926_885_056_189,
        ];
        let n = 2000;
        let vmax = b.sqrt();
        let mut s = 0.0;
        for k in 0..n {
            let a0 = vmax * k as f64 / n as f64;
            let a1 = vmax * (k + 1) as f64 / n as f64;
            for (x, w) in xs.iter().zip(ws) {
                let v = 0.5 * (a0 + a1) + 0.5 * (a1 - a0) * x;
                let th = b - v * v;
                let den = if v < 1e-12 {
                    b.cos().sqrt()
                } else {
                    ((b.sin() - th.sin()) / (v * v)).sqrt()
                };
                s += w * 0.5 * (a1 - a0) * 2.0 * g(th) / den;
            }
        }
        s
    };
    let (mut lo, mut hi) = (1e-6, std::f64::consts::FRAC_PI_2 - 1e-9);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if integral(mid, &|_| 1.0) < (2.0 * alpha).sqrt() {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let b = 0.5 * (lo + hi);
    let transverse = l / (2.0 * alpha).sqrt() * integral(b, &|th| th.sin());
    let axial = l * (2.0 * b.sin() / alpha).sqrt();
    // Plant segment: base along +y, load along +x (transverse), free tip.
    let p = SegmentParams {
        theta0: std::f64::consts::FRAC_PI_2,
        length: l,
        ei,
        steps: 200,
    };
    let mut m0 = 0.0;
    for _ in 0..30 {
        let e = integrate(&p, m0, [load, 0.0]);
        m0 -= e.moment / e.jac[3][0];
    }
    let e = integrate(&p, m0, [load, 0.0]);
    eprintln!(
        "alpha 2: elastica tip ({transverse:.6}, {axial:.6}) mm, plant ({:.6}, {:.6}) mm",
        e.pos[0], e.pos[1]
    );
    assert!(
        (e.pos[0] - transverse).abs() < 1e-5,
        "{} vs {transverse}",
        e.pos[0]
    );
    assert!((e.pos[1] - axial).abs() < 1e-5, "{} vs {axial}", e.pos[1]);
    // Bisshopp & Drucker (1945), alpha = 2: deflection 0.4934 L, tip at 0.8394 L.
    assert!((transverse / l - 0.4934).abs() < 2e-4);
}

#[test]
fn loaded_platform_reference_values() {
    let t = ideal();
    let eq = loaded(&t, [1.0, 0.0, 0.0]);
    let (dx, dy, dphi) = (eq.pose[0], eq.pose[1], eq.pose[2].to_degrees());
    eprintln!("1 N along +x: ({dx:.4}, {dy:.4}) mm, {dphi:.4} deg");
    assert!((dx - 1.6602).abs() < 2e-4, "{dx}");
    assert!((dy + 0.0085).abs() < 2e-4, "{dy}");
    assert!((dphi + 0.0049).abs() < 2e-4, "{dphi}");
    let eq = loaded(&t, [0.0, 0.0, 100.0]);
    let (dx, dy, dphi) = (eq.pose[0], eq.pose[1], eq.pose[2].to_degrees());
    eprintln!("+100 N mm: ({dx:.5}, {dy:.5}) mm, {dphi:.4} deg");
    assert!((dphi - 2.5132).abs() < 2e-4, "{dphi}");
    assert!(dx.abs() < 1e-3 && dy.abs() < 1e-3, "{dx} {dy}");
}

#[test]
fn small_load_compliance_is_isotropic() {
    let t = ideal();
    let f = 0.01;
    let ex = loaded(&t, [f, 0.0, 0.0]);
    let ey = loaded(&t, [0.0, f, 0.0]);
    let cx = norm([ex.pose[0], ex.pose[1]]) / f;
    let cy = norm([ey.pose[0], ey.pose[1]]) / f;
    eprintln!("compliance x {cx:.4} mm/N, y {cy:.4} mm/N");
    assert!((cx - 1.65).abs() < 0.02 && (cy - 1.65).abs() < 0.02);
    assert!((cx - cy).abs() < 1e-3 * cx);
}

/// Maxwell-Betti reciprocity (the statics derive from an energy): the platform compliance
/// matrix d(x, y, phi)/d(Fx, Fy, Mz) is symmetric.
#[test]
fn compliance_matrix_is_symmetric() {
    let t = ideal();
    let h = [1e-3, 1e-3, 1e-1];
    let mut c = [[0.0; 3]; 3];
    for k in 0..3 {
        let mut w = [0.0; 3];
        w[k] = h[k];
        let ep = loaded(&t, w);
        w[k] = -h[k];
        let em = loaded(&t, w);
        for r in 0..3 {
            c[r][k] = (ep.pose[r] - em.pose[r]) / (2.0 * h[k]);
        }
    }
    for r in 0..3 {
        for k in 0..r {
            let tol = 1e-6 * (c[r][k].abs() + c[k][r].abs()) + 1e-9;
            assert!(
                (c[r][k] - c[k][r]).abs() < tol,
                "C[{r}][{k}] {} vs {}",
                c[r][k],
                c[k][r]
            );
        }
    }
}

/// Work of the external wrench along a loading path equals the change of elastic energy
/// (bending fixed by the tendons, so they do no work).
#[test]
fn energy_balance_under_load() {
    let t = ideal();
    let energy = |eq: &Equilibrium| -> f64 {
        let mut u = 0.0;
        for i in 0..3 {
            let p = SegmentParams {
                theta0: t.statics.legs[i].theta0,
                length: t.statics.legs[i].l_c,
                ei: t.statics.ei,
                steps: t.statics.steps,
            };
            let pts = pcr_plant::segment::shape(&p, eq.z[9 + i], eq.tip_load[i]);
            // m = EI theta'; U = int m^2 / (2 EI) ds, theta' by differences (trapezoid).
            let h = p.length / p.steps as f64;
            for w in pts.windows(2) {
                let k = (w[1].1 - w[0].1) / h;
                u += 0.5 * p.ei * k * k * h;
            }
        }
        u
    };
    let w_end = [1.5, -0.8, 60.0];
    let n = 40;
    let mut work = 0.0;
    let mut prev = loaded(&t, [0.0; 3]);
    let u0 = energy(&prev);
    for k in 1..=n {
        let s = k as f64 / n as f64;
        let eq = loaded(&t, w_end.map(|v| v * s));
        let sm = (k as f64 - 0.5) / n as f64;
        for r in 0..3 {
            work += w_end[r] * sm * (eq.pose[r] - prev.pose[r]);
        }
        prev = eq;
    }
    let du = energy(&prev) - u0;
    eprintln!("work {work:.6} N mm, energy change {du:.6} N mm");
    assert!((work - du).abs() < 2e-3 * work.abs(), "{work} vs {du}");
}

/// Prototype plant (deviations, tendon map, springs on, wrench): every equilibrium equation
/// recomputed from the reported quantities holds.
#[test]
fn equilibrium_residuals_below_tolerance() {
    let mut cfg = PlantConfig::prototype();
    cfg.mechanics.k_m_n_mm_per_rad = 50.0;
    cfg.mechanics.k_p_n_mm_per_rad = 30.0;
    cfg.external_wrench.fx_n = 0.4;
    cfg.external_wrench.fy_n = -0.3;
    cfg.external_wrench.mz_n_mm = 20.0;
    let t = TruthModel::new(&RobotConfig::nominal(), &cfg).unwrap();
    for q in [
        [176.0, 176.0, 176.0],
        [250.0, 120.0, 180.0],
        [100.0, 300.0, 150.0],
    ] {
        let eq = t.solve_steps(&q).unwrap();
        assert!(eq.residual < 1e-9);
        let mut fsum = [t.wrench[0], t.wrench[1]];
        let mut msum = t.wrench[2];
        for i in 0..3 {
            let g = &t.statics.legs[i];
            assert!((norm(sub(eq.p[i], eq.m[i])) - g.l_st).abs() < 1e-9);
            let f = eq.link_force[i];
            fsum[0] += f[0];
            fsum[1] += f[1];
            let r = sub(eq.p[i], [eq.pose[0], eq.pose[1]]);
            msum += r[0] * f[1] - r[1] * f[0] - eq.joint_torque[i][1];
            // The link's moment balance: transverse force from the joint couples.
            let u = sub(eq.p[i], eq.m[i]).map(|v| v / g.l_st);
            let fn_ = -u[1] * f[0] + u[0] * f[1];
            assert!((fn_ * g.l_st - eq.joint_torque[i][0] - eq.joint_torque[i][1]).abs() < 1e-6);
        }
        assert!(
            fsum[0].abs() < 1e-9 && fsum[1].abs() < 1e-9 && msum.abs() < 1e-7,
            "{fsum:?} {msum}"
        );
    }
}

#[test]
fn errors_name_the_leg() {
    let t = ideal();
    // Leg 2 bent beyond 180 degrees.
    let e = t
        .solve_steps(&[176.0, 1700.0, 176.0])
        .unwrap_err()
        .to_string();
    assert!(e.contains("leg 2") && e.contains("bending"), "{e}");
    // A joint range that excludes the home angle of leg 1's joint M (-82.9 deg).
    let mut robot = RobotConfig::nominal();
    robot.limits.joint_min_deg = -80.0;
    let e = TruthModel::new(&robot, &PlantConfig::ideal())
        .unwrap_err()
        .to_string();
    assert!(e.contains("leg 1") && e.contains("joint M"), "{e}");
}

/// A couple beyond the platform's limit load (about -275 N mm at home: the links turn radial)
/// has no equilibrium in the robot's assembly mode.
#[test]
fn limit_load_is_reported() {
    let t = ideal();
    let mut l = t.home_loads;
    l.wrench = [0.0, 0.0, -2000.0];
    let e = t.solve_loads(&l).unwrap_err();
    assert!(matches!(e, StaticsError::Singular { .. }), "{e}");
    l.wrench = [0.0, 0.0, -250.0];
    assert!(t.solve_loads(&l).is_ok());
}

/// A stateless solve lands in the robot's working and assembly mode: for random poses of the
/// workspace, the bending of the CC IK (branch gamma < 0) gives back the same pose.
#[test]
fn stateless_solve_keeps_the_assembly_mode() {
    use rand::{Rng, SeedableRng};
    let t = ideal();
    let robot = RobotConfig::nominal();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let mut n = 0;
    while n < 25 {
        let pose = [
            rng.random_range(-70.0..70.0),
            rng.random_range(-60.0..75.0),
            rng.random_range(-12f64..12.0).to_radians(),
        ];
        let Some(phi) = (0..3)
            .map(|i| cc_ik_bending(&robot.legs[i], pose))
            .collect::<Option<Vec<f64>>>()
        else {
            continue;
        };
        let loads = Loads {
            phi_b: [phi[0], phi[1], phi[2]],
            wrench: [0.0; 3],
            friction: None,
        };
        let eq = t.solve_loads(&loads).unwrap();
        for k in 0..3 {
            assert!(
                (eq.pose[k] - pose[k]).abs() < 1e-6,
                "{pose:?} -> {:?}",
                eq.pose
            );
        }
        assert!(eq.gamma.iter().all(|g| *g < 0.0));
        n += 1;
    }
}

/// The prototype's effects without history: the geometry deviations and the true tendon map
/// move the home pose by millimetres / degrees, and the tendon map saturates.
#[test]
fn geometry_and_tendon_map_signatures() {
    let robot = RobotConfig::nominal();
    let ideal = ideal();
    let mut cfg = PlantConfig::ideal();
    cfg.geometry = PlantConfig::prototype().geometry;
    let geo = TruthModel::new(&robot, &cfg).unwrap();
    let d = norm(sub(
        [geo.home.pose[0], geo.home.pose[1]],
        [ideal.home.pose[0], ideal.home.pose[1]],
    ));
    eprintln!("geometry deviations move home by {d:.3} mm");
    assert!(d > 0.1 && d < 5.0, "{d}");
    let proto = TruthModel::new(&robot, &PlantConfig::prototype()).unwrap();
    for i in 0..3 {
        let m = proto.robot.maps[i];
        let slope = |dl: f64| (m.bending(dl + 1e-4) - m.bending(dl - 1e-4)) / 2e-4;
        // Stiffening tendon: the slope falls with the displacement, and is odd around dl0.
        assert!(slope(15.0) < 0.9 * slope(m.dl0));
        assert!((m.bending(m.dl0 + 5.0) + m.bending(m.dl0 - 5.0)).abs() < 1e-12);
        assert!((slope(m.dl0) * m.a - m.gain).abs() < 1e-9);
    }
    // A leg that bends differently each way: the slope below dl0 is the other tendon's.
    let mut cfg = PlantConfig::prototype();
    cfg.tendon_map.gain_neg = Some([0.80, 1.05, 0.90]);
    let asym = TruthModel::new(&robot, &cfg).unwrap();
    for i in 0..3 {
        let (m, p) = (asym.robot.maps[i], proto.robot.maps[i]);
        let slope = |dl: f64| (m.bending(dl + 1e-4) - m.bending(dl - 1e-4)) / 2e-4;
        assert!((slope(m.dl0 - 0.5) * m.a / m.gain_neg - 1.0).abs() < 1e-3);
        assert!((slope(m.dl0 + 0.5) * m.a / m.gain - 1.0).abs() < 1e-3);
        assert_eq!(m.bending(m.dl0 + 3.0), p.bending(p.dl0 + 3.0));
        let ratio = m.bending(m.dl0 - 3.0) / -m.bending(m.dl0 + 3.0);
        assert!((ratio - m.gain_neg / m.gain).abs() < 0.01, "{ratio}");
        assert!(m.bending(m.dl0).abs() < 1e-15);
    }
}

/// det A of geometry.md at the home pose of the nominal robot: +3.82e9.
#[test]
fn det_a_at_home_matches_geometry_md() {
    let t = ideal();
    let (_, eq) = exact_home(&t);
    assert!((eq.det_a / 3.82e9 - 1.0).abs() < 2e-3, "{:e}", eq.det_a);
}

/// Joint springs are relaxed at home (no link force there) and load the links away from home;
/// they also make the platform stiffer against a couple.
#[test]
fn joint_springs_signature() {
    let robot = RobotConfig::nominal();
    let mut cfg = PlantConfig::ideal();
    cfg.mechanics.k_m_n_mm_per_rad = 200.0;
    cfg.mechanics.k_p_n_mm_per_rad = 200.0;
    let sprung = TruthModel::new(&robot, &cfg).unwrap();
    let free = ideal();
    let home = sprung.robot.home_steps.map(f64::from);
    let eq = sprung.solve_steps(&home).unwrap();
    assert!(eq.lambda.iter().all(|l| l.abs() < 1e-9));
    let q = [home[0] + 80.0, home[1] - 40.0, home[2]];
    let (es, ef) = (
        sprung.solve_steps(&q).unwrap(),
        free.solve_steps(&q).unwrap(),
    );
    assert!(es.link_force.iter().any(|f| norm(*f) > 0.05));
    assert!(ef.link_force.iter().all(|f| norm(*f) < 1e-9));
    assert!(norm(sub([es.pose[0], es.pose[1]], [ef.pose[0], ef.pose[1]])) > 0.01);
    let mut l = sprung.home_loads;
    l.wrench = [0.0, 0.0, 100.0];
    let turn_sprung = sprung.solve_loads(&l).unwrap().pose[2] - sprung.home.pose[2];
    let turn_free = free.solve_loads(&l).unwrap().pose[2] - free.home.pose[2];
    assert!(
        turn_sprung < 0.9 * turn_free,
        "{turn_sprung} vs {turn_free}"
    );
}

/// The buckling criterion: a straight segment whose end rotation is held by the tendons
/// (clamped-guided column) reaches its conjugate point at the Euler load pi^2 EI / L^2, where
/// d theta(l_C) / d m(0) changes sign; an equilibrium with that sign is reported as buckling of
/// its leg.
#[test]
fn buckling_criterion_at_the_euler_load() {
    let (l, ei) = (125.0, 6.5e4);
    let p = SegmentParams {
        theta0: std::f64::consts::FRAC_PI_2,
        length: l,
        ei,
        steps: 100,
    };
    let euler = std::f64::consts::PI.powi(2) * ei / (l * l);
    let below = integrate(&p, 0.0, [0.0, -0.99 * euler]).jac[2][0];
    let above = integrate(&p, 0.0, [0.0, -1.01 * euler]).jac[2][0];
    assert!(below > 0.0 && above < 0.0, "{below} {above}");
    let t = ideal();
    let (_, mut eq) = exact_home(&t);
    eq.jacobi[1] = above;
    let e = t.statics.check(&eq).unwrap_err();
    assert!(matches!(e, StaticsError::Buckling { leg: 2, .. }), "{e}");
}
