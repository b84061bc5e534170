//! The extended model: the calibrated constant-curvature robot plus the effects its file
//! declares, predicting the measured pose of every row of a recording.
//!
//! The chain of a prediction, in the order the physics runs (each effect's part of a stage is
//! its [`crate::extension::Extension`], in its own module under [`crate::effects`]):
//! 1. timing: the motors are where the command was the recording's command delay
//!    (`Series::delay_s`: what the file declares, `shared/spec/recording.md` "Timing"; a chain
//!    whose drive executes a setpoint over the following cycle declares one period) plus the
//!    effects' delay (`latency`) earlier;
//! 2. transmission: the output of a motor as a function of its position (`periodic`: the output
//!    lags the motor by `A sin(2 pi q / P + phase)`);
//! 3. play: the output follows the motor through a play (`backlash`: `b` steps);
//! 4. tendons: the tendon lengthens, so the segment sees less displacement (`creep`:
//!    `de/dt = (gain dl - e) / T`, then `drift`: `rate * (t - t0)`, t0 the recording's first
//!    row);
//! 5. the tendon map gives the curvatures and the forward kinematics the pose, loaded when an
//!    effect loads the robot (`joint_springs`, `external_load`: `[effects.compliance]`); then
//!    the friction of the joints and their supports deflects it by what the path before each
//!    row left stuck or slipping (`friction`: a pass over every row of the series in order);
//! 6. measurement: the measurement is corrected before it is compared (`frame`).

use crate::extension::Chain;
use crate::interpolation::WithGradient;
use crate::series::Series;
use nalgebra::Matrix3;
use pcr_kinematics::friction::{Friction, FrictionState};
use pcr_kinematics::statics::{LoadedWarm, Loads};
use pcr_kinematics::{Pose, Robot};
use pcr_robot::effects::Effects;
use pcr_robot::RobotConfig;
use rayon::prelude::*;

/// The rows `ks` of a series of `n` rows as a mask (what [`ExtendedModel::predict_where_from`]
/// asks of every row: a lookup, not a hash).
pub(crate) fn mask(n: usize, ks: &[usize]) -> Vec<bool> {
    let mut m = vec![false; n];
    for &k in ks {
        m[k] = true;
    }
    m
}

/// Rows of a series solved in one pass (warm-started from row to row) by one thread.
pub const PREDICT_CHUNK: usize = 2048;

/// Largest error (mm) of an interpolated deflection of the platform position by the loads, on
/// the middle row of a stretch ([`crate::interpolation`]); a stretch off by more is bisected.
pub const DEFLECTION_TOLERANCE_MM: f64 = 1e-3;

/// Largest error (rad) of an interpolated deflection of the platform orientation.
pub const DEFLECTION_TOLERANCE_RAD: f64 = 2e-5;

/// The loaded solver's state at each row of one series that was solved with it (row index to
/// state), kept from one prediction of the row to the next: a fit's evaluations predict the
/// same rows with nearby models, and a row started from its own last equilibrium converges in
/// a step or two where one started from the previous row of a subsample needs several and a
/// fresh Jacobian ([`ExtendedModel::predict_where_from`], [`ExtendedModel::sensitivities`]).
pub type RowStates = std::sync::Mutex<std::collections::HashMap<usize, LoadedWarm>>;

/// Stages 1 to 4 of every row of a series ([`ExtendedModel::tendons`]): the effective motor
/// positions (steps), the effective tendon displacements (mm), and the legs' mm per step.
type Tendons = (Vec<[f64; 3]>, Vec<[f64; 3]>, [f64; 3]);

/// How a prediction solves its rows beyond the defaults ([`ExtendedModel::predict_where_from`]).
#[derive(Default, Clone, Copy)]
pub struct Solving<'s> {
    /// Loaded rows solved in sequence start from the state kept here for them, and keep theirs.
    pub states: Option<&'s RowStates>,
    /// The wanted rows with a measured pose that had none predicted, and how many the caller
    /// can do with: once there are more, the rows not yet solved are left unsolved (a caller
    /// that needs every row stops at the first it cannot have).
    pub failures: Option<(&'s std::sync::atomic::AtomicUsize, usize)>,
    /// Only the poses are wanted: the rows' first-order responses ([`Prediction::j_q`],
    /// [`Prediction::j_kappa`]) are left zero (a refinement's evaluations read the poses).
    pub poses_only: bool,
}

impl Solving<'_> {
    fn stopped(&self) -> bool {
        self.failures
            .is_some_and(|(n, most)| n.load(std::sync::atomic::Ordering::Relaxed) > most)
    }

    /// Counts a wanted row left without a pose (only one with a measurement counts).
    fn failed(&self, measured: bool) {
        if let (Some((n, _)), true) = (self.failures, measured) {
            n.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        }
    }
}

/// Starts `warm` from the state `states` holds for row `k`, if any.
fn resume(states: Option<&RowStates>, k: usize, warm: &mut LoadedWarm) {
    if let Some(Ok(m)) = states.map(|s| s.lock()) {
        if let Some(w) = m.get(&k) {
            warm.resume_from(w);
        }
    }
}

/// Keeps `warm` (just solved at row `k`) in `states`.
fn keep(states: Option<&RowStates>, k: usize, warm: &LoadedWarm) {
    if let Some(Ok(mut m)) = states.map(|s| s.lock()) {
        m.insert(k, warm.clone());
    }
}

/// The prediction for one row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prediction {
    /// Predicted pose (x mm, y mm, phi rad); `None` where the model has no pose.
    pub pose: Option<[f64; 3]>,
    /// Effective motor positions after latency, periodic errors and backlash, steps.
    pub q_eff: [f64; 3],
    /// Effective tendon displacement after creep, mm.
    pub dl_eff: [f64; 3],
    /// Curvatures, 1/mm.
    pub kappa: [f64; 3],
    /// d pose / d q_eff (rows x mm, y mm, phi rad; columns steps).
    pub j_q: Matrix3<f64>,
    /// d pose / d kappa.
    pub j_kappa: Matrix3<f64>,
    /// The friction's deflection that `pose` includes (x mm, y mm, phi rad); `None` without
    /// friction or without a pose.
    pub friction: Option<[f64; 3]>,
}

/// A row's predicted pose and its first-order responses ([`ExtendedModel::sensitivities`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sensitivity {
    /// Predicted pose (x mm, y mm, phi rad).
    pub pose: [f64; 3],
    /// The curvatures it was predicted at, 1/mm.
    pub kappa: [f64; 3],
    /// d pose / d kappa (rows x mm, y mm, phi rad), under the model's loads.
    pub d_kappa: Matrix3<f64>,
    /// d pose / d (force x N, force y N, couple N mm, k_M, k_P N mm/rad); zero unloaded.
    pub d_loads: [[f64; 3]; 5],
}

/// Rows of a series per piece of a friction pass ([`along_path`]), on average: the pieces run
/// in parallel, each from a history rebuilt over the configurations before it. A series of 44k
/// rows is six pieces: the rebuilding costs 5 % more work in all (backlash + friction at 3x),
/// and about twice that in pieces of 4096 rows. A series of half this length or more is cut
/// into an even number of pieces, so that two cores share them evenly: the held-out 17k rows
/// in three pieces kept one core idle for a third of each of their passes.
const PASS_CHUNK: usize = 8192;

/// The pieces' shares of a friction pass of `count` pieces ([`RigidPath::piece_starts`]), in
/// order along the path: two of each weight, the largest first (6 pieces: 3, 3, 2, 2, 1, 1).
/// The pieces are answered in that order, each by the first core free ([`along_path_in`]), so
/// that the smallest come last and fill the time one core would otherwise wait for the other:
/// with six equal pieces each core took three, and their times differed by up to a third (the
/// configurations' cost varies with how many elements slip).
fn piece_weights(count: usize) -> Vec<usize> {
    if count < 4 || count % 2 == 1 {
        return vec![1; count];
    }
    (0..count).map(|j| count / 2 - j / 2).collect()
}

/// Configurations passed between rows (the stairs' steps, [`RigidPath::stairs`]) a piece of a
/// friction pass runs through before its first row, from every element unloaded, to rebuild
/// the history it starts from ([`along_path`]). On backlash + friction at 3x (39 passes, 5
/// pieces after the first in each), the rebuilt history was the one the pass before it ended
/// with, to [`SAME_HISTORY`] and [`SAME_DERIVATIVES`], in every piece at 500; at 350 one
/// piece, at 250 15, at 150 76 were answered again.
const BURN_IN_CONFIGURATIONS: usize = 500;

/// A piece's rebuilt history is the one the pass before it ended with where the two differ by
/// at most this ([`FrictionState::difference`]: mm for the tips and the supports' anchors, rad
/// for the joints'): a tenth of what the equilibrium's iteration leaves at each row (1e-5 mm,
/// [`pcr_kinematics::friction`]). On the recording above, histories rebuilt over 256 rows with
/// a move differed from the pass's by 5e-14 in the median and 2e-7 at most.
const SAME_HISTORY: f64 = 1e-6;

/// The derivatives of a piece's rebuilt history ([`SAME_HISTORY`]) are those the pass before
/// it ended with where each differs by less than this share of the largest derivative by the
/// same value ([`pcr_kinematics::friction::FrictionTangent::difference`]): the direction of a
/// linearised step, which the fit takes again from where it lands, changes by as much.
const SAME_DERIVATIVES: f64 = 1e-4;

/// Rows between the states a piece of a friction pass keeps ([`along_path`]): a piece answered
/// again from the history the piece before ended with is answered so only until that history
/// agrees with the piece's own at one of them. On friction at 10x (31 passes), 48 of the 119
/// pieces after the first did not agree where they started, and each rejoined its own answers
/// at its first or second checkpoint: 17k rows answered again in all, of 1.04 M.
const CHECKPOINT: usize = 256;

/// A friction pass's state: the history of the elements and, in a pass with the derivatives,
/// theirs.
trait PassState: Default + Clone + Send {
    /// Whether `other` holds the same history as this one ([`SAME_HISTORY`],
    /// [`SAME_DERIVATIVES`]).
    fn agrees(&self, other: &Self) -> bool;
}

impl PassState for FrictionState {
    fn agrees(&self, other: &Self) -> bool {
        self.difference(other) <= SAME_HISTORY
    }
}

impl PassState for (FrictionState, pcr_kinematics::friction::FrictionTangent) {
    fn agrees(&self, other: &Self) -> bool {
        self.0.agrees(&other.0) && self.1.difference(&other.1) <= SAME_DERIVATIVES
    }
}

/// `step` along every row of a path in order, from every friction element unloaded at its
/// first row; `None` where a row has no rigid pose (the elements stay as they were) or `step`
/// has no answer.
///
/// Before each row, the elements are taken through the configurations its legs' steps passed
/// since the row before ([`RigidPath::stairs`]); only the row's own answer is kept.
///
/// The rows are answered in pieces in parallel, as many as pieces of [`PASS_CHUNK`] rows make,
/// cut by the configurations they pass and largest first ([`piece_weights`]). A
/// piece after the first rebuilds the history it starts from: from every element unloaded,
/// through the rows before it that pass [`BURN_IN_CONFIGURATIONS`] configurations (a friction
/// element's history is wiped where it slips, and the moves make every element slip). Then, in
/// order, a piece's rebuilt history is compared with the one the piece before it ended with:
/// where they differ by more than [`SAME_HISTORY`] (or [`SAME_DERIVATIVES`]), the piece is
/// answered again from the latter, up to the first of its [`CHECKPOINT`]s where the two
/// histories agree. The answer is that of one pass from the first row to within the
/// equilibrium's own tolerance, and does not depend on the number of threads.
fn along_path<S: PassState, T: Send>(
    rigid: &RigidPath,
    kappa: &[[f64; 3]],
    step: impl Fn(&Pose, &[f64; 3], &mut S, Passing) -> Option<T> + Sync,
) -> Vec<Option<T>> {
    along_path_in(rigid, kappa, Pieces::PASS, step).0
}

