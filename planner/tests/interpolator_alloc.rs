//! The interpolator's cycle does not allocate: a counting global allocator observes no
//! allocation during `step()` (including a stop request).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

use pcr_planner::composite::{CompositeLimits, CompositeMotion, CompositePath};
use pcr_planner::interpolator::{Interpolator, MotionCommand, Phase};
use pcr_planner::path::{Path, Pose};
use pcr_planner::speed::SpeedLimits;

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

#[test]
fn step_and_stop_do_not_allocate() {
    let start = Pose::new(0.0, 0.0, 0.0);
    let mut ip = Interpolator::new(start, 100.0, 1000.0).unwrap();
    let rect = Path::rectangle(start, 20.0, 10.0, 0.3).unwrap();
    let circle = Path::circle(10.0, 0.0, 10.0, std::f64::consts::PI, true, 0.0).unwrap();
    let lim = SpeedLimits::JerkLimited {
        vmax: 20.0,
        amax: 50.0,
        jmax: 500.0,
    };
    ip.push(MotionCommand {
        path: rect,
        limits: lim,
    })
    .unwrap();
    ip.push(MotionCommand {
        path: circle,
        limits: lim,
    })
    .unwrap();
    // a composite (boxed when pushed, before the counting starts): line, arc, line
    let mut c = CompositePath::new(circle.end()).unwrap();
    c.line_to(Pose::new(10.0, 0.0, 0.0), None).unwrap();
    c.arc_around(10.0, 5.0, std::f64::consts::PI, 0.0, None)
        .unwrap();
    c.line_to(Pose::new(0.0, 10.0, 0.0), None).unwrap();
    let m = CompositeMotion::plan(
        &c,
        &CompositeLimits {
            vmax: 20.0,
            amax: 50.0,
            jmax: 500.0,
        },
    )
    .unwrap();
    ip.push_composite(m).unwrap();
    let before = ALLOCS.load(Ordering::SeqCst);
    COUNT_HERE.with(|c| c.set(true));
    let mut steps = 0;
    let mut on_composite = None;
    let mut stopped = false;
    for k in 0..10_000 {
        if ip.queued() == 0 && on_composite.is_none() {
            on_composite = Some(k);
        }
        if on_composite.is_some_and(|k0| k == k0 + 50) {
            // 1 s into the composite
            ip.request_stop();
            stopped = true;
        }
        let sp = ip.step();
        steps += 1;
        if sp.phase == Phase::Idle {
            break;
        }
    }
    COUNT_HERE.with(|c| c.set(false));
    let after = ALLOCS.load(Ordering::SeqCst);
    assert!(steps > 200 && stopped);
    assert_eq!(after, before, "step() allocated");
}
