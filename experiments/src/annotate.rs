//! The streaming annotator: labels each recorded row from what the row itself carries (its
//! time `t_s`, the planned pose `xp_mm, yp_mm, phip_deg` and the commanded motor positions
//! `q1..q3`), never from the runtime's clock, so that the same code labels a run of the
//! in-process runner and a live run recorded by the supervisor (with its pauses, delays and
//! jittery times).
//!
//! It walks the design's items in order:
//!
//! - **static visits** (calibration, repeatability): the dwell of the next visit starts at the
//!   first row whose planned pose equals the visit's target (within the tolerances) and equals
//!   the previous row's planned pose (the planned motion has stopped). The dwell lasts while
//!   the planned pose stays at that pose; its rows carry `pose_id`, `rep`, `set`, and
//!   `settled = 1` once `t_s - t_start >= settle_s` (before that `settled = 0`) and while the
//!   commanded motor positions stay those of the previous row: the chain commands one period
//!   ahead of the plan, so the last rows of a dwell may already carry the next move's first
//!   steps, and a changed command ends the measurement of the visit. The first row
//!   whose planned pose differs ends the dwell and the visit; the next visit is looked for from
//!   there. All other rows (approach, return) are unlabelled, with `settled = 0`. A pause
//!   (planned pose held away from the target) starts no dwell; a pause in a dwell lengthens it.
//! - **paths**: the next path is entered at the first row whose planned pose is at the path's
//!   start point (the circle's `centre + (r, 0)`, the square's corner `(+s/2, -s/2)`); from
//!   there every row whose planned pose lies on the path's geometry (within the tolerances) is
//!   labelled `segment = circle|square`, and the first row off it closes the path. (Entering
//!   only at the start point keeps another path's approach or return, which may cross the
//!   path elsewhere, unlabelled.)
//! - **backlash blocks** (motor i, n steps, `periods` periods): a block starts at the first row
//!   whose commanded q differs from the home positions only on motor i, by 1..=n steps upwards;
//!   its rows carry `motor = i`, `amplitude_steps = n` until the row on which motor i is back
//!   home for the `periods`-th time after reaching home + n. Rows between blocks are unlabelled.
//!
//! Items that never show up stall the walk: [`Annotator::found`] and [`Annotator::waiting_for`]
//! say where it stands.

use crate::design::{BacklashBlock, Design, PathShape};
use pcr_recording::{Row, Split};

/// The extra columns the experiments add to the recording format, in order.
pub const EXTRA_COLUMNS: [&str; 3] = ["segment", "motor", "amplitude_steps"];

/// How close a planned pose must be to count as equal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerances {
    /// Position, mm (per coordinate; and distance from a path).
    pub position_mm: f64,
    /// Orientation, deg.
    pub angle_deg: f64,
}

impl Default for Tolerances {
    /// 1e-3 mm and 1e-3 deg: far below any motion of a cycle, far above the rounding of a
    /// recorded planned pose (1e-4 mm, 1e-5 deg).
    fn default() -> Self {
        Tolerances {
            position_mm: 1e-3,
            angle_deg: 1e-3,
        }
    }
}

/// The labels of one row. Empty (`None`) where they do not apply.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Label {
    /// Pose id of the visit whose dwell the row is in.
    pub pose_id: Option<u64>,
    /// Its repetition index.
    pub rep: Option<u64>,
    /// Its split.
    pub set: Option<Split>,
    /// Measured at rest (`settled = 1`).
    pub settled: bool,
    /// `circle` / `square` on path rows.
    pub segment: Option<&'static str>,
    /// Backlash: the excited motor, 1..=3.
    pub motor: Option<u8>,
    /// Backlash: the step count n of the block.
    pub amplitude_steps: Option<u32>,
}

impl Label {
    /// Writes the labels of the format's columns into `row` (`pose_id`, `rep`, `set`,
    /// `settled`).
    pub fn apply(&self, row: &mut Row) {
        row.pose_id = self.pose_id;
        row.rep = self.rep;
        row.set = self.set;
        row.settled = Some(self.settled);
    }

    /// The cells of [`EXTRA_COLUMNS`].
    pub fn extra_cells(&self) -> [Option<String>; 3] {
        [
            self.segment.map(str::to_string),
            self.motor.map(|m| m.to_string()),
            self.amplitude_steps.map(|n| n.to_string()),
        ]
    }
}

