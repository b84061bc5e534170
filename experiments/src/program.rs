//! A design as chain commands: lists of [`Move`]s of at most [`MAX_MOVES`] each, run one after
//! the other on the same chain, each continuing from where the previous one ended.
//!
//! - every program starts with a lead-in dwell of [`LEAD_IN_S`] (the chain settles at home);
//! - a static visit is three moves: `Line` origin -> target at the design's speed (rest to
//!   rest, the planner's jerk-limited profile), `Dwell` of settle_s + measure_s, `Line` back to
//!   the origin; whole visits are packed into commands (10 per command);
//! - the paths are `pcr_control::paper_circle()` then `paper_square()`, one command each;
//! - backlash: a `Joint` move to the home steps, then per block `periods` times
//!   [`Joint` home + n on the motor, `Dwell`, `Joint` home, `Dwell`], the dwells being half a
//!   period minus the move's duration (computed with the planner's own joint-move planning), so
//!   that the forth moves start exactly 1/f apart; the block's last dwell also holds the rest
//!   between blocks. A block of up to 8 periods is one command; longer blocks are split into
//!   commands of 8 periods, and each join delays the next forth move by less than one control
//!   period (documented in docs/experiments.md).

use crate::design::{BacklashDesign, Design, PathShape, StaticDesign};
use pcr_control::{paper_circle, paper_square, Move};
use pcr_messages::MAX_MOVES;
use pcr_planner::joint::{JointLimits, JointMove};
use pcr_planner::program::JointSettings;
use pcr_robot::RobotConfig;

/// Dwell at the start of every program, s.
pub const LEAD_IN_S: f64 = 1.0;

/// One command of a program.
#[derive(Debug, Clone, PartialEq)]
pub struct ProgramCommand {
    /// Its moves (1..=32).
    pub moves: Vec<Move>,
    /// What each move does, for messages (`pose_id 12 rep 0: approach`).
    pub labels: Vec<String>,
}

impl ProgramCommand {
    /// What the command covers (its first and last move labels).
    pub fn describe(&self) -> String {
        match (self.labels.first(), self.labels.last()) {
            (Some(a), Some(b)) if a != b => format!("{a} .. {b}"),
            (Some(a), _) => a.clone(),
            _ => "empty command".into(),
        }
    }
}

/// A design's commands in order.
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    /// The commands.
    pub commands: Vec<ProgramCommand>,
}

impl Program {
    /// Number of moves over all commands.
    pub fn moves(&self) -> usize {
        self.commands.iter().map(|c| c.moves.len()).sum()
    }
}

/// Why a design could not be turned into commands.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProgramError {
    /// A backlash joint move cannot be planned or is too slow for the frequency.
    #[error("backlash: {0}")]
    Backlash(String),
}

/// Packs atoms (moves that must stay in one command) greedily into commands of at most
/// [`MAX_MOVES`] moves.
fn pack(atoms: Vec<(Vec<Move>, Vec<String>)>) -> Program {
    let mut commands: Vec<ProgramCommand> = Vec::new();
    for (moves, labels) in atoms {
        debug_assert!(moves.len() <= MAX_MOVES);
        match commands.last_mut() {
            Some(c) if c.moves.len() + moves.len() <= MAX_MOVES => {
                c.moves.extend(moves);
                c.labels.extend(labels);
            }
            _ => commands.push(ProgramCommand { moves, labels }),
        }
    }
    Program { commands }
}

fn lead_in() -> (Vec<Move>, Vec<String>) {
    (
        vec![Move::Dwell {
            duration_s: LEAD_IN_S,
        }],
        vec!["lead-in dwell".into()],
    )
}

/// The commands of a design; `robot` is the model that drives (its step rates time the
/// backlash moves).
pub fn program_of(design: &Design, robot: &RobotConfig) -> Result<Program, ProgramError> {
    Ok(match design {
        Design::Static(d) => static_program(d),
        Design::Paths(p) => {
            let mut atoms = vec![lead_in()];
            for s in &p.paths {
                let moves = match s {
                    PathShape::Circle { .. } => paper_circle(),
                    PathShape::Square { .. } => paper_square(),
                };
                let labels = vec![s.name().to_string(); moves.len()];
                atoms.push((moves, labels));
            }
            // The lead-in joins the first path; each path is its own command.
            let mut prog = pack(atoms.drain(..2).collect());
            prog.commands.extend(pack(atoms).commands);
            prog
        }
        Design::Backlash(b) => backlash_program(b, robot)?,
    })
}

