//! The paper's two-step calibration of a whole robot from one recording.
//!
//! 1. Static poses and their split ([`StaticData`]).
//! 2. Step 1 for each of the 13 Table I functions and each leg ([`crate::step1`]); the function
//!    with the lowest test RMS of M_i over the three legs is selected (one function for all legs,
//!    as in the paper), unless one is forced.
//! 3. Step 2 with the selected legs fixed ([`crate::step2`]).
//! 4. The calibrated robot is checked (finite, valid, has its home pose) and compared with the
//!    starting robot on the training and the test poses.

use crate::data::{DataError, SplitSource, StaticData};
use crate::step1::{self, FreeGeometry, LegFit, LegObservation, Step1Error};
use crate::step2::{self, PoseErrors, PoseObservation, Step2Error, Step2Fit, Step2Params};
use pcr_kinematics::Robot;
use pcr_recording::{Recording, Split};
use pcr_robot::{RobotConfig, TendonMapKind};
use serde::Serialize;

/// Which parameter sets the two steps free.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ParameterSet {
    /// The paper's: step 1 [l_C, psi, k], step 2 [r_p, theta_p].
    Paper,
    /// Also the base points, tip extensions (step 1) and link lengths (step 2).
    Extended,
}

impl ParameterSet {
    fn step1(self) -> FreeGeometry {
        match self {
            ParameterSet::Paper => FreeGeometry::PAPER,
            ParameterSet::Extended => FreeGeometry::EXTENDED,
        }
    }
    fn step2(self) -> Step2Params {
        match self {
            ParameterSet::Paper => Step2Params::PAPER,
            ParameterSet::Extended => Step2Params::EXTENDED,
        }
    }
}

/// Settings of a calibration.
#[derive(Debug, Clone, Serialize)]
pub struct Options {
    /// Which parameters are freed.
    pub parameters: ParameterSet,
    /// Use this Table I function instead of selecting by test RMS.
    pub function: Option<TendonMapKind>,
    /// Weight of one degree of orientation error in step 2, mm (None: r_p pi / 180).
    pub phi_weight_mm_per_deg: Option<f64>,
    /// Seed of the random split (recordings without a `set` column).
    pub seed: u64,
    /// Fraction of targets held out by the random split.
    pub test_fraction: f64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            parameters: ParameterSet::Paper,
            function: None,
            phi_weight_mm_per_deg: None,
            seed: 1,
            test_fraction: 1.0 / 3.0,
        }
    }
}

/// Why a calibration failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalibError {
    /// The recording cannot be used.
    #[error(transparent)]
    Data(#[from] DataError),
    /// A leg could not be fitted with the forced function.
    #[error(transparent)]
    Step1(#[from] Step1Error),
    /// No function could be fitted to every leg.
    #[error("{origin}: no Table I function could be fitted to all three legs:\n{reasons}")]
    NoFunction {
        /// The file.
        origin: String,
        /// One line per failure.
        reasons: String,
    },
    /// Step 2 failed.
    #[error("{origin}: {source}")]
    Step2 {
        /// The file.
        origin: String,
        /// Why.
        source: Step2Error,
    },
    /// The calibrated robot is not usable.
    #[error("{origin}: the calibrated robot is not usable: {reason}")]
    Invalid {
        /// The file.
        origin: String,
        /// Why.
        reason: String,
    },
}

/// One row of Table I: a function fitted to the three legs.
#[derive(Debug, Clone, Serialize)]
pub struct TableRow {
    /// Table I number (1..13).
    pub index: usize,
    /// Family name as in robot files.
    pub name: &'static str,
    /// The paper's form.
    pub form: &'static str,
    /// The form as evaluated for every dl.
    pub extended_form: &'static str,
    /// Per-leg fits (absent where the fit failed).
    pub legs: Vec<LegFit>,
    /// RMS of |M^ - M| over the three legs' training points, mm.
    pub train_rms_mm: Option<f64>,
    /// RMS over the test points, mm.
    pub test_rms_mm: Option<f64>,
    /// Whether all three fits converged.
    pub converged: bool,
    /// Whether all three maps are monotonic over the data's range and invertible up to the
    /// robot's bending limit (else not selectable).
    pub monotonic: bool,
    /// Why a fit failed.
    pub error: Option<String>,
}

/// Model accuracy on a set of static poses.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ModelAccuracy {
    /// RMS |M^ - M| over legs and poses, mm.
    pub m_rms_mm: f64,
    /// Largest |M^ - M|, mm.
    pub m_max_mm: f64,
    /// Platform pose errors of the forward kinematics.
    pub pose: PoseErrors,
}

/// Accuracy on the training and the test poses.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SplitAccuracy {
    /// Training poses.
    pub train: ModelAccuracy,
    /// Test poses (`None` without any).
    pub test: Option<ModelAccuracy>,
}