#[derive(Debug, Clone)]
struct Target {
    pose_id: u64,
    rep: u64,
    set: Split,
    /// x mm, y mm, phi deg.
    pose: [f64; 3],
}

#[derive(Debug, Clone)]
enum Plan {
    Visits {
        targets: Vec<Target>,
        settle_s: f64,
    },
    Paths(Vec<PathShape>),
    Backlash {
        home: [i32; 3],
        blocks: Vec<BacklashBlock>,
        periods: u32,
    },
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    /// Looking for the next item.
    Waiting,
    /// In a visit's dwell since `t0`, planned pose `anchor`; `over` once the commanded motor
    /// positions changed after the measurement began (the next move has started: the chain
    /// commands one period ahead of the plan).
    Dwell {
        t0: f64,
        anchor: [f64; 3],
        over: bool,
    },
    /// On the current path.
    OnPath,
    /// In a backlash block: reached home + n since the last return, returns so far.
    Block { top: bool, backs: u32 },
}

/// Labels rows one by one (see the module documentation). Cheap per row, no allocation.
#[derive(Debug, Clone)]
pub struct Annotator {
    plan: Plan,
    tol: Tolerances,
    next: usize,
    phase: Phase,
    prev_planned: Option<[f64; 3]>,
    prev_q: Option<[i32; 3]>,
}

impl Annotator {
    /// An annotator for `design`'s rows.
    pub fn new(design: &Design, tol: Tolerances) -> Annotator {
        let plan = match design {
            Design::Static(d) => Plan::Visits {
                targets: d
                    .visits
                    .iter()
                    .map(|v| Target {
                        pose_id: v.pose_id,
                        rep: v.rep,
                        set: v.set,
                        pose: [v.target.x, v.target.y, v.target.phi.to_degrees()],
                    })
                    .collect(),
                settle_s: d.timing.settle_s,
            },
            Design::Paths(p) => Plan::Paths(p.paths.clone()),
            Design::Backlash(b) => Plan::Backlash {
                home: b.home_steps,
                blocks: b.blocks.clone(),
                periods: b.options.periods,
            },
        };
        Annotator {
            plan,
            tol,
            next: 0,
            phase: Phase::Waiting,
            prev_planned: None,
            prev_q: None,
        }
    }

    /// Number of items (visits, paths, blocks) of the design.
    pub fn total(&self) -> usize {
        match &self.plan {
            Plan::Visits { targets, .. } => targets.len(),
            Plan::Paths(p) => p.len(),
            Plan::Backlash { blocks, .. } => blocks.len(),
        }
    }

    /// Number of items whose rows have begun.
    pub fn found(&self) -> usize {
        self.next + usize::from(self.phase != Phase::Waiting)
    }

    /// Whether every item has begun and ended.
    pub fn finished(&self) -> bool {
        self.next >= self.total()
    }

    /// What the walk waits for next (for messages), or None when finished.
    pub fn waiting_for(&self) -> Option<String> {
        let k = self.next;
        match &self.plan {
            Plan::Visits { targets, .. } => targets.get(k).map(|t| {
                format!(
                    "pose_id {} rep {} at ({} mm, {} mm, {} deg)",
                    t.pose_id, t.rep, t.pose[0], t.pose[1], t.pose[2]
                )
            }),
            Plan::Paths(p) => p.get(k).map(|s| format!("the {}", s.name())),
            Plan::Backlash { blocks, .. } => blocks.get(k).map(|b| {
                format!(
                    "the block of motor {} with {} steps",
                    b.motor, b.amplitude_steps
                )
            }),
        }
    }

    fn same(&self, a: [f64; 3], b: [f64; 3]) -> bool {
        (a[0] - b[0]).abs() <= self.tol.position_mm
            && (a[1] - b[1]).abs() <= self.tol.position_mm
            && (a[2] - b[2]).abs() <= self.tol.angle_deg
    }

    /// The labels of the next row (rows must come in time order, each once).
    pub fn label(&mut self, row: &Row) -> Label {
        let planned = match row.planned {
            [Some(x), Some(y), Some(p)] => Some([x, y, p]),
            _ => None,
        };
        let label = match &self.plan {
            Plan::Visits { .. } => self.label_visit(row.t_s, planned, row.q),
            Plan::Paths(_) => self.label_path(planned),
            Plan::Backlash { .. } => self.label_backlash(row.q),
        };
        self.prev_planned = planned;
        self.prev_q = Some(row.q);
        label
    }