/// How [`along_path`] cuts a pass: pieces of at most `rows` rows, each rebuilding its history
/// over `burn_in` configurations and keeping its state every `checkpoint` rows.
#[derive(Debug, Clone, Copy)]
struct Pieces {
    rows: usize,
    burn_in: usize,
    checkpoint: usize,
}

impl Pieces {
    /// [`PASS_CHUNK`], [`BURN_IN_CONFIGURATIONS`] and [`CHECKPOINT`].
    const PASS: Pieces = Pieces {
        rows: PASS_CHUNK,
        burn_in: BURN_IN_CONFIGURATIONS,
        checkpoint: CHECKPOINT,
    };
}

/// One piece of a pass answered from its rebuilt history ([`along_path_in`]).
struct Piece<S, T> {
    /// Its rows.
    rows: std::ops::Range<usize>,
    /// The history rebuilt for it (none for the first piece).
    rebuilt: Option<S>,
    /// Its rows' answers.
    out: Vec<Option<T>>,
    /// The state before every `checkpoint`th row after its first.
    checkpoints: Vec<S>,
    /// The state after its last row.
    end: S,
}

/// [`along_path`] in `pieces`, with the number of pieces answered again.
fn along_path_in<S: PassState, T: Send>(
    rigid: &RigidPath,
    kappa: &[[f64; 3]],
    pieces: Pieces,
    step: impl Fn(&Pose, &[f64; 3], &mut S, Passing) -> Option<T> + Sync,
) -> (Vec<Option<T>>, usize) {
    let n = rigid.poses.len().min(kappa.len());
    let run = |state: &mut S, rows: std::ops::Range<usize>, out: &mut Vec<Option<T>>| {
        for k in rows {
            let answer = rigid.poses[k].as_ref().and_then(|p| {
                if let Some(stair) = rigid.stairs.get(k) {
                    for (q, kq) in stair {
                        let _ = step(q, kq, state, Passing::Between);
                    }
                }
                step(p, &kappa[k], state, Passing::Row)
            });
            out.push(answer);
        }
    };
    // The stretches of a piece between its checkpoints.
    let every = pieces.checkpoint.max(1);
    let stretches = |rows: std::ops::Range<usize>| {
        let end = rows.end;
        rows.step_by(every)
            .map(move |k| k..k.saturating_add(every).min(end))
    };
    // Pieces of equal length, as many as pieces of `pieces.rows` take, and an even number of
    // them from half that length on ([`PASS_CHUNK`]).
    let rows = pieces.rows.max(1);
    let count = n.div_ceil(rows).max(1);
    let count = if 2 * n >= rows {
        count + count % 2
    } else {
        count
    };
    let starts = rigid.piece_starts(n, count);
    let answer = |j: usize| {
        let first = starts[j];
        let rows = first..starts.get(j + 1).copied().unwrap_or(n);
        let mut state = S::default();
        let mut out = Vec::with_capacity(rows.len());
        let rebuilt = (first > 0).then(|| {
            run(&mut state, rigid.burn_in(first, pieces)..first, &mut out);
            out.clear();
            state.clone()
        });
        let mut checkpoints = Vec::new();
        for stretch in stretches(rows.clone()) {
            if stretch.start > first {
                checkpoints.push(state.clone());
            }
            run(&mut state, stretch, &mut out);
        }
        Piece {
            rows,
            rebuilt,
            out,
            checkpoints,
            end: state,
        }
    };
    // The pieces in order, the largest first ([`piece_weights`]), each taken by the first core
    // free.
    let next = std::sync::atomic::AtomicUsize::new(0);
    let slots: Vec<std::sync::Mutex<Option<Piece<S, T>>>> =
        starts.iter().map(|_| std::sync::Mutex::new(None)).collect();
    let take = || loop {
        let j = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        if j >= starts.len() {
            break;
        }
        let piece = answer(j);
        if let Ok(mut slot) = slots[j].lock() {
            *slot = Some(piece);
        }
    };
    rayon::scope(|s| {
        for _ in 1..rayon::current_num_threads().min(starts.len()) {
            s.spawn(|_| take());
        }
        take();
    });
    // A piece's panic propagates from the scope: every slot is filled here.
    let answered: Vec<Piece<S, T>> = slots
        .into_iter()
        .filter_map(|m| m.into_inner().ok().flatten())
        .collect();
    let mut out = Vec::with_capacity(n);
    let mut history: Option<S> = None;
    let (mut again, mut rows_again) = (0, 0);
    for mut piece in answered {
        let mut before = match history.take() {
            Some(b) if piece.rebuilt.as_ref().is_some_and(|r| !r.agrees(&b)) => b,
            // The first piece, or one whose rebuilt history agrees.
            _ => {
                out.append(&mut piece.out);
                history = Some(piece.end);
                continue;
            }
        };
        // Answered again from where the piece before ended, until the history agrees with the
        // piece's own at one of its checkpoints: from there on, the piece's answers are the
        // pass's.
        again += 1;
        let first = piece.rows.start;
        for (j, stretch) in stretches(piece.rows.clone()).enumerate() {
            let kept = j.checked_sub(1).and_then(|c| piece.checkpoints.get(c));
            if kept.is_some_and(|c| before.agrees(c)) {
                out.extend(piece.out.drain(stretch.start - first..));
                history = Some(piece.end);
                break;
            }
            rows_again += stretch.len();
            run(&mut before, stretch, &mut out);
        }
        if history.is_none() {
            history = Some(before);
        }
    }
    tracing::debug!(
        rows = n,
        pieces = starts.len(),
        again,
        rows_again,
        "friction pass in pieces"
    );
    (out, again)
}

/// Where [`along_path`] is: at a row (its answer kept) or passing a configuration on the stair
/// before it ([`pcr_kinematics::Robot::friction_pass`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Passing {
    Row,
    Between,
}

/// Most configurations between two rows on a [`RigidPath`]'s stair: a leg that took more steps
/// than this between them has them grouped (12 is the most at the drive's 600 steps/s in a
/// 20 ms cycle).
const MAX_STAIR: usize = 64;

/// The rigid poses of a series' rows and the staircase between them: between two rows each
/// leg moves step by step, every leg at its own even rate over the interval (the firmware
/// spreads a cycle's steps evenly, each motor on its own), so that the joints and their
/// supports go through a staircase of configurations rather than along the chord between the
/// two rows. A friction element sees that staircase: on the plant's supports alone at its
/// test strength, the deflection along the chord missed the plant's by 0.014 mm RMS, along
/// the staircase by 0.0009 mm.
#[derive(Debug, Clone, Default)]
pub struct RigidPath {
    /// Per row, its rigid pose; `None` where the kinematics do not close.
    pub poses: Vec<Option<Pose>>,
    /// Per row, the configurations (rigid pose, curvatures) after each of the step times
    /// between the row before and this one, in order, the row's own excluded; empty at rest,
    /// at the first row and next to a row without a pose.
    pub stairs: Vec<Vec<(Pose, [f64; 3])>>,
}

impl RigidPath {
    /// The first rows of `count` pieces of the path's first `n` rows, in order along the path,
    /// the configurations each passes (a row and the stair before it, [`RigidPath::stairs`])
    /// in proportion to its weight ([`piece_weights`]): the work of a friction pass is in its
    /// configurations, and a row at rest passes one where a moving row passes up to a dozen
    /// (pieces of equal rows on the 44k rows of backlash + supports at 3x passed 14.6k to 19.2k
    /// configurations).
    fn piece_starts(&self, n: usize, count: usize) -> Vec<usize> {
        let cost = |k: usize| 1 + self.stairs.get(k).map_or(0, Vec::len);
        let total: usize = (0..n).map(cost).sum();
        let weights = piece_weights(count);
        let sum: usize = weights.iter().sum();
        // The cumulative weight at each piece's start, in configurations times `sum`.
        let mut bounds = weights.iter().scan(0, |acc, w| {
            *acc += w;
            Some(*acc * total)
        });
        let mut next = bounds.next();
        let mut starts = vec![0];
        let mut passed = 0;
        for k in 0..n {
            if starts.len() < count
                && k > *starts.last().unwrap_or(&0)
                && next.is_some_and(|b| passed * sum >= b)
            {
                starts.push(k);
                next = bounds.next();
            }
            passed += cost(k);
        }
        starts
    }

    /// The first row of the history rebuilt for a piece of a friction pass starting at row
    /// `first` ([`along_path`]): the last row before it at which the stairs from there to
    /// `first` pass `pieces.burn_in` configurations ([`BURN_IN_CONFIGURATIONS`]), at most a
    /// piece's rows before it, and at most the first row; `first` itself for none (the piece
    /// starts from every element unloaded, which no history the pass had before agrees with).
    fn burn_in(&self, first: usize, pieces: Pieces) -> usize {
        if pieces.burn_in == 0 {
            return first;
        }
        let earliest = first.saturating_sub(pieces.rows);
        let mut passed = 0;
        for k in (earliest..first).rev() {
            if let Some(s) = self.stairs.get(k) {
                passed += s.len();
                if passed >= pieces.burn_in {
                    return k;
                }
            }
        }
        earliest
    }
}

/// A row's friction deflection (x mm, y mm, phi rad) and its derivatives by the friction's
/// fitted values (the joints' couple N mm, the supports' force N, the joints' pre-sliding
/// travel rad).
pub type DeflectionTangent = ([f64; 3], [[f64; 3]; 3]);

/// A row's friction deflection and the displacement of the joints M_i (base frame, mm).
pub type DeflectionAndJoints = ([f64; 3], [[f64; 2]; 3]);

/// Forgets the friction passes and rigid paths kept ([`ExtendedModel::friction_path`],
/// [`ExtendedModel::rigid_path`]): at the end of an analysis, whose recordings the next one
/// does not share (they hold some tens of megabytes).
pub(crate) fn forget_kept() {
    kept::forget();
}

/// One row of a friction pass: the deflection (x mm, y mm, phi rad), its derivatives by the
/// friction's fitted values (zero in a pass made without them), and the displacement of the
/// joints M_i (base frame, mm).
#[derive(Debug, Clone, Copy)]
struct PassRow {
    d: [f64; 3],
    t: [[f64; 3]; 3],
    joints: [[f64; 2]; 3],
}

/// The friction passes made last, each with what it was made for, so that a pass asked for
/// again is not made again: a pass runs the friction's history through every configuration of
/// a series (a tenth to a fifth of a second on 44k rows), and the search asks for the same one
/// from different places (the prediction of a model, then the refinement that starts from it
/// and linearises its friction; the calibration from the drawing reading the joints of the
/// pass the prediction made). A pass is the same when the legs, the path (every rigid pose and
/// curvature, the stairs' too, to the bit) and the friction are: its answer is then the same
/// to the bit. A pass with the derivatives answers one asked without them, and one at a
/// negligible joints' couple one at zero couple (to the bit too, its derivatives by the joints'
/// values zeroed).
mod kept {
    use super::{PassRow, RigidPath};
    use crate::series::Series;
    use pcr_kinematics::friction::Friction;
    use pcr_kinematics::Pose;
    use pcr_robot::RobotConfig;
    use std::sync::{Arc, Mutex};

    /// Entries kept per list (each series of a model is one): a model's calibration recording
    /// and its held-out one, for the last three models.
    const KEPT: usize = 6;

    /// A list of the entries made last, the one used last at the end.
    struct Lru<T>(Mutex<Vec<T>>);

    impl<T> Lru<T> {
        const fn new() -> Self {
            Lru(Mutex::new(Vec::new()))
        }