/// What the data held.
#[derive(Debug, Clone, Serialize)]
pub struct DataSummary {
    /// The recording.
    pub file: String,
    /// Static poses (visits).
    pub poses: usize,
    /// Training poses.
    pub train: usize,
    /// Test poses.
    pub test: usize,
    /// How they were split.
    pub split: SplitSource,
    /// Capture noise of one row estimated from the settled rows (x mm, y mm, phi deg).
    pub row_noise: Option<[f64; 3]>,
}

/// The whole result (the JSON of `pcr calibrate`).
#[derive(Debug, Clone, Serialize)]
pub struct Calibration {
    /// The input.
    pub data: DataSummary,
    /// The settings.
    pub options: Options,
    /// Table I: every function.
    pub table1: Vec<TableRow>,
    /// The function used.
    pub selected: usize,
    /// Why it was used.
    pub selected_by: String,
    /// Step 1 of the selected function, per leg.
    pub step1: Vec<LegFit>,
    /// Step 2.
    pub step2: Step2Fit,
    /// The starting robot on the data.
    pub before: SplitAccuracy,
    /// The calibrated robot on the data.
    pub after: SplitAccuracy,
    /// Things the user should know (correlated parameters, parameters on bounds, ...).
    pub warnings: Vec<String>,
    /// The calibrated robot configuration.
    #[serde(skip)]
    pub robot: RobotConfig,
}

/// Observations of leg `i` in one split.
pub fn leg_observations(
    robot: &RobotConfig,
    data: &StaticData,
    i: usize,
    set: Split,
) -> Vec<LegObservation> {
    let mmps = robot.legs[i].actuation.mm_per_step();
    data.of(set)
        .filter_map(|p| {
            p.settled.m[i].map(|m| LegObservation {
                dl_mm: p.q()[i] * mmps,
                m,
            })
        })
        .collect()
}

/// Platform-pose observations of one split.
pub fn pose_observations(data: &StaticData, set: Split) -> Vec<PoseObservation> {
    data.of(set)
        .filter_map(|p| {
            p.settled
                .pose
                .map(|pose| PoseObservation { q: p.q(), pose })
        })
        .collect()
}

/// The model's accuracy (M_i and platform pose by forward kinematics) on one split of static
/// poses; `None` when the split has nothing measured or the robot has no home pose.
pub fn model_accuracy(robot: &RobotConfig, data: &StaticData, set: Split) -> Option<ModelAccuracy> {
    let model = Robot::new(robot).ok()?;
    let (mut ss, mut n, mut mx) = (0.0, 0usize, 0.0f64);
    for i in 0..3 {
        let obs = leg_observations(robot, data, i, set);
        if obs.is_empty() {
            continue;
        }
        let (rms, max) = step1::m_errors(&robot.legs[i], &obs);
        ss += rms * rms * obs.len() as f64;
        n += obs.len();
        mx = mx.max(max);
    }
    let poses = pose_observations(data, set);
    if n == 0 && poses.is_empty() {
        return None;
    }
    Some(ModelAccuracy {
        m_rms_mm: (ss / n.max(1) as f64).sqrt(),
        m_max_mm: mx,
        pose: step2::pose_errors(&model, &poses),
    })
}

fn split_accuracy(robot: &RobotConfig, data: &StaticData) -> SplitAccuracy {
    SplitAccuracy {
        train: model_accuracy(robot, data, Split::Train).unwrap_or(ModelAccuracy {
            m_rms_mm: 0.0,
            m_max_mm: 0.0,
            pose: PoseErrors::default(),
        }),
        test: model_accuracy(robot, data, Split::Test),
    }
}

/// Pooled RMS of several legs' fits (weighted by their point counts).
fn pooled(fits: &[LegFit], test: bool) -> Option<f64> {
    let (mut ss, mut n) = (0.0, 0usize);
    for f in fits {
        let (rms, k) = if test {
            (f.test_rms_mm?, f.n_test)
        } else {
            (f.train_rms_mm, f.n_train)
        };
        ss += rms * rms * k as f64;
        n += k;
    }
    (n > 0).then(|| (ss / n as f64).sqrt())
}

/// Calibrates `start` (the model the robot ran with) from a recording of static poses.
pub fn calibrate(
    start: &RobotConfig,
    rec: &Recording,
    origin: &str,
    opts: &Options,
) -> Result<Calibration, CalibError> {
    let data = StaticData::from_recording(rec, origin, opts.seed, opts.test_fraction)?;
    calibrate_data(start, &data, opts)
}

