//! A recording as a time series for the residual analysis: commanded motors, measured pose and
//! joints, planned pose, the static-pose grouping, and the held-out blocks.

use pcr_recording::{settled_poses, Recording};
use std::collections::BTreeMap;

/// One row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Time since the start of its recording, s.
    pub t_s: f64,
    /// Commanded motor positions, steps.
    pub q: [f64; 3],
    /// Measured pose (x mm, y mm, phi rad), if measured.
    pub pose: Option<[f64; 3]>,
    /// Planned pose (x mm, y mm, phi rad), if recorded.
    pub planned: Option<[f64; 3]>,
    /// Settled (static measurement) row.
    pub settled: bool,
    /// Static target, if any.
    pub pose_id: Option<u64>,
}

/// One recording.
#[derive(Debug, Clone)]
pub struct Series {
    /// The file.
    pub origin: String,
    /// Rows in time order.
    pub samples: Vec<Sample>,
    /// Pooled within-visit standard deviation of x, y (mm) and phi (rad) of the settled rows:
    /// the capture noise of one row.
    pub row_noise: Option<[f64; 3]>,
    /// The control period (median spacing of the rows), s.
    pub period_s: f64,
    /// The command delay the file declares (`# command_delay_s = D`, 0 when absent), s: the
    /// pose measured at t answers the command of row time t - D (`shared/spec/recording.md`,
    /// "Timing").
    pub declared_delay_s: f64,
    /// Whether the file declares it.
    pub delay_declared: bool,
    /// The delay the base model uses, s: the declared one, unless the alignment found the data
    /// answer their commands sooner than declared (a timing declaration error), in which case
    /// the delay the data show.
    pub delay_s: f64,
}

/// Why a recording cannot be analysed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SeriesError {
    /// The timing declaration cannot be read.
    #[error("{origin}: {message}")]
    Timing {
        /// The file.
        origin: String,
        /// What is wrong.
        message: String,
    },
    /// No row has a measured pose.
    #[error("{origin}: no row has a measured platform pose (columns x_mm, y_mm, phi_deg): there is no residual to analyse")]
    NoPose {
        /// The file.
        origin: String,
    },
}

impl Series {
    /// Reads a recording.
    pub fn from_recording(rec: &Recording, origin: &str) -> Result<Series, SeriesError> {
        let declared_delay_s = rec.command_delay_s().map_err(|e| SeriesError::Timing {
            origin: origin.into(),
            message: e.to_string(),
        })?;
        let samples: Vec<Sample> = rec
            .rows
            .iter()
            .map(|r| Sample {
                t_s: r.t_s,
                q: r.q.map(f64::from),
                pose: r.measured_pose().map(|p| [p[0], p[1], p[2].to_radians()]),
                planned: match r.planned {
                    [Some(x), Some(y), Some(p)] => Some([x, y, p.to_radians()]),
                    _ => None,
                },
                settled: r.settled == Some(true),
                pose_id: r.pose_id,
            })
            .collect();
        if !samples.iter().any(|s| s.pose.is_some()) {
            return Err(SeriesError::NoPose {
                origin: origin.into(),
            });
        }
        let row_noise = settled_poses(rec, origin).ok().and_then(|groups| {
            let (mut ss, mut dof) = ([0.0; 3], 0.0);
            for g in groups {
                if let Some(s) = g.pose_std {
                    let n = g.pose_rows as f64 - 1.0;
                    for k in 0..3 {
                        ss[k] += s[k] * s[k] * n;
                    }
                    dof += n;
                }
            }
            (dof > 0.0).then(|| {
                let s = ss.map(|v| (v / dof).sqrt());
                [s[0], s[1], s[2].to_radians()]
            })
        });
        let mut dts: Vec<f64> = samples
            .windows(2)
            .map(|w| w[1].t_s - w[0].t_s)
            .filter(|d| *d > 0.0)
            .collect();
        dts.sort_by(f64::total_cmp);
        let period_s = dts.get(dts.len() / 2).copied().unwrap_or(0.02);
        Ok(Series {
            origin: origin.into(),
            samples,
            row_noise,
            period_s,
            declared_delay_s,
            delay_declared: rec.declares_command_delay(),
            delay_s: declared_delay_s,
        })
    }

    /// Rows with a measured pose.
    pub fn measured(&self) -> impl Iterator<Item = (usize, &Sample)> {
        self.samples
            .iter()
            .enumerate()
            .filter(|(_, s)| s.pose.is_some())
    }
}

/// Held-out blocks: contiguous stretches of time (so that history effects do not leak between
/// the fit and the score), every `every`-th block held out.
#[derive(Debug, Clone, PartialEq)]
pub struct Blocks {
    /// Block index of every row of every series (`series[s][k]`).
    pub block: Vec<Vec<usize>>,
    /// Whether a block is held out.
    pub held_out: Vec<bool>,
}

impl Blocks {
    /// Blocks of about `block_s` seconds; blocks never split a static visit; every `every`-th
    /// block (starting with the second) is held out.
    pub fn in_time(series: &[Series], block_s: f64, every: usize) -> Blocks {
        let mut block = Vec::with_capacity(series.len());
        let mut n = 0usize;
        for s in series {
            let mut b = Vec::with_capacity(s.samples.len());
            let mut start = s.samples.first().map_or(0.0, |x| x.t_s);
            for (k, x) in s.samples.iter().enumerate() {
                let in_visit = x.settled && k > 0 && s.samples[k - 1].settled;
                if x.t_s - start >= block_s && !in_visit {
                    n += 1;
                    start = x.t_s;
                }
                b.push(n);
            }
            n += 1;
            block.push(b);
        }
        let held_out = (0..n)
            .map(|b| every > 0 && b % every == every - 1)
            .collect();
        Blocks { block, held_out }
    }

    /// Everything in `train` is fitted, everything in `test` held out (the `--holdout` case):
    /// one block per static visit or per `block_s` of each series.
    pub fn by_series(train: &[Series], test: &[Series], block_s: f64) -> Blocks {
        let all: Vec<Series> = train.iter().chain(test).cloned().collect();
        let mut b = Blocks::in_time(&all, block_s, 0);
        let first_test_block = b.block.get(train.len()).and_then(|v| v.first().copied());
        for (k, h) in b.held_out.iter_mut().enumerate() {
            *h = first_test_block.is_some_and(|f| k >= f);
        }
        b
    }

    /// Number of blocks.
    pub fn len(&self) -> usize {
        self.held_out.len()
    }

    /// Whether there are no blocks.
    pub fn is_empty(&self) -> bool {
        self.held_out.is_empty()
    }
}

/// Static visits (`pose_id` groups of settled rows) per series: row indices of each.
pub fn visits(series: &Series) -> BTreeMap<(u64, usize), Vec<usize>> {
    let mut out: BTreeMap<(u64, usize), Vec<usize>> = BTreeMap::new();
    let mut visit = 0usize;
    for (k, s) in series.samples.iter().enumerate() {
        if s.settled {
            if k == 0 || !series.samples[k - 1].settled {
                visit += 1;
            }
            out.entry((s.pose_id.unwrap_or(u64::MAX), visit))
                .or_default()
                .push(k);
        }
    }
    out
}