        fn list(&self) -> std::sync::MutexGuard<'_, Vec<T>> {
            self.0.lock().unwrap_or_else(|e| e.into_inner())
        }

        /// What `get` gives of the first entry `is` accepts, that entry now the last used.
        fn find<R>(&self, is: impl Fn(&T) -> bool, get: impl Fn(&T) -> R) -> Option<R> {
            let mut list = self.list();
            let i = list.iter().position(is)?;
            let e = list.remove(i);
            let out = get(&e);
            list.push(e);
            Some(out)
        }

        /// Keeps `e` in place of the entry used longest ago.
        fn keep(&self, e: T) {
            let mut list = self.list();
            if list.len() >= KEPT {
                list.remove(0);
            }
            list.push(e);
        }
    }

    /// What a pass and a rigid path depend on of the robot file: its legs (the kinematics and
    /// the structure).
    #[derive(PartialEq)]
    struct Legs {
        legs: Vec<pcr_robot::LegConfig>,
        mode: [pcr_robot::WorkingMode; 3],
        limits: pcr_robot::Limits,
    }

    impl Legs {
        fn of(c: &RobotConfig) -> Legs {
            Legs {
                legs: c.legs.clone(),
                mode: c.working_mode,
                limits: c.limits.clone(),
            }
        }

        fn are(&self, c: &RobotConfig) -> bool {
            self.legs == c.legs && self.mode == c.working_mode && self.limits == c.limits
        }
    }

    struct Pass {
        legs: Legs,
        f: Friction,
        tangent: bool,
        rigid: RigidPath,
        kappa: Vec<[f64; 3]>,
        rows: Arc<Vec<Option<PassRow>>>,
    }

    /// A rigid path ([`super::ExtendedModel::rigid_path`]) with what it was made of: the
    /// curvatures, the effective motor positions (the stairs' steps) and the measured poses
    /// (the kinematics' warm starts).
    struct Rigid {
        legs: Legs,
        kappa: Vec<[f64; 3]>,
        q_eff: Vec<[f64; 3]>,
        measured: Vec<Option<[f64; 3]>>,
        path: Arc<RigidPath>,
    }

    static PASSES: Lru<Pass> = Lru::new();
    static RIGID: Lru<Rigid> = Lru::new();

    fn bits(v: &[f64; 3]) -> [u64; 3] {
        v.map(f64::to_bits)
    }

    fn same_rows(a: &[[f64; 3]], b: &[[f64; 3]]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| bits(x) == bits(y))
    }

    fn same_pose(a: &Pose, b: &Pose) -> bool {
        bits(&[a.x, a.y, a.phi]) == bits(&[b.x, b.y, b.phi])
    }

    /// Whether two lists of optional values (of one length) hold values at the same places,
    /// and the same ones by `eq`.
    fn same_each<A, B>(
        a: impl Iterator<Item = Option<A>>,
        b: impl Iterator<Item = Option<B>>,
        eq: impl Fn(A, B) -> bool,
    ) -> bool {
        a.zip(b).all(|(p, q)| match (p, q) {
            (Some(p), Some(q)) => eq(p, q),
            (None, None) => true,
            _ => false,
        })
    }

    fn same_poses(a: &[Option<Pose>], b: &[Option<Pose>]) -> bool {
        a.len() == b.len()
            && same_each(
                a.iter().map(Option::as_ref),
                b.iter().map(Option::as_ref),
                same_pose,
            )
    }

    fn same_path(a: &RigidPath, b: &RigidPath) -> bool {
        same_poses(&a.poses, &b.poses)
            && a.stairs.len() == b.stairs.len()
            && a.stairs.iter().zip(&b.stairs).all(|(s, t)| {
                s.len() == t.len()
                    && s.iter()
                        .zip(t)
                        .all(|((p, k), (q, l))| same_pose(p, q) && bits(k) == bits(l))
            })
    }

    fn same_friction(a: &Friction, b: &Friction) -> bool {
        let v = |f: &Friction| {
            [
                f.joint_torque,
                f.joint_presliding,
                f.support_force,
                f.support_presliding,
                f.ei,
            ]
            .map(f64::to_bits)
        };
        v(a) == v(b)
    }

    /// Whether the pass kept with `kept` answers as one with `asked` would where `asked`'s
    /// joints do not rub (a couple of zero) and `kept`'s couple is negligible
    /// ([`pcr_kinematics::friction::NEGLIGIBLE_COUPLE`]: the equilibrium leaves those joints
    /// out): the same supports' friction and bending stiffness. Its derivatives by the joints'
    /// couple and travel are not the asked pass's (zero: no joints there), and are zeroed
    /// ([`asked_at_zero_couple`]). A fit that holds the couple at zero steps from the model's
    /// couple (1e-25 N mm, its bound approached from inside) to zero, and asked for the pass
    /// again (the consistency check of the supports' friction, 0.3 s).
    fn negligible_for(kept: &Friction, asked: &Friction) -> bool {
        let v = |f: &Friction| [f.support_force, f.support_presliding, f.ei].map(f64::to_bits);
        asked.joint_torque == 0.0
            && kept.joint_torque <= pcr_kinematics::friction::NEGLIGIBLE_COUPLE
            && v(kept) == v(asked)
    }

    /// The rows of a pass kept at a negligible joints' couple as a pass at zero couple answers
    /// them ([`negligible_for`]): the derivatives by the joints' couple and pre-sliding travel
    /// zero.
    fn asked_at_zero_couple(rows: &[Option<PassRow>]) -> Vec<Option<PassRow>> {
        rows.iter()
            .map(|r| {
                r.map(|mut r| {
                    r.t[0] = [0.0; 3];
                    r.t[2] = [0.0; 3];
                    r
                })
            })
            .collect()
    }

    /// The kept pass of `config`'s legs along `rigid` with `f` (one with the derivatives where
    /// `tangent`).
    pub(super) fn find(
        config: &RobotConfig,
        rigid: &RigidPath,
        kappa: &[[f64; 3]],
        f: &Friction,
        tangent: bool,
    ) -> Option<Arc<Vec<Option<PassRow>>>> {
        let same = |k: &Pass| {
            (k.tangent || !tangent)
                && k.legs.are(config)
                && same_rows(&k.kappa, kappa)
                && same_path(&k.rigid, rigid)
        };
        PASSES
            .find(|k| same_friction(&k.f, f) && same(k), |k| k.rows.clone())
            .or_else(|| {
                PASSES.find(
                    |k| negligible_for(&k.f, f) && same(k),
                    |k| Arc::new(asked_at_zero_couple(&k.rows)),
                )
            })
    }

    /// Keeps a pass made ([`find`]'s arguments).
    pub(super) fn keep(
        config: &RobotConfig,
        rigid: &RigidPath,
        kappa: &[[f64; 3]],
        f: &Friction,
        tangent: bool,
        rows: Arc<Vec<Option<PassRow>>>,
    ) {
        PASSES.keep(Pass {
            legs: Legs::of(config),
            f: *f,
            tangent,
            rigid: rigid.clone(),
            kappa: kappa.to_vec(),
            rows,
        });
    }

    fn measured(s: &Series) -> impl Iterator<Item = Option<[f64; 3]>> + '_ {
        s.samples.iter().map(|x| x.pose)
    }

    /// The kept rigid path of `config`'s legs for the series `s` at `kappa` and `q_eff`.
    pub(super) fn find_rigid(
        config: &RobotConfig,
        s: &Series,
        kappa: &[[f64; 3]],
        q_eff: &[[f64; 3]],
    ) -> Option<Arc<RigidPath>> {
        RIGID.find(
            |k| {
                same_rows(&k.kappa, kappa)
                    && same_rows(&k.q_eff, q_eff)
                    && k.legs.are(config)
                    && k.measured.len() == s.samples.len()
                    && same_each(k.measured.iter().copied(), measured(s), |a, b| {
                        bits(&a) == bits(&b)
                    })
            },
            |k| k.path.clone(),
        )
    }

    /// Keeps a rigid path made ([`find_rigid`]'s arguments).
    pub(super) fn keep_rigid(
        config: &RobotConfig,
        s: &Series,
        kappa: &[[f64; 3]],
        q_eff: &[[f64; 3]],
        path: Arc<RigidPath>,
    ) {
        RIGID.keep(Rigid {
            legs: Legs::of(config),
            kappa: kappa.to_vec(),
            q_eff: q_eff.to_vec(),
            measured: measured(s).collect(),
            path,
        });
    }

    /// Forgets every kept pass and rigid path.
    pub(super) fn forget() {
        PASSES.list().clear();
        RIGID.list().clear();
    }
}

/// The model of one robot file.
#[derive(Debug, Clone)]
pub struct ExtendedModel {
    /// The robot file (legs and effects).
    pub config: RobotConfig,
    /// Its constant-curvature model.
    pub robot: Robot,
    /// Loads of the compliance effect.
    pub loads: Option<Loads>,
    /// Friction of the joints and their supports.
    pub friction: Option<Friction>,
    /// Every row solved on its own (no reuse of the previous row's configuration or
    /// equilibrium): the reference the fast path is tested against.
    pub exact: bool,
    /// Loaded rows between solved ones take the loads' deflection interpolated along the
    /// configuration (the default); off, every row is solved (still warm-started). A model
    /// whose predictions are differentiated by its parameters (the refinement's forward
    /// differences) solves every row: an interpolation's stretches depend on the parameters.
    pub interpolate: bool,
    /// A prediction's friction pass made with its derivatives by the friction's values, over
    /// every row of a series, and kept ([`kept`]): for a model whose friction is linearised
    /// next (an acceptance's step, the refinement and the consistency check that follow a
    /// search's iterate), which then takes the pass instead of making it again (a pass with
    /// the derivatives costs about 1.4 of one without). Not carried by [`ExtendedModel::like`].
    pub friction_derivatives: bool,
    /// The effects' parts of the prediction ([`crate::effects::chain`]).
    pub chain: Chain,
}

/// Why a model cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("robot model: {0}")]
pub struct ModelError(pub String);

impl ExtendedModel {
    /// The model of a robot file whose effects predict through `chain` (the registered
    /// effects: [`crate::effects::chain`]).
    pub fn new(config: &RobotConfig, chain: Chain) -> Result<ExtendedModel, ModelError> {
        let robot = Robot::new(config).map_err(|e| ModelError(e.to_string()))?;
        Ok(ExtendedModel {
            loads: chain.iter().find_map(|x| x.loads(&config.effects)),
            friction: chain
                .iter()
                .find_map(|x| x.friction(&config.effects))
                .filter(|f| !f.is_off()),
            robot,
            config: config.clone(),
            exact: false,
            interpolate: true,
            friction_derivatives: false,
            chain,
        })
    }

    /// The model of a robot file, solved as `like` is (exact or fast, the same chain).
    pub fn like(config: &RobotConfig, like: &ExtendedModel) -> Result<ExtendedModel, ModelError> {
        let mut m = ExtendedModel::new(config, like.chain)?;
        m.exact = like.exact;
        Ok(m)
    }

    /// The effects.
    pub fn effects(&self) -> &Effects {
        &self.config.effects
    }

    /// Predictions for every row of a series.
    pub fn predict(&self, s: &Series) -> Vec<Prediction> {
        self.predict_where(s, &|_| true)
    }

    /// Predictions for every row of a series; the pose (forward kinematics) only where `want`
    /// says so (the histories of latency, backlash and creep always run over every row).
    ///
    /// The rows are solved in chunks of [`PREDICT_CHUNK`] in parallel, each started from the
    /// last measured pose at or before its first row: the result does not depend on the number
    /// of threads. An exact model ([`ExtendedModel::exact`]) solves the series in one pass.
    pub fn predict_where(
        &self,
        s: &Series,
        want: &(dyn Fn(usize) -> bool + Sync),
    ) -> Vec<Prediction> {
        self.predict_where_from(s, want, Solving::default())
    }

