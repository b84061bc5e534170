//! Static measurements: the settled rows of a recording grouped per target visit and averaged.
//!
//! A group is a maximal run of consecutive rows with `settled = 1` and the same `pose_id`, `rep`
//! and commanded motor positions. A robot whose command changes while its rows say `settled` is
//! not at rest at every one of those commands (a logger that marks rest from the measured motion
//! keeps marking it for the rows a latency hides the next move in; one that writes the position
//! reached shows the last steps of the approach): of one visit's consecutive settled rows, only
//! the command held the longest is a static measurement, and the other rows are counted in
//! [`SettledPose::moved_rows`]. Its measured values are the means over the rows of the group
//! that have them (orientation as a circular mean); the sample standard deviations are kept as
//! a measure of the capture noise. Calibration, evaluation and residual tools all read static
//! poses through this one definition.

use crate::{Recording, Split};

/// Why the static measurements could not be taken from a recording.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SettledError {
    /// The recording has no `settled` column.
    #[error(
        "{origin}: no `settled` column: static measurements are the rows marked `settled = 1`"
    )]
    NoSettledColumn {
        /// The file.
        origin: String,
    },
    /// The column exists but no row is marked settled.
    #[error("{origin}: no row has `settled = 1`: the recording holds no static measurement")]
    NoSettledRows {
        /// The file.
        origin: String,
    },
    /// Rows of one group disagree on their split.
    #[error(
        "{origin}: row {row} (t = {t_s} s): `set` changes inside the settled rows of pose {pose}"
    )]
    MixedSplit {
        /// The file.
        origin: String,
        /// 0-based data row index.
        row: usize,
        /// Its time, s.
        t_s: f64,
        /// The pose id (or `-`).
        pose: String,
    },
}

/// One visit of a static target: consecutive settled rows, averaged.
#[derive(Debug, Clone, PartialEq)]
pub struct SettledPose {
    /// `pose_id` of the rows (if the column exists).
    pub pose_id: Option<u64>,
    /// `rep` of the rows.
    pub rep: Option<u64>,
    /// The split of the rows (`set` column).
    pub set: Option<Split>,
    /// Commanded motor positions, steps.
    pub q: [i32; 3],
    /// Time of the first and last settled row, s.
    pub t_s: [f64; 2],
    /// 0-based index of the first row of the group in `Recording::rows`.
    pub first_row: usize,
    /// Number of settled rows in the group.
    pub rows: usize,
    /// Mean measured platform pose (x mm, y mm, phi deg) over the rows that have all three.
    pub pose: Option<[f64; 3]>,
    /// Rows that contributed to `pose`.
    pub pose_rows: usize,
    /// Sample standard deviation of x, y (mm) and phi (deg) over those rows (two rows or more).
    pub pose_std: Option<[f64; 3]>,
    /// Mean measured M_i (x mm, y mm) over the rows that have both coordinates.
    pub m: [Option<[f64; 2]>; 3],
    /// Rows that contributed to each `m`.
    pub m_rows: [usize; 3],
    /// Planned pose of the first row of the group (x mm, y mm, phi deg), if recorded.
    pub planned: Option<[f64; 3]>,
    /// Settled rows of the same visit (adjacent, same `pose_id` and `rep`) left out because
    /// their command differs from the one this group held longest.
    pub moved_rows: usize,
}

impl SettledPose {
    /// A label for messages: `pose 12 rep 3 (t = 14.2 s)`.
    pub fn label(&self) -> String {
        let mut s = match self.pose_id {
            Some(p) => format!("pose {p}"),
            None => format!("settled group at row {}", self.first_row + 1),
        };
        if let Some(r) = self.rep {
            s.push_str(&format!(" rep {r}"));
        }
        s.push_str(&format!(" (t = {} s)", self.t_s[0]));
        s
    }
}

#[derive(Default)]
struct Acc {
    n: usize,
    sum: [f64; 3],
    sum2: [f64; 3],
    sc: [f64; 2],
}