/// [`calibrate`] on static poses already read.
pub fn calibrate_data(
    start: &RobotConfig,
    data: &StaticData,
    opts: &Options,
) -> Result<Calibration, CalibError> {
    let origin = data.origin.clone();
    let mut warnings = Vec::new();
    // Enough measured joints and poses?
    for i in 0..3 {
        let have = data.count_m(Split::Train, i);
        if have == 0 {
            return Err(DataError::Missing {
                origin: origin.clone(),
                what: format!("a measured passive joint M{} in the training set", i + 1),
                columns: format!("m{0}x_mm, m{0}y_mm", i + 1),
            }
            .into());
        }
    }
    if data.count_pose(Split::Train) == 0 {
        return Err(DataError::Missing {
            origin: origin.clone(),
            what: "a measured platform pose in the training set".into(),
            columns: "x_mm, y_mm, phi_deg".into(),
        }
        .into());
    }
    let obs: [(Vec<LegObservation>, Vec<LegObservation>); 3] = std::array::from_fn(|i| {
        (
            leg_observations(start, data, i, Split::Train),
            leg_observations(start, data, i, Split::Test),
        )
    });
    let free = opts.parameters.step1();
    let kinds: Vec<TendonMapKind> = TendonMapKind::ALL.to_vec();
    let mut table1 = Vec::with_capacity(kinds.len());
    for kind in kinds {
        let mut legs = Vec::with_capacity(3);
        let mut error = None;
        for i in 0..3 {
            match step1::fit_leg(
                &format!("leg {}", i + 1),
                Some(i),
                &start.legs[i],
                free,
                kind,
                &obs[i].0,
                &obs[i].1,
            ) {
                Ok(f) => legs.push(f),
                Err(e) => {
                    error = Some(e.to_string());
                    break;
                }
            }
        }
        let complete = error.is_none();
        table1.push(TableRow {
            index: kind.table_index(),
            name: kind.name(),
            form: kind.paper_form(),
            extended_form: kind.extended_form(),
            train_rms_mm: complete.then(|| pooled(&legs, false)).flatten(),
            test_rms_mm: complete.then(|| pooled(&legs, true)).flatten(),
            converged: complete && legs.iter().all(|f| f.converged),
            monotonic: complete
                && legs.iter().all(|f| {
                    f.monotonic
                        && crate::step1::reaches_bending_limit(
                            &pcr_kinematics::TendonMap::from_spec(&f.config.tendon_map),
                            f.config.l_c_mm,
                            start.limits.bending_max_deg,
                        )
                }),
            legs,
            error,
        });
    }
    // Selection.
    let has_test = (0..3).all(|i| !obs[i].1.is_empty());
    let (selected, selected_by) = match opts.function {
        Some(k) => {
            let row = &table1[k.table_index() - 1];
            if let Some(e) = &row.error {
                return Err(CalibError::NoFunction {
                    origin,
                    reasons: format!("  {e}"),
                });
            }
            if let Some(f) = row.legs.iter().find(|f| !f.converged) {
                return Err(CalibError::NoFunction {
                    origin,
                    reasons: format!(
                        "  leg {}: function {} ({}): the fit did not converge ({} after {} evaluations)",
                        f.leg.map_or(0, |i| i + 1),
                        row.index,
                        row.name,
                        f.status,
                        f.evaluations
                    ),
                });
            }
            (k.table_index(), "forced by the user".to_string())
        }
        None => {
            let usable = table1
                .iter()
                .filter(|r| r.error.is_none() && r.converged && r.monotonic);
            let best = if has_test {
                usable
                    .filter_map(|r| Some((r.index, r.test_rms_mm?)))
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .map(|(i, v)| (i, format!("lowest test RMS of M_i ({v:.3} mm)")))
            } else {
                warnings.push(
                    "no test poses: the function was selected by the Akaike information \
                     criterion on the training poses, not by held-out error"
                        .into(),
                );
                usable
                    .map(|r| {
                        let n: usize = r.legs.iter().map(|f| 2 * f.n_train).sum();
                        let k: usize = r.legs.iter().map(|f| f.params.len()).sum();
                        let rss = r.train_rms_mm.unwrap_or(f64::INFINITY).powi(2) * n as f64 / 2.0;
                        let aic = n as f64 * (rss / n as f64).ln() + 2.0 * k as f64;
                        (r.index, aic)
                    })
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .map(|(i, v)| (i, format!("lowest AIC on the training poses ({v:.1})")))
            };
            match best {
                Some(b) => b,
                None => {
                    let reasons = table1
                        .iter()
                        .map(|r| match &r.error {
                            Some(e) => format!("  {e}"),
                            None if !r.converged => format!(
                                "  function {} ({}): the fit did not converge",
                                r.index, r.name
                            ),
                            None => format!(
                                "  function {} ({}): the fitted map turns back inside the data's range or cannot be inverted up to the bending limit",
                                r.index, r.name
                            ),
                        })
                        .collect::<Vec<_>>()
                        .join("\n");
                    return Err(CalibError::NoFunction { origin, reasons });
                }
            }
        }
    };
    let step1_fits = table1[selected - 1].legs.clone();
    let mut robot = start.clone();
    for f in &step1_fits {
        let i = f.leg.unwrap_or(0);
        robot.legs[i] = f.config.clone();
        if !f.converged {
            warnings.push(format!(
                "leg {}: step 1 stopped before converging ({})",
                i + 1,
                f.status
            ));
        }
        note_params(
            &mut warnings,
            &format!("leg {}", i + 1),
            &f.params,
            &f.correlated,
        );
    }
    // Step 2.
    let w = opts
        .phi_weight_mm_per_deg
        .unwrap_or_else(|| step2::default_phi_weight(start));
    let train_poses = pose_observations(data, Split::Train);
    let s2 = step2::fit_platform(&robot, opts.parameters.step2(), &train_poses, w).map_err(
        |source| CalibError::Step2 {
            origin: origin.clone(),
            source,
        },
    )?;
    if !s2.converged {
        warnings.push(format!("step 2 stopped before converging ({})", s2.status));
    }
    note_params(&mut warnings, "platform", &s2.params, &s2.correlated);
    let mut robot = s2.config.clone();
    robot.name = format!("{}, calibrated from {}", start.name, data.origin);
    check_usable(&robot, &origin)?;
    let before = split_accuracy(start, data);
    let after = split_accuracy(&robot, data);
    Ok(Calibration {
        data: DataSummary {
            file: data.origin.clone(),
            poses: data.poses.len(),
            train: data.of(Split::Train).count(),
            test: data.of(Split::Test).count(),
            split: data.split.clone(),
            row_noise: data.row_noise,
        },
        options: opts.clone(),
        table1,
        selected,
        selected_by,
        step1: step1_fits,
        step2: s2,
        before,
        after,
        warnings,
        robot,
    })
}