    /// [`ExtendedModel::predict_where`] solved as `how` says: a loaded row solved in sequence
    /// (not interpolated) started from the state `how.states` keeps for it from an earlier
    /// prediction (of a nearby model), and its state kept there; the rows not yet solved left
    /// unsolved once more wanted rows have failed than `how.failures` allows.
    pub fn predict_where_from(
        &self,
        s: &Series,
        want: &(dyn Fn(usize) -> bool + Sync),
        how: Solving,
    ) -> Vec<Prediction> {
        let tendons = self.tendons(s);
        let n = s.samples.len();
        let chunk = if self.exact { n.max(1) } else { PREDICT_CHUNK };
        let starts: Vec<usize> = (0..n).step_by(chunk).collect();
        let parts: Vec<Vec<Prediction>> = starts
            .par_iter()
            .map(|&k0| {
                let range = k0..(k0 + chunk).min(n);
                self.predict_range(s, range, &tendons, want, how)
            })
            .collect();
        // Gathered on every core (a series of 44k rows is 12 MB of predictions, one core's
        // copy of it and its fresh pages 5-10 ms at each prediction).
        let mut preds: Vec<Prediction> = (0..n)
            .into_par_iter()
            .map(|k| parts[k / chunk][k % chunk])
            .collect();
        // The friction's history runs from the first row to the last one wanted (the rows after
        // it are not predicted; a series none of whose rows is wanted, e.g. the holdout in a
        // training context, takes no pass).
        let last_wanted = (0..n).rev().find(|&k| want(k));
        if let (Some(f), Some(last)) = (&self.friction, last_wanted) {
            let started = std::time::Instant::now();
            // With the derivatives, the pass a linearisation makes: over every row.
            let upto = if self.friction_derivatives {
                n - 1
            } else {
                last
            };
            let kappa: Vec<[f64; 3]> = preds[..=upto].iter().map(|p| p.kappa).collect();
            let rigid = self.rigid_path(s, &kappa);
            let path = if self.friction_derivatives {
                self.friction_path_tangent(&rigid, &kappa, f)
                    .into_iter()
                    .map(|r| r.map(|(d, _)| d))
                    .collect()
            } else {
                self.friction_path(&rigid, &kappa, f)
            };
            for (k, d) in path.into_iter().enumerate() {
                let p = &mut preds[k];
                match (p.pose.as_mut(), d) {
                    (Some(q), Some(d)) => {
                        for c in 0..3 {
                            q[c] += d[c];
                        }
                        p.friction = Some(d);
                    }
                    (Some(_), None) => {
                        p.pose = None;
                        how.failed(s.samples[k].pose.is_some());
                    }
                    _ => {}
                }
            }
            tracing::debug!(
                rows = preds.len(),
                seconds = started.elapsed().as_secs_f64(),
                "friction path of a prediction"
            );
        }
        preds
    }

    /// The predicted poses of the rows `rows` of a series (ascending), in their order, solved
    /// as [`ExtendedModel::predict_where_from`] solves them with `want` true on exactly those
    /// rows (the same chunks, warm starts and histories: bit for bit its poses), for a model
    /// without friction; with friction, read from that prediction. What a refinement's
    /// evaluation reads (a few thousand rows of a series of 40k): each chunk's predictions are
    /// dropped once its rows' poses are read, instead of a prediction of every row (280 bytes
    /// a row) gathered into one vector.
    pub fn predict_poses(&self, s: &Series, rows: &[usize], how: Solving) -> Vec<Option<[f64; 3]>> {
        let want = mask(s.samples.len(), rows);
        if self.friction.is_some() {
            let preds = self.predict_where_from(s, &|k| want[k], how);
            return rows.iter().map(|&k| preds[k].pose).collect();
        }
        let tendons = self.tendons(s);
        let n = s.samples.len();
        let chunk = if self.exact { n.max(1) } else { PREDICT_CHUNK };
        let starts: Vec<usize> = (0..n).step_by(chunk).collect();
        let parts: Vec<Vec<Option<[f64; 3]>>> = starts
            .par_iter()
            .map(|&k0| {
                let range = k0..(k0 + chunk).min(n);
                let lo = rows.partition_point(|&k| k < range.start);
                let hi = rows.partition_point(|&k| k < range.end);
                if lo == hi {
                    return Vec::new();
                }
                let preds = self.predict_range(s, range, &tendons, &|k| want[k], how);
                rows[lo..hi].iter().map(|&k| preds[k - k0].pose).collect()
            })
            .collect();
        parts.concat()
    }

    /// The rigid pose of every row of a series for the curvatures `kappa` (one per row),
    /// warm-started from row to row and from the measured poses; `None` where the kinematics do
    /// not close.
    pub fn rigid_path(&self, s: &Series, kappa: &[[f64; 3]]) -> std::sync::Arc<RigidPath> {
        let q_eff = self.effective_steps(s, &self.config.effects);
        if let Some(p) = kept::find_rigid(&self.config, s, kappa, &q_eff) {
            tracing::debug!(rows = kappa.len(), "rigid path kept");
            return p;
        }
        // In chunks of about PREDICT_CHUNK rows in parallel, each starting at a row that the
        // pass from the first row solves from its own measured pose (its curvatures not the
        // row before's): the same poses, to the bit, as that pass.
        let n = kappa.len().min(s.samples.len());
        let mut starts: Vec<usize> = (0..n)
            .step_by(PREDICT_CHUNK)
            .filter_map(|k0| {
                (k0..n)
                    .find(|&k| k == 0 || (kappa[k] != kappa[k - 1] && s.samples[k].pose.is_some()))
            })
            .collect();
        starts.dedup();
        let ends: Vec<usize> = starts.iter().skip(1).copied().chain([n]).collect();
        let poses: Vec<Option<Pose>> = starts
            .par_iter()
            .zip(&ends)
            .map(|(&k0, &k1)| self.rigid_poses(s, kappa, k0..k1))
            .flatten_iter()
            .collect();
        let stairs = (0..poses.len())
            .into_par_iter()
            .map(|k| {
                let (Some(prev), Some(_)) = (k.checked_sub(1).and_then(|j| poses[j]), poses[k])
                else {
                    return Vec::new();
                };
                self.stair(&prev, &kappa[k - 1], &kappa[k], &q_eff[k - 1], &q_eff[k])
            })
            .collect();
        let path = std::sync::Arc::new(RigidPath { poses, stairs });
        kept::keep_rigid(&self.config, s, kappa, &q_eff, path.clone());
        path
    }

    /// The rigid poses of the rows `rows` of a series at the curvatures `kappa` (all the
    /// series'), solved in order from the last measured pose at or before the first: each row
    /// from its own measured pose, or from the row before's answer where it has none; a row at
    /// the curvatures of the row before takes its pose.
    fn rigid_poses(
        &self,
        s: &Series,
        kappa: &[[f64; 3]],
        rows: std::ops::Range<usize>,
    ) -> Vec<Option<Pose>> {
        let mut guess = start_guess(s, rows.start);
        let mut last: Option<([f64; 3], Pose)> = None;
        kappa[rows.clone()]
            .iter()
            .zip(&s.samples[rows])
            .map(|(k, smp)| {
                if let Some((_, lp)) = last.filter(|(lk, _)| lk == k) {
                    return Some(lp);
                }
                if let Some(p) = smp.pose {
                    guess = Pose::new(p[0], p[1], p[2]);
                }
                let p = self.robot.fk_warm(k, &guess).ok()?;
                guess = p;
                last = Some((*k, p));
                Some(p)
            })
            .collect()
    }

    /// The configurations between two rows (pose `p0` at curvatures `k0` and motor positions
    /// `q0`, then `k1` at `q1`) after each step time of the legs, the last (the row's own)
    /// excluded ([`RigidPath`]). Leg l's n_l = |q1 - q0| steps (rounded) come at the fractions
    /// j / n_l of the interval, its curvature changing by an equal share at each; legs stepping
    /// at the same fraction step together.
    fn stair(
        &self,
        p0: &Pose,
        k0: &[f64; 3],
        k1: &[f64; 3],
        q0: &[f64; 3],
        q1: &[f64; 3],
    ) -> Vec<(Pose, [f64; 3])> {
        if k0 == k1 {
            return Vec::new();
        }
        let n: [usize; 3] = std::array::from_fn(|l| {
            if k0[l] == k1[l] {
                0
            } else {
                ((q1[l] - q0[l]).abs().round() as usize).clamp(1, MAX_STAIR)
            }
        });
        // The step times as fractions j / n_l, in order, each once.
        let mut times: Vec<(usize, usize)> = (0..3)
            .flat_map(|l| (1..=n[l]).map(move |j| (j, n[l])))
            .collect();
        times.sort_by(|a, b| (a.0 * b.1).cmp(&(b.0 * a.1)));
        times.dedup_by(|a, b| a.0 * b.1 == b.0 * a.1);
        times.pop(); // 1: the row itself
        let mut guess = *p0;
        let mut out = Vec::with_capacity(times.len());
        for (j, m) in times {
            let kq: [f64; 3] = std::array::from_fn(|l| {
                if n[l] == 0 {
                    return k0[l];
                }
                // The steps leg l has taken by j / m of the interval.
                let done = (j * n[l]) / m;
                k0[l] + (k1[l] - k0[l]) * done as f64 / n[l] as f64
            });
            if let Ok(q) = self.robot.fk_warm(&kq, &guess) {
                guess = q;
                out.push((q, kq));
            }
        }
        out
    }

    /// Stage 5b: the friction's deflection of every row of a path (x mm, y mm, phi rad) from
    /// its rigid poses and curvatures ([`ExtendedModel::rigid_path`]), in order from the first
    /// row (every element unloaded there); `None` where the row has no rigid pose or the
    /// friction has no answer (a row without a pose leaves the elements as they were).
    pub fn friction_path(
        &self,
        rigid: &RigidPath,
        kappa: &[[f64; 3]],
        f: &Friction,
    ) -> Vec<Option<[f64; 3]>> {
        let rows = self.kept_pass(rigid, kappa, f, false);
        rows.iter().map(|r| r.map(|r| r.d)).collect()
    }

    /// [`ExtendedModel::friction_path`] with the derivatives of every row's deflection by the
    /// friction's fitted values (the joints' couple N mm, the supports' force N, the joints'
    /// pre-sliding travel rad), in the same pass
    /// ([`pcr_kinematics::Robot::friction_step_tangent`]).
    pub fn friction_path_tangent(
        &self,
        rigid: &RigidPath,
        kappa: &[[f64; 3]],
        f: &Friction,
    ) -> Vec<Option<DeflectionTangent>> {
        let rows = self.kept_pass(rigid, kappa, f, true);
        rows.iter().map(|r| r.map(|r| (r.d, r.t))).collect()
    }

    /// [`ExtendedModel::friction_path`] with the displacement of the joints M_i at every row
    /// (base frame, mm): what the friction does to the markers a calibration reads. With
    /// `linearised`, from the pass with the derivatives by the friction's values
    /// ([`ExtendedModel::friction_path_tangent`]), made and kept where none is: the pass a
    /// refinement of this model's effects then linearises its friction with.
    pub fn friction_path_with_joints(
        &self,
        rigid: &RigidPath,
        kappa: &[[f64; 3]],
        f: &Friction,
        linearised: bool,
    ) -> Vec<Option<DeflectionAndJoints>> {
        let rows = self.kept_pass(rigid, kappa, f, linearised);
        rows.iter().map(|r| r.map(|r| (r.d, r.joints))).collect()
    }

