//! Evaluation of a robot from its recordings, as in the paper's reading of ISO 9283:
//! repeatability, pose accuracy and path accuracy (Table II), plus the model's prediction
//! accuracy on the static poses.
//!
//! - **Repeatability** (targets visited several times, `pose_id` with several `rep`): per target
//!   the ISO 9283 figure RP = mean(l) + 3 S_l (l: distance of each visit to the visits'
//!   barycentre) and 3 S_phi; over all targets the paper's "2-sigma neighbourhood":
//!   2 sqrt(sum d^2 / (N - P)) with d the distance of each visit to its target's mean
//!   (N visits of P targets), and the same for the orientation.
//! - **Pose accuracy**: each static pose (settled rows averaged) against the pose the planner
//!   targeted there (`xp_mm, yp_mm, phip_deg`): mean, max, sigma of |dr| and |dphi|; ISO's
//!   AP (distance of each target's barycentre to the target) as well.
//! - **Path accuracy**: every row with a planned and a measured pose, planned minus measured at
//!   the same time; split by the extra column `segment` (e.g. `circle`, `square`) when the
//!   recording has one, else one path for the whole recording.
//! - **Model accuracy**: the forward kinematics of the commanded motors (the robot file given)
//!   against the measured static poses.
//!
//! Percentages are of the mean l_C of the robot file.

use crate::calibrate::ModelAccuracy;
use crate::data::{DataError, StaticData};
use crate::stats::{circular_mean_deg, iso_repeatability, IsoRepeatability, Summary};
use crate::step2::angle_diff_deg;
use pcr_kinematics::Robot;
use pcr_recording::{settled_poses, Recording, SettledError, Split};
use pcr_robot::RobotConfig;
use serde::Serialize;
use std::collections::BTreeMap;

/// Why a recording cannot be evaluated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EvalError {
    /// The static poses are unusable.
    #[error(transparent)]
    Data(#[from] DataError),
    /// Nothing to evaluate.
    #[error("{origin}: nothing to evaluate: no settled rows with a measured pose (repeatability, pose accuracy) and no rows with both a planned and a measured pose (path accuracy)")]
    Nothing {
        /// The file.
        origin: String,
    },
}

/// Repeatability of one target.
#[derive(Debug, Clone, Serialize)]
pub struct TargetRepeatability {
    /// The target.
    pub pose_id: Option<u64>,
    /// The ISO figures.
    pub iso: IsoRepeatability,
}

/// Repeatability over all targets visited more than once.
#[derive(Debug, Clone, Serialize)]
pub struct Repeatability {
    /// Targets with two visits or more.
    pub targets: usize,
    /// Their visits.
    pub visits: usize,
    /// Largest ISO RP over the targets, mm.
    pub iso_rp_max_mm: f64,
    /// Mean ISO RP, mm.
    pub iso_rp_mean_mm: f64,
    /// Largest ISO 3 S_phi, deg.
    pub iso_rp_phi_max_deg: f64,
    /// The paper's 2-sigma neighbourhood of the position, mm.
    pub two_sigma_mm: f64,
    /// The paper's 2-sigma neighbourhood of the orientation, deg.
    pub two_sigma_deg: f64,
    /// 2-sigma position as a percentage of l_C.
    pub two_sigma_percent_l_c: f64,
    /// Per target.
    pub per_target: Vec<TargetRepeatability>,
}

/// Accuracy of static poses against their targets.
#[derive(Debug, Clone, Serialize)]
pub struct PoseAccuracy {
    /// Static poses compared.
    pub poses: usize,
    /// |dr|, mm.
    pub position_mm: Summary,
    /// |dr| as a percentage of l_C.
    pub position_percent_l_c: Summary,
    /// |dphi|, deg.
    pub orientation_deg: Summary,
    /// ISO AP per target (distance of the visits' barycentre to the target): mean and max, mm.
    pub iso_ap_mean_mm: f64,
    /// Largest ISO AP, mm.
    pub iso_ap_max_mm: f64,
}

/// Accuracy along a path.
#[derive(Debug, Clone, Serialize)]
pub struct PathAccuracy {
    /// Which path (`segment` value, or `all`).
    pub name: String,
    /// Rows compared.
    pub rows: usize,
    /// Time from the first to the last compared row, s.
    pub duration_s: f64,
    /// |planned - measured| position, mm.
    pub position_mm: Summary,
    /// Position as a percentage of l_C.
    pub position_percent_l_c: Summary,
    /// |planned - measured| orientation, deg.
    pub orientation_deg: Summary,
}

