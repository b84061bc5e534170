//! One interpolator: the poses `pcr plan` plans for a program
//! ([`pcr_control::plan_moves`], the chain's `InterpolatorStep` over `PlannerSource` on a
//! simulated clock) are the planned poses the running chain records for the same program on the
//! ideal drive (the `planned` pose of each driver-state row: the recording's `xp_mm, yp_mm,
//! phip_deg`), cycle by cycle, to 1e-9 mm and 1e-9 deg; and a stop, or a pause and a resume,
//! requested at the same cycle brakes (and accelerates) along the same poses in both.
//!
//! Programs: the paper's circle, square and both (the chain's built-in programs, sent by id),
//! `configs/programs/slot.toml` and a seeded random set of lines, circles, dwells, rectangles
//! and arcs (composites with blended corners) and joint moves, sent in the wire form.

use pcr_control::{
    command_of_moves, moves_of_program, paper_circle, paper_program, paper_square, plan_moves,
    simple_command, IdealChain, MotionLimits, Move, PlannedCycle, PlannerSource,
};
use pcr_kinematics::{Pose, Robot};
use pcr_messages::{command_kind, planner_state, program_id, Command};
use pcr_planner::program::{JointSettings, PathLimits};
use rand::{Rng, SeedableRng};

const PERIOD: f64 = 0.02;

/// The planned pose of each cycle the chain records, with its time: runs `run` on the ideal
/// chain, applying `commands` before their cycles, until the interpolator is at rest (as the
/// offline plan ends), at most `max` cycles.
fn chain_record(run: &Command, commands: &[(usize, u32)], max: usize) -> Vec<(f64, [f64; 3])> {
    let mut chain = IdealChain::ideal(Robot::nominal(), MotionLimits::default(), PERIOD);
    chain
        .interp
        .command(run)
        .expect("the chain accepts the program");
    let mut out = Vec::new();
    for k in 0..max {
        for &(_, kind) in commands.iter().filter(|c| c.0 == k) {
            chain
                .interp
                .command(&simple_command(kind, 0, run.run_id))
                .unwrap();
        }
        let o = chain.cycle().expect("the ideal drive follows");
        assert_eq!(o.state.planned, o.task.nominal);
        out.push((o.state.t_s, o.state.planned));
        let state = chain.interp.status(chain.time_s()).state;
        let at_rest = chain.interp.program_rate() == 0.0;
        let pending = commands.iter().any(|c| c.0 > k);
        let done = match state {
            planner_state::RUNNING => false,
            planner_state::PAUSED => !pending && at_rest,
            _ => chain.interp.can_start().is_ok(),
        };
        if done {
            break;
        }
    }
    out
}

fn offline(moves: &[Move], commands: &[(usize, u32)]) -> Vec<PlannedCycle> {
    let src = PlannerSource::new(Robot::nominal(), MotionLimits::default());
    plan_moves(src, Pose::default(), moves, commands, PERIOD)
        .expect("pcr plan accepts the program")
        .cycles
}

/// Asserts that the offline plan and the chain's record agree cycle by cycle; returns the
/// number of cycles.
fn assert_same(what: &str, moves: &[Move], run: &Command, commands: &[(usize, u32)]) -> usize {
    let plan = offline(moves, commands);
    let rec = chain_record(run, commands, plan.len() + 10);
    assert_eq!(
        plan.len(),
        rec.len(),
        "{what} {commands:?}: {} cycles planned, {} recorded",
        plan.len(),
        rec.len()
    );
    for (k, (p, (t, r))) in plan.iter().zip(&rec).enumerate() {
        let q = p.task.nominal;
        let (dx, dy) = ((q[0] - r[0]).abs(), (q[1] - r[1]).abs());
        let dphi_deg = (q[2].to_degrees() - r[2].to_degrees()).abs();
        assert!(
            dx <= 1e-9 && dy <= 1e-9 && dphi_deg <= 1e-9,
            "{what} {commands:?}: cycle {k} (t = {t} s): planned {q:?}, recorded {r:?}"
        );
        assert!((p.task.t_s - t).abs() < 1e-12, "{what}: cycle {k} time");
    }
    plan.len()
}

