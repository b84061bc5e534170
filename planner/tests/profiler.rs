//! Invariant-based tests of the profiler: every trajectory respects the limits (1e-9 relative,
//! fine sampling plus segment ends), reaches the target (1e-8), and its duration is minimal
//! (analytic formulas, reference values, and "slightly shorter is infeasible" checks).

use pcr_planner::profiler::{
    calculate, shapes, step1::Step1, ControlInterface, Input, Limits, ProfileError, State,
    Synchronization, Trajectory,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn input1(cur: State, tgt: State, lim: Limits) -> Input {
    let mut i = Input::new(1);
    i.current[0] = cur;
    i.target[0] = tgt;
    i.limits[0] = lim;
    i
}

/// Checks limits (after each DoF's brake) and the final state of a trajectory.
fn check_invariants(input: &Input, traj: &Trajectory) {
    let d = traj.duration();
    assert!(d.is_finite() && d >= 0.0);
    for k in 0..input.dofs {
        let lim = &input.limits[k];
        let step = Step1::solve(
            input.control_interface,
            &input.current[k],
            &input.target[k],
            lim,
        )
        .unwrap();
        let tb = step.brake_duration();
        let prof = traj.profile(k);
        let vel = input.control_interface == ControlInterface::Position;
        let n = 2000;
        let tv = 1e-9 * lim.vmax.abs().max(lim.vmin.abs());
        let ta = 1e-9 * lim.amax.abs().max(lim.amin.abs());
        for s in 0..=n {
            let t = tb + (d - tb) * s as f64 / n as f64;
            let (st, j) = traj.at_dof(k, t);
            assert!(j.abs() <= lim.jmax * (1.0 + 1e-12), "jerk {j} at {t}");
            assert!(
                st.a <= lim.amax + ta && st.a >= lim.amin - ta,
                "dof {k}: a = {} at t = {t} outside [{}, {}]",
                st.a,
                lim.amin,
                lim.amax
            );
            if vel {
                assert!(
                    st.v <= lim.vmax + tv && st.v >= lim.vmin - tv,
                    "dof {k}: v = {} at t = {t} outside [{}, {}]",
                    st.v,
                    lim.vmin,
                    lim.vmax
                );
            }
        }
        // Segment ends of the main profile (the brake is exempt).
        let mut t = 0.0;
        for i in 0..prof.len() {
            t += prof.segment(i).0;
            if t > tb + 1e-12 {
                let (st, _) = prof.at(t);
                assert!(st.a <= lim.amax + ta && st.a >= lim.amin - ta);
                if vel {
                    assert!(st.v <= lim.vmax + tv && st.v >= lim.vmin - tv);
                }
            }
        }
        if input.synchronization != Synchronization::None {
            let (e, _) = traj.at_dof(k, d);
            let tg = input.target[k];
            let tol = |x: f64| 1e-8 * x.abs().max(1.0);
            if vel {
                assert!((e.p - tg.p).abs() <= tol(tg.p), "p {} vs {}", e.p, tg.p);
            }
            assert!((e.v - tg.v).abs() <= tol(tg.v), "v {} vs {}", e.v, tg.v);
            assert!((e.a - tg.a).abs() <= tol(tg.a), "a {} vs {}", e.a, tg.a);
        }
    }
}

/// The main-profile duration `t` is infeasible for a single DoF: the target position lies
/// outside `[Pmin(t), Pmax(t)]` (or the target velocity/acceleration cannot be reached).
fn infeasible_1dof(cur: State, tgt: State, lim: Limits, t: f64) -> bool {
    let pr = shapes::Problem::new(&cur, &tgt, &lim);
    match (
        shapes::extreme_at(&pr, 1.0, t),
        shapes::extreme_at(&pr, -1.0, t),
    ) {
        (Some((hi, _)), Some((lo, _))) => pr.d > hi + 1e-12 || pr.d < lo - 1e-12,
        _ => true,
    }
}

fn solve1(cur: State, tgt: State, lim: Limits) -> Trajectory {
    let inp = input1(cur, tgt, lim);
    let traj = calculate(&inp).expect("solvable");
    check_invariants(&inp, &traj);
    traj
}

fn rest(p: f64) -> State {
    State::new(p, 0.0, 0.0)
}

// --- Shapes, rest to rest, against closed forms -------------------------------------------

#[test]
fn rest_to_rest_ramps_only_matches_closed_form() {
    // Short distance: no plateau, T = 4 (d / (2 j))^(1/3).
    let lim = Limits::symmetric(10.0, 10.0, 2.0);
    let d: f64 = 0.3;
    let traj = solve1(rest(0.0), rest(d), lim);
    let expect = 4.0 * (d / (2.0 * 2.0)).cbrt();
    assert!((traj.duration() - expect).abs() < 1e-12 * expect);
}

#[test]
fn rest_to_rest_acceleration_plateau_matches_closed_form() {
    // No velocity plateau but acceleration plateau: d = amax T1 (T1 + amax/j)... solve numerically:
    // with t_a = amax/j ramps and plateau tp: d = amax (ta + tp)(2 ta + tp) / 1 ... use formula
    // T = 2 ta + ... from d = amax * tq * (tq + ta) where tq = ta + tp is half the accel time.
    let (vmax, amax, j) = (100.0, 1.0, 4.0);
    let lim = Limits::symmetric(vmax, amax, j);
    let d = 5.0;
    let traj = solve1(rest(0.0), rest(d), lim);
    let ta = amax / j;
    // d = amax * x * (x + ta) with x = ta + tp  ->  x = (-ta + sqrt(ta^2 + 4 d / amax)) / 2
    let x = (-ta + (ta * ta + 4.0 * d / amax).sqrt()) / 2.0;
    let expect = 2.0 * (x + ta);
    assert!(
        (traj.duration() - expect).abs() < 1e-12 * expect,
        "{} vs {expect}",
        traj.duration()
    );
}

#[test]
fn rest_to_rest_all_plateaus_matches_closed_form() {
    let lim = Limits::symmetric(1.0, 2.0, 10.0);
    let d = 10.0;
    let traj = solve1(rest(1.0), rest(1.0 + d), lim);
    let expect = d / 1.0 + 1.0 / 2.0 + 2.0 / 10.0;
    assert!((traj.duration() - expect).abs() < 1e-12 * expect);
}

#[test]
fn rest_to_rest_velocity_plateau_without_acceleration_plateau() {
    // vmax reached before amax: ramps of sqrt(vmax/j), T = d/vmax + 2 sqrt(vmax/j).
    let lim = Limits::symmetric(0.5, 10.0, 2.0);
    let d = 4.0;
    let traj = solve1(rest(0.0), rest(-d), lim);
    let expect = d / 0.5 + 2.0 * (0.5f64 / 2.0).sqrt();
    assert!((traj.duration() - expect).abs() < 1e-12 * expect);
}

// --- Arbitrary states: reference values computed with ruckig 0.19.4 --------------------------

#[test]
fn arbitrary_states_match_reference_durations() {
    let lim = Limits::symmetric(1.0, 1.0, 1.0);
    let cases = [
        // (v0, a0, pf, vf, af, ruckig duration)
        (0.5, 0.0, 1.0, 1.0, 0.5, 1.374443386082731),
        (0.5, 0.0, 1.0, 0.9, 0.5, 1.4487582053139683),
        (0.5, 1.0, 1.0, 0.0, 0.0, 5.0323624234861635),
        (1.0, 0.0, 1.0, 0.0, 0.0, 2.0),
        (0.95, 0.3, 1.0, 0.0, 0.0, 3.5554701455893563),
    ];
    for (v0, a0, pf, vf, af, expect) in cases {
        let traj = solve1(State::new(0.0, v0, a0), State::new(pf, vf, af), lim);
        assert!(
            (traj.duration() - expect).abs() < 1e-9 * expect,
            "({v0}, {a0}) -> ({pf}, {vf}, {af}): {} vs {expect}",
            traj.duration()
        );
    }
}

// --- Brake pre-trajectory ------------------------------------------------------------------

#[test]
fn states_outside_limits_brake_then_match_reference() {
    let lim = Limits::symmetric(1.0, 1.0, 1.0);
    let cases = [
        (3.0, 0.5, 12.611979166666767),
        (1.2, 0.0, 3.52469507659596),
        (0.9, 0.6, 4.6019807291359465),
        (0.0, 1.5, 6.1193063937629155),
        (0.0, -1.5, 7.945312499999999),
        (1.2, -0.5, 1.950317109773668),
        (1.2, -2.0, 6.791094592650918),
        (3.0, -0.5, 8.528645833333433),
        (-1.2, -2.0, 19.98666666666678),
    ];
    for (v0, a0, expect) in cases {
        let traj = solve1(State::new(0.0, v0, a0), rest(1.0), lim);
        assert!(
            (traj.duration() - expect).abs() < 1e-9 * expect,
            "({v0}, {a0}): {} vs {expect}",
            traj.duration()
        );
    }
}

// --- Minimality by infeasibility of slightly shorter durations ----------------------------

#[test]
fn random_states_are_minimal_and_valid() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for _ in 0..300 {
        let vmax = rng.random_range(0.3..3.0);
        let amax = rng.random_range(0.3..3.0);
        let lim = Limits {
            vmax,
            vmin: -vmax * rng.random_range(0.4..1.6),
            amax,
            amin: -amax * rng.random_range(0.4..1.6),
            jmax: rng.random_range(0.5..8.0),
        };
        let pick = |rng: &mut ChaCha8Rng| loop {
            let v = rng.random_range(lim.vmin..lim.vmax);
            let a = rng.random_range(lim.amin..lim.amax);
            let reach = a * a.abs() / (2.0 * lim.jmax);
            if v + reach <= lim.vmax
                && v + reach >= lim.vmin
                && v - reach >= lim.vmin
                && v - reach <= lim.vmax
            {
                break (v, a);
            }
        };
        let (v0, a0) = pick(&mut rng);
        let (vf, af) = pick(&mut rng);
        let cur = State::new(rng.random_range(-2.0..2.0), v0, a0);
        let tgt = State::new(rng.random_range(-2.0..2.0), vf, af);
        let traj = solve1(cur, tgt, lim);
        let t = traj.duration();
        if t > 1e-6 {
            assert!(
                infeasible_1dof(cur, tgt, lim, t * (1.0 - 1e-6)),
                "shorter duration feasible for {cur:?} -> {tgt:?} {lim:?}"
            );
        }
    }
}