fn static_program(d: &StaticDesign) -> Program {
    let mut atoms = vec![lead_in()];
    let t = d.timing;
    for v in &d.visits {
        let tag = format!("pose_id {} rep {}", v.pose_id, v.rep);
        atoms.push((
            vec![
                Move::Line {
                    to: v.target,
                    speed_mm_s: t.speed_mm_s,
                },
                Move::Dwell {
                    duration_s: t.settle_s + t.measure_s,
                },
                Move::Line {
                    to: d.origin,
                    speed_mm_s: t.speed_mm_s,
                },
            ],
            vec![
                format!("{tag}: approach"),
                format!("{tag}: dwell"),
                format!("{tag}: return"),
            ],
        ));
    }
    pack(atoms)
}

/// Periods per command of a long backlash block (4 moves each).
const PERIODS_PER_COMMAND: u32 = (MAX_MOVES / 4) as u32;

fn backlash_program(b: &BacklashDesign, robot: &RobotConfig) -> Result<Program, ProgramError> {
    let o = &b.options;
    let settings = JointSettings {
        acceleration: o.joint_acceleration,
        jerk: o.joint_jerk,
    };
    // As the planner plans joint moves (pcr_control::PlannerSource).
    let mut limits = JointLimits::from_config(robot, 1.0, settings.acceleration, settings.jerk)
        .map_err(|e| ProgramError::Backlash(e.to_string()))?;
    for r in &mut limits.rate {
        *r *= 1.0 - 1e-6;
    }
    let home = b.home_steps.map(i64::from);
    if !(o.freq_hz.is_finite() && o.freq_hz > 0.0 && o.periods > 0) {
        return Err(ProgramError::Backlash(format!(
            "{} periods at {} Hz",
            o.periods, o.freq_hz
        )));
    }
    let half = 0.5 / o.freq_hz;
    let mut atoms = vec![lead_in()];
    atoms.push((
        vec![Move::Joint {
            steps: home,
            limits: settings,
        }],
        vec!["joint move to the home steps".into()],
    ));
    // The home move and the first block's first period go into separate commands.
    let mut prog = pack(atoms);
    for blk in &b.blocks {
        if !(1..=3).contains(&blk.motor) || blk.amplitude_steps == 0 {
            return Err(ProgramError::Backlash(format!(
                "block of motor {} with {} steps: motors are 1..=3, steps >= 1",
                blk.motor, blk.amplitude_steps
            )));
        }
        let i = usize::from(blk.motor - 1);
        let mut top = home;
        top[i] += i64::from(blk.amplitude_steps);
        let dur = JointMove::plan(home.map(|v| v as f64), top.map(|v| v as f64), &limits)
            .map_err(|e| ProgramError::Backlash(e.to_string()))?
            .duration();
        if dur >= half {
            return Err(ProgramError::Backlash(format!(
                "the move of {} steps on motor {} takes {dur:.3} s, not less than half a period \
                 ({half:.3} s at {} Hz): lower the frequency or raise the joint limits",
                blk.amplitude_steps, blk.motor, o.freq_hz
            )));
        }
        let tag = format!("motor {} {} steps", blk.motor, blk.amplitude_steps);
        let mut p = 0;
        while p < o.periods {
            let n = PERIODS_PER_COMMAND.min(o.periods - p);
            let mut moves = Vec::with_capacity(4 * n as usize);
            let mut labels = Vec::with_capacity(4 * n as usize);
            for k in p..p + n {
                let last = k + 1 == o.periods;
                moves.extend([
                    Move::Joint {
                        steps: top,
                        limits: settings,
                    },
                    Move::Dwell {
                        duration_s: half - dur,
                    },
                    Move::Joint {
                        steps: home,
                        limits: settings,
                    },
                    Move::Dwell {
                        duration_s: half - dur + if last { o.rest_s } else { 0.0 },
                    },
                ]);
                for what in ["forth", "hold", "back", if last { "rest" } else { "hold" }] {
                    labels.push(format!("{tag}: period {k}: {what}"));
                }
            }
            prog.commands.push(ProgramCommand { moves, labels });
            p += n;
        }
    }
    Ok(prog)
}
