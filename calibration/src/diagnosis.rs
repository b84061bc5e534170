//! Why a calibration stays above the capture noise.
//!
//! When the calibrated robot's held-out platform position error is far above what the capture
//! noise explains ([`FAR_ABOVE`] times the noise of a static pose), three likely reasons are
//! weighed. Each is a small model of the residual, fitted on the training poses by linear
//! least squares around the calibrated robot and judged by the share of the held-out excess
//! (the test poses' squared error above their noise) that it removes:
//!
//! 1. **A map the families cannot follow**: per leg, a smooth function of the tendon
//!    displacement added to the curvature (piecewise linear on eight knots over the data's
//!    range and one at dl = 0, so that it may bend differently each way), mapped to the platform
//!    through the Jacobian J = -A^-1 B.
//! 2. **A time-dependent effect in the static poses**: the platform error as a linear and a
//!    quadratic function of the time of the pose in the recording (drift, creep, warming). Where
//!    targets were visited more than once, the spread of the visits of one target against the
//!    noise of a visit is reported beside it: repeated visits that disagree over time are the
//!    same evidence without a model.
//! 3. **Geometry outside the parameter set**: the base points B_i (r_base, beta) and the link
//!    lengths l_st, which the paper's set does not free (one linearised step around the
//!    calibrated robot; `--params extended` frees them).
//!
//! The reasons are named in the order of the share they explain; one line says it.

use crate::data::StaticData;
use crate::step2::predict_pose;
use nalgebra::{DMatrix, DVector};
use pcr_kinematics::{Pose, Robot};
use pcr_recording::Split;
use pcr_robot::RobotConfig;
use serde::Serialize;

/// Held-out platform position RMS above this multiple of the capture noise of a static pose is
/// "far above" and diagnosed.
pub const FAR_ABOVE: f64 = 2.0;

/// One candidate reason and what it explains.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Reason {
    /// Short name: `map`, `time`, `geometry`.
    pub name: &'static str,
    /// What it stands for, as the line says it.
    pub what: &'static str,
    /// Share of the held-out excess it removes (0..1; negative when it predicts worse).
    pub share: f64,
    /// Extra evidence, if any (e.g. the spread of repeated visits).
    pub detail: Option<String>,
}

/// The diagnosis of a calibration whose held-out error stays far above the capture noise.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Diagnosis {
    /// Held-out platform position RMS of the calibrated robot, mm.
    pub test_rms_mm: f64,
    /// What the capture noise explains on the same poses, mm.
    pub noise_rms_mm: f64,
    /// The reasons, most likely first.
    pub reasons: Vec<Reason>,
    /// The one line.
    pub line: String,
}

/// One static pose with its error against the calibrated robot.
struct Obs {
    q: [f64; 3],
    t: f64,
    measured: [f64; 3],
    /// measured - predicted: x mm, y mm, phi deg.
    error: [f64; 3],
    /// Noise variance of the pose's position (x + y), mm^2.
    noise: f64,
    test: bool,
}

/// Diagnoses `robot` (the calibrated one) on the static poses; `None` when the held-out error
/// is within [`FAR_ABOVE`] times the noise, or when the data do not allow it (no test poses, no
/// noise estimate).
pub fn diagnose(robot: &RobotConfig, data: &StaticData) -> Option<Diagnosis> {
    let noise = data.row_noise?;
    let model = Robot::new(robot).ok()?;
    let obs: Vec<Obs> = data
        .poses
        .iter()
        .filter_map(|p| {
            let measured = p.settled.pose?;
            let q = p.q();
            let pred = predict_pose(&model, &q, &measured)?;
            let n = p.settled.pose_rows.max(1) as f64;
            Some(Obs {
                q,
                t: 0.5 * (p.settled.t_s[0] + p.settled.t_s[1]),
                measured,
                error: [
                    measured[0] - pred[0],
                    measured[1] - pred[1],
                    crate::step2::angle_diff_deg(measured[2], pred[2]),
                ],
                noise: (noise[0].powi(2) + noise[1].powi(2)) / n,
                test: p.set == Split::Test,
            })
        })
        .collect();
    let test: Vec<&Obs> = obs.iter().filter(|o| o.test).collect();
    if test.is_empty() || obs.iter().filter(|o| !o.test).count() < 10 {
        return None;
    }
    let n = test.len() as f64;
    let sse: f64 = test
        .iter()
        .map(|o| o.error[0].powi(2) + o.error[1].powi(2))
        .sum();
    let floor: f64 = test.iter().map(|o| o.noise).sum();
    let (test_rms, noise_rms) = ((sse / n).sqrt(), (floor / n).sqrt());
    if test_rms <= FAR_ABOVE * noise_rms {
        return None;
    }
    let excess = (sse - floor).max(f64::MIN_POSITIVE);
    let share = |columns: &dyn Fn(&Obs) -> Option<Vec<[f64; 2]>>| -> f64 {
        held_out_share(&obs, columns).map_or(0.0, |after| (sse - after) / excess)
    };
    let map = share(&|o| map_columns(&model, data_range(&obs, robot), robot, o));
    let time = share(&|o| Some(time_columns(&obs, o)));
    let geometry = share(&|o| geometry_columns(robot, &model, o));
    let mut reasons = vec![
        Reason {
            name: "map",
            what: "a map the families cannot follow",
            share: map,
            detail: None,
        },
        Reason {
            name: "time",
            what: "a time-dependent effect in the static poses",
            share: time,
            detail: repeated_visits(data, noise),
        },
        Reason {
            name: "geometry",
            what: "geometry outside the parameter set (B_i, l_st: try --params extended)",
            share: geometry,
            detail: None,
        },
    ];
    reasons.sort_by(|a, b| b.share.total_cmp(&a.share));
    let listed: Vec<String> = reasons
        .iter()
        .map(|r| {
            let mut s = format!(
                "{} ({:.0} % of the held-out excess)",
                r.what,
                100.0 * r.share.max(0.0)
            );
            if let Some(d) = &r.detail {
                s += &format!(", {d}");
            }
            s
        })
        .collect();
    let line = format!(
        "the held-out platform error ({test_rms:.3} mm RMS) stays {:.1} x above what the capture noise explains ({noise_rms:.3} mm); likely reasons, in order: {}",
        test_rms / noise_rms,
        listed.join("; ")
    );
    Some(Diagnosis {
        test_rms_mm: test_rms,
        noise_rms_mm: noise_rms,
        reasons,
        line,
    })
}