#[test]
fn multi_dof_time_synchronisation_reaches_all_targets_together() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for _ in 0..100 {
        let mut inp = Input::new(3);
        for k in 0..3 {
            let lim = Limits::symmetric(
                rng.random_range(0.3..3.0),
                rng.random_range(0.3..3.0),
                rng.random_range(0.5..8.0),
            );
            inp.limits[k] = lim;
            inp.current[k] = State::new(rng.random_range(-2.0..2.0), 0.0, 0.0);
            let vf = rng.random_range(-0.5..0.5) * lim.vmax;
            inp.target[k] = State::new(rng.random_range(-2.0..2.0), vf, 0.0);
        }
        let traj = calculate(&inp).unwrap();
        check_invariants(&inp, &traj);
        let t_max = (0..3)
            .map(|k| {
                Step1::solve(
                    ControlInterface::Position,
                    &inp.current[k],
                    &inp.target[k],
                    &inp.limits[k],
                )
                .unwrap()
                .t_min()
            })
            .fold(0.0, f64::max);
        assert!(traj.duration() >= t_max - 1e-12);
    }
}

#[test]
fn blocked_interval_is_skipped() {
    // Cruising backwards at full speed with a target slightly behind, arriving at full speed
    // backwards: short durations work, a window is blocked, longer ones (after a reversal) work.
    let lim = Limits::symmetric(1.0, 1.0, 1.0);
    let cur = State::new(0.0, -1.0, 0.0);
    let tgt = State::new(-0.5, -1.0, 0.0);
    let s = Step1::solve(ControlInterface::Position, &cur, &tgt, &lim).unwrap();
    let (ints, n) = s.feasible_intervals();
    let ints = &ints[..n];
    assert!((s.t_min() - 0.5).abs() < 1e-12);
    assert!(ints.len() >= 2, "expected a blocked interval, got {ints:?}");
    let (_, end0) = ints[0];
    let (start1, _) = ints[1];
    assert!(end0 < start1);
    // Synchronise with a second DoF that needs a duration inside the blocked interval.
    let mut inp = Input::new(2);
    inp.current[0] = cur;
    inp.target[0] = tgt;
    inp.limits[0] = lim;
    let mid = 0.5 * (end0 + start1);
    // Rest-to-rest DoF with minimal duration `mid`: short-distance closed form.
    let d = 2.0 * (mid / 4.0).powi(3);
    inp.limits[1] = Limits::symmetric(10.0, 10.0, 1.0);
    inp.target[1] = State::new(d, 0.0, 0.0);
    let traj = calculate(&inp).unwrap();
    check_invariants(&inp, &traj);
    assert!(
        (traj.duration() - start1).abs() < 1e-9,
        "{} vs {start1}",
        traj.duration()
    );
}

