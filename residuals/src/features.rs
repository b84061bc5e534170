//! Explanatory features of every measured row: where the robot is, how it got there, how fast
//! it moves, how long it has run, and what the model says about its joints and loads. They sit
//! beside the residuals in the report and name what an unexplained remainder correlates with.

use crate::context::Context;
use crate::series::Series;
use rayon::prelude::*;
use serde::Serialize;

/// The feature names, in column order.
pub fn names() -> Vec<String> {
    let mut v: Vec<String> = ["x_mm", "y_mm", "phi_deg"].map(String::from).to_vec();
    for i in 1..=3 {
        v.push(format!("q{i}_steps"));
    }
    for i in 1..=3 {
        v.push(format!("reversal_dir{i}"));
    }
    for i in 1..=3 {
        v.push(format!("steps_since_reversal{i}"));
    }
    v.extend(
        [
            "vx_mm_s",
            "vy_mm_s",
            "speed_mm_s",
            "ax_mm_s2",
            "ay_mm_s2",
            "accel_mm_s2",
            "time_s",
        ]
        .map(String::from),
    );
    for i in 1..=3 {
        v.push(format!("gamma{i}_deg"));
    }
    for i in 1..=3 {
        v.push(format!("zeta{i}_deg"));
    }
    for i in 1..=3 {
        v.push(format!("bending{i}_deg"));
    }
    v.push("approach_dir_deg".into());
    v
}

/// Per-row reversal state of each motor: last direction (+1/-1, 0 before any motion) and the
/// steps travelled since the last reversal.
fn reversal_state(s: &Series) -> Vec<([f64; 3], [f64; 3])> {
    let mut dir = [0.0f64; 3];
    let mut since = [0.0f64; 3];
    let mut prev = s.samples.first().map_or([0.0; 3], |x| x.q);
    s.samples
        .iter()
        .map(|x| {
            for i in 0..3 {
                let d = x.q[i] - prev[i];
                if d != 0.0 {
                    let sd = d.signum();
                    if sd != dir[i] {
                        dir[i] = sd;
                        since[i] = 0.0;
                    }
                    since[i] += d.abs();
                }
            }
            prev = x.q;
            (dir, since)
        })
        .collect()
}

/// Velocity and acceleration of the planned pose (central differences), mm/s and mm/s^2.
fn planned_motion(s: &Series) -> Vec<([f64; 2], [f64; 2])> {
    let n = s.samples.len();
    let pos = |k: usize| {
        s.samples[k]
            .planned
            .or(s.samples[k].pose)
            .map(|p| [p[0], p[1]])
    };
    (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
            let v = match (pos(a), pos(b)) {
                (Some(pa), Some(pb)) if b > a => {
                    let dt = s.samples[b].t_s - s.samples[a].t_s;
                    [(pb[0] - pa[0]) / dt, (pb[1] - pa[1]) / dt]
                }
                _ => [0.0; 2],
            };
            let acc = match (pos(a), pos(k), pos(b)) {
                (Some(pa), Some(pk), Some(pb)) if b > k && k > a => {
                    let dt = 0.5 * (s.samples[b].t_s - s.samples[a].t_s);
                    [
                        (pb[0] - 2.0 * pk[0] + pa[0]) / (dt * dt),
                        (pb[1] - 2.0 * pk[1] + pa[1]) / (dt * dt),
                    ]
                }
                _ => [0.0; 2],
            };
            (v, acc)
        })
        .collect()
}

/// The feature table: one row per measured row of the context (same order).
#[derive(Debug, Clone, Serialize)]
pub struct Features {
    /// Column names.
    pub names: Vec<String>,
    /// Values, `values[row][feature]`.
    pub values: Vec<Vec<f64>>,
}

impl Features {
    /// Computes the features of every measured row of a context.
    pub fn of(ctx: &Context) -> Features {
        let rev: Vec<_> = ctx.series.iter().map(reversal_state).collect();
        let mot: Vec<_> = ctx.series.iter().map(planned_motion).collect();
        // Approach direction: the direction of the last planned motion before each row.
        let approach: Vec<Vec<f64>> = mot
            .iter()
            .map(|m| {
                let mut last = 0.0;
                m.iter()
                    .map(|(v, _)| {
                        if v[0].hypot(v[1]) > 1e-3 {
                            last = v[1].atan2(v[0]).to_degrees();
                        }
                        last
                    })
                    .collect()
            })
            .collect();
        let t0: Vec<f64> = ctx
            .series
            .iter()
            .map(|s| s.samples.first().map_or(0.0, |x| x.t_s))
            .collect();
        let values = ctx
            .rows
            .iter()
            .map(|row| {
                let smp = &ctx.series[row.s].samples[row.k];
                let p = ctx.pred(row);
                let pose = p.pose.unwrap_or([0.0; 3]);
                let (dir, since) = rev[row.s][row.k];
                let (v, a) = mot[row.s][row.k];
                let mut f = vec![pose[0], pose[1], pose[2].to_degrees()];
                f.extend(smp.q);
                f.extend(dir);
                f.extend(since);
                f.extend([v[0], v[1], v[0].hypot(v[1]), a[0], a[1], a[0].hypot(a[1])]);
                f.push(smp.t_s - t0[row.s]);
                let x = pcr_kinematics::Pose::new(pose[0], pose[1], pose[2]);
                let angles: Vec<(f64, f64)> = (0..3)
                    .map(|i| ctx.model.robot.joint_angles(i, &x, p.kappa[i]))
                    .collect();
                f.extend(angles.iter().map(|a| a.0.to_degrees()));
                f.extend(angles.iter().map(|a| a.1.to_degrees()));
                f.extend((0..3).map(|i| (p.kappa[i] * ctx.model.robot.legs[i].l_c).to_degrees()));
                f.push(approach[row.s][row.k]);
                f
            })
            .collect();
        Features {
            names: names(),
            values,
        }
    }
}

