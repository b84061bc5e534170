//! The in-process runtime on the interim plant: accuracy, determinism, stale setpoints.

use pcr_control::{simple_command, InterimChain, Recorder, STALE_CYCLES};
use pcr_kinematics::Robot;
use pcr_messages::{command_kind, driver_flags, program_id};

fn chain() -> InterimChain {
    InterimChain::interim(Robot::nominal(), 0.02)
}

#[test]
fn circle_meets_the_accuracy_bound() {
    let mut c = chain();
    let mut rows = 0;
    let acc = c
        .run(
            &simple_command(command_kind::RUN, program_id::CIRCLE, 1),
            60.0,
            |_| rows += 1,
        )
        .unwrap();
    println!("circle: {acc}");
    // 2 pi 50 mm at 50 mm/s = 6.3 s of circle, plus approach and return.
    assert!(acc.n > 300, "{}", acc.n);
    // The ideal drive follows within a step: errors are the step quantisation only.
    assert!(acc.max_pos_mm < 0.5, "{acc}");
    assert!(acc.rms_pos_mm() < 0.2, "{acc}");
    assert!(acc.max_phi_deg < 0.5, "{acc}");
}

#[test]
fn paper_program_runs_faster_than_real_time_and_records() {
    let mut c = chain();
    let mut buf = Vec::new();
    let mut rec = Recorder::new(&mut buf, &[("source", "test")]).unwrap();
    let t0 = std::time::Instant::now();
    let acc = c
        .run(
            &simple_command(command_kind::RUN, program_id::PAPER, 1),
            120.0,
            |s| rec.row(s).unwrap(),
        )
        .unwrap();
    let rows = rec.rows();
    rec.finish().unwrap();
    let wall = t0.elapsed().as_secs_f64();
    assert!(
        wall < c.time_s(),
        "wall {wall} s vs simulated {} s",
        c.time_s()
    );
    assert!(acc.max_pos_mm < 0.5, "{acc}");
    let text = String::from_utf8(buf).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("# source = test"));
    assert_eq!(lines.next(), Some(pcr_control::recorder::HEADER));
    assert_eq!(lines.count() as u64, rows);
}

#[test]
fn runs_are_deterministic() {
    let run = || {
        let mut c = chain();
        let mut v = Vec::new();
        c.run(
            &simple_command(command_kind::RUN, program_id::SQUARE, 1),
            60.0,
            |s| v.push((s.commanded, s.measured.map(f64::to_bits))),
        )
        .unwrap();
        v
    };
    assert_eq!(run(), run());
}

#[test]
fn stale_setpoints_hold_position_then_resume() {
    let mut c = chain();
    c.interp
        .command(&simple_command(command_kind::RUN, program_id::CIRCLE, 1))
        .unwrap();
    for _ in 0..100 {
        c.cycle().unwrap();
    }
    // Setpoints stop arriving.
    let mut last = None;
    for k in 0..10u32 {
        let out = c.cycle_with(true).unwrap();
        let hold = out.state.flags & driver_flags::STALE_HOLD != 0;
        assert_eq!(hold, k + 1 >= STALE_CYCLES, "cycle {k}");
        if hold {
            if let Some(l) = last {
                assert_eq!(out.state.steps, l, "motors must stop while holding");
            }
            last = Some(out.state.steps);
        }
    }
    assert!(c.driver.holding());
    // They come back: the hold ends.
    let out = c.cycle().unwrap();
    assert_eq!(out.state.flags & driver_flags::STALE_HOLD, 0);
    assert!(!c.driver.holding());
}

#[test]
fn pause_after_lost_setpoints_resumes_from_the_executed_setpoint_without_error() {
    let mut c = chain();
    c.interp
        .command(&simple_command(command_kind::RUN, program_id::CIRCLE, 1))
        .unwrap();
    let mut acc = pcr_control::Accuracy::default();
    for _ in 0..150 {
        acc.add(&c.cycle().unwrap().state);
    }
    // The IK "dies" for 5 cycles: the driver holds after 2.
    let mut executed = 0;
    for _ in 0..5 {
        executed = c.cycle_with(true).unwrap().state.seq;
    }
    // The supervisor pauses; the planner rewinds to what the drive executed, then resumes.
    c.interp
        .command(&simple_command(command_kind::PAUSE, 0, 1))
        .unwrap();
    assert!(c.interp.rewind_to_seq(executed));
    for _ in 0..10 {
        acc.add(&c.cycle().unwrap().state);
    }
    let rest = c.run(&simple_command(command_kind::RESUME, 0, 1), 60.0, |_| {});
    let rest = rest.unwrap();
    assert!(acc.max_pos_mm < 0.5, "{acc}");
    assert!(rest.max_pos_mm < 0.5, "{rest}");
    assert!(rest.n > 100);
}
