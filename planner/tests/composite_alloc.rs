//! Planning and sampling a composite motion and sampling a joint move do not allocate: a
//! counting global allocator observes no allocation. Only the test's own thread is counted (the
//! test harness may allocate on its thread at the same time).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

use pcr_planner::composite::{CompositeLimits, CompositeMotion, CompositePath};
use pcr_planner::joint::{JointLimits, JointMove};
use pcr_planner::path::Pose;

struct Counting;

static ALLOCS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
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

#[test]
fn composite_and_joint_moves_do_not_allocate() {
    let lim = CompositeLimits {
        vmax: 30.0,
        amax: 200.0,
        jmax: 2000.0,
    };
    let jl = JointLimits {
        rate: [600.0; 3],
        accel: [2000.0; 3],
        jerk: [20000.0; 3],
    };
    COUNT_HERE.with(|c| c.set(true));
    let before = ALLOCS.load(Ordering::SeqCst);
    let path = CompositePath::rectangle(Pose::new(0.0, 0.0, 0.0), 40.0, 20.0, 0.2, 5.0).unwrap();
    let m = CompositeMotion::plan(&path, &lim).unwrap();
    let mut acc = 0.0;
    let mut t = 0.0;
    while t <= m.duration() + 0.1 {
        let s = m.sample(t);
        acc += s.pose.x + s.speed;
        t += 0.02;
    }
    let j = JointMove::plan([0.0; 3], [500.0, -200.0, 30.0], &jl).unwrap();
    let mut t = 0.0;
    while t <= j.duration() + 0.1 {
        acc += j.steps_at(t)[0] as f64;
        t += 0.02;
    }
    let after = ALLOCS.load(Ordering::SeqCst);
    COUNT_HERE.with(|c| c.set(false));
    assert!(acc.is_finite());
    assert_eq!(after - before, 0, "allocations while planning or sampling");
}