    /// The friction's pass along `rigid` (with the derivatives when `tangent`), as one made
    /// before for the same legs, path and friction left it ([`KEPT`]), or made now and kept.
    fn kept_pass(
        &self,
        rigid: &RigidPath,
        kappa: &[[f64; 3]],
        f: &Friction,
        tangent: bool,
    ) -> std::sync::Arc<Vec<Option<PassRow>>> {
        if let Some(rows) = kept::find(&self.config, rigid, kappa, f, tangent) {
            tracing::debug!(rows = kappa.len(), tangent, "friction pass kept");
            return rows;
        }
        let rows = std::sync::Arc::new(if tangent {
            along_path(rigid, kappa, |p, k, (state, tan), at| match at {
                Passing::Row => {
                    let (d, t) = self.robot.friction_step_tangent(f, p, k, state, tan).ok()?;
                    Some(PassRow {
                        d,
                        t,
                        joints: state.joints(),
                    })
                }
                Passing::Between => {
                    let _ = self.robot.friction_pass(f, p, k, state, Some(tan));
                    None
                }
            })
        } else {
            along_path(rigid, kappa, |p, k, state, at| {
                let d = match at {
                    Passing::Row => self.robot.friction_step(f, p, k, state).ok()?,
                    Passing::Between => self.robot.friction_pass(f, p, k, state, None).ok()?,
                };
                Some(PassRow {
                    d,
                    t: [[0.0; 3]; 3],
                    joints: state.joints(),
                })
            })
        });
        kept::keep(&self.config, rigid, kappa, f, tangent, rows.clone());
        rows
    }

    /// The derivatives of every row's friction deflection with respect to the joints' and the
    /// supports' limits at zero friction ([`pcr_kinematics::Robot::friction_onset`]): per row,
    /// (x mm, y mm, phi rad) per N mm of the joints' couple and per N of the supports' force,
    /// with the pre-sliding travels and the bending stiffness of `f`.
    pub fn friction_onset_path(
        &self,
        rigid: &RigidPath,
        kappa: &[[f64; 3]],
        f: &Friction,
    ) -> Vec<Option<[[f64; 3]; 2]>> {
        along_path(rigid, kappa, |p, k, state, at| match at {
            Passing::Row => self.robot.friction_onset(f, p, k, state).ok(),
            Passing::Between => {
                let _ = self.robot.friction_onset_pass(f, p, k, state);
                None
            }
        })
    }

    /// Stages 1 to 4 of every row of a series: the effective motor positions (steps), the
    /// effective tendon displacements (mm), and the legs' mm per step.
    fn tendons(&self, s: &Series) -> Tendons {
        let e = &self.config.effects;
        let q_eff = self.effective_steps(s, e);
        let mmps: [f64; 3] = std::array::from_fn(|i| self.config.legs[i].actuation.mm_per_step());
        let mut dl_eff: Vec<[f64; 3]> = q_eff
            .iter()
            .map(|q| std::array::from_fn(|i| q[i] * mmps[i]))
            .collect();
        for x in self.chain {
            x.tendons(e, s, &mut dl_eff);
        }
        (q_eff, dl_eff, mmps)
    }

    /// The curvatures of the rows `rows` of a series (stages 1 to 5 up to the tendon map, the
    /// histories over every row; no kinematics), in the order of `rows`.
    pub fn curvatures(&self, s: &Series, rows: &[usize]) -> Vec<[f64; 3]> {
        let (_, dl_eff, _) = self.tendons(s);
        rows.iter()
            .map(|&k| std::array::from_fn(|i| self.robot.legs[i].map.kappa(dl_eff[k][i])))
            .collect()
    }

    /// The predicted pose of the rows `rows` of a series (ascending) with its first-order
    /// responses to the curvatures and, when the model is loaded, to the five load parameters
    /// ([`pcr_kinematics::Robot::loaded_sensitivity_warm`]): the derivative of the prediction
    /// with respect to any parameter that acts through the curvatures or the loads, without
    /// solving the kinematics again per parameter. `None` where the model has no pose. The
    /// rows are solved in chunks in parallel, each warm-started along the chunk from the
    /// measured poses.
    ///
    /// With `states`, a loaded row is started from the state kept for it (an earlier solve of
    /// the row for a nearby model), and its state is kept there.
    pub fn sensitivities(
        &self,
        s: &Series,
        rows: &[usize],
        states: Option<&RowStates>,
    ) -> Vec<Option<Sensitivity>> {
        const CHUNK: usize = 256;
        let kappa = self.curvatures(s, rows);
        let parts: Vec<Vec<Option<Sensitivity>>> = rows
            .par_chunks(CHUNK)
            .zip(kappa.par_chunks(CHUNK))
            .map(|(c, kc)| {
                let mut warm = pcr_kinematics::statics::LoadedWarm::default();
                let mut guess = start_guess(s, c[0]);
                // The last row solved: a row at rest (the same curvatures) takes its result.
                let mut last: Option<Sensitivity> = None;
                c.iter()
                    .zip(kc)
                    .map(|(&k, &kp)| {
                        if let Some(p) = s.samples[k].pose {
                            guess = Pose::new(p[0], p[1], p[2]);
                        }
                        if let Some(x) = last.filter(|x| x.kappa == kp) {
                            return Some(x);
                        }
                        let out = match &self.loads {
                            Some(l) => {
                                resume(states, k, &mut warm);
                                let x = self
                                    .robot
                                    .loaded_sensitivity_warm(&kp, l, &guess, &mut warm);
                                if x.is_ok() {
                                    keep(states, k, &warm);
                                }
                                x.ok().map(|x| Sensitivity {
                                    pose: [x.pose.x, x.pose.y, x.pose.phi],
                                    kappa: kp,
                                    d_kappa: Matrix3::from_fn(|r, c| x.d_kappa[c][r]),
                                    d_loads: x.d_loads,
                                })
                            }
                            None => self.robot.fk_warm(&kp, &guess).ok().and_then(|p| {
                                Some(Sensitivity {
                                    pose: [p.x, p.y, p.phi],
                                    kappa: kp,
                                    d_kappa: self.robot.jacobian(&p, &kp)?,
                                    d_loads: [[0.0; 3]; 5],
                                })
                            }),
                        };
                        if let Some(x) = &out {
                            guess = Pose::new(x.pose[0], x.pose[1], x.pose[2]);
                        }
                        last = out;
                        out
                    })
                    .collect()
            })
            .collect();
        parts.concat()
    }

    /// A row's prediction before its kinematics: its effective motor positions and tendon
    /// displacements, and the curvatures the map gives; no pose.
    fn unsolved(&self, q_eff: [f64; 3], dl_eff: [f64; 3]) -> Prediction {
        Prediction {
            pose: None,
            q_eff,
            dl_eff,
            kappa: std::array::from_fn(|i| self.robot.legs[i].map.kappa(dl_eff[i])),
            j_q: Matrix3::zeros(),
            j_kappa: Matrix3::zeros(),
            friction: None,
        }
    }

    /// d pose / d q_eff and d pose / d kappa of a row at `pose` (the rigid kinematics).
    fn jacobians(
        &self,
        pose: &Pose,
        kappa: &[f64; 3],
        dl_eff: &[f64; 3],
        mmps: &[f64; 3],
    ) -> (Matrix3<f64>, Matrix3<f64>) {
        let jk = self
            .robot
            .jacobian(pose, kappa)
            .unwrap_or_else(Matrix3::zeros);
        let d = Matrix3::from_diagonal(&nalgebra::Vector3::from(std::array::from_fn::<f64, 3, _>(
            |i| {
                // The slope over one motor step: the root maps' slope is infinite at dl = 0, a
                // step is the smallest change there is.
                let m = &self.robot.legs[i].map;
                let h = 0.5 * mmps[i];
                let dl = dl_eff[i];
                (m.kappa(dl + h) - m.kappa(dl - h)) / (2.0 * h) * mmps[i]
            },
        )));
        (jk * d, jk)
    }

    /// [`ExtendedModel::predict_range`] for a loaded model: the rigid kinematics at every row,
    /// the loads' deflection of the pose (loaded less rigid) solved with its gradient in the
    /// configuration where [`crate::interpolation::interpolate`] says (the anchors of the
    /// configuration's path and the middle of every stretch between them) and interpolated
    /// along the configuration elsewhere, each stretch checked to [`DEFLECTION_TOLERANCE_MM`]
    /// (position) and [`DEFLECTION_TOLERANCE_RAD`]. With joint springs every row was solved
    /// until the gradients came (interpolated linearly, 98 % of the stretches failed their
    /// check: the deflection changes by 10-15 mm per rad of bending across the staircase the
    /// stepping motors draw about each chord); a constant load was interpolated linearly, and
    /// its rows between the checked ones were off by up to 3x the tolerance in position and
    /// 7x in orientation (the test below).
    fn predict_range_loaded(
        &self,
        s: &Series,
        range: std::ops::Range<usize>,
        tendons: &Tendons,
        want: &(dyn Fn(usize) -> bool + Sync),
        how: Solving,
    ) -> Vec<Prediction> {
        let (q_eff, dl_eff, mmps) = (&tendons.0, &tendons.1, &tendons.2);
        let Some(loads) = &self.loads else {
            return Vec::new();
        };
        let k0 = range.start;
        let mut guess = start_guess(s, k0);
        let mut out: Vec<Prediction> = Vec::with_capacity(range.len());
        // The rows whose loaded equilibrium is needed (a row at rest takes its predecessor's).
        let mut unique: Vec<usize> = Vec::new();
        let mut source: Vec<Option<usize>> = Vec::with_capacity(range.len());
        for k in range.clone() {
            let smp = &s.samples[k];
            let mut pred = self.unsolved(q_eff[k], dl_eff[k]);
            let kappa = pred.kappa;
            if let Some(p) = smp.pose {
                guess = Pose::new(p[0], p[1], p[2]);
            }
            if !want(k) || how.stopped() {
                out.push(pred);
                source.push(None);
                continue;
            }
            if let Some(&Some(prev)) = source.last() {
                let p: &Prediction = &out[prev - k0];
                if p.pose.is_some() && p.kappa == kappa && p.dl_eff == dl_eff[k] {
                    pred.pose = p.pose;
                    out.push(pred);
                    source.push(Some(prev));
                    continue;
                }
            }
            let rigid = self.robot.fk_warm(&kappa, &guess).ok();
            if let Some(r) = rigid {
                guess = r;
                unique.push(k);
                source.push(Some(k));
            } else {
                how.failed(smp.pose.is_some());
                source.push(None);
            }
            pred.pose = rigid.map(|p| [p.x, p.y, p.phi]);
            out.push(pred);
        }
        let lc: [f64; 3] = std::array::from_fn(|i| self.robot.legs[i].l_c);
        let cfg: Vec<[f64; 3]> = unique
            .iter()
            .map(|&k| std::array::from_fn(|l| out[k - k0].kappa[l] * lc[l]))
            .collect();
        let breaks = vec![false; unique.len()];
        // Each row solved keeps its solver state: a row is started from the state of the
        // nearest row solved before it (the middle of a stretch from the stretch's start),
        // where the configuration is closest.
        let mut states: std::collections::BTreeMap<usize, pcr_kinematics::statics::LoadedWarm> =
            std::collections::BTreeMap::new();
        // Each row solved carries the deflection's gradient in the configuration (the loaded
        // responses to the curvatures less the rigid ones, per segment's bending), so that the
        // rows between take the steep change across the path's chords where the motors step
        // one at a time ([`WithGradient`]). Where the warm-started solve fails, the cold one
        // gives the value alone (its stretches interpolated linearly, still checked).
        let mut solve = |idx: &[usize]| -> Vec<Option<WithGradient<3>>> {
            idx.iter()
                .map(|&u| {
                    let mut warm = states
                        .range(..u)
                        .next_back()
                        .map(|(_, w)| w.clone())
                        .unwrap_or_default();
                    let k = unique[u];
                    let p = &out[k - k0];
                    let rigid = p.pose?;
                    let guess = s.samples[k]
                        .pose
                        .map_or(Pose::new(rigid[0], rigid[1], rigid[2]), |m| {
                            Pose::new(m[0], m[1], m[2])
                        });
                    let rigid_pose = Pose::new(rigid[0], rigid[1], rigid[2]);
                    let (pose, gradient) = match self
                        .robot
                        .loaded_sensitivity_warm(&p.kappa, loads, &guess, &mut warm)
                    {
                        Ok(x) => {
                            let gradient = self.robot.jacobian(&rigid_pose, &p.kappa).map(|jr| {
                                std::array::from_fn(|l| {
                                    std::array::from_fn(|j| (x.d_kappa[l][j] - jr[(j, l)]) / lc[l])
                                })
                            });
                            (x.pose, gradient)
                        }
                        Err(_) => (
                            self.robot.fk_loaded(&p.kappa, loads, &guess).ok()?.pose,
                            None,
                        ),
                    };
                    states.insert(u, warm);
                    Some(WithGradient {
                        value: [pose.x - rigid[0], pose.y - rigid[1], pose.phi - rigid[2]],
                        gradient,
                    })
                })
                .collect()
        };
        let within = |a: &WithGradient<3>, b: &WithGradient<3>| {
            let (a, b) = (&a.value, &b.value);
            (a[0] - b[0]).abs() <= DEFLECTION_TOLERANCE_MM
                && (a[1] - b[1]).abs() <= DEFLECTION_TOLERANCE_MM
                && (a[2] - b[2]).abs() <= DEFLECTION_TOLERANCE_RAD
        };
        let (deflection, st) = crate::interpolation::interpolate::<WithGradient<3>>(
            &cfg, &breaks, &mut solve, &within,
        );
        tracing::trace!(
            "loaded rows {}..{}: {} of {} solved ({} anchors, {} checks, {} bisected)",
            range.start,
            range.end,
            st.solved,
            st.rows,
            st.anchors,
            st.checked,
            st.bisected
        );
        for (&k, d) in unique.iter().zip(deflection) {
            let p = &mut out[k - k0];
            p.pose = match (p.pose, d.map(|d| d.value)) {
                (Some(r), Some(d)) => Some([r[0] + d[0], r[1] + d[1], r[2] + d[2]]),
                _ => {
                    how.failed(s.samples[k].pose.is_some());
                    None
                }
            };
            if let Some(q) = p.pose.filter(|_| !how.poses_only) {
                let (j_q, j_kappa) =
                    self.jacobians(&Pose::new(q[0], q[1], q[2]), &p.kappa, &p.dl_eff, mmps);
                p.j_q = j_q;
                p.j_kappa = j_kappa;
            }
        }
        for (i, src) in source.iter().enumerate() {
            if let Some(j) = *src {
                if j - k0 != i {
                    let from = out[j - k0];
                    let p = &mut out[i];
                    p.pose = from.pose;
                    p.j_q = from.j_q;
                    p.j_kappa = from.j_kappa;
                }
            }
        }
        out
    }

