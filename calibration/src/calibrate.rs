//! The paper's two-step calibration of a whole robot from one recording.
//!
//! 1. Static poses and their split ([`StaticData`]).
//! 2. Step 1 for each of the 13 Table I functions, in both readings (symmetric: the odd
//!    extension; asymmetric: coefficients per bending direction), and each leg
//!    ([`crate::step1`]). Each leg takes the reading with its lower test RMS of M_i; the function
//!    with the lowest test RMS of M_i over the three legs is selected (one function for all legs,
//!    as in the paper), unless one is forced. [`Readings`] restricts the readings.
//! 3. Step 2 with the selected legs fixed ([`crate::step2`]).
//! 4. With [`Method::Joint`] (the default), every parameter of both steps refined together on
//!    the M_i and the platform poses ([`crate::joint`]); [`Method::Paper`] stops after step 2.
//! 5. The calibrated robot is checked (finite, valid, has its home pose) and compared with the
//!    starting robot on the training and the test poses, beside the paper's two-step robot.

use crate::data::{DataError, SplitSource, StaticData};
use crate::diagnosis::{diagnose, Diagnosis};
use crate::joint::{self, JointFit, JointObservations, JointParams};
use crate::step1::{self, FreeGeometry, LegFit, LegObservation, Step1Error};
use crate::step2::{self, PoseErrors, PoseObservation, Step2Error, Step2Fit, Step2Params};
use pcr_kinematics::Robot;
use pcr_recording::{Recording, Split};
use pcr_robot::effects::FrameCorrection;
use pcr_robot::{MapForm, MapReading, RobotConfig, TendonMapKind};
use rayon::prelude::*;
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

/// How the calibrated parameters are fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// The paper's two steps, then every parameter of both refined jointly on the M_i and the
    /// platform poses ([`crate::joint`]).
    #[default]
    Joint,
    /// The paper's two steps alone (step 1: each leg on its M_i; step 2: the platform joints).
    Paper,
}

/// Which readings of the Table I forms are fitted, and how one is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Readings {
    /// Both readings; each leg takes the one with its lower held-out error of M_i (a lab cannot
    /// know in advance whether its legs bend alike both ways).
    #[default]
    PerLeg,
    /// The symmetric reading only (the odd extension: the paper's forms as before).
    Symmetric,
    /// The asymmetric reading only (coefficients per bending direction).
    Asymmetric,
}

impl Readings {
    /// The readings fitted.
    pub fn fitted(self) -> &'static [MapReading] {
        match self {
            Readings::PerLeg => &MapReading::ALL,
            Readings::Symmetric => &[MapReading::Symmetric],
            Readings::Asymmetric => &[MapReading::Asymmetric],
        }
    }
}