/// The program, the same program with a stop at a cycle, and with a pause and a resume.
fn assert_same_with_requests(what: &str, moves: &[Move], run: &Command, rng: &mut impl Rng) {
    let n = assert_same(what, moves, run, &[]);
    assert!(n > 20, "{what}: {n} cycles");
    let stop = rng.random_range(5..n - 5);
    assert_same(what, moves, run, &[(stop, command_kind::STOP)]);
    let pause = rng.random_range(5..n - 5);
    let resume = pause + rng.random_range(1..60);
    assert_same(
        what,
        moves,
        run,
        &[(pause, command_kind::PAUSE), (resume, command_kind::RESUME)],
    );
    // a pause, and a stop while it brakes or holds
    let stop = pause + rng.random_range(1..30);
    assert_same(
        what,
        moves,
        run,
        &[(pause, command_kind::PAUSE), (stop, command_kind::STOP)],
    );
}

fn slot_moves() -> Vec<Move> {
    let file = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/programs/slot.toml");
    let p = pcr_planner::program::load(file, &Default::default()).unwrap();
    moves_of_program(&p)
}

#[test]
fn pcr_plan_plans_what_the_chain_records_for_the_papers_programs_and_the_slot() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(13);
    for (what, moves, id) in [
        ("circle", paper_circle(), program_id::CIRCLE),
        ("square", paper_square(), program_id::SQUARE),
        ("paper", paper_program(), program_id::PAPER),
    ] {
        let run = simple_command(command_kind::RUN, id, 1);
        assert_same_with_requests(what, &moves, &run, &mut rng);
    }
    let slot = slot_moves();
    let run = command_of_moves(1, &slot).unwrap();
    assert_same_with_requests("slot", &slot, &run, &mut rng);
}

#[test]
fn a_stop_at_the_same_cycle_brakes_along_the_same_poses_on_the_path() {
    // The stop brakes: it ends earlier than the program, and moves along the circle (radius
    // 50 mm) for more than one cycle after the request.
    let moves = paper_circle();
    let run = simple_command(command_kind::RUN, program_id::CIRCLE, 1);
    let full = offline(&moves, &[]);
    let stop = 200;
    let n = assert_same("circle", &moves, &run, &[(stop, command_kind::STOP)]);
    let braked = offline(&moves, &[(stop, command_kind::STOP)]);
    assert_eq!(braked.len(), n);
    assert!(n < full.len() - 50, "{n} of {}", full.len());
    let on_circle = |c: &PlannedCycle| {
        let p = c.pose();
        (p.x.hypot(p.y) - 50.0).abs() < 1e-9
    };
    assert!(braked[stop..].iter().all(on_circle));
    let moving = braked[stop..]
        .windows(2)
        .filter(|w| w[0].pose() != w[1].pose())
        .count();
    assert!(moving > 5, "stopped at once ({moving} cycles of braking)");
    assert_eq!(braked.last().unwrap().state, planner_state::STOPPED);
    assert_eq!(braked.last().unwrap().speed_mm_s, 0.0);
}

/// A random point within `r` mm of the origin.
fn point(rng: &mut impl Rng, r: f64) -> [f64; 2] {
    let (a, d): (f64, f64) = (
        rng.random_range(0.0..std::f64::consts::TAU),
        rng.random_range(0.0..r),
    );
    [d * a.cos(), d * a.sin()]
}