/// How much of the residual one feature predicts on held-out rows.
#[derive(Debug, Clone, Serialize)]
pub struct FeatureLink {
    /// Feature name.
    pub feature: String,
    /// Share of the held-out residual variance a quadratic in the feature (fitted on the
    /// training rows, per residual component) removes.
    pub held_out_r2: f64,
    /// Largest |correlation| of the feature with a residual component on the held-out rows.
    pub correlation: f64,
    /// Which component (`x`, `y` or `phi`).
    pub component: String,
}

/// Ranks the features by how much of the held-out residual a quadratic in each one explains.
pub fn links(ctx: &Context, feats: &Features, train: &[usize], test: &[usize]) -> Vec<FeatureLink> {
    let comps = ["x", "y", "phi"];
    // The features in parallel, each as it was alone.
    let link = |j: usize, name: &String| -> Option<FeatureLink> {
        let mut ss_before = 0.0;
        let mut ss_after = 0.0;
        let mut best_corr = (0.0f64, 0usize);
        // Standardise the feature on the training rows.
        let fv = |i: usize| feats.values[i][j];
        let n = train.len() as f64;
        let mean = train.iter().map(|&i| fv(i)).sum::<f64>() / n;
        let sd = (train.iter().map(|&i| (fv(i) - mean).powi(2)).sum::<f64>() / n).sqrt();
        if sd.is_nan() || sd <= 0.0 {
            return None;
        }
        let z = |i: usize| (fv(i) - mean) / sd;
        let (z_train, z_test): (Vec<f64>, Vec<f64>) = (
            train.iter().map(|&i| z(i)).collect(),
            test.iter().map(|&i| z(i)).collect(),
        );
        for c in 0..3 {
            // Quadratic fit r ~ a + b z + c z^2 on the training rows.
            let mut ata = nalgebra::Matrix3::<f64>::zeros();
            let mut atr = nalgebra::Vector3::<f64>::zeros();
            for (&i, &zz) in train.iter().zip(&z_train) {
                let b = nalgebra::Vector3::new(1.0, zz, zz * zz);
                ata += b * b.transpose();
                atr += b * ctx.rows[i].r[c];
            }
            let Some(coef) = ata.lu().solve(&atr) else {
                continue;
            };
            let (mut sr, mut sz, mut szz, mut srr, mut szr) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for (&i, &zz) in test.iter().zip(&z_test) {
                let r = ctx.rows[i].r[c];
                let pred = coef[0] + coef[1] * zz + coef[2] * zz * zz;
                ss_before += r * r;
                ss_after += (r - pred).powi(2);
                sr += r;
                sz += zz;
                szz += zz * zz;
                srr += r * r;
                szr += zz * r;
            }
            let m = test.len() as f64;
            let cov = szr / m - sr * sz / (m * m);
            let vz = szz / m - (sz / m).powi(2);
            let vr = srr / m - (sr / m).powi(2);
            let corr = if vz > 0.0 && vr > 0.0 {
                cov / (vz * vr).sqrt()
            } else {
                0.0
            };
            if corr.abs() > best_corr.0.abs() {
                best_corr = (corr, c);
            }
        }
        (ss_before > 0.0).then(|| FeatureLink {
            feature: name.clone(),
            held_out_r2: 1.0 - ss_after / ss_before,
            correlation: best_corr.0,
            component: comps[best_corr.1].into(),
        })
    };
    let mut out: Vec<FeatureLink> = feats
        .names
        .par_iter()
        .enumerate()
        .filter_map(|(j, name)| link(j, name))
        .collect();
    out.sort_by(|a, b| b.held_out_r2.total_cmp(&a.held_out_r2));
    out
}

/// Writes every measured row's residual (x, y mm; phi deg) beside its features as CSV: the
/// table a lab studies when the verdict is `unexplained`.
pub fn write_csv(
    ctx: &Context,
    feats: &Features,
    out: &mut dyn std::io::Write,
) -> std::io::Result<()> {
    write!(out, "file,t_s,block,held_out,rx_mm,ry_mm,rphi_deg")?;
    for n in &feats.names {
        write!(out, ",{n}")?;
    }
    writeln!(out)?;
    for (row, f) in ctx.rows.iter().zip(&feats.values) {
        let s = &ctx.series[row.s];
        write!(
            out,
            "{},{},{},{},{:.5},{:.5},{:.5}",
            s.origin.replace(',', "_"),
            s.samples[row.k].t_s,
            row.block,
            u8::from(row.held_out),
            row.r[0],
            row.r[1],
            (row.r[2] / ctx.w_phi).to_degrees()
        )?;
        for v in f {
            write!(out, ",{v:.6}")?;
        }
        writeln!(out)?;
    }
    Ok(())
}