    /// Labels `row` and writes the format's labels into it (see [`Label::apply`]).
    pub fn annotate(&mut self, row: &mut Row) -> Label {
        let l = self.label(row);
        l.apply(row);
        l
    }

    fn label_visit(&mut self, t_s: f64, planned: Option<[f64; 3]>, q: [i32; 3]) -> Label {
        let Plan::Visits { targets, settle_s } = &self.plan else {
            return Label::default();
        };
        let settle_s = *settle_s;
        if let Phase::Dwell { t0, anchor, over } = self.phase {
            if planned.is_some_and(|p| self.same(p, anchor)) {
                let t = &targets[self.next];
                // Settled: the settle time has passed and the motors are still where they
                // were (a changed command ends the measurement of this visit).
                let timed = t_s - t0 >= settle_s - 1e-9;
                let moved = self.prev_q.is_some_and(|p| p != q);
                let over = over || (timed && moved);
                self.phase = Phase::Dwell { t0, anchor, over };
                return Label {
                    pose_id: Some(t.pose_id),
                    rep: Some(t.rep),
                    set: Some(t.set),
                    settled: timed && !over && !moved,
                    ..Label::default()
                };
            }
            // The planned pose moved: the visit is over.
            self.next += 1;
            self.phase = Phase::Waiting;
        }
        let (Some(p), Some(prev), Some(t)) = (planned, self.prev_planned, targets.get(self.next))
        else {
            return Label::default();
        };
        if self.same(p, t.pose) && self.same(p, prev) {
            self.phase = Phase::Dwell {
                t0: t_s,
                anchor: p,
                over: false,
            };
            return Label {
                pose_id: Some(t.pose_id),
                rep: Some(t.rep),
                set: Some(t.set),
                settled: settle_s <= 1e-9,
                ..Label::default()
            };
        }
        Label::default()
    }

    fn label_path(&mut self, planned: Option<[f64; 3]>) -> Label {
        let Plan::Paths(paths) = &self.plan else {
            return Label::default();
        };
        let (tol_mm, tol_deg) = (self.tol.position_mm, self.tol.angle_deg);
        let on = |k: usize| {
            paths
                .get(k)
                .is_some_and(|s| planned.is_some_and(|p| s.contains(p, tol_mm, tol_deg)))
        };
        if self.phase == Phase::OnPath && !on(self.next) {
            self.next += 1;
            self.phase = Phase::Waiting;
        }
        // A path is entered at its start point only (another path's approach or return may
        // cross it elsewhere, e.g. the circle's return crosses the square's side at (25, 0)).
        let at_start = |k: usize| {
            paths.get(k).is_some_and(|s| {
                let a = s.start();
                planned.is_some_and(|p| {
                    (p[0] - a[0]).abs() <= tol_mm
                        && (p[1] - a[1]).abs() <= tol_mm
                        && (p[2] - s.phi_deg()).abs() <= tol_deg
                })
            })
        };
        if on(self.next) && (self.phase == Phase::OnPath || at_start(self.next)) {
            self.phase = Phase::OnPath;
            return Label {
                segment: Some(paths[self.next].name()),
                ..Label::default()
            };
        }
        Label::default()
    }

    fn label_backlash(&mut self, q: [i32; 3]) -> Label {
        let Plan::Backlash {
            home,
            blocks,
            periods,
        } = &self.plan
        else {
            return Label::default();
        };
        let Some(b) = blocks.get(self.next) else {
            return Label::default();
        };
        // (motors are 1..=3 in a design built by BacklashDesign::new)
        let i = usize::from(b.motor.clamp(1, 3) - 1);
        let n = i64::from(b.amplitude_steps);
        let others_home = (0..3).all(|j| j == i || q[j] == home[j]);
        let d = i64::from(q[i]) - i64::from(home[i]);
        let label = Label {
            motor: Some(b.motor),
            amplitude_steps: Some(b.amplitude_steps),
            ..Label::default()
        };
        match self.phase {
            Phase::Block { mut top, mut backs } => {
                if d == n {
                    top = true;
                } else if d == 0 && others_home && top {
                    top = false;
                    backs += 1;
                }
                self.phase = if backs >= *periods {
                    self.next += 1;
                    Phase::Waiting
                } else {
                    Phase::Block { top, backs }
                };
                label
            }
            _ => {
                if others_home && d > 0 && d <= n {
                    self.phase = Phase::Block {
                        top: d == n,
                        backs: 0,
                    };
                    label
                } else {
                    Label::default()
                }
            }
        }
    }
}
