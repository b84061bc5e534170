//! Timing of the kineto-static model along a series of 2000 consecutive curvature triples:
//! `fk_loaded_warm`, `load_response_warm`, `loaded_sensitivity_warm` and
//! `loaded_directions_warm` toward 20 changed robots (the residual analysis's calibration
//! parameters: psi, l_C, r_p, theta_p and a map gain per leg, and more) (springs and an
//! external force), plus a checksum of the results to compare builds. Run: `cargo bench -p pcr-kinematics --bench statics`.

use pcr_kinematics::statics::{Direction, LoadedWarm, Loads};
use pcr_kinematics::{Pose, Robot};
use std::hint::black_box;
use std::time::Instant;

fn series(r: &Robot) -> Vec<([f64; 3], Pose)> {
    let mut v = Vec::new();
    for k in 0..2000 {
        let t = k as f64 * 0.004;
        let p = Pose::from_mm_deg(
            40.0 * (1.1 * t).cos(),
            40.0 * (1.7 * t).sin(),
            6.0 * (1.3 * t).sin(),
        );
        if let Ok(s) = r.ik(&p) {
            v.push((s.kappa, p));
        }
    }
    v
}

/// 20 robots, each the nominal one with one parameter of a leg changed by 1e-4 (psi, l_C, r_p,
/// theta_p, l_st, l_CE, beta on legs 1-3 minus one): what the residual analysis's calibration
/// columns differentiate toward.
fn changed_robots() -> Vec<Robot> {
    let cfg = pcr_robot::RobotConfig::nominal();
    let mut out = Vec::new();
    for k in 0..20 {
        let mut c = cfg.clone();
        let leg = &mut c.legs[k % 3];
        match k / 3 {
            0 => leg.psi_deg += 1e-4,
            1 => leg.l_c_mm += 1e-4,
            2 => leg.r_p_mm += 1e-4,
            3 => leg.theta_p_deg += 1e-4,
            4 => leg.l_st_mm += 1e-4,
            5 => leg.l_ce_mm += 1e-4,
            _ => leg.beta_deg += 1e-4,
        }
        out.push(Robot::new(&c).unwrap());
    }
    out
}

fn main() {
    let r = Robot::nominal();
    let s = series(&r);
    let others = changed_robots();
    let rests: Vec<[(f64, f64); 3]> = others.iter().map(|o| o.home_joint_angles()).collect();
    let cases = [
        (
            "force",
            Loads {
                ei: 6.5e4,
                force: [0.392, -0.280],
                couple: 0.0,
                k_m: 0.0,
                k_p: 0.0,
            },
        ),
        (
            "springs",
            Loads {
                ei: 6.5e4,
                force: [0.0, 0.0],
                couple: 0.0,
                k_m: 300.0,
                k_p: 200.0,
            },
        ),
    ];
    // STATICS_DUMP=path: every pose and response of the first repetition, to compare builds.
    let mut dump = std::env::var("STATICS_DUMP")
        .ok()
        .map(|p| std::fs::File::create(p).unwrap());
    for (name, loads) in cases {
        for rep in 0..8 {
            let t0 = Instant::now();
            let mut warm = LoadedWarm::default();
            let mut sum = [0.0f64; 3];
            for (kappa, p) in &s {
                let e = r
                    .fk_loaded_warm(black_box(kappa), &loads, p, &mut warm)
                    .unwrap();
                sum[0] += e.pose.x;
                sum[1] += e.pose.y;
                sum[2] += e.pose.phi;
                if rep == 0 {
                    if let Some(f) = dump.as_mut() {
                        use std::io::Write;
                        writeln!(
                            f,
                            "{name} fk {:e} {:e} {:e}",
                            e.pose.x, e.pose.y, e.pose.phi
                        )
                        .unwrap();
                    }
                }
            }
            let fk = t0.elapsed();
            let t1 = Instant::now();
            let mut warm = LoadedWarm::default();
            let mut rsum = 0.0f64;
            for (kappa, p) in &s {
                let resp = r
                    .load_response_warm(black_box(kappa), &loads, p, &mut warm)
                    .unwrap();
                rsum += resp.iter().flatten().map(|v| v.abs()).sum::<f64>();
                if rep == 0 {
                    if let Some(f) = dump.as_mut() {
                        use std::io::Write;
                        let v: Vec<String> =
                            resp.iter().flatten().map(|v| format!("{v:e}")).collect();
                        writeln!(f, "{name} lr {}", v.join(" ")).unwrap();
                    }
                }
            }
            let lr = t1.elapsed();
            let t2 = Instant::now();
            let mut warm = LoadedWarm::default();
            let mut ssum = 0.0f64;
            for (kappa, p) in &s {
                let x = r
                    .loaded_sensitivity_warm(black_box(kappa), &loads, p, &mut warm)
                    .unwrap();
                ssum += x.d_kappa.iter().flatten().map(|v| v.abs()).sum::<f64>();
            }
            let sens = t2.elapsed();
            let t3 = Instant::now();
            let mut warm = LoadedWarm::default();
            let mut dsum = 0.0f64;
            let mut out = vec![[0.0; 3]; others.len()];
            for (kappa, p) in &s {
                let dirs: Vec<Direction> = others
                    .iter()
                    .zip(&rests)
                    .map(|(o, rest)| Direction {
                        robot: o,
                        kappa: *kappa,
                        rest: *rest,
                        step: 1e-4,
                    })
                    .collect();
                r.loaded_directions_warm(black_box(kappa), &loads, p, &mut warm, &dirs, &mut out)
                    .unwrap();
                dsum += out.iter().flatten().map(|v| v.abs()).sum::<f64>();
            }
            let dirs = t3.elapsed();
            println!(
                "{name} rep {rep}: fk_loaded_warm {:.3} ms/{} rows ({:.2} us/row), load_response_warm {:.3} ms ({:.2} us/row), loaded_sensitivity_warm {:.3} ms ({:.2} us/row), loaded_directions_warm x{} {:.3} ms ({:.2} us/row); sums {:.12} {:.12} {:.15} {:.12} {:.6} {:.6}",
                fk.as_secs_f64() * 1e3,
                s.len(),
                fk.as_secs_f64() * 1e6 / s.len() as f64,
                lr.as_secs_f64() * 1e3,
                lr.as_secs_f64() * 1e6 / s.len() as f64,
                sens.as_secs_f64() * 1e3,
                sens.as_secs_f64() * 1e6 / s.len() as f64,
                others.len(),
                dirs.as_secs_f64() * 1e3,
                dirs.as_secs_f64() * 1e6 / s.len() as f64,
                sum[0], sum[1], sum[2], rsum, ssum, dsum
            );
        }
    }
}