/// The evaluation of one recording.
#[derive(Debug, Clone, Serialize)]
pub struct Evaluation {
    /// The file.
    pub file: String,
    /// Its label in tables (e.g. `calibrated`).
    pub label: String,
    /// l_C used for percentages, mm.
    pub l_c_mm: f64,
    /// Repeatability (targets visited more than once).
    pub repeatability: Option<Repeatability>,
    /// Pose accuracy (static poses with a planned target).
    pub pose_accuracy: Option<PoseAccuracy>,
    /// Path accuracy.
    pub paths: Vec<PathAccuracy>,
    /// The robot file's forward kinematics against the static poses (all of them).
    pub model: Option<ModelAccuracy>,
}

/// Evaluates one recording. `robot` gives l_C for percentages and the model whose predictions
/// are checked.
pub fn evaluate(
    rec: &Recording,
    origin: &str,
    label: &str,
    robot: &RobotConfig,
) -> Result<Evaluation, EvalError> {
    let l_c = robot.legs.iter().map(|l| l.l_c_mm).sum::<f64>() / 3.0;
    let statics = match settled_poses(rec, origin) {
        Ok(s) => s,
        Err(SettledError::NoSettledColumn { .. } | SettledError::NoSettledRows { .. }) => {
            Vec::new()
        }
        Err(e) => return Err(DataError::from(e).into()),
    };
    // Repeatability: targets by pose_id with several visits.
    let mut by_target: BTreeMap<u64, Vec<[f64; 3]>> = BTreeMap::new();
    for s in &statics {
        if let (Some(id), Some(p)) = (s.pose_id, s.pose) {
            by_target.entry(id).or_default().push(p);
        }
    }
    let per_target: Vec<TargetRepeatability> = by_target
        .iter()
        .filter_map(|(id, v)| {
            Some(TargetRepeatability {
                pose_id: Some(*id),
                iso: iso_repeatability(v)?,
            })
        })
        .collect();
    let repeatability = (!per_target.is_empty()).then(|| {
        let (mut ss, mut ssp, mut n, mut p) = (0.0, 0.0, 0usize, 0usize);
        for v in by_target.values().filter(|v| v.len() >= 2) {
            let k = v.len() as f64;
            let (mx, my) = (
                v.iter().map(|q| q[0]).sum::<f64>() / k,
                v.iter().map(|q| q[1]).sum::<f64>() / k,
            );
            let mphi = circular_mean_deg(&v.iter().map(|q| q[2]).collect::<Vec<_>>());
            for q in v {
                ss += (q[0] - mx).powi(2) + (q[1] - my).powi(2);
                ssp += angle_diff_deg(q[2], mphi).powi(2);
            }
            n += v.len();
            p += 1;
        }
        let dof = (n - p).max(1) as f64;
        let two_sigma_mm = 2.0 * (ss / dof).sqrt();
        Repeatability {
            targets: per_target.len(),
            visits: n,
            iso_rp_max_mm: per_target.iter().map(|t| t.iso.rp).fold(0.0, f64::max),
            iso_rp_mean_mm: per_target.iter().map(|t| t.iso.rp).sum::<f64>()
                / per_target.len() as f64,
            iso_rp_phi_max_deg: per_target.iter().map(|t| t.iso.rp_phi).fold(0.0, f64::max),
            two_sigma_mm,
            two_sigma_deg: 2.0 * (ssp / dof).sqrt(),
            two_sigma_percent_l_c: 100.0 * two_sigma_mm / l_c,
            per_target,
        }
    });
    // Pose accuracy against the planned target.
    let mut dr = Vec::new();
    let mut dphi = Vec::new();
    let mut ap: BTreeMap<u64, (Vec<[f64; 3]>, [f64; 3])> = BTreeMap::new();
    for (k, s) in statics.iter().enumerate() {
        if let (Some(m), Some(t)) = (s.pose, s.planned) {
            dr.push((m[0] - t[0]).hypot(m[1] - t[1]));
            dphi.push(angle_diff_deg(m[2], t[2]).abs());
            ap.entry(s.pose_id.unwrap_or(u64::MAX - k as u64))
                .or_insert_with(|| (Vec::new(), t))
                .0
                .push(m);
        }
    }
    let pose_accuracy = Summary::of(&dr).map(|position_mm| {
        let aps: Vec<f64> = ap
            .values()
            .map(|(v, t)| {
                let k = v.len() as f64;
                let bx = v.iter().map(|q| q[0]).sum::<f64>() / k;
                let by = v.iter().map(|q| q[1]).sum::<f64>() / k;
                (bx - t[0]).hypot(by - t[1])
            })
            .collect();
        PoseAccuracy {
            poses: dr.len(),
            position_percent_l_c: position_mm.percent_of(l_c),
            position_mm,
            orientation_deg: Summary::of(&dphi).unwrap_or_default(),
            iso_ap_mean_mm: aps.iter().sum::<f64>() / aps.len().max(1) as f64,
            iso_ap_max_mm: aps.iter().copied().fold(0.0, f64::max),
        }
    });
    // Path accuracy.
    let seg_col = rec.extra_index("segment");
    let mut groups: BTreeMap<String, (Vec<f64>, Vec<f64>, f64, f64)> = BTreeMap::new();
    for row in &rec.rows {
        let name = match seg_col {
            Some(c) => match row.extra.get(c).and_then(|v| v.clone()) {
                Some(v) if !v.is_empty() => v,
                _ => continue,
            },
            None => "all".to_string(),
        };
        let (Some(m), Some(x), Some(y), Some(phi)) = (
            row.measured_pose(),
            row.planned[0],
            row.planned[1],
            row.planned[2],
        ) else {
            continue;
        };
        let g = groups
            .entry(name)
            .or_insert_with(|| (Vec::new(), Vec::new(), row.t_s, row.t_s));
        g.0.push((x - m[0]).hypot(y - m[1]));
        g.1.push(angle_diff_deg(phi, m[2]).abs());
        g.3 = row.t_s;
    }
    let paths: Vec<PathAccuracy> = groups
        .into_iter()
        .filter_map(|(name, (p, o, t0, t1))| {
            let position_mm = Summary::of(&p)?;
            Some(PathAccuracy {
                name,
                rows: p.len(),
                duration_s: t1 - t0,
                position_percent_l_c: position_mm.percent_of(l_c),
                position_mm,
                orientation_deg: Summary::of(&o).unwrap_or_default(),
            })
        })
        .collect();
    if statics.is_empty() && paths.is_empty() {
        return Err(EvalError::Nothing {
            origin: origin.into(),
        });
    }
    // The robot file's predictions on every static pose.
    let model = if statics.iter().any(|s| s.pose.is_some()) {
        let data = StaticData {
            origin: origin.into(),
            poses: statics
                .iter()
                .map(|s| crate::data::StaticPose {
                    settled: s.clone(),
                    set: Split::Test,
                    q_eff: None,
                })
                .collect(),
            split: crate::data::SplitSource::Column,
            row_noise: None,
        };
        Robot::new(robot)
            .ok()
            .and_then(|_| crate::calibrate::model_accuracy(robot, &data, Split::Test))
    } else {
        None
    };
    Ok(Evaluation {
        file: origin.into(),
        label: label.into(),
        l_c_mm: l_c,
        repeatability,
        pose_accuracy,
        paths,
        model,
    })
}

