//! The interpolator's cycle does not allocate: a counting global allocator observes no
//! allocation in `InterpolatorStep::step` over the planner's paths (rest-to-rest lines, the
//! circle, a composite, dwells and joint moves: the slot program after the paper's circle), nor
//! in a pause, a resume and a stop (their brake and ramp are planned in the cycle's thread).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

use pcr_control::{
    moves_of_program, paper_circle, simple_command, InterpolatorStep, MotionLimits, PlannerSource,
};
use pcr_kinematics::{Pose, Robot};
use pcr_messages::{command_kind, planner_state};

struct Counting;

static ALLOCS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    // Only the test's own thread is counted (the harness may allocate on its thread meanwhile).
    static COUNT_HERE: Cell<bool> = const { Cell::new(false) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNT_HERE.try_with(|c| c.get()).unwrap_or(false) {
            ALLOCS.fetch_add(1, Ordering::SeqCst);
        }
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn counted<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let before = ALLOCS.load(Ordering::SeqCst);
    COUNT_HERE.with(|c| c.set(true));
    let r = f();
    COUNT_HERE.with(|c| c.set(false));
    (r, ALLOCS.load(Ordering::SeqCst) - before)
}

#[test]
fn step_pause_resume_and_stop_do_not_allocate() {
    let file = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/programs/slot.toml");
    let slot = pcr_planner::program::load(file, &Default::default()).unwrap();
    let mut moves = paper_circle();
    moves.extend(moves_of_program(&slot));
    for stop_in_slot in [false, true] {
        let src = PlannerSource::new(Robot::nominal(), MotionLimits::default());
        let mut ip = InterpolatorStep::new(src, Pose::default());
        // planning allocates: before the counting starts
        ip.run_moves(&moves, 1).unwrap();
        let duration = ip.status(0.0).duration_s;
        let circle_end = pcr_control::plan_moves(
            PlannerSource::new(Robot::nominal(), MotionLimits::default()),
            Pose::default(),
            &paper_circle(),
            &[],
            0.02,
        )
        .unwrap()
        .cycles
        .len();
        let ((steps, speeds), n) = counted(|| {
            let mut t = 0.0;
            let mut steps = 0usize;
            let mut speeds = 0.0;
            for k in 0..100_000 {
                // a pause on the circle, a resume, and (once) a stop in the slot's composite
                let cmd = match k {
                    100 => Some(command_kind::PAUSE),
                    160 => Some(command_kind::RESUME),
                    _ if stop_in_slot && k == circle_end + 120 => Some(command_kind::STOP),
                    _ => None,
                };
                if let Some(kind) = cmd {
                    ip.command(&simple_command(kind, 0, 1)).unwrap();
                }
                ip.step(t);
                speeds += ip.speed_mm_s();
                steps += 1;
                t += 0.02;
                if ip.can_start().is_ok() {
                    break;
                }
            }
            (steps, speeds)
        });
        assert_eq!(
            n, 0,
            "the cycle allocated (stop in the slot: {stop_in_slot})"
        );
        assert!(speeds > 0.0);
        let state = ip.status(0.0).state;
        if stop_in_slot {
            assert_eq!(state, planner_state::STOPPED);
            assert!(steps < circle_end + 200, "{steps}");
        } else {
            assert_eq!(state, planner_state::DONE);
            assert!(
                steps as f64 * 0.02 > duration,
                "{steps} cycles for {duration} s"
            );
        }
    }
}