/// Settings of a calibration.
#[derive(Debug, Clone, Serialize)]
pub struct Options {
    /// Which parameters are freed.
    pub parameters: ParameterSet,
    /// The paper's two steps alone, or followed by the joint refinement.
    pub method: Method,
    /// Use this Table I function instead of selecting by test RMS.
    pub function: Option<TendonMapKind>,
    /// Which readings of the forms are fitted and chosen from.
    pub reading: Readings,
    /// Weight of one degree of orientation error in step 2, mm (None: r_p pi / 180).
    pub phi_weight_mm_per_deg: Option<f64>,
    /// Seed of the random split (recordings without a `set` column).
    pub seed: u64,
    /// Fraction of targets held out by the random split.
    pub test_fraction: f64,
    /// Fit a correction of the capture frame with the robot in the joint refinement
    /// ([`crate::joint::JointParams::frame`]): for a model that holds a frame error, whose
    /// registration the static poses pin better than the motion does.
    pub frame: bool,
    /// Fit every Table I function (the table a report shows) even when `function` forces one.
    /// `false` fits the forced function alone, a thirteenth of step 1's work; the other rows
    /// then say they were not fitted. The residual analysis' calibrations from the drawing
    /// read only the forced function's result, and made the whole table on every one of them
    /// (a tenth of the analysis' time on a tendon cross-coupling of 7 %).
    pub every_function: bool,
    /// Diagnose the calibrated robot on the static poses ([`Calibration::diagnosis`]). The
    /// residual analysis' calibrations from the drawing read the robot alone, and skip it.
    pub diagnose: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            parameters: ParameterSet::Paper,
            method: Method::Joint,
            function: None,
            reading: Readings::PerLeg,
            phi_weight_mm_per_deg: None,
            seed: 1,
            test_fraction: 1.0 / 3.0,
            frame: false,
            every_function: true,
            diagnose: true,
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

/// One function in one reading fitted to the three legs.
#[derive(Debug, Clone, Serialize)]
pub struct ReadingFit {
    /// The reading.
    pub reading: MapReading,
    /// Per-leg fits, leg order (absent where the fit failed: see `errors`).
    pub legs: Vec<LegFit>,
    /// Why a leg could not be fitted (one line each, naming the leg).
    pub errors: Vec<String>,
    /// RMS of |M^ - M| over the three legs' training points, mm (all three legs fitted).
    pub train_rms_mm: Option<f64>,
    /// RMS over the test points, mm.
    pub test_rms_mm: Option<f64>,
}

/// One row of Table I: a function fitted to the three legs in each reading, and the reading
/// each leg would take.
#[derive(Debug, Clone, Serialize)]
pub struct TableRow {
    /// Table I number (1..13).
    pub index: usize,
    /// Family name as in robot files.
    pub name: &'static str,
    /// The paper's form.
    pub form: &'static str,
    /// The form as evaluated for every dl in the symmetric reading.
    pub extended_form: &'static str,
    /// The fits per reading ([`Options::reading`] decides which are made).
    pub readings: Vec<ReadingFit>,
    /// The reading each leg takes in this row: among its selectable fits, the one with the
    /// lower test RMS of M_i (AIC without test points).
    pub chosen: Vec<MapReading>,
    /// RMS of |M^ - M| of the chosen fits over the three legs' training points, mm.
    pub train_rms_mm: Option<f64>,
    /// RMS of the chosen fits over the test points, mm.
    pub test_rms_mm: Option<f64>,
    /// Whether every chosen fit converged.
    pub converged: bool,
    /// Whether every leg has a selectable fit: converged, and a map monotonic over the data's
    /// range and invertible up to the robot's bending limit.
    pub monotonic: bool,
    /// Why the row cannot be used (a leg without any selectable fit).
    pub error: Option<String>,
}

impl TableRow {
    /// The chosen fit of each leg (leg order; fewer than three when a leg has none).
    pub fn chosen_legs(&self) -> Vec<LegFit> {
        (0..3)
            .filter_map(|i| {
                let reading = *self.chosen.get(i)?;
                self.fit(reading, i).cloned()
            })
            .collect()
    }

    /// The fit of leg `i` (0-based) in `reading`, if it was made and succeeded.
    pub fn fit(&self, reading: MapReading, i: usize) -> Option<&LegFit> {
        self.readings
            .iter()
            .find(|r| r.reading == reading)?
            .legs
            .iter()
            .find(|f| f.leg == Some(i))
    }

    /// The fits of one reading.
    pub fn reading(&self, reading: MapReading) -> Option<&ReadingFit> {
        self.readings.iter().find(|r| r.reading == reading)
    }