/// One column of Table II.
#[derive(Debug, Clone, Serialize)]
pub struct TableTwoColumn {
    /// Column head (`pose calibrated`, `circle uncalibrated`, ...).
    pub head: String,
    /// mean, max, sigma of dr (mm); mean, max, sigma of dphi (deg); RMS mm; RMS deg.
    pub position_mm: Summary,
    /// Orientation, deg.
    pub orientation_deg: Summary,
    /// Whether the RMS rows apply (paths; the paper leaves them empty for poses).
    pub path: bool,
}

/// Table II of the paper from several evaluations: a pose column and one column per path for
/// each recording.
pub fn table_two(evals: &[Evaluation]) -> Vec<TableTwoColumn> {
    let mut cols = Vec::new();
    for e in evals {
        if let Some(p) = &e.pose_accuracy {
            cols.push(TableTwoColumn {
                head: format!("pose {}", e.label),
                position_mm: p.position_mm,
                orientation_deg: p.orientation_deg,
                path: false,
            });
        }
        for p in &e.paths {
            cols.push(TableTwoColumn {
                head: format!("{} {}", p.name, e.label),
                position_mm: p.position_mm,
                orientation_deg: p.orientation_deg,
                path: true,
            });
        }
    }
    cols
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(text: &str) -> Recording {
        Recording::read(text.as_bytes(), "e.csv").unwrap()
    }

    #[test]
    fn repeatability_and_pose_accuracy_by_hand() {
        // Target 0 at (10, 0, 0) visited twice: measured (11, 0, 0) and (11, 2, 0).
        // Target 1 at (0, 10, 0) visited twice: (0, 10, 1) and (0, 10, -1).
        let r = rec(
            "t_s,q1,q2,q3,x_mm,y_mm,phi_deg,xp_mm,yp_mm,phip_deg,pose_id,rep,settled\n\
             0.1,1,1,1,11,0,0,10,0,0,0,0,1\n\
             0.2,1,1,1,,,,10,0,0,0,0,0\n\
             0.3,1,1,1,11,2,0,10,0,0,0,1,1\n\
             0.4,2,2,2,0,10,1,0,10,0,1,0,1\n\
             0.5,2,2,2,,,,0,10,0,1,0,0\n\
             0.6,2,2,2,0,10,-1,0,10,0,1,1,1\n",
        );
        let e = evaluate(&r, "e.csv", "x", &RobotConfig::nominal()).unwrap();
        let rep = e.repeatability.unwrap();
        assert_eq!((rep.targets, rep.visits), (2, 4));
        // target 0: barycentre (11, 1), l = 1, 1: RP = 1; target 1: RP = 0, 3 S_phi = 3 sqrt(2)
        assert!((rep.iso_rp_max_mm - 1.0).abs() < 1e-12);
        assert!((rep.iso_rp_phi_max_deg - 3.0 * 2f64.sqrt()).abs() < 1e-9);
        // 2-sigma: sum d^2 = 1 + 1 + 0 + 0 over N - P = 2: 2 sqrt(1) = 2 mm;
        // phi: 0 + 0 + 1 + 1 over 2: 2 deg
        assert!((rep.two_sigma_mm - 2.0).abs() < 1e-12);
        assert!((rep.two_sigma_deg - 2.0).abs() < 1e-9);
        assert!((rep.two_sigma_percent_l_c - 1.6).abs() < 1e-12);
        // pose accuracy: dr = 1, sqrt(5), 0, 0; dphi = 0, 0, 1, 1
        let p = e.pose_accuracy.unwrap();
        assert_eq!(p.poses, 4);
        assert!((p.position_mm.mean - (1.0 + 5f64.sqrt()) / 4.0).abs() < 1e-12);
        assert!((p.position_mm.max - 5f64.sqrt()).abs() < 1e-12);
        assert!((p.orientation_deg.mean - 0.5).abs() < 1e-12);
        // ISO AP: target 0 barycentre (11, 1) -> sqrt(2); target 1 (0, 10) -> 0
        assert!((p.iso_ap_max_mm - 2f64.sqrt()).abs() < 1e-12);
        assert!((p.iso_ap_mean_mm - 2f64.sqrt() / 2.0).abs() < 1e-12);
        // every row has a planned and (most) a measured pose: one path "all" of 4 rows
        assert_eq!(e.paths.len(), 1);
        assert_eq!(e.paths[0].rows, 4);
    }

    #[test]
    fn paths_split_by_segment() {
        let r = rec(
            "t_s,q1,q2,q3,x_mm,y_mm,phi_deg,xp_mm,yp_mm,phip_deg,segment\n\
             0.0,1,1,1,0,0,0,0,0,0,\n\
             0.1,1,1,1,3,4,0,0,0,0,circle\n\
             0.2,1,1,1,0,0,2,0,0,0,circle\n\
             0.3,1,1,1,1,0,0,0,0,0,square\n",
        );
        let e = evaluate(&r, "e.csv", "x", &RobotConfig::nominal()).unwrap();
        assert_eq!(e.paths.len(), 2);
        let c = e.paths.iter().find(|p| p.name == "circle").unwrap();
        assert_eq!(c.rows, 2);
        assert!((c.position_mm.mean - 2.5).abs() < 1e-12);
        assert!((c.position_mm.rms - 12.5f64.sqrt()).abs() < 1e-12);
        assert!((c.orientation_deg.max - 2.0).abs() < 1e-12);
        assert!((c.duration_s - 0.1).abs() < 1e-12);
        let cols = table_two(&[e]);
        assert_eq!(cols.len(), 2);
        assert_eq!(cols[0].head, "circle x");
    }

    #[test]
    fn a_recording_without_anything_to_evaluate_is_an_error() {
        let r = rec("t_s,q1,q2,q3,x_mm,y_mm,phi_deg\n0.1,1,1,1,1,1,1\n");
        let e = evaluate(&r, "e.csv", "x", &RobotConfig::nominal()).unwrap_err();
        assert!(e.to_string().contains("e.csv"), "{e}");
    }
}