#[test]
fn minimum_duration_is_respected() {
    let mut inp = input1(rest(0.0), rest(1.0), Limits::symmetric(1.0, 1.0, 1.0));
    inp.minimum_duration = Some(10.0);
    let traj = calculate(&inp).unwrap();
    check_invariants(&inp, &traj);
    assert!((traj.duration() - 10.0).abs() < 1e-12);
}

#[test]
fn velocity_interface_reference() {
    let lim = Limits::symmetric(1.0, 1.0, 1.0);
    let mut inp = input1(State::new(0.0, 0.5, 0.0), State::new(0.0, 2.0, 0.0), lim);
    inp.control_interface = ControlInterface::Velocity;
    let traj = calculate(&inp).unwrap();
    check_invariants(&inp, &traj);
    assert!((traj.duration() - 2.5).abs() < 1e-12);
    inp.current[0] = State::new(0.0, 0.5, 2.0);
    let traj = calculate(&inp).unwrap();
    check_invariants(&inp, &traj);
    assert!((traj.duration() - 3.414213562373095).abs() < 1e-12);
}

#[test]
fn phase_synchronisation_is_a_straight_line() {
    let mut inp = Input::new(2);
    inp.synchronization = Synchronization::Phase;
    inp.limits[0] = Limits::symmetric(1.0, 1.0, 1.0);
    inp.limits[1] = Limits::symmetric(2.0, 2.0, 2.0);
    inp.target[0] = rest(1.0);
    inp.target[1] = rest(-0.5);
    let traj = calculate(&inp).unwrap();
    check_invariants(&inp, &traj);
    for k in 0..50 {
        let t = traj.duration() * k as f64 / 49.0;
        let (a, _) = traj.at_dof(0, t);
        let (b, _) = traj.at_dof(1, t);
        assert!((b.p + 0.5 * a.p).abs() < 1e-12);
    }
}

