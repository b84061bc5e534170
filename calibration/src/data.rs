//! The static measurements a calibration fits: settled poses of a recording with their split.
//!
//! A static pose is one visit of a target (`pcr_recording::settled_poses`: consecutive settled
//! rows, averaged). Its split comes from the recording's `set` column when the experimenter gave
//! one; otherwise a seeded random third of the targets is held out. The split is drawn by target
//! (`pose_id`), never by visit, so that the repetitions of one pose never sit on both sides.

use pcr_recording::{settled_poses, Recording, SettledError, SettledPose, Split};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use std::collections::BTreeMap;

/// Why the static measurements of a recording cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DataError {
    /// No settled rows, no settled column, a split changing inside a group.
    #[error(transparent)]
    Settled(#[from] SettledError),
    /// Some groups carry a split and others do not.
    #[error("{origin}: {label} has no `set` value while other static poses do: give every settled row a split or none")]
    PartialSplit {
        /// The file.
        origin: String,
        /// The pose without a split.
        label: String,
    },
    /// A quantity the fit needs is missing from every static pose.
    #[error("{origin}: no static pose has {what} (columns {columns})")]
    Missing {
        /// The file.
        origin: String,
        /// What is missing.
        what: String,
        /// The columns that carry it.
        columns: String,
    },
    /// Too few poses for the parameters.
    #[error("{origin}: {have} {what} in the {set} set, at least {need} needed{hint}")]
    TooFew {
        /// The file.
        origin: String,
        /// What was counted.
        what: String,
        /// train or test.
        set: &'static str,
        /// How many there are.
        have: usize,
        /// How many are needed.
        need: usize,
        /// Advice.
        hint: String,
    },
}

/// How the train/test split was made.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum SplitSource {
    /// From the recording's `set` column.
    Column,
    /// Seeded random by target: `test_fraction` of the targets held out.
    Seeded {
        /// The seed.
        seed: u64,
        /// Fraction of the targets in the test set.
        test_fraction: f64,
    },
}

/// One static pose with its split resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticPose {
    /// The aggregated settled rows.
    pub settled: SettledPose,
    /// Train or test.
    pub set: Split,
    /// The motor positions the robot's legs actually reached, steps, where a model of effects
    /// on the drive side (drift, creep, play, periodic errors) says they differ from the
    /// commanded ones (`None`: the commanded positions). Set by the residual analysis when it
    /// re-runs the calibration with its effects in the model.
    pub q_eff: Option<[f64; 3]>,
}

impl StaticPose {
    /// Motor positions of the pose, steps: the effective ones where set, else the commanded.
    pub fn q(&self) -> [f64; 3] {
        self.q_eff.unwrap_or(self.settled.q.map(f64::from))
    }
}

/// The static poses of one recording.
#[derive(Debug, Clone)]
pub struct StaticData {
    /// The file.
    pub origin: String,
    /// Static poses, file order.
    pub poses: Vec<StaticPose>,
    /// How the split was made.
    pub split: SplitSource,
    /// Capture noise estimated from the spread of the settled rows: pooled standard deviation of
    /// one row's x, y (mm) and phi (deg); `None` when no group has two rows.
    pub row_noise: Option<[f64; 3]>,
}

impl StaticData {
    /// Reads the static poses of a recording. Without a `set` column a seeded random
    /// `test_fraction` of the targets (by `pose_id`, else by visit) is held out.
    pub fn from_recording(
        rec: &Recording,
        origin: &str,
        seed: u64,
        test_fraction: f64,
    ) -> Result<StaticData, DataError> {
        let groups = settled_poses(rec, origin)?;
        let with_set = groups.iter().filter(|g| g.set.is_some()).count();
        let (poses, split) = if with_set > 0 {
            if let Some(g) = groups.iter().find(|g| g.set.is_none()) {
                return Err(DataError::PartialSplit {
                    origin: origin.into(),
                    label: g.label(),
                });
            }
            let poses: Vec<StaticPose> = groups
                .into_iter()
                .map(|g| StaticPose {
                    set: g.set.unwrap_or(Split::Train),
                    settled: g,
                    q_eff: None,
                })
                .collect();
            (poses, SplitSource::Column)
        } else {
            // Targets: pose_id where known, else each visit on its own.
            let key = |k: usize, g: &SettledPose| g.pose_id.map_or(u64::MAX - k as u64, |p| p);
            let mut targets: Vec<u64> = groups.iter().enumerate().map(|(k, g)| key(k, g)).collect();
            targets.sort_unstable();
            targets.dedup();
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            targets.shuffle(&mut rng);
            let n_test = (targets.len() as f64 * test_fraction).round() as usize;
            let test: BTreeMap<u64, ()> = targets[..n_test].iter().map(|t| (*t, ())).collect();
            let poses: Vec<StaticPose> = groups
                .into_iter()
                .enumerate()
                .map(|(k, g)| StaticPose {
                    set: if test.contains_key(&key(k, &g)) {
                        Split::Test
                    } else {
                        Split::Train
                    },
                    settled: g,
                    q_eff: None,
                })
                .collect();
            (
                poses,
                SplitSource::Seeded {
                    seed,
                    test_fraction,
                },
            )
        };
        let row_noise = pooled_noise(&poses);
        Ok(StaticData {
            origin: origin.into(),
            poses,
            split,
            row_noise,
        })
    }

