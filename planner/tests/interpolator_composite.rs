//! The 20 ms interpolator runs composite motions from its queue: continuous speed through the
//! smooth junctions, the exact end pose, queued after and before single paths, and a stop
//! request brakes along the composite path without exceeding the stop limits.

use pcr_planner::composite::{CompositeLimits, CompositeMotion, CompositePath};
use pcr_planner::interpolator::{Interpolator, InterpolatorError, MotionCommand, Phase, CYCLE_S};
use pcr_planner::path::{Path, Pose};
use pcr_planner::speed::SpeedLimits;
use std::f64::consts::PI;

const LIM: CompositeLimits = CompositeLimits {
    vmax: 30.0,
    amax: 200.0,
    jmax: 2000.0,
};

/// A slot starting at (-20, -10): G1 everywhere, ends where it starts.
fn slot() -> CompositeMotion {
    let mut c = CompositePath::new(Pose::new(-20.0, -10.0, 0.0)).unwrap();
    c.line_to(Pose::new(20.0, -10.0, 0.0), None).unwrap();
    c.arc_around(20.0, 0.0, PI, 0.0, None).unwrap();
    c.line_to(Pose::new(-20.0, 10.0, 0.0), None).unwrap();
    c.arc_around(-20.0, 0.0, PI, 0.0, None).unwrap();
    CompositeMotion::plan(&c, &LIM).unwrap()
}

#[test]
fn a_composite_runs_without_stopping_and_ends_on_its_end_pose() {
    let m = slot();
    let duration = m.duration();
    let start = m.path().start();
    let mut ip = Interpolator::new(start, 200.0, 2000.0).unwrap();
    // a single line into the slot's start, the slot, and a line out
    let before = Pose::new(-20.0, -20.0, 0.0);
    let mut ip0 = Interpolator::new(before, 200.0, 2000.0).unwrap();
    let jl = SpeedLimits::JerkLimited {
        vmax: 20.0,
        amax: 100.0,
        jmax: 1000.0,
    };
    ip0.push(MotionCommand {
        path: Path::line(before, start).unwrap(),
        limits: jl,
    })
    .unwrap();
    ip0.push_composite(m.clone()).unwrap();
    assert!(matches!(
        ip0.push(MotionCommand {
            path: Path::line(Pose::new(0.0, 0.0, 0.0), before).unwrap(),
            limits: jl,
        }),
        Err(InterpolatorError::Discontinuous { .. })
    ));
    ip0.push(MotionCommand {
        path: Path::line(start, before).unwrap(),
        limits: jl,
    })
    .unwrap();
    let mut moving = 0;
    let mut last = before;
    for _ in 0..2000 {
        let sp = ip0.step();
        assert!(
            sp.pose.max_diff(&last) <= 30.0 * CYCLE_S + 1e-9,
            "jump at {}",
            sp.t
        );
        last = sp.pose;
        if sp.phase == Phase::Idle {
            break;
        }
        moving += 1;
    }
    assert!(last.max_diff(&before) < 1e-12, "{last:?}");
    assert!(moving as f64 * CYCLE_S > duration);

    // the slot alone: the speed never drops to rest between start and end
    ip.push_composite(m).unwrap();
    let mut speeds = Vec::new();
    loop {
        let sp = ip.step();
        if sp.phase == Phase::Idle {
            assert!(sp.pose.max_diff(&start) < 1e-12);
            break;
        }
        assert!(sp.speed <= LIM.vmax * (1.0 + 1e-9));
        speeds.push(sp.speed);
    }
    let n = speeds.len();
    assert!((n as f64 * CYCLE_S - duration).abs() <= CYCLE_S + 1e-9);
    let interior = &speeds[n / 10..n - n / 10];
    let vmin = interior.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(vmin > 10.0, "the slot slowed to {vmin} mm/s");
}

#[test]
fn a_stop_request_brakes_along_the_composite_path() {
    let m = slot();
    let start = m.path().start();
    let mut ip = Interpolator::new(start, 100.0, 1000.0).unwrap();
    ip.push_composite(m.clone()).unwrap();
    // stop on the first arc, at speed
    let mut t = 0.0;
    let mut sp = ip.step();
    while m.path().segment_at(sp.s) < 1 || sp.speed < 20.0 {
        sp = ip.step();
        t += CYCLE_S;
        assert!(t < m.duration());
    }
    ip.request_stop();
    assert!(matches!(
        ip.push_composite(m.clone()),
        Err(InterpolatorError::Stopping)
    ));
    let (mut v_prev, mut s_prev) = (sp.speed, sp.s);
    let mut a_prev = f64::NAN;
    loop {
        let sp = ip.step();
        // braking: the speed only falls, the path length only grows, on the path
        assert!(sp.speed <= v_prev + 1e-9 && sp.s >= s_prev - 1e-12);
        let a = (sp.speed - v_prev) / CYCLE_S;
        assert!(a >= -(200.0 + 1e-6), "deceleration {a}");
        if a_prev.is_finite() {
            // at least the motion's own jerk limit (2000 mm/s^3) is allowed
            assert!(((a - a_prev) / CYCLE_S).abs() <= 2000.0 * 1.001 + 1e-6);
        }
        a_prev = a;
        let (on_path, _) = m.path().sample(sp.s);
        assert!(on_path.max_diff(&sp.pose) < 1e-9);
        v_prev = sp.speed;
        s_prev = sp.s;
        if sp.phase == Phase::Idle {
            assert_eq!(sp.speed, 0.0);
            break;
        }
    }
    assert!(
        s_prev < m.path().length() / 2.0,
        "stopped early, not at the end"
    );
    assert!(ip.is_idle());
}
