//! The profiler does not allocate: a counting global allocator observes no allocation during
//! `calculate()` and trajectory evaluation (time/phase/no synchronisation, brake, velocity
//! interface, blocked intervals).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

use pcr_planner::profiler::{calculate, ControlInterface, Input, Limits, State, Synchronization};

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

fn inputs() -> [Input; 4] {
    let mut a = Input::new(3);
    a.current[0] = State::new(0.0, 3.0, 0.5); // outside the limits: brake
    a.current[1] = State::new(0.0, -1.0, 0.0);
    a.target[1] = State::new(-0.5, -1.0, 0.0); // blocked interval
    a.target[2] = State::new(0.3, 0.2, 0.1);
    let mut b = a;
    b.synchronization = Synchronization::Phase;
    let mut c = a;
    c.synchronization = Synchronization::None;
    c.minimum_duration = Some(20.0);
    let mut d = Input::new(2);
    d.control_interface = ControlInterface::Velocity;
    d.current[0] = State::new(0.0, 0.5, 2.0);
    d.target[0] = State::new(0.0, 2.0, 0.0);
    d.target[1] = State::new(0.0, -0.5, 0.2);
    d.limits[1] = Limits::symmetric(1.0, 0.5, 2.0);
    [a, b, c, d]
}

#[test]
fn calculate_and_evaluate_do_not_allocate() {
    let inputs = inputs();
    let mut buf = [State::default(); 3];
    let before = ALLOCS.load(Ordering::SeqCst);
    COUNT_HERE.with(|c| c.set(true));
    let mut sum = 0.0;
    for inp in &inputs {
        let traj = calculate(inp).expect("solvable");
        for k in 0..100 {
            traj.at(traj.duration() * k as f64 / 99.0, &mut buf[..traj.dofs()]);
            sum += buf[0].p;
        }
        sum += traj.position_extrema(0).max;
    }
    COUNT_HERE.with(|c| c.set(false));
    let after = ALLOCS.load(Ordering::SeqCst);
    assert!(sum.is_finite());
    assert_eq!(after, before, "the profiler allocated");
}