    /// The poses of one split.
    pub fn of(&self, set: Split) -> impl Iterator<Item = &StaticPose> {
        self.poses.iter().filter(move |p| p.set == set)
    }

    /// Number of poses of a split with a measured M_i of leg `leg`.
    pub fn count_m(&self, set: Split, leg: usize) -> usize {
        self.of(set).filter(|p| p.settled.m[leg].is_some()).count()
    }

    /// Number of poses of a split with a measured platform pose.
    pub fn count_pose(&self, set: Split) -> usize {
        self.of(set).filter(|p| p.settled.pose.is_some()).count()
    }
}

/// Pooled within-group standard deviation of x, y, phi over the groups with two rows or more.
fn pooled_noise(poses: &[StaticPose]) -> Option<[f64; 3]> {
    let mut ss = [0.0; 3];
    let mut dof = 0.0;
    for p in poses {
        if let Some(s) = p.settled.pose_std {
            let n = p.settled.pose_rows as f64 - 1.0;
            for k in 0..3 {
                ss[k] += s[k] * s[k] * n;
            }
            dof += n;
        }
    }
    (dof > 0.0).then(|| ss.map(|v| (v / dof).sqrt()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(text: &str) -> Recording {
        Recording::read(text.as_bytes(), "t.csv").unwrap()
    }

    fn visits(n: usize, reps: usize) -> String {
        let mut s = String::from("t_s,q1,q2,q3,x_mm,y_mm,phi_deg,pose_id,rep,settled\n");
        let mut t = 0.0;
        for p in 0..n {
            for r in 0..reps {
                for k in 0..3 {
                    t += 0.02;
                    s += &format!("{t:.2},{p},0,0,{},0,0,{p},{r},1\n", k as f64 * 0.1);
                }
                t += 0.02;
                s += &format!("{t:.2},{p},0,0,0,0,0,{p},{r},0\n");
            }
        }
        s
    }

    #[test]
    fn seeded_split_is_by_target_and_reproducible() {
        let r = rec(&visits(30, 3));
        let a = StaticData::from_recording(&r, "t.csv", 7, 1.0 / 3.0).unwrap();
        let b = StaticData::from_recording(&r, "t.csv", 7, 1.0 / 3.0).unwrap();
        assert_eq!(a.poses, b.poses);
        assert_eq!(a.poses.len(), 90);
        assert_eq!(a.of(Split::Test).count(), 30);
        // every repetition of a target on the same side
        for p in &a.poses {
            for o in &a.poses {
                if p.settled.pose_id == o.settled.pose_id {
                    assert_eq!(p.set, o.set);
                }
            }
        }
        let c = StaticData::from_recording(&r, "t.csv", 8, 1.0 / 3.0).unwrap();
        assert_ne!(a.poses, c.poses);
        // pooled noise of x over rows 0, 0.1, 0.2: sd 0.1
        let noise = a.row_noise.unwrap();
        assert!((noise[0] - 0.1).abs() < 1e-12, "{noise:?}");
    }

    #[test]
    fn a_partial_set_column_is_refused() {
        let r = rec("t_s,q1,q2,q3,pose_id,settled,set\n\
                     0.1,1,1,1,0,1,train\n0.2,1,1,1,0,0,\n0.3,2,2,2,1,1,\n");
        let e = StaticData::from_recording(&r, "t.csv", 1, 0.3).unwrap_err();
        assert!(e.to_string().contains("pose 1"), "{e}");
    }

    #[test]
    fn the_set_column_is_used_when_present() {
        let r = rec("t_s,q1,q2,q3,pose_id,settled,set\n\
                     0.1,1,1,1,0,1,train\n0.2,1,1,1,0,0,train\n0.3,2,2,2,1,1,test\n");
        let d = StaticData::from_recording(&r, "t.csv", 1, 0.3).unwrap();
        assert_eq!(d.split, SplitSource::Column);
        assert_eq!(d.poses[1].set, Split::Test);
    }
}