fn note_params(
    warnings: &mut Vec<String>,
    what: &str,
    params: &[step1::Param],
    correlated: &[step1::Correlated],
) {
    for p in params {
        if p.at_bound {
            warnings.push(format!(
                "{what}: {} = {} {} sits on its bound: the data pull it beyond the allowed range",
                p.name, p.value, p.unit
            ));
        }
    }
    for c in correlated {
        warnings.push(format!(
            "{what}: {} and {} are strongly correlated (rho = {:+.3}): the data hardly separate them",
            c.a, c.b, c.rho
        ));
    }
}

/// A calibrated robot must be finite, valid and have its home pose.
fn check_usable(robot: &RobotConfig, origin: &str) -> Result<(), CalibError> {
    let invalid = |reason: String| CalibError::Invalid {
        origin: origin.into(),
        reason,
    };
    for (i, l) in robot.legs.iter().enumerate() {
        let v = [
            l.r_base_mm,
            l.beta_deg,
            l.psi_deg,
            l.l_c_mm,
            l.l_ce_mm,
            l.l_st_mm,
            l.r_p_mm,
            l.theta_p_deg,
        ];
        if v.iter().chain(&l.tendon_map.coeffs).any(|x| !x.is_finite()) {
            return Err(invalid(format!("leg {} has a non-finite parameter", i + 1)));
        }
    }
    robot
        .validate("calibrated robot")
        .map_err(|e| invalid(e.to_string()))?;
    Robot::new(robot).map_err(|e| invalid(e.to_string()))?;
    Ok(())
}

/// The calibrated robot as a TOML file with the shape of `configs/robot.toml`, with a header
/// saying where it came from.
pub fn robot_file(cal: &Calibration, created: &str) -> String {
    let best = &cal.table1[cal.selected - 1];
    let mut s = format!(
        "# Calibrated robot written by `pcr calibrate` ({created}).\n\
         # Data: {} ({} static poses: {} train, {} test).\n\
         # Tendon map: Table I function {} ({}), {}.\n\
         # Parameters freed: {:?}. Test RMS of M_i {} mm; platform position RMS on the test set {} mm\n\
         # (before: {} mm). Use it as `robot = \"<this file>\"` in a supervisor configuration.\n",
        cal.data.file,
        cal.data.poses,
        cal.data.train,
        cal.data.test,
        best.index,
        best.name,
        cal.selected_by,
        cal.options.parameters,
        fmt_opt(best.test_rms_mm),
        fmt_opt(cal.after.test.map(|a| a.pose.position_rms_mm)),
        fmt_opt(cal.before.test.map(|a| a.pose.position_rms_mm)),
    );
    s.push_str(&cal.robot.to_toml_string());
    s
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or("-".into(), |v| format!("{v:.3}"))
}