    /// Predictions for the rows `range` of a series from their effective motor positions and
    /// tendon displacements.
    fn predict_range(
        &self,
        s: &Series,
        range: std::ops::Range<usize>,
        tendons: &Tendons,
        want: &(dyn Fn(usize) -> bool + Sync),
        how: Solving,
    ) -> Vec<Prediction> {
        let (q_eff, dl_eff, mmps) = (&tendons.0, &tendons.1, &tendons.2);
        if self.loads.is_some() && !self.exact && self.interpolate {
            return self.predict_range_loaded(s, range, tendons, want, how);
        }
        let mut out: Vec<Prediction> = Vec::with_capacity(range.len());
        let mut warm = pcr_kinematics::statics::LoadedWarm::default();
        let mut guess = start_guess(s, range.start);
        for k in range {
            let smp = &s.samples[k];
            let mut pred = self.unsolved(q_eff[k], dl_eff[k]);
            let kappa = pred.kappa;
            // Warm start at the measured pose where there is one (robust across jumps).
            if let Some(p) = smp.pose {
                guess = Pose::new(p[0], p[1], p[2]);
            }
            if !want(k) || how.stopped() {
                out.push(pred);
                continue;
            }
            // A row whose configuration is the previous one's (at rest) has its prediction.
            if !self.exact {
                if let Some(prev) = out.last().filter(|p: &&Prediction| {
                    p.pose.is_some() && p.kappa == kappa && p.dl_eff == dl_eff[k]
                }) {
                    let mut same = *prev;
                    same.q_eff = q_eff[k];
                    out.push(same);
                    continue;
                }
            }
            let pose = match &self.loads {
                Some(l) if self.exact => {
                    self.robot.fk_loaded(&kappa, l, &guess).ok().map(|e| e.pose)
                }
                Some(l) => {
                    resume(how.states, k, &mut warm);
                    let e = self.robot.fk_loaded_warm(&kappa, l, &guess, &mut warm);
                    if e.is_ok() {
                        keep(how.states, k, &warm);
                    }
                    e.or_else(|_| self.robot.fk_loaded(&kappa, l, &guess))
                        .ok()
                        .map(|e| e.pose)
                }
                None => self.robot.fk_warm(&kappa, &guess).ok(),
            };
            match pose {
                Some(p) => {
                    if !how.poses_only {
                        (pred.j_q, pred.j_kappa) = self.jacobians(&p, &kappa, &dl_eff[k], mmps);
                    }
                    pred.pose = Some([p.x, p.y, p.phi]);
                    guess = p;
                }
                None => how.failed(smp.pose.is_some()),
            }
            out.push(pred);
        }
        out
    }

    /// The measured pose of a row (x mm, y mm, phi rad) with the effects' corrections of the
    /// measurement applied (stage 6).
    pub fn corrected(&self, m: [f64; 3]) -> [f64; 3] {
        self.chain
            .iter()
            .fold(m, |m, x| x.corrected(&self.config.effects, m))
    }

    /// A row's residual, measured - predicted (x mm, y mm, and phi as `w_phi * dphi`, mm), the
    /// measurement corrected by the effects ([`ExtendedModel::corrected`]).
    pub fn residual(&self, measured: [f64; 3], predicted: [f64; 3], w_phi: f64) -> [f64; 3] {
        let m = self.corrected(measured);
        [
            m[0] - predicted[0],
            m[1] - predicted[1],
            w_phi * pcr_robot::geometry::wrap_angle(m[2] - predicted[2]),
        ]
    }

    /// The motor outputs of every row of a series (steps) before the play, when the model's
    /// effects are `effects`: the commands delayed (stage 1) and through the transmission
    /// (stage 2).
    pub fn steps_before_play(&self, s: &Series, effects: &Effects) -> Vec<[f64; 3]> {
        let delay: f64 = self.chain.iter().map(|x| x.delay_s(effects)).sum();
        let mut q = delayed_steps(s, s.delay_s + delay);
        for x in self.chain {
            x.transmission(effects, &mut q);
        }
        q
    }

    /// The motor outputs of every row of a series (steps) when the model's effects are
    /// `effects`: stages 1 to 3 (timing, transmission, play).
    pub fn effective_steps(&self, s: &Series, effects: &Effects) -> Vec<[f64; 3]> {
        let mut q = self.steps_before_play(s, effects);
        for x in self.chain {
            x.play(effects, &mut q);
        }
        q
    }

    /// [`ExtendedModel::effective_steps`] of the rows `ks` of a series (ascending), the same
    /// values. Without a play (no stage [`Extension::plays`]) only those rows are computed: a
    /// profile over a latency evaluates some eighty delays on a fifth of the rows.
    pub fn effective_steps_at(&self, s: &Series, effects: &Effects, ks: &[usize]) -> Vec<[f64; 3]> {
        if self.chain.iter().any(|x| x.plays(effects)) {
            let q = self.effective_steps(s, effects);
            return ks.iter().map(|&k| q[k]).collect();
        }
        let delay: f64 = self.chain.iter().map(|x| x.delay_s(effects)).sum();
        let mut q = delayed_steps_at(s, s.delay_s + delay, ks.iter().copied());
        for x in self.chain {
            x.transmission(effects, &mut q);
        }
        q
    }
}

/// Where the kinematics of a series' rows from row `k` on start: the last measured pose at or
/// before it (the first of the series where there is none before).
fn start_guess(s: &Series, k: usize) -> Pose {
    s.samples[..=k.min(s.samples.len().saturating_sub(1))]
        .iter()
        .rev()
        .find_map(|x| x.pose)
        .or_else(|| s.samples.iter().find_map(|x| x.pose))
        .map_or(Pose::default(), |p| Pose::new(p[0], p[1], p[2]))
}

/// The commanded motor positions of every row shifted back by `delay` (interpolated; one pass).
pub fn delayed_steps(s: &Series, delay: f64) -> Vec<[f64; 3]> {
    delayed_steps_at(s, delay, 0..s.samples.len())
}