#[test]
fn no_synchronisation_uses_each_optimum() {
    let mut inp = Input::new(2);
    inp.synchronization = Synchronization::None;
    inp.target[0] = rest(1.0);
    inp.target[1] = rest(0.1);
    let traj = calculate(&inp).unwrap();
    check_invariants(&inp, &traj);
    assert!(traj.profile(1).duration() < traj.profile(0).duration());
    assert_eq!(traj.duration(), traj.profile(0).duration());
    // A minimum duration only extends the total (as ruckig).
    inp.minimum_duration = Some(8.0);
    let traj2 = calculate(&inp).unwrap();
    assert_eq!(traj2.duration(), 8.0);
    assert_eq!(traj2.profile(0).duration(), traj.profile(0).duration());
}

#[test]
fn already_at_target_has_zero_duration() {
    let traj = solve1(
        State::new(1.0, 0.0, 0.0),
        rest(1.0),
        Limits::symmetric(1.0, 1.0, 1.0),
    );
    assert_eq!(traj.duration(), 0.0);
}

#[test]
fn position_extrema_cover_overshoot() {
    // Moving fast towards a target just ahead: must overshoot and come back.
    let traj = solve1(
        State::new(0.0, 1.0, 0.0),
        rest(0.1),
        Limits::symmetric(1.0, 1.0, 1.0),
    );
    let ex = traj.position_extrema(0);
    assert!(ex.max > 0.1 + 1e-3);
    let (s, _) = traj.at_dof(0, ex.t_max);
    assert!((s.p - ex.max).abs() < 1e-12 && s.v.abs() < 1e-9);
}

// --- Bad inputs ----------------------------------------------------------------------------

#[test]
fn bad_inputs_are_errors() {
    let lim = Limits::symmetric(1.0, 1.0, 1.0);
    let nan = input1(State::new(f64::NAN, 0.0, 0.0), rest(1.0), lim);
    assert!(matches!(
        calculate(&nan),
        Err(ProfileError::NotFinite { .. })
    ));
    for bad in [
        Limits { vmax: 0.0, ..lim },
        Limits { vmin: 0.5, ..lim },
        Limits { amax: -1.0, ..lim },
        Limits { amin: 0.0, ..lim },
        Limits { jmax: 0.0, ..lim },
    ] {
        let i = input1(rest(0.0), rest(1.0), bad);
        assert!(
            matches!(calculate(&i), Err(ProfileError::BadLimit { .. })),
            "{bad:?}"
        );
    }
    let inf = input1(
        rest(0.0),
        rest(1.0),
        Limits {
            jmax: f64::INFINITY,
            ..lim
        },
    );
    assert!(matches!(
        calculate(&inf),
        Err(ProfileError::NotFinite { .. })
    ));
    let fast = input1(rest(0.0), State::new(1.0, 2.0, 0.0), lim);
    assert!(matches!(
        calculate(&fast),
        Err(ProfileError::TargetOutsideLimits { .. })
    ));
    let acc = input1(rest(0.0), State::new(1.0, 0.0, -2.0), lim);
    assert!(matches!(
        calculate(&acc),
        Err(ProfileError::TargetOutsideLimits { .. })
    ));
    // Positive target acceleration at the lower velocity limit: velocity was below it before.
    let unreachable = input1(rest(0.0), State::new(1.0, -1.0, 0.5), lim);
    assert!(matches!(
        calculate(&unreachable),
        Err(ProfileError::TargetUnreachable { .. })
    ));
    let mut none = Input::new(0);
    none.dofs = 0;
    assert!(matches!(
        calculate(&none),
        Err(ProfileError::DofMismatch { .. })
    ));
    let mut md = input1(rest(0.0), rest(1.0), lim);
    md.minimum_duration = Some(-1.0);
    assert!(matches!(
        calculate(&md),
        Err(ProfileError::BadMinimumDuration(_))
    ));
}