/// The held-out position SSE after fitting the columns (per pose, each column's change of x and
/// y) to the training poses' position errors by ridge-stabilised linear least squares; `None`
/// when the columns cannot be evaluated or the fit fails.
fn held_out_share(obs: &[Obs], columns: &dyn Fn(&Obs) -> Option<Vec<[f64; 2]>>) -> Option<f64> {
    let cols: Vec<Vec<[f64; 2]>> = obs.iter().map(columns).collect::<Option<_>>()?;
    let k = cols.first()?.len();
    let train: Vec<usize> = (0..obs.len()).filter(|&i| !obs[i].test).collect();
    let mut a = DMatrix::zeros(2 * train.len(), k);
    let mut b = DVector::zeros(2 * train.len());
    for (r, &i) in train.iter().enumerate() {
        for c in 0..k {
            a[(2 * r, c)] = cols[i][c][0];
            a[(2 * r + 1, c)] = cols[i][c][1];
        }
        b[2 * r] = obs[i].error[0];
        b[2 * r + 1] = obs[i].error[1];
    }
    let scale: Vec<f64> = (0..k)
        .map(|c| {
            let n = a.column(c).norm();
            if n > 0.0 {
                n
            } else {
                1.0
            }
        })
        .collect();
    for (c, s) in scale.iter().enumerate() {
        a.column_mut(c).unscale_mut(*s);
    }
    let x = a.svd(true, true).solve(&b, 1e-9).ok()?;
    let x: Vec<f64> = (0..k).map(|c| x[c] / scale[c]).collect();
    Some(
        obs.iter()
            .zip(&cols)
            .filter(|(o, _)| o.test)
            .map(|(o, c)| {
                let d: [f64; 2] = std::array::from_fn(|j| (0..k).map(|m| c[m][j] * x[m]).sum());
                (o.error[0] - d[0]).powi(2) + (o.error[1] - d[1]).powi(2)
            })
            .sum(),
    )
}

/// Knots of the map correction per leg: eight over the data's displacement range and dl = 0.
fn data_range(obs: &[Obs], robot: &RobotConfig) -> [Vec<f64>; 3] {
    std::array::from_fn(|i| {
        let mmps = robot.legs[i].actuation.mm_per_step();
        let (lo, hi) = obs.iter().fold((0.0f64, 0.0f64), |a, o| {
            (a.0.min(o.q[i] * mmps), a.1.max(o.q[i] * mmps))
        });
        let mut k: Vec<f64> = (0..8)
            .map(|j| lo + (hi - lo) * j as f64 / 7.0)
            .chain([0.0])
            .collect();
        k.sort_by(f64::total_cmp);
        k.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
        k
    })
}

/// Piecewise-linear hat functions on `knots` at `x`.
fn hats(knots: &[f64], x: f64) -> Vec<f64> {
    let mut out = vec![0.0; knots.len()];
    if knots.len() == 1 {
        out[0] = 1.0;
        return out;
    }
    let j = knots
        .windows(2)
        .position(|w| x <= w[1])
        .unwrap_or(knots.len() - 2);
    let (a, b) = (knots[j], knots[j + 1]);
    let u = ((x - a) / (b - a)).clamp(0.0, 1.0);
    out[j] = 1.0 - u;
    out[j + 1] = u;
    out
}