/// [`delayed_steps`] of the rows `ks` (ascending): one pass that moves from each row's bracket
/// to the next one's.
fn delayed_steps_at(
    s: &Series,
    delay: f64,
    ks: impl ExactSizeIterator<Item = usize>,
) -> Vec<[f64; 3]> {
    let x = &s.samples;
    let mut out = Vec::with_capacity(ks.len());
    let mut j = 0usize;
    for k in ks {
        let t = x[k].t_s - delay;
        while j + 1 < x.len() && x[j + 1].t_s <= t {
            j += 1;
        }
        while j > 0 && x[j].t_s > t {
            j -= 1;
        }
        let q = if t <= x[0].t_s {
            x[0].q
        } else if j + 1 >= x.len() {
            x[x.len() - 1].q
        } else {
            let (a, b) = (&x[j], &x[j + 1]);
            let f = (t - a.t_s) / (b.t_s - a.t_s);
            std::array::from_fn(|i| a.q[i] + f * (b.q[i] - a.q[i]))
        };
        out.push(q);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delayed_steps_interpolate_in_one_pass() {
        let mut rec = pcr_recording::Recording::default();
        for k in 0..10 {
            let mut r = pcr_recording::Row::new(k as f64 * 0.02, [k * 10, 0, -k]);
            r.pose = [Some(0.0); 3];
            rec.rows.push(r);
        }
        let s = Series::from_recording(&rec, "t").unwrap();
        let d = delayed_steps(&s, 0.03);
        assert_eq!(d[0], [0.0, 0.0, 0.0]);
        assert!(
            (d[5][0] - 35.0).abs() < 1e-9 && (d[5][2] + 3.5).abs() < 1e-9,
            "{:?}",
            d[5]
        );
        assert_eq!(delayed_steps(&s, -1.0)[3], [90.0, 0.0, -9.0]);
    }

    /// Between two rows each leg takes its steps at its own even rate: leg 1's two steps at 1/2
    /// and 1 of the interval, leg 2's three at 1/3, 2/3 and 1, leg 3 at rest; the stair holds
    /// the configurations after 1/3, 1/2 and 2/3 (the row's own, at 1, is not on it).
    #[test]
    fn a_stair_takes_each_legs_steps_at_its_own_rate() {
        let cfg = RobotConfig::nominal();
        let m = ExtendedModel::new(&cfg, crate::effects::chain()).unwrap();
        let home = m.robot.ik(&Pose::new(0.0, 0.0, 0.0)).unwrap();
        let k0 = home.kappa;
        let per_step = 2e-5;
        let k1 = [k0[0] + 2.0 * per_step, k0[1] - 3.0 * per_step, k0[2]];
        let p0 = m.robot.fk_warm(&k0, &Pose::new(0.0, 0.0, 0.0)).unwrap();
        let stair = m.stair(&p0, &k0, &k1, &[0.0, 0.0, 5.0], &[2.0, -3.0, 5.0]);
        let want = [
            [k0[0], k0[1] - per_step, k0[2]],
            [k0[0] + per_step, k0[1] - per_step, k0[2]],
            [k0[0] + per_step, k0[1] - 2.0 * per_step, k0[2]],
        ];
        assert_eq!(stair.len(), 3, "{stair:?}");
        for ((pose, k), w) in stair.iter().zip(want) {
            for l in 0..3 {
                assert!((k[l] - w[l]).abs() < 1e-15, "{k:?} against {w:?}");
            }
            let exact = m.robot.fk_warm(k, &p0).unwrap();
            assert!((pose.x - exact.x).abs() < 1e-9 && (pose.phi - exact.phi).abs() < 1e-12);
        }
        // At rest, no stair.
        assert!(m.stair(&p0, &k0, &k0, &[1.0; 3], &[1.0; 3]).is_empty());
    }

    /// Some rows' motor outputs are the whole series' at those rows, with a latency and a
    /// periodic error (computed at those rows alone) and with a play besides (the whole path).
    #[test]
    fn some_rows_motor_outputs_are_the_whole_series_at_them() {
        let cfg = RobotConfig::nominal();
        let s = swinging(&cfg, 400, 60.0, 1.3, 0.7);
        let m = ExtendedModel::new(&cfg, crate::effects::chain()).unwrap();
        let mut e = cfg.effects.clone();
        e.latency = Some(pcr_robot::effects::Latency { latency_s: 0.037 });
        e.periodic = vec![pcr_robot::effects::Periodic {
            motor: 2,
            period_steps: 16.0,
            amplitude_steps: 0.8,
            phase_deg: 30.0,
        }];
        let ks: Vec<usize> = (0..400)
            .filter(|k| k % 7 == 3 || *k < 2 || *k == 399)
            .collect();
        for backlash in [None, Some([3.0, 4.0, 3.0])] {
            e.backlash = backlash.map(|steps| pcr_robot::effects::Backlash { steps });
            let whole = m.effective_steps(&s, &e);
            let some = m.effective_steps_at(&s, &e, &ks);
            assert_eq!(some.len(), ks.len());
            for (q, &k) in some.iter().zip(&ks) {
                assert_eq!(*q, whole[k], "row {k}, backlash {backlash:?}");
            }
        }
    }

    #[test]
    fn the_poses_of_some_rows_are_the_prediction_of_those_rows() {
        // Rigid, under a load with springs (interpolated along the configuration), and with
        // friction (read from the whole prediction): bit for bit the poses of a prediction
        // that wants exactly those rows, spread over several chunks and none in some.
        let cfg = RobotConfig::nominal();
        let n = 3 * PREDICT_CHUNK + 100;
        let s = swinging(&cfg, n, 60.0, 1.3, 0.7);
        let ks: Vec<usize> = (0..n)
            .filter(|k| (*k < PREDICT_CHUNK && k % 97 == 5) || *k >= 2 * PREDICT_CHUNK + 7)
            .filter(|k| k % 13 == 0 || *k == n - 1)
            .collect();
        let loaded = {
            let mut c = cfg.clone();
            c.effects.compliance = Some(pcr_robot::effects::Compliance {
                ei_n_mm2: 6.5e4,
                force_n: [0.4, -0.3],
                couple_n_mm: 0.0,
                k_m_n_mm_per_rad: 300.0,
                k_p_n_mm_per_rad: 200.0,
            });
            c
        };
        for c in [cfg.clone(), loaded, rubbing()] {
            let m = ExtendedModel::new(&c, crate::effects::chain()).unwrap();
            let want = mask(n, &ks);
            let whole = m.predict_where(&s, &|k| want[k]);
            let some = m.predict_poses(&s, &ks, Solving::default());
            assert_eq!(some.len(), ks.len());
            for (p, &k) in some.iter().zip(&ks) {
                assert_eq!(*p, whole[k].pose, "row {k}");
            }
        }
    }

    /// The nominal robot with friction at three times the prototype's.
    fn rubbing() -> RobotConfig {
        let mut cfg = RobotConfig::nominal();
        cfg.effects.friction = Some(pcr_robot::effects::Friction {
            joint_torque_n_mm: 6.0,
            support_force_n: 0.12,
            joint_presliding_rad: pcr_robot::effects::Friction::default_joint_presliding(),
            support_presliding_mm: pcr_robot::effects::Friction::default_support_presliding(),
            ei_n_mm2: pcr_robot::effects::Friction::default_ei(),
        });
        cfg
    }

    /// Under friction, a prediction of some rows runs the friction's history only to the last
    /// of them: those rows are the whole prediction's, to the bit, and the rows after it are
    /// not predicted.
    #[test]
    fn some_rows_under_friction_are_the_whole_prediction_at_them() {
        let cfg = rubbing();
        let s = swinging(&cfg, 300, 80.0, 1.1, 0.9);
        let m = ExtendedModel::new(&cfg, crate::effects::chain()).unwrap();
        assert!(m.friction.is_some());
        let whole = m.predict(&s);
        let want = |k: usize| k % 4 == 1 && k < 200;
        let some = m.predict_where(&s, &want);
        for k in 0..300 {
            if want(k) {
                assert_eq!(whole[k].pose, some[k].pose, "row {k}");
                assert!(some[k].pose.is_some(), "row {k}");
            } else if k > 197 {
                assert!(some[k].pose.is_none(), "row {k} is not wanted");
            }
        }
        // A row wanted alone still has the history of the path that led to it.
        assert_eq!(
            m.predict_where(&s, &|j| j == 197)[197].pose,
            whole[197].pose
        );
        // And the friction acts on these rows.
        let mut none = cfg.clone();
        none.effects.friction = None;
        let rigid = ExtendedModel::new(&none, crate::effects::chain())
            .unwrap()
            .predict(&s);
        let moved = (0..300)
            .filter(|&k| match (whole[k].pose, rigid[k].pose) {
                (Some(a), Some(b)) => (a[0] - b[0]).hypot(a[1] - b[1]) > 1e-3,
                _ => false,
            })
            .count();
        assert!(moved > 100, "{moved} rows deflected by the friction");
    }

    /// A swinging series of `n` rows under [`rubbing`]'s friction: the model, its friction, the
    /// rows' curvatures and the rigid path.
    fn rubbing_path(
        n: usize,
    ) -> (
        Series,
        ExtendedModel,
        Friction,
        Vec<[f64; 3]>,
        std::sync::Arc<RigidPath>,
    ) {
        let cfg = rubbing();
        let s = swinging(&cfg, n, 80.0, 1.1, 0.9);
        let m = ExtendedModel::new(&cfg, crate::effects::chain()).unwrap();
        let f = m.friction.unwrap();
        let kappa: Vec<[f64; 3]> = m.predict(&s).iter().map(|p| p.kappa).collect();
        let rigid = m.rigid_path(&s, &kappa);
        (s, m, f, kappa, rigid)
    }

    /// A friction pass given again from the kept ones ([`kept`]) is the pass made afresh, to the
    /// bit; one without the derivatives does not answer one with them; another friction is
    /// another pass, but one at a negligible joints' couple answers one at zero couple as that
    /// one made afresh does; and a prediction made with the derivatives predicts what one
    /// without does.
    #[test]
    fn a_kept_friction_pass_is_the_pass_made_again() {
        let (s, m, f, kappa, rigid) = rubbing_path(300);
        assert_eq!(m.rigid_path(&s, &kappa).poses, rigid.poses);
        forget_kept();
        let plain = m.friction_path(&rigid, &kappa, &f);
        // Asked for with the derivatives after a pass without them: made, with them.
        let tangent = m.friction_path_tangent(&rigid, &kappa, &f);
        let derivatives = tangent
            .iter()
            .flatten()
            .filter(|(_, t)| t.iter().flatten().any(|v| *v != 0.0))
            .count();
        assert!(derivatives > 100, "{derivatives} rows with derivatives");
        let deflections: Vec<Option<[f64; 3]>> =
            tangent.iter().map(|r| r.map(|(d, _)| d)).collect();
        assert_eq!(deflections, plain);
        // Given again (kept, or made again when another test forgot it), the same to the bit.
        assert_eq!(m.friction_path_tangent(&rigid, &kappa, &f), tangent);
        assert_eq!(m.friction_path(&rigid, &kappa, &f), plain);
        let joints = m.friction_path_with_joints(&rigid, &kappa, &f, false);
        forget_kept();
        assert_eq!(
            m.friction_path_with_joints(&rigid, &kappa, &f, false),
            joints
        );
        assert_eq!(m.friction_path_tangent(&rigid, &kappa, &f), tangent);
        // Asked for from the pass with the derivatives: the same joints, and that pass kept.
        forget_kept();
        assert_eq!(
            m.friction_path_with_joints(&rigid, &kappa, &f, true),
            joints
        );
        assert_eq!(m.friction_path_tangent(&rigid, &kappa, &f), tangent);
        // Another friction is another pass.
        let stronger = Friction {
            joint_torque: 2.0 * f.joint_torque,
            ..f
        };
        assert_ne!(m.friction_path(&rigid, &kappa, &stronger), plain);
        // A pass at a negligible joints' couple serves one at zero couple: what the pass made
        // at zero couple answers, to the bit (the derivatives by the joints' values zero).
        let (negligible, zero) = (
            Friction {
                joint_torque: 1e-25,
                ..f
            },
            Friction {
                joint_torque: 0.0,
                ..f
            },
        );
        forget_kept();
        let fresh = m.friction_path_tangent(&rigid, &kappa, &zero);
        forget_kept();
        let at_negligible = m.friction_path_tangent(&rigid, &kappa, &negligible);
        assert!(at_negligible
            .iter()
            .flatten()
            .any(|(_, t)| t[0].iter().any(|v| *v != 0.0)));
        assert_eq!(m.friction_path_tangent(&rigid, &kappa, &zero), fresh);
        assert!(fresh.iter().flatten().all(|(_, t)| t[0] == [0.0; 3]));
        // A prediction with the derivatives is the prediction.
        let mut with = m.clone();
        with.friction_derivatives = true;
        let a: Vec<_> = m.predict(&s).iter().map(|p| p.pose).collect();
        let b: Vec<_> = with.predict(&s).iter().map(|p| p.pose).collect();
        assert_eq!(a, b);
    }

    #[test]
    fn a_pass_is_cut_by_configurations_the_largest_pieces_first() {
        assert_eq!(piece_weights(6), vec![3, 3, 2, 2, 1, 1]);
        assert_eq!(piece_weights(4), vec![2, 2, 1, 1]);
        assert_eq!(piece_weights(2), vec![1, 1]);
        assert_eq!(piece_weights(3), vec![1, 1, 1]);
        // 1200 rows: the first 600 at rest (one configuration each), the last 600 moving (a
        // stair of three before each row): 3000 configurations in all.
        let pose = Pose {
            x: 0.0,
            y: 0.0,
            phi: 0.0,
        };
        let step = (pose, [0.0; 3]);
        let rigid = RigidPath {
            poses: vec![Some(pose); 1200],
            stairs: (0..1200)
                .map(|k| if k < 600 { Vec::new() } else { vec![step; 3] })
                .collect(),
        };
        let starts = rigid.piece_starts(1200, 6);
        assert_eq!(starts.len(), 6);
        assert_eq!(starts[0], 0);
        let cost =
            |a: usize, b: usize| -> usize { (a..b).map(|k| 1 + rigid.stairs[k].len()).sum() };
        let ends: Vec<usize> = starts[1..].iter().copied().chain([1200]).collect();
        let costs: Vec<usize> = starts
            .iter()
            .zip(&ends)
            .map(|(&a, &b)| cost(a, b))
            .collect();
        // 3000 * 3/12 = 750 for the two largest, 500 and 250 for the others, to a row's cost.
        for (c, want) in costs.iter().zip([750, 750, 500, 500, 250, 250]) {
            assert!(c.abs_diff(want) <= 4, "{costs:?}");
        }
        // The first piece holds every row at rest and a few moving ones (pieces of equal rows
        // would have ended it at row 200).
        assert!((630..=645).contains(&ends[0]), "{starts:?}");
    }

    /// A friction pass in pieces is the pass in one from the first row: with its history
    /// rebuilt over the configurations before each piece, every piece agrees with the end of the
    /// one before and the deflections and their derivatives are the one pass's to well within
    /// the equilibrium's tolerance; with no history rebuilt, no piece agrees and each is
    /// answered again from where the one before ended: to its end, the one pass to the bit, or
    /// up to the checkpoint where it rejoins its own answers, the one pass to the tolerance.
    /// The answer does not depend on the number of threads.
    #[test]
    fn a_friction_pass_in_pieces_is_the_pass_in_one() {
        let (_, m, f, kappa, rigid) = rubbing_path(1500);
        type WithTangent = (FrictionState, pcr_kinematics::friction::FrictionTangent);
        let pass = |pieces: Pieces| {
            along_path_in(
                &rigid,
                &kappa,
                pieces,
                |p, k, (state, tan): &mut WithTangent, at| match at {
                    Passing::Row => m.robot.friction_step_tangent(&f, p, k, state, tan).ok(),
                    Passing::Between => {
                        let _ = m.robot.friction_pass(&f, p, k, state, Some(tan));
                        None
                    }
                },
            )
        };
        let (one, again) = pass(Pieces {
            rows: usize::MAX,
            burn_in: 500,
            checkpoint: usize::MAX,
        });
        assert_eq!(again, 0);
        let near = |a: &[Option<DeflectionTangent>], b: &[Option<DeflectionTangent>]| {
            let (mut deflection, mut derivative) = (0.0_f64, 0.0_f64);
            for (a, b) in a.iter().zip(b) {
                let ((da, ta), (db, tb)) = (a.unwrap(), b.unwrap());
                for c in 0..3 {
                    deflection = deflection.max((da[c] - db[c]).abs());
                    for j in 0..3 {
                        // Of the row's largest derivative by the same value, as the pieces'
                        // histories are compared ([`SAME_DERIVATIVES`]).
                        let scale = (0..3)
                            .map(|r| ta[r][j].abs().max(tb[r][j].abs()))
                            .fold(1e-9, f64::max);
                        derivative = derivative.max((ta[c][j] - tb[c][j]).abs() / scale);
                    }
                }
            }
            assert!(deflection < 1e-6, "deflections differ by {deflection:e}");
            assert!(
                derivative < 1e-3,
                "derivatives differ by {derivative:e} of themselves"
            );
        };
        let rebuilt = Pieces {
            rows: 300,
            burn_in: 500,
            checkpoint: 64,
        };
        let (pieces, again) = pass(rebuilt);
        assert_eq!(again, 0, "every rebuilt history agrees");
        assert_eq!(pieces.len(), one.len());
        near(&one, &pieces);
        // Not rebuilt: every piece after the first is answered again, to its end without
        // checkpoints (the one pass, to the bit), or until it rejoins its own answers.
        let (redone, again) = pass(Pieces {
            rows: 300,
            burn_in: 0,
            checkpoint: usize::MAX,
        });
        // 1500 rows in pieces of at most 300: five, made six (an even number).
        assert_eq!(again, 5, "no piece after the first agrees");
        assert_eq!(redone, one);
        let (rejoined, again) = pass(Pieces {
            rows: 300,
            burn_in: 0,
            checkpoint: 64,
        });
        assert_eq!(again, 5);
        assert_ne!(rejoined, one, "the pieces' own answers after they rejoined");
        near(&one, &rejoined);
        let threads = |n: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap()
                .install(|| pass(rebuilt).0)
        };
        assert_eq!(threads(1), pieces);
        assert_eq!(threads(3), pieces);
    }

    /// With one class of elements without friction (the supports alone, the joints alone),
    /// every piece's rebuilt history still agrees with the end of the one before: the elements
    /// without friction keep no history. (Their anchors stayed where each piece started, and
    /// five of six pieces of every pass were answered twice.)
    #[test]
    fn a_pass_of_one_class_of_friction_agrees_in_pieces() {
        let (_, m, f, kappa, rigid) = rubbing_path(1500);
        for one_class in [
            Friction {
                joint_torque: 0.0,
                ..f
            },
            Friction {
                support_force: 0.0,
                ..f
            },
        ] {
            let pass = |rows: usize| {
                along_path_in(
                    &rigid,
                    &kappa,
                    Pieces {
                        rows,
                        burn_in: 500,
                        checkpoint: 64,
                    },
                    |p, k, state: &mut FrictionState, at| match at {
                        Passing::Row => m.robot.friction_step(&one_class, p, k, state).ok(),
                        Passing::Between => {
                            let _ = m.robot.friction_pass(&one_class, p, k, state, None);
                            None
                        }
                    },
                )
            };
            let (one, _) = pass(usize::MAX);
            let (pieces, again) = pass(300);
            assert_eq!(again, 0, "{one_class:?}: every rebuilt history agrees");
            let moved = one
                .iter()
                .flatten()
                .filter(|d| d[0].hypot(d[1]) > 1e-4)
                .count();
            assert!(moved > 100, "{one_class:?}: {moved} rows deflected");
            for (a, b) in one.iter().zip(&pieces) {
                let (a, b) = (a.unwrap(), b.unwrap());
                assert!(
                    (0..3).all(|c| (a[c] - b[c]).abs() < 1e-6),
                    "{a:?} against {b:?}"
                );
            }
        }
    }

    /// The rigid path, solved in chunks in parallel, is the path solved row after row from the
    /// first ([`ExtendedModel::rigid_poses`] over every row), to the bit.
    #[test]
    fn the_rigid_path_in_chunks_is_the_path_in_one() {
        let cfg = RobotConfig::nominal();
        let mut s = swinging(&cfg, 2 * PREDICT_CHUNK + 300, 80.0, 1.1, 0.9);
        // Rows at rest (the same curvatures) and rows without a measured pose across the
        // chunks' first rows.
        for k in [PREDICT_CHUNK - 1, PREDICT_CHUNK, PREDICT_CHUNK + 1] {
            s.samples[k].q = s.samples[k - 1].q;
        }
        for k in (2 * PREDICT_CHUNK - 3)..(2 * PREDICT_CHUNK + 3) {
            s.samples[k].pose = None;
        }
        let m = ExtendedModel::new(&cfg, crate::effects::chain()).unwrap();
        let kappa = m.curvatures(&s, &(0..s.samples.len()).collect::<Vec<_>>());
        let chunked = m.rigid_path(&s, &kappa);
        let one = m.rigid_poses(&s, &kappa, 0..s.samples.len());
        assert!(one.iter().all(Option::is_some));
        assert_eq!(chunked.poses, one);
    }

    /// A series of `n` rows 20 ms apart whose motors swing about home by `amplitude` steps
    /// (motor i at `rate` t + `phase` i rad), rounded to whole steps, each row with a measured
    /// pose.
    fn swinging(cfg: &RobotConfig, n: usize, amplitude: f64, rate: f64, phase: f64) -> Series {
        let home = Robot::new(cfg).unwrap().home_motor_steps();
        let mut rec = pcr_recording::Recording::default();
        for k in 0..n {
            let t = k as f64 * 0.02;
            let q: [i32; 3] = std::array::from_fn(|i| {
                (home[i] + amplitude * (rate * t + phase * i as f64).sin()).round() as i32
            });
            let mut r = pcr_recording::Row::new(t, q);
            r.pose = [Some(0.0); 3];
            rec.rows.push(r);
        }
        Series::from_recording(&rec, "t").unwrap()
    }

    /// Rows solved from the states an earlier prediction kept for them (a fit's evaluations)
    /// are the rows solved along the series, to the solver's tolerance, for other loads too.
    #[test]
    fn rows_resumed_from_their_states_are_the_rows_solved_in_sequence() {
        let mut cfg = RobotConfig::nominal();
        let s = swinging(&cfg, 300, 80.0, 0.9, 1.0);
        let states = RowStates::default();
        let every_fifth = |k: usize| k.is_multiple_of(5);
        for (force, k_m) in [([0.4, -0.3], 300.0), ([0.5, -0.2], 320.0)] {
            cfg.effects.compliance = Some(pcr_robot::effects::Compliance {
                ei_n_mm2: 6.5e4,
                force_n: force,
                couple_n_mm: 0.0,
                k_m_n_mm_per_rad: k_m,
                k_p_n_mm_per_rad: 200.0,
            });
            let mut m = ExtendedModel::new(&cfg, crate::effects::chain()).unwrap();
            m.interpolate = false;
            let plain = m.predict_where(&s, &every_fifth);
            let how = Solving {
                states: Some(&states),
                ..Default::default()
            };
            let resumed = m.predict_where_from(&s, &every_fifth, how);
            assert_eq!(states.lock().unwrap().len(), 60);
            for (k, (a, b)) in plain.iter().zip(&resumed).enumerate() {
                assert_eq!(a.pose.is_some(), every_fifth(k), "row {k}");
                if let (Some(a), Some(b)) = (a.pose, b.pose) {
                    for c in 0..3 {
                        assert!((a[c] - b[c]).abs() < 1e-8, "row {k}: {a:?} {b:?}");
                    }
                }
            }
        }
    }

    /// Under loads (joint springs, or a constant load) a prediction solves some rows and
    /// interpolates the others with the deflection's gradients
    /// ([`crate::interpolation::WithGradient`]); every row is then its solved prediction
    /// within the interpolation's tolerance, on a path where the motors step one at a time.
    /// (Linearly, the load's rows were off by 0.0027 mm and 1.45e-4 rad here.)
    #[test]
    fn a_loaded_model_interpolates_its_rows_within_the_tolerance() {
        let mut cfg = RobotConfig::nominal();
        let s = swinging(&cfg, 1500, 150.0, 0.2, 2.0);
        for (force, k_m, k_p) in [([0.0, 0.0], 900.0, 600.0), ([1.2, -0.9], 0.0, 0.0)] {
            cfg.effects.compliance = Some(pcr_robot::effects::Compliance {
                ei_n_mm2: 6.5e4,
                force_n: force,
                couple_n_mm: 0.0,
                k_m_n_mm_per_rad: k_m,
                k_p_n_mm_per_rad: k_p,
            });
            let mut m = ExtendedModel::new(&cfg, crate::effects::chain()).unwrap();
            let fast = m.predict_where(&s, &|_| true);
            m.interpolate = false;
            let solved = m.predict_where(&s, &|_| true);
            let mut worst = [0.0f64; 3];
            for (k, (a, b)) in fast.iter().zip(&solved).enumerate() {
                assert_eq!(a.pose.is_some(), b.pose.is_some(), "row {k}");
                let (Some(a), Some(b)) = (a.pose, b.pose) else {
                    continue;
                };
                for c in 0..3 {
                    worst[c] = worst[c].max((a[c] - b[c]).abs());
                }
            }
            assert!(
                worst[0] <= 3.0 * DEFLECTION_TOLERANCE_MM
                    && worst[1] <= 3.0 * DEFLECTION_TOLERANCE_MM
                    && worst[2] <= 3.0 * DEFLECTION_TOLERANCE_RAD,
                "springs {k_m}, load {force:?}: {worst:?}"
            );
        }
    }
}