impl Acc {
    fn add_xy(&mut self, x: f64, y: f64) {
        self.n += 1;
        self.sum[0] += x;
        self.sum[1] += y;
        self.sum2[0] += x * x;
        self.sum2[1] += y * y;
    }
    fn add_pose(&mut self, p: [f64; 3]) {
        self.add_xy(p[0], p[1]);
        self.sum[2] += p[2];
        self.sum2[2] += p[2] * p[2];
        let (s, c) = p[2].to_radians().sin_cos();
        self.sc[0] += s;
        self.sc[1] += c;
    }
    fn mean(&self, k: usize) -> f64 {
        self.sum[k] / self.n as f64
    }
    fn std(&self, k: usize) -> f64 {
        let n = self.n as f64;
        let m = self.sum[k] / n;
        ((self.sum2[k] - n * m * m).max(0.0) / (n - 1.0)).sqrt()
    }
}

/// The static measurements of a recording, in file order. `origin` names the file in errors.
pub fn settled_poses(rec: &Recording, origin: &str) -> Result<Vec<SettledPose>, SettledError> {
    if !rec.columns.iter().any(|c| c == "settled") {
        return Err(SettledError::NoSettledColumn {
            origin: origin.into(),
        });
    }
    let mut out: Vec<SettledPose> = Vec::new();
    let mut open: Option<(SettledPose, Acc, [Acc; 3])> = None;
    let close = |o: Option<(SettledPose, Acc, [Acc; 3])>, out: &mut Vec<SettledPose>| {
        if let Some((mut g, p, m)) = o {
            if p.n > 0 {
                let phi = p.sc[0].atan2(p.sc[1]).to_degrees();
                g.pose = Some([p.mean(0), p.mean(1), phi]);
                g.pose_rows = p.n;
                if p.n >= 2 {
                    g.pose_std = Some([p.std(0), p.std(1), p.std(2)]);
                }
            }
            for i in 0..3 {
                if m[i].n > 0 {
                    g.m[i] = Some([m[i].mean(0), m[i].mean(1)]);
                    g.m_rows[i] = m[i].n;
                }
            }
            out.push(g);
        }
    };
    for (k, row) in rec.rows.iter().enumerate() {
        if row.settled != Some(true) {
            close(open.take(), &mut out);
            continue;
        }
        let same = open
            .as_ref()
            .is_some_and(|(g, _, _)| g.pose_id == row.pose_id && g.rep == row.rep && g.q == row.q);
        if !same {
            close(open.take(), &mut out);
            open = Some((
                SettledPose {
                    pose_id: row.pose_id,
                    rep: row.rep,
                    set: row.set,
                    q: row.q,
                    t_s: [row.t_s, row.t_s],
                    first_row: k,
                    rows: 0,
                    pose: None,
                    pose_rows: 0,
                    pose_std: None,
                    m: [None; 3],
                    m_rows: [0; 3],
                    planned: row
                        .planned
                        .iter()
                        .all(Option::is_some)
                        .then(|| row.planned.map(|v| v.unwrap_or(0.0))),
                    moved_rows: 0,
                },
                Acc::default(),
                Default::default(),
            ));
        }
        let (g, p, m) = open.as_mut().expect("a group is open");
        if g.set != row.set {
            return Err(SettledError::MixedSplit {
                origin: origin.into(),
                row: k,
                t_s: row.t_s,
                pose: g.pose_id.map_or("-".into(), |v| v.to_string()),
            });
        }
        g.rows += 1;
        g.t_s[1] = row.t_s;
        if let Some(pose) = row.measured_pose() {
            p.add_pose(pose);
        }
        for i in 0..3 {
            if let [Some(x), Some(y)] = row.m[i] {
                m[i].add_xy(x, y);
            }
        }
    }
    close(open.take(), &mut out);
    if out.is_empty() {
        return Err(SettledError::NoSettledRows {
            origin: origin.into(),
        });
    }
    Ok(held_commands(out))
}