/// A random program from home inside the workspace: lines, circles, dwells, rectangles and
/// arcs (composites, one set of path limits), and joint moves near home.
fn random_program(rng: &mut impl Rng) -> Vec<Move> {
    let limits = PathLimits {
        speed: rng.random_range(10.0..40.0),
        acceleration: rng.random_range(100.0..300.0),
        jerk: rng.random_range(1000.0..3000.0),
        blend_radius: rng.random_range(0.0..3.0),
        rotation_radius: 50.0,
    };
    let mut moves = Vec::new();
    let mut at = [0.0f64, 0.0f64];
    let n = rng.random_range(2..7);
    for _ in 0..n {
        match rng.random_range(0..6) {
            0 => {
                let p = point(rng, 30.0);
                moves.push(Move::Line {
                    to: Pose::new(p[0], p[1], rng.random_range(-0.1..0.1)),
                    speed_mm_s: rng.random_range(5.0..40.0),
                });
                at = p;
            }
            1 => {
                let c = point(rng, 10.0);
                let r = rng.random_range(5.0..25.0);
                moves.push(Move::Circle {
                    centre: c,
                    radius_mm: r,
                    speed_mm_s: rng.random_range(5.0..40.0),
                    phi: rng.random_range(-0.1..0.1),
                });
                at = [c[0] + r, c[1]];
            }
            2 => moves.push(Move::Dwell {
                duration_s: rng.random_range(0.0..0.3),
            }),
            3 => {
                // a rectangle from the current point, one composite with blended corners
                let (w, h) = (rng.random_range(4.0..12.0), rng.random_range(4.0..12.0));
                let (sx, sy) = (-at[0].signum(), -at[1].signum());
                let corners = [
                    [at[0] + sx * w, at[1]],
                    [at[0] + sx * w, at[1] + sy * h],
                    [at[0], at[1] + sy * h],
                    at,
                ];
                for (k, c) in corners.into_iter().enumerate() {
                    moves.push(Move::PathLine {
                        to: c,
                        phi: None,
                        speed_mm_s: rng.random_bool(0.3).then(|| rng.random_range(5.0..30.0)),
                        blend_radius_mm: None,
                        continues: k > 0,
                        limits,
                    });
                }
            }
            4 => {
                // an arc towards the origin's side, continuing into a line
                let c = [at[0] * 0.7, at[1] * 0.7 + 3.0];
                let sweep =
                    rng.random_range(0.5..3.0) * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                moves.push(Move::Arc {
                    centre: c,
                    sweep_rad: sweep,
                    phi: Some(rng.random_range(-0.1..0.1)),
                    speed_mm_s: None,
                    continues: false,
                    limits,
                });
                let to = point(rng, 25.0);
                moves.push(Move::PathLine {
                    to,
                    phi: None,
                    speed_mm_s: None,
                    blend_radius_mm: None,
                    continues: true,
                    limits,
                });
                at = to;
            }
            _ => {
                let steps = std::array::from_fn(|_| 176 + rng.random_range(-50..=50));
                moves.push(Move::Joint {
                    steps,
                    limits: JointSettings {
                        acceleration: 2000.0,
                        jerk: 20000.0,
                    },
                });
                // the pose after a joint move is near home; a later rectangle starts there
                at = [0.0, 0.0];
            }
        }
    }
    moves
}

#[test]
fn pcr_plan_plans_what_the_chain_records_for_random_programs() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1313);
    let (mut accepted, mut tried) = (0, 0);
    while accepted < 24 {
        tried += 1;
        assert!(
            tried < 400,
            "too few random programs are accepted ({accepted})"
        );
        let moves = random_program(&mut rng);
        let src = PlannerSource::new(Robot::nominal(), MotionLimits::default());
        if plan_moves(src, Pose::default(), &moves, &[], PERIOD).is_err() {
            // refused by the planner (and so by the chain): not a comparison
            continue;
        }
        let run = command_of_moves(1, &moves).unwrap();
        assert_same_with_requests(&format!("random program {tried}"), &moves, &run, &mut rng);
        accepted += 1;
    }
    eprintln!("{accepted} of {tried} random programs accepted by the planner and compared");
}
