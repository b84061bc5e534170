//! The residual analysis's set-up, as `pcr residuals` and `pcr.residuals` do it: the options
//! checked, the recordings read as series, the robot calibrated first on the static poses of
//! the first recording that has some (unless told not to), and the held-out blocks chosen
//! (every third block of the data, or the holdout recordings whole). The attribution itself is
//! [`pcr_residuals::attribute`] on the result.

use crate::error::OfflineError;
use pcr_calibration::calibrate::{self, Calibration, Options as CalOptions};
use pcr_calibration::StaticData;
use pcr_recording::Recording;
use pcr_residuals::{Blocks, Series};
use pcr_robot::RobotConfig;

/// Checks the attribution's settings: block length, significance level, candidate names.
pub fn check_options(block_s: f64, alpha: f64, candidates: &[String]) -> Result<(), OfflineError> {
    if !(block_s > 0.0 && block_s.is_finite()) {
        return Err(OfflineError::invalid(format!(
            "block length {block_s}: must be a positive number of seconds"
        )));
    }
    if !(alpha > 0.0 && alpha < 1.0) {
        return Err(OfflineError::invalid(format!(
            "significance level {alpha}: must be in (0, 1)"
        )));
    }
    for c in candidates {
        if pcr_residuals::effects::named(c).is_none() {
            return Err(OfflineError::invalid(format!(
                "unknown effect `{c}` (known: {})",
                pcr_residuals::effects::names().join(", ")
            )));
        }
    }
    Ok(())
}

/// A recording with the name it is reported by.
pub type Named = (Recording, String);

/// Reads recordings from files, each on its own thread (a 44k-row calibration recording takes
/// some 50 ms, its holdout 20 ms: the analysis read them one after the other on one core); the
/// first file in `paths` that cannot be read is the error.
pub fn read_all(paths: &[std::path::PathBuf]) -> Result<Vec<Named>, OfflineError> {
    std::thread::scope(|s| {
        let reading: Vec<_> = paths
            .iter()
            .map(|p| s.spawn(move || Recording::read_path(p)))
            .collect();
        reading
            .into_iter()
            .zip(paths)
            .map(|(r, p)| {
                let rec = r.join().unwrap_or_else(|e| std::panic::resume_unwind(e))?;
                Ok((rec, p.display().to_string()))
            })
            .collect()
    })
}

/// The analysis ready to attribute.
#[derive(Debug)]
pub struct Prepared {
    /// The robot the attribution starts from (calibrated, or the file as it is).
    pub robot: RobotConfig,
    /// The calibration done first, with the recording it was done on.
    pub calibration: Option<(String, Calibration)>,
    /// Every series: the data's, then the holdout's.
    pub series: Vec<Series>,
    /// The held-out blocks.
    pub blocks: Blocks,
    /// The static poses of the calibration done first, for the analysis to make it again from
    /// the drawing with its effects in the model (`Options::recalibration`).
    pub recalibration: Option<std::sync::Arc<pcr_residuals::options::Recalibration>>,
}

/// Reads the series of `data` and `holdout`, calibrates `start` on the static poses of the
/// first data recording that has some (not with `no_calibrate`; never on the holdout), and
/// cuts the blocks of about `block_s`. `say` reports what is done (the calibration's summary,
/// or that there were no static poses).
pub fn prepare(
    start: &RobotConfig,
    data: &[Named],
    holdout: &[Named],
    no_calibrate: bool,
    block_s: f64,
    say: &dyn Fn(&str),
) -> Result<Prepared, OfflineError> {
    let series = |v: &[Named]| -> Result<Vec<Series>, OfflineError> {
        v.iter()
            .map(|(r, o)| Series::from_recording(r, o).map_err(OfflineError::from))
            .collect()
    };
    let train = series(data)?;
    let test = series(holdout)?;
    let mut calibration = None;
    let mut recalibration = None;
    let robot = if no_calibrate {
        start.clone()
    } else {
        let with_statics = data
            .iter()
            .zip(&train)
            .enumerate()
            .find(|(_, ((r, _), _))| r.rows.iter().any(|x| x.settled == Some(true)));
        match with_statics {
            Some((index, ((rec, _), s))) => {
                let sd = StaticData::from_recording(rec, &s.origin, 1, 1.0 / 3.0)?;
                let cal =
                    calibrate::calibrate_data(start, &sd, &CalOptions::default()).map_err(|e| {
                        OfflineError::from(e).context(
                            "calibration before the residual analysis (--no-calibrate skips it)",
                        )
                    })?;
                say(&format!(
                    "calibrated on {}: function {}, platform position RMS on its test poses {:.3} mm",
                    s.origin,
                    cal.selected,
                    cal.after.test.map_or(f64::NAN, |t| t.pose.position_rms_mm)
                ));
                let robot = cal.robot.clone();
                calibration = Some((s.origin.clone(), cal));
                recalibration = Some(std::sync::Arc::new(pcr_residuals::options::Recalibration {
                    data: sd,
                    series: index,
                    options: CalOptions::default(),
                }));
                robot
            }
            None => {
                say("no static poses in --data: the robot file is used as it is");
                start.clone()
            }
        }
    };
    let (series, blocks) = if test.is_empty() {
        let b = Blocks::in_time(&train, block_s, 3);
        (train, b)
    } else {
        let b = Blocks::by_series(&train, &test, block_s);
        (train.into_iter().chain(test).collect::<Vec<_>>(), b)
    };
    Ok(Prepared {
        robot,
        calibration,
        series,
        blocks,
        recalibration,
    })
}

/// The extended robot file of an analysis, with a header naming the effects.
pub fn extended_file(res: &pcr_residuals::Attribution, created: &str) -> String {
    format!(
        "# Extended robot written by `pcr residuals` ({created}): effects {}.\n{}",
        if res.effects.is_empty() {
            "none".to_string()
        } else {
            res.effects
                .iter()
                .map(|e| e.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        },
        res.robot.to_toml_string()
    )
}