/// Of every visit's adjacent groups (consecutive rows, same `pose_id` and `rep`, different
/// commands), keeps the one with the most rows (the first of equals) and counts the others'
/// rows in its `moved_rows`.
fn held_commands(groups: Vec<SettledPose>) -> Vec<SettledPose> {
    let mut out: Vec<SettledPose> = Vec::with_capacity(groups.len());
    // The end (exclusive row index) of the visit the last kept group belongs to.
    let mut visit_end = usize::MAX;
    for g in groups {
        let same_visit = out.last().is_some_and(|last| {
            g.first_row == visit_end && g.pose_id == last.pose_id && g.rep == last.rep
        });
        visit_end = g.first_row + g.rows;
        if !same_visit {
            out.push(g);
            continue;
        }
        let last = out.last_mut().expect("a visit is open");
        if g.rows > last.rows {
            let moved = last.moved_rows + last.rows;
            *last = g;
            last.moved_rows = moved;
        } else {
            last.moved_rows += g.rows;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(text: &str) -> Recording {
        Recording::read(text.as_bytes(), "t.csv").unwrap()
    }

    #[test]
    fn a_command_that_changes_inside_a_visit_keeps_the_one_held_longest() {
        // Visit 0: the first row still shows the last step of the approach, the last one the
        // next move's first command (a latency keeps the robot at rest for a row); visit 1 is
        // the same target, later, with another command: a visit of its own.
        let r = rec("t_s,q1,q2,q3,x_mm,y_mm,phi_deg,pose_id,rep,settled\n\
             0.00,9,2,3,0,0,0,0,0,1\n\
             0.02,10,2,3,1,1,0,0,0,1\n\
             0.04,10,2,3,1,1,0,0,0,1\n\
             0.06,10,2,3,1,1,0,0,0,1\n\
             0.08,11,2,3,1,1,0,0,0,1\n\
             0.10,12,2,3,5,5,0,0,0,0\n\
             0.12,12,2,3,5,5,0,0,1,1\n");
        let g = settled_poses(&r, "t.csv").unwrap();
        assert_eq!(g.len(), 2);
        assert_eq!((g[0].q, g[0].rows, g[0].moved_rows), ([10, 2, 3], 3, 2));
        assert_eq!(g[0].pose, Some([1.0, 1.0, 0.0]));
        assert_eq!((g[1].q, g[1].rows, g[1].moved_rows), ([12, 2, 3], 1, 0));
    }

    #[test]
    fn groups_consecutive_settled_rows_and_averages_them() {
        let r = rec(
            "t_s,q1,q2,q3,x_mm,y_mm,phi_deg,m1x_mm,m1y_mm,pose_id,rep,settled,set\n\
             0.00,1,2,3,9,9,9,,,0,0,0,train\n\
             0.02,1,2,3,1.0,2.0,179,5,6,0,0,1,train\n\
             0.04,1,2,3,3.0,4.0,-179,,,0,0,1,train\n\
             0.06,1,2,3,,,,7,8,0,0,1,train\n\
             0.08,4,5,6,0,0,0,,,1,0,0,test\n\
             0.10,4,5,6,10,20,1,,,1,0,1,test\n\
             0.12,4,5,6,10,20,1,,,1,1,1,test\n",
        );
        let g = settled_poses(&r, "t.csv").unwrap();
        assert_eq!(g.len(), 3);
        assert_eq!(g[0].rows, 3);
        assert_eq!(g[0].pose_rows, 2);
        let p = g[0].pose.unwrap();
        assert!((p[0] - 2.0).abs() < 1e-12 && (p[1] - 3.0).abs() < 1e-12);
        // circular mean of 179 and -179 is 180, not 0
        assert!((p[2].abs() - 180.0).abs() < 1e-9, "{p:?}");
        let s = g[0].pose_std.unwrap();
        assert!((s[0] - 2f64.sqrt()).abs() < 1e-12);
        assert_eq!(g[0].m[0], Some([6.0, 7.0]));
        assert_eq!(g[0].m_rows[0], 2);
        assert_eq!(g[0].m[1], None);
        assert_eq!(g[0].set, Some(Split::Train));
        assert_eq!((g[1].pose_id, g[1].rep), (Some(1), Some(0)));
        assert_eq!((g[2].pose_id, g[2].rep), (Some(1), Some(1)));
        assert_eq!(g[2].pose_std, None);
        assert_eq!(g[1].first_row, 5);
    }

    #[test]
    fn refuses_recordings_without_static_measurements() {
        let r = rec("t_s,q1,q2,q3\n0,1,2,3\n");
        assert!(matches!(
            settled_poses(&r, "a.csv"),
            Err(SettledError::NoSettledColumn { .. })
        ));
        let r = rec("t_s,q1,q2,q3,settled\n0,1,2,3,0\n");
        let e = settled_poses(&r, "a.csv").unwrap_err().to_string();
        assert!(e.contains("a.csv") && e.contains("no row"), "{e}");
        let r = rec("t_s,q1,q2,q3,settled,set,pose_id\n0,1,2,3,1,train,4\n1,1,2,3,1,test,4\n");
        let e = settled_poses(&r, "a.csv").unwrap_err().to_string();
        assert!(e.contains("row 1") && e.contains("pose 4"), "{e}");
    }
}