/// Columns of the map correction: d(x, y)/d kappa_i times each hat function of dl_i.
fn map_columns(
    model: &Robot,
    knots: [Vec<f64>; 3],
    robot: &RobotConfig,
    o: &Obs,
) -> Option<Vec<[f64; 2]>> {
    let kappa: [f64; 3] = std::array::from_fn(|i| model.steps_to_kappa(i, o.q[i]));
    let pose = Pose::from_mm_deg(
        o.measured[0] - o.error[0],
        o.measured[1] - o.error[1],
        o.measured[2] - o.error[2],
    );
    let j = model.jacobian(&pose, &kappa)?;
    let mut out = Vec::new();
    for i in 0..3 {
        let dl = o.q[i] * robot.legs[i].actuation.mm_per_step();
        for h in hats(&knots[i], dl) {
            out.push([j[(0, i)] * h, j[(1, i)] * h]);
        }
    }
    Some(out)
}

/// Columns of the time trend: x and y each linear and quadratic in the pose's time.
fn time_columns(all: &[Obs], o: &Obs) -> Vec<[f64; 2]> {
    let (t0, t1) = all.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, o| {
        (a.0.min(o.t), a.1.max(o.t))
    });
    let u = (o.t - 0.5 * (t0 + t1)) / (0.5 * (t1 - t0)).max(1e-9);
    vec![[u, 0.0], [0.0, u], [u * u, 0.0], [0.0, u * u]]
}

/// Columns of the geometry outside the paper's set: r_base, beta and l_st of each leg, by
/// forward differences of the predicted pose.
fn geometry_columns(robot: &RobotConfig, model: &Robot, o: &Obs) -> Option<Vec<[f64; 2]>> {
    let near = [
        o.measured[0] - o.error[0],
        o.measured[1] - o.error[1],
        o.measured[2] - o.error[2],
    ];
    let base = predict_pose(model, &o.q, &near)?;
    let mut out = Vec::with_capacity(9);
    for i in 0..3 {
        for k in 0..3 {
            const H: f64 = 1e-4;
            let mut c = robot.clone();
            let l = &mut c.legs[i];
            match k {
                0 => l.r_base_mm += H,
                1 => l.beta_deg += H,
                _ => l.l_st_mm += H,
            }
            let p = predict_pose(&Robot::new(&c).ok()?, &o.q, &near)?;
            out.push([(p[0] - base[0]) / H, (p[1] - base[1]) / H]);
        }
    }
    Some(out)
}

/// Where targets were visited more than once: the RMS distance of each visit from its target's
/// mean, against the noise of a visit (`None` without repeated visits).
fn repeated_visits(data: &StaticData, noise: [f64; 3]) -> Option<String> {
    let (rms, ratio) = visit_spread(data, noise)?;
    Some(format!(
        "repeated visits of one target spread {rms:.3} mm RMS, {ratio:.1} x their noise"
    ))
}

/// The spread of repeated visits of one target: the RMS distance (mm) of each visit's position
/// from its target's mean (over the degrees of freedom), and its ratio to what the capture
/// noise `noise` (x, y mm per row) explains; `None` without a target visited twice. A ratio
/// well above 1 says the robot did not come back to where it was: a time-dependent effect
/// (drift, creep, warming) or a history effect in the static poses.
pub fn visit_spread(data: &StaticData, noise: [f64; 3]) -> Option<(f64, f64)> {
    let mut by_target: std::collections::BTreeMap<u64, Vec<([f64; 2], usize)>> = Default::default();
    for p in &data.poses {
        if let (Some(id), Some(pose)) = (p.settled.pose_id, p.settled.pose) {
            by_target
                .entry(id)
                .or_default()
                .push(([pose[0], pose[1]], p.settled.pose_rows.max(1)));
        }
    }
    let (mut ss, mut expected, mut dof) = (0.0, 0.0, 0usize);
    for visits in by_target.values().filter(|v| v.len() > 1) {
        let n = visits.len() as f64;
        let mean: [f64; 2] =
            std::array::from_fn(|j| visits.iter().map(|v| v.0[j]).sum::<f64>() / n);
        for v in visits {
            ss += (v.0[0] - mean[0]).powi(2) + (v.0[1] - mean[1]).powi(2);
            expected += (noise[0].powi(2) + noise[1].powi(2)) / v.1 as f64 * (n - 1.0) / n;
        }
        dof += visits.len() - 1;
    }
    (dof > 0).then(|| {
        (
            (ss / dof as f64).sqrt(),
            (ss / expected.max(f64::MIN_POSITIVE)).sqrt(),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hats_interpolate_linearly_and_sum_to_one() {
        let k = [-2.0, 0.0, 1.0, 4.0];
        for x in [-3.0, -2.0, -0.5, 0.0, 0.3, 2.5, 4.0, 6.0] {
            let h = hats(&k, x);
            assert!((h.iter().sum::<f64>() - 1.0).abs() < 1e-12, "{x}");
            let back: f64 = h.iter().zip(&k).map(|(a, b)| a * b).sum();
            assert!((back - x.clamp(-2.0, 4.0)).abs() < 1e-12, "{x}: {back}");
        }
    }
}