    /// The chosen readings as text: `symmetric` when every leg takes it, else one per leg.
    pub fn chosen_text(&self) -> String {
        match self.chosen.first() {
            Some(r) if self.chosen.iter().all(|c| c == r) => r.to_string(),
            _ => self
                .chosen
                .iter()
                .enumerate()
                .map(|(i, r)| format!("leg {}: {r}", i + 1))
                .collect::<Vec<_>>()
                .join(", "),
        }
    }
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
    /// Settled rows left out because their command changed inside a visit
    /// (`pcr_recording::SettledPose::moved_rows`).
    pub moved_rows: usize,
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
    /// The reading of each leg's map.
    pub selected_readings: Vec<MapReading>,
    /// Why it was used.
    pub selected_by: String,
    /// Step 1 of the selected function, per leg.
    pub step1: Vec<LegFit>,
    /// Step 2.
    pub step2: Step2Fit,
    /// The paper's two steps (the robot of step 2) on the data.
    pub paper: SplitAccuracy,
    /// The joint refinement (absent with [`Method::Paper`] or when it failed: see `warnings`).
    pub joint: Option<JointResult>,
    /// Which result is the calibrated robot.
    pub used: Method,
    /// The starting robot on the data.
    pub before: SplitAccuracy,
    /// The calibrated robot on the data (the joint result's, or the paper's two steps').
    pub after: SplitAccuracy,
    /// Things the user should know (correlated parameters, parameters on bounds, ...).
    pub warnings: Vec<String>,
    /// Why the held-out error stays far above the capture noise, when it does
    /// ([`crate::diagnosis`]).
    pub diagnosis: Option<Diagnosis>,
    /// The robot of the paper's two steps.
    #[serde(skip)]
    pub paper_robot: RobotConfig,
    /// The calibrated robot configuration.
    #[serde(skip)]
    pub robot: RobotConfig,
    /// The capture-frame correction fitted with it ([`Options::frame`]), when the joint result
    /// is used.
    pub frame: Option<FrameCorrection>,
}

/// The joint refinement with the refined robot's accuracy.
#[derive(Debug, Clone, Serialize)]
pub struct JointResult {
    /// The fit: parameters with their joint uncertainties.
    pub fit: JointFit,
    /// The refined robot on the data.
    pub accuracy: SplitAccuracy,
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
///
/// The outline: check the data, fit Table I (step 1 for every function and leg), select the
/// function, fit the platform (step 2), then, with [`Method::Joint`], refine every parameter
/// jointly ([`crate::joint`]); compare every model on the training and the test poses.
pub fn calibrate_data(
    start: &RobotConfig,
    data: &StaticData,
    opts: &Options,
) -> Result<Calibration, CalibError> {
    check_enough_data(data)?;
    let origin = data.origin.clone();
    let mut warnings = Vec::new();
    note_moved_rows(data, &mut warnings);
    let obs: LegSets = std::array::from_fn(|i| {
        (
            leg_observations(start, data, i, Split::Train),
            leg_observations(start, data, i, Split::Test),
        )
    });
    let has_test = obs.iter().all(|o| !o.1.is_empty());
    let travel = leg_travels(start, data);
    let only = opts.function.filter(|_| !opts.every_function);
    let table1 = table_one(
        start,
        &obs,
        &travel,
        opts.parameters.step1(),
        opts.reading,
        has_test,
        only,
    );
    let (selected, selected_by) =
        select_function(&table1, opts.function, has_test, &origin, &mut warnings)?;
    let step1_fits = table1[selected - 1].chosen_legs();
    let selected_readings = table1[selected - 1].chosen.clone();
    let legs_robot = apply_step1(start, &step1_fits, &mut warnings);
    let w = opts
        .phi_weight_mm_per_deg
        .unwrap_or_else(|| step2::default_phi_weight(start));
    let train_poses = pose_observations(data, Split::Train);
    let s2 = run_step2(&legs_robot, opts.parameters, &train_poses, w, &origin)?;
    if !s2.converged {
        warnings.push(format!("step 2 stopped before converging ({})", s2.status));
    }
    note_params(&mut warnings, "platform", &s2.params);
    let mut paper_robot = s2.config.clone();
    paper_robot.name = format!("{}, calibrated from {}", start.name, data.origin);
    check_usable(&paper_robot, &origin)?;
    let paper = split_accuracy(&paper_robot, data);
    let joint = match opts.method {
        Method::Paper => None,
        Method::Joint => {
            let free = JointParams {
                legs: opts.parameters.step1(),
                platform: opts.parameters.step2(),
                forms: std::array::from_fn(|i| paper_robot.legs[i].tendon_map.form()),
                frame: opts.frame,
            };
            let train: [Vec<LegObservation>; 3] = std::array::from_fn(|i| obs[i].0.clone());
            let joint_obs = JointObservations {
                legs: &train,
                poses: &train_poses,
            };
            refine_jointly(start, &paper_robot, free, joint_obs, w, data, &mut warnings)
        }
    };
    let used = joint_usable(joint.as_ref(), &travel, &origin, &obs, &mut warnings);
    let (robot, after, frame) = match (used, &joint) {
        (Method::Joint, Some(j)) => (j.fit.config.clone(), j.accuracy, j.fit.frame.clone()),
        _ => (paper_robot.clone(), paper, None),
    };
    compare_with_paper(joint.as_ref(), &paper, &mut warnings);
    let diagnosis = if opts.diagnose {
        diagnose(&robot, data)
    } else {
        None
    };
    Ok(Calibration {
        data: summary(data),
        options: opts.clone(),
        table1,
        selected,
        selected_readings,
        selected_by,
        step1: step1_fits,
        step2: s2,
        paper,
        joint,
        used,
        before: split_accuracy(start, data),
        after,
        warnings,
        diagnosis,
        paper_robot,
        robot,
        frame,
    })
}

/// The static poses with their measurements (platform pose and M_i) taken through the frame
/// correction `f`.
pub fn framed(data: &StaticData, f: &FrameCorrection) -> StaticData {
    let mut out = data.clone();
    for p in &mut out.poses {
        if let Some(pose) = &mut p.settled.pose {
            let c = f.apply([pose[0], pose[1], pose[2].to_radians()]);
            *pose = [c[0], c[1], c[2].to_degrees()];
        }
        for m in p.settled.m.iter_mut().flatten() {
            let c = f.apply([m[0], m[1], 0.0]);
            *m = [c[0], c[1]];
        }
    }
    out
}

/// Training and test observations of the three legs.
type LegSets = [(Vec<LegObservation>, Vec<LegObservation>); 3];

/// Every leg needs a measured M_i, and the platform a measured pose, in the training set.
fn check_enough_data(data: &StaticData) -> Result<(), CalibError> {
    for i in 0..3 {
        if data.count_m(Split::Train, i) == 0 {
            return Err(DataError::Missing {
                origin: data.origin.clone(),
                what: format!("a measured passive joint M{} in the training set", i + 1),
                columns: format!("m{0}x_mm, m{0}y_mm", i + 1),
            }
            .into());
        }
    }
    if data.count_pose(Split::Train) == 0 {
        return Err(DataError::Missing {
            origin: data.origin.clone(),
            what: "a measured platform pose in the training set".into(),
            columns: "x_mm, y_mm, phi_deg".into(),
        }
        .into());
    }
    Ok(())
}

fn summary(data: &StaticData) -> DataSummary {
    DataSummary {
        file: data.origin.clone(),
        poses: data.poses.len(),
        train: data.of(Split::Train).count(),
        test: data.of(Split::Test).count(),
        split: data.split.clone(),
        row_noise: data.row_noise,
        moved_rows: moved_rows(data),
    }
}

/// Settled rows left out of the static poses because their command changed inside a visit.
fn moved_rows(data: &StaticData) -> usize {
    data.poses.iter().map(|p| p.settled.moved_rows).sum()
}

fn note_moved_rows(data: &StaticData, warnings: &mut Vec<String>) {
    let n = moved_rows(data);
    if n > 0 {
        let visits = data
            .poses
            .iter()
            .filter(|p| p.settled.moved_rows > 0)
            .count();
        warnings.push(format!(
            "{}: {n} settled rows in {visits} visits have a command other than the one their visit held longest; they are left out (a robot is not at rest at a command it has just been given or is still reaching)",
            data.origin
        ));
    }
}

/// The curvature range (1/mm) each leg's map must invert: the travel the starting robot's
/// workspace asks of the leg at the orientations of the recording's static poses (the smallest,
/// zero and the largest, to the degree; `pcr_kinematics::workspace::leg_travel`, a 4 mm grid),
/// or the bending limit where no pose of that workspace is feasible.
pub fn leg_travels(start: &RobotConfig, data: &StaticData) -> [[f64; 2]; 3] {
    let limit = |i: usize| {
        let k = start.limits.bending_max_deg.to_radians() / start.legs[i].l_c_mm;
        [-k, k]
    };
    let (lo, hi) = data
        .poses
        .iter()
        .filter_map(|p| p.settled.pose.map(|x| x[2].round()))
        .fold((0.0f64, 0.0f64), |a, p| (a.0.min(p), a.1.max(p)));
    let mut orientations = vec![lo.to_radians(), 0.0, hi.to_radians()];
    orientations.dedup();
    // The residual analysis calibrates again from the same drawing many times over, its
    // static poses at the same orientations to the degree: the last few answers are kept.
    type Kept = Vec<(RobotConfig, Vec<f64>, [[f64; 2]; 3])>;
    static KEPT: std::sync::Mutex<Kept> = std::sync::Mutex::new(Vec::new());
    let kept = |k: &Kept| {
        k.iter()
            .find(|(c, o, _)| c == start && *o == orientations)
            .map(|e| e.2)
    };
    if let Some(t) = KEPT.lock().ok().and_then(|k| kept(&k)) {
        return t;
    }
    let travels = Robot::new(start)
        .ok()
        .and_then(|r| pcr_kinematics::workspace::leg_travel(&r, &orientations, 4.0))
        .unwrap_or_else(|| std::array::from_fn(limit));
    if let Ok(mut k) = KEPT.lock() {
        if k.len() >= 4 {
            k.remove(0);
        }
        k.push((start.clone(), orientations, travels));
    }
    travels
}

/// Table I: step 1 of every function (of `only` alone when given, the other rows not fitted),
/// in the readings of `readings`, on the three legs.
fn table_one(
    start: &RobotConfig,
    obs: &LegSets,
    travel: &[[f64; 2]; 3],
    free: FreeGeometry,
    readings: Readings,
    has_test: bool,
    only: Option<TendonMapKind>,
) -> Vec<TableRow> {
    // The functions' fits are independent of one another: one per thread, in Table I's order.
    TendonMapKind::ALL
        .par_iter()
        .map(|&kind| match only {
            Some(k) if k != kind => not_fitted(kind, k),
            _ => table_row(start, obs, travel, free, kind, readings, has_test),
        })
        .collect()
}

/// The Table I row of a function the calibration did not fit, `only` being the one it fitted
/// ([`Options::every_function`]).
fn not_fitted(kind: TendonMapKind, only: TendonMapKind) -> TableRow {
    TableRow {
        index: kind.table_index(),
        name: kind.name(),
        form: kind.paper_form(),
        extended_form: kind.extended_form(),
        readings: Vec::new(),
        chosen: Vec::new(),
        train_rms_mm: None,
        test_rms_mm: None,
        converged: false,
        monotonic: false,
        error: Some(format!(
            "function {} ({}): not fitted, function {} ({}) alone was asked for",
            kind.table_index(),
            kind.name(),
            only.table_index(),
            only.name()
        )),
    }
}

/// Step 1 of one function in each reading on the three legs, and each leg's choice.
fn table_row(
    start: &RobotConfig,
    obs: &LegSets,
    travel: &[[f64; 2]; 3],
    free: FreeGeometry,
    kind: TendonMapKind,
    readings: Readings,
    has_test: bool,
) -> TableRow {
    let fits: Vec<ReadingFit> = readings
        .fitted()
        .par_iter()
        .map(|&reading| reading_fit(start, obs, travel, free, MapForm { kind, reading }))
        .collect();
    // Each leg: the selectable fit with the lower held-out error (AIC without test points).
    let score = |f: &LegFit| {
        if has_test {
            f.test_rms_mm.unwrap_or(f64::INFINITY)
        } else {
            leg_aic(f)
        }
    };
    let mut chosen = Vec::with_capacity(3);
    let mut error = None;
    for i in 0..3 {
        let best = fits
            .iter()
            .filter_map(|r| r.legs.iter().find(|f| f.leg == Some(i)))
            .filter(|f| f.converged && f.refused.is_none())
            .min_by(|a, b| score(a).total_cmp(&score(b)));
        match best {
            Some(f) => chosen.push(f.reading),
            None => {
                let why: Vec<String> = fits
                    .iter()
                    .flat_map(|r| {
                        r.errors.iter().cloned().chain(
                            r.legs
                                .iter()
                                .filter(|f| f.leg == Some(i))
                                .map(|f| leg_unusable(f, kind)),
                        )
                    })
                    .collect();
                error.get_or_insert_with(|| why.join("; "));
                break;
            }
        }
    }
    let complete = error.is_none();
    let mut row = TableRow {
        index: kind.table_index(),
        name: kind.name(),
        form: kind.paper_form(),
        extended_form: kind.extended_form(),
        readings: fits,
        chosen,
        train_rms_mm: None,
        test_rms_mm: None,
        converged: complete,
        monotonic: complete,
        error,
    };
    if complete {
        let legs = row.chosen_legs();
        row.train_rms_mm = pooled(&legs, false);
        row.test_rms_mm = pooled(&legs, true);
    }
    row
}

/// Why a leg's fit cannot be chosen.
fn leg_unusable(f: &LegFit, kind: TendonMapKind) -> String {
    let label = MapForm {
        kind,
        reading: f.reading,
    }
    .label();
    let leg = f.leg.map_or(0, |i| i + 1);
    match &f.refused {
        Some(r) => format!("leg {leg}: function {label}: {r}"),
        None => format!(
            "leg {leg}: function {label}: the fit did not converge ({} after {} evaluations)",
            f.status, f.evaluations
        ),
    }
}

/// One function in one reading on the three legs; each map is checked for the IK (its
/// `refused` says why it cannot serve).
fn reading_fit(
    start: &RobotConfig,
    obs: &LegSets,
    travel: &[[f64; 2]; 3],
    free: FreeGeometry,
    form: MapForm,
) -> ReadingFit {
    // The legs' fits are independent: one per thread, gathered in the legs' order.
    let fitted: Vec<Result<LegFit, Step1Error>> = (0..3)
        .into_par_iter()
        .map(|i| {
            let what = format!("leg {}", i + 1);
            let (train, test) = &obs[i];
            step1::fit_leg(&what, Some(i), &start.legs[i], free, form, train, test).map(|mut f| {
                f.refused = map_refusal(&f.config, travel[i], &obs[i]);
                f
            })
        })
        .collect();
    let mut legs = Vec::with_capacity(3);
    let mut errors = Vec::new();
    for f in fitted {
        match f {
            Ok(f) => legs.push(f),
            Err(e) => errors.push(e.to_string()),
        }
    }
    let complete = legs.len() == 3;
    ReadingFit {
        reading: form.reading,
        train_rms_mm: complete.then(|| pooled(&legs, false)).flatten(),
        test_rms_mm: complete.then(|| pooled(&legs, true)).flatten(),
        legs,
        errors,
    }
}

/// The tendon displacements of a leg's observations (both splits), mm.
fn dl_range(obs: &(Vec<LegObservation>, Vec<LegObservation>)) -> (f64, f64) {
    obs.0
        .iter()
        .chain(&obs.1)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, o| {
            (a.0.min(o.dl_mm), a.1.max(o.dl_mm))
        })
}

/// Why a leg's map cannot serve the IK over the leg's travel (`None` when it can): the map must
/// be strictly monotonic over the data's displacements widened by 10 % and invertible over the
/// curvatures the workspace asks of the leg (`travel`, 1/mm) widened by 10 %.
fn map_refusal(
    leg: &pcr_robot::LegConfig,
    travel: [f64; 2],
    obs: &(Vec<LegObservation>, Vec<LegObservation>),
) -> Option<String> {
    let (lo, hi) = dl_range(obs);
    step1::map_coverage(
        &pcr_kinematics::TendonMap::from_spec(&leg.tendon_map),
        leg.l_c_mm,
        travel,
        lo,
        hi,
    )
    .err()
}

/// Akaike information criterion of one leg's fit on its training points (two coordinates per
/// point, Gaussian errors).
fn leg_aic(f: &LegFit) -> f64 {
    let n = 2 * f.n_train;
    let rss = f.train_rms_mm.powi(2) * n as f64 / 2.0;
    n as f64 * (rss / n as f64).ln() + 2.0 * f.params.len() as f64
}

/// The function to use: forced, or the selectable one with the lowest test RMS of M_i (the
/// lowest AIC on the training poses without test poses).
fn select_function(
    table1: &[TableRow],
    forced: Option<TendonMapKind>,
    has_test: bool,
    origin: &str,
    warnings: &mut Vec<String>,
) -> Result<(usize, String), CalibError> {
    if let Some(k) = forced {
        return check_forced(&table1[k.table_index() - 1], origin)
            .map(|()| (k.table_index(), "forced by the user".to_string()));
    }
    let usable = || {
        table1
            .iter()
            .filter(|r| r.error.is_none() && r.converged && r.monotonic)
    };
    let best = if has_test {
        usable()
            .filter_map(|r| Some((r.index, r.test_rms_mm?)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, v)| (i, format!("lowest test RMS of M_i ({v:.3} mm)")))
    } else {
        warnings.push(
            "no test poses: the function was selected by the Akaike information \
             criterion on the training poses, not by held-out error"
                .into(),
        );
        usable()
            .map(|r| (r.index, aic(r)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, v)| (i, format!("lowest AIC on the training poses ({v:.1})")))
    };
    best.ok_or_else(|| CalibError::NoFunction {
        origin: origin.to_string(),
        reasons: no_function_reasons(table1),
    })
}

/// A forced function must have been fitted, and have converged, on every leg.
fn check_forced(row: &TableRow, origin: &str) -> Result<(), CalibError> {
    if let Some(e) = &row.error {
        return Err(CalibError::NoFunction {
            origin: origin.to_string(),
            reasons: format!("  {e}"),
        });
    }
    Ok(())
}

/// Akaike information criterion of a Table I row on its training points (two coordinates per
/// point, Gaussian errors).
fn aic(r: &TableRow) -> f64 {
    let legs = r.chosen_legs();
    let n: usize = legs.iter().map(|f| 2 * f.n_train).sum();
    let k: usize = legs.iter().map(|f| f.params.len()).sum();
    let rss = r.train_rms_mm.unwrap_or(f64::INFINITY).powi(2) * n as f64 / 2.0;
    n as f64 * (rss / n as f64).ln() + 2.0 * k as f64
}

/// One line per function saying why it cannot be used.
fn no_function_reasons(table1: &[TableRow]) -> String {
    table1
        .iter()
        .map(|r| match &r.error {
            Some(e) => format!("  {e}"),
            None if !r.converged => format!(
                "  function {} ({}): the fit did not converge",
                r.index, r.name
            ),
            None => format!("  function {} ({}): not selectable", r.index, r.name),
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The starting robot with the legs of step 1, noting what the user should know.
fn apply_step1(start: &RobotConfig, fits: &[LegFit], warnings: &mut Vec<String>) -> RobotConfig {
    let mut robot = start.clone();
    for f in fits {
        let i = f.leg.unwrap_or(0);
        robot.legs[i] = f.config.clone();
        if !f.converged {
            warnings.push(format!(
                "leg {}: step 1 stopped before converging ({})",
                i + 1,
                f.status
            ));
        }
        note_params(warnings, &format!("leg {}", i + 1), &f.params);
    }
    robot
}

/// Step 2 on the robot with the step-1 legs.
fn run_step2(
    legs_robot: &RobotConfig,
    parameters: ParameterSet,
    train_poses: &[PoseObservation],
    w: f64,
    origin: &str,
) -> Result<Step2Fit, CalibError> {
    step2::fit_platform(legs_robot, parameters.step2(), train_poses, w).map_err(|source| {
        CalibError::Step2 {
            origin: origin.to_string(),
            source,
        }
    })
}

/// The joint refinement and its accuracy; `None` (with a warning) when it fails, so that the
/// paper's result stands.
fn refine_jointly(
    start: &RobotConfig,
    paper_robot: &RobotConfig,
    free: JointParams,
    train: JointObservations<'_>,
    w: f64,
    data: &StaticData,
    warnings: &mut Vec<String>,
) -> Option<JointResult> {
    match joint::refine(start, paper_robot, free, train, w) {
        Ok(mut fit) => {
            fit.config.name = paper_robot.name.clone();
            if !fit.converged {
                warnings.push(format!(
                    "joint refinement stopped before converging ({})",
                    fit.status
                ));
            }
            note_params(warnings, "joint fit", &fit.params);
            let accuracy = match &fit.frame {
                Some(f) => split_accuracy(&fit.config, &framed(data, f)),
                None => split_accuracy(&fit.config, data),
            };
            Some(JointResult { fit, accuracy })
        }
        Err(e) => {
            warnings.push(format!("{e}: the paper's two steps are used"));
            None
        }
    }
}

/// Which result becomes the calibrated robot: the joint one when it exists, is usable and its
/// maps can be inverted over the data and up to the bending limit; else the paper's (with a
/// warning saying why).
fn joint_usable(
    joint: Option<&JointResult>,
    travel: &[[f64; 2]; 3],
    origin: &str,
    obs: &LegSets,
    warnings: &mut Vec<String>,
) -> Method {
    let Some(j) = joint else {
        return Method::Paper;
    };
    let reason = check_usable(&j.fit.config, origin)
        .err()
        .map(|e| e.to_string())
        .or_else(|| maps_not_invertible(&j.fit.config, travel, obs));
    match reason {
        Some(r) => {
            warnings.push(format!(
                "the joint refinement is not used ({r}): the paper's two steps are"
            ));
            Method::Paper
        }
        None => Method::Joint,
    }
}

/// Why a robot's maps cannot serve the IK over the data's displacements and the legs' travel
/// (`None` when they can).
fn maps_not_invertible(
    robot: &RobotConfig,
    travel: &[[f64; 2]; 3],
    obs: &LegSets,
) -> Option<String> {
    robot.legs.iter().enumerate().find_map(|(i, leg)| {
        map_refusal(leg, travel[i], &obs[i]).map(|r| format!("leg {}: the refined map {r}", i + 1))
    })
}

/// Held-out platform position RMS of the joint refinement above this multiple of the two steps'
/// gets a warning: smaller differences are within the sampling error of a test set of tens of
/// poses (docs/calibration.md).
const JOINT_WORSE_WARNING: f64 = 1.05;

/// A warning when the joint refinement predicts the held-out platform positions clearly worse
/// than the paper's two steps (it fits the training poses at least as well by construction).
fn compare_with_paper(
    joint: Option<&JointResult>,
    paper: &SplitAccuracy,
    warnings: &mut Vec<String>,
) {
    let (Some(j), Some(p)) = (joint.and_then(|j| j.accuracy.test), paper.test) else {
        return;
    };
    if j.pose.position_rms_mm > JOINT_WORSE_WARNING * p.pose.position_rms_mm {
        warnings.push(format!(
            "the joint refinement predicts the test poses worse than the paper's two steps \
             (platform position RMS {:.4} against {:.4} mm): compare with --method paper",
            j.pose.position_rms_mm, p.pose.position_rms_mm
        ));
    }
}

/// Warns of the parameters that end on a bound. The strongly correlated pairs are not repeated
/// as warnings: `report::correlated_summary` names them all in one line, the report lists each.
fn note_params(warnings: &mut Vec<String>, what: &str, params: &[step1::Param]) {
    for p in params {
        if p.at_bound {
            warnings.push(format!(
                "{what}: {} = {} {} sits on its bound: the data pull it beyond the allowed range",
                p.name, p.value, p.unit
            ));
        }
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
        if v.iter()
            .chain(&l.tendon_map.coeffs)
            .chain(&l.tendon_map.coeffs_neg)
            .any(|x| !x.is_finite())
        {
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
         # Tendon map: Table I function {} ({}; {}), {}.\n\
         # Parameters freed: {:?}; {}. Test RMS of M_i {} mm; platform position RMS on the\n\
         # test set {} mm (before: {} mm; the paper's two steps: {} mm).\n\
         # Use it as `robot = \"<this file>\"` in a supervisor configuration.\n",
        cal.data.file,
        cal.data.poses,
        cal.data.train,
        cal.data.test,
        best.index,
        best.name,
        best.chosen_text(),
        cal.selected_by,
        cal.options.parameters,
        match cal.used {
            Method::Joint => "the paper's two steps refined jointly",
            Method::Paper => "the paper's two steps",
        },
        fmt_opt(cal.after.test.map(|a| a.m_rms_mm)),
        fmt_opt(cal.after.test.map(|a| a.pose.position_rms_mm)),
        fmt_opt(cal.before.test.map(|a| a.pose.position_rms_mm)),
        fmt_opt(cal.paper.test.map(|a| a.pose.position_rms_mm)),
    );
    s.push_str(&cal.robot.to_toml_string());
    s
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or("-".into(), |v| format!("{v:.3}"))
}
