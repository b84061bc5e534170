//! No heap allocation in a steady-state cycle of any node of the chain: a counting global
//! allocator observes the cycle bodies the processes run ([`pcr_nodes::cycle`]), on real iceoryx2
//! services (their own prefix, removed afterwards): the planner's setpoint (a running program)
//! with its input drains, the IK and the driver (sim backend inside the safety stack), each woken
//! on its hop listener ([`pcr_nodes::hop::wait`]) as the processes are, the mocap correction
//! woken by its WaitSet, and the heartbeat with the protocol check. Every publication goes through the loan helper ([`pcr_nodes::publish`]).
//!
//! iceoryx2 0.10 itself allocates in two places of a cycle, which no caller can avoid: every
//! loaned sample gets a small reference-counted shared state (`Rc::new` in
//! `ChunkMutSharedState::new`, under `Publisher::loan_uninit`, and so under `send_copy` too), and
//! every WaitSet wake-up collects the triggered descriptors into two `Vec`s
//! (`WaitSet::wait_and_process_once_with_timeout`, `handle_all_attachments`). The test measures
//! those per loan and per wake-up on a service of its own and requires the cycles to allocate
//! exactly that much and nothing more: any allocation of the chain's own code fails it
//! (`PCR_ALLOC_TRACE=1` prints where the first allocations of each part come from).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use iceoryx2::prelude::*;
use pcr_control::{
    max_step_rate, prepare_run, safety_stack, simple_command, CorrectionConfig, CorrectionStep,
    DriverStep, FkPoseSensor, IdealDrive, IkStep, InterpolatorStep, MotionLimits, PlannerSource,
};
use pcr_kinematics::{Pose, Robot};
use pcr_messages::{
    command_kind, program_id, services as s, Command, Correction, DriverStateMsg, Heartbeat,
    JointSetpoint, MeasuredPose, NodeKind, TaskSetpoint, PROTOCOL_VERSION,
};
use pcr_nodes::cycle::{driver_on_setpoint, ik_on_setpoint, mocap_on_state, planner_emit};
use pcr_nodes::ports::{latest, remove_leftovers};
use pcr_nodes::{hop, publish, ChainNode, CycleStats, ProtocolGuard};

struct Counting;

static ALLOCS: AtomicUsize = AtomicUsize::new(0);
/// Allocations per part of the cycle (see [`PARTS`]), to tell which part allocates.
static BY_PART: [AtomicUsize; 8] = [const { AtomicUsize::new(0) }; 8];
const PARTS: [&str; 8] = [
    "planner inputs",
    "planner setpoint",
    "ik (hop wait + cycle)",
    "driver (hop wait + cycle)",
    "mocap (WaitSet + cycle)",
    "heartbeat",
    "protocol check",
    "heartbeat drain",
];

thread_local! {
    // Only the test's own thread is counted (the harness may allocate on its thread meanwhile).
    static COUNT_HERE: Cell<bool> = const { Cell::new(false) };
    static PART: Cell<usize> = const { Cell::new(0) };
}

fn part(i: usize) {
    PART.with(|p| p.set(i));
}

fn count_one() {
    if COUNT_HERE.try_with(|c| c.get()).unwrap_or(false) {
        ALLOCS.fetch_add(1, Ordering::SeqCst);
        let p = PART.try_with(|p| p.get()).unwrap_or(0);
        let k = BY_PART[p].fetch_add(1, Ordering::SeqCst);
        if k < 4 && std::env::var_os("PCR_ALLOC_TRACE").is_some() {
            COUNT_HERE.with(|c| c.set(false));
            eprintln!(
                "{}\n{}",
                PARTS[p],
                std::backtrace::Backtrace::force_capture()
            );
            COUNT_HERE.with(|c| c.set(true));
        }
    }
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count_one();
        unsafe { System.alloc(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count_one();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Removes the prefix's iceoryx2 files when the test ends (also on a failed assertion).
struct Cleanup(String);
impl Drop for Cleanup {
    fn drop(&mut self) {
        remove_leftovers(&self.0);
    }
}

fn counted<R>(f: impl FnOnce() -> R) -> (R, usize) {
    let before = ALLOCS.load(Ordering::SeqCst);
    COUNT_HERE.with(|c| c.set(true));
    let r = f();
    COUNT_HERE.with(|c| c.set(false));
    (r, ALLOCS.load(Ordering::SeqCst) - before)
}

#[test]
fn steady_state_cycles_allocate_nothing_beyond_iceoryx2s_own() {
    let prefix = format!("pcrtalloc{}_", std::process::id());
    let _cleanup = Cleanup(prefix.clone());
    run(&prefix);
}

/// iceoryx2's own allocations: (per loaned and sent sample, per WaitSet wake-up).
fn iceoryx2_allocations(cn: &ChainNode) -> (usize, usize) {
    let p = cn.publisher::<u64>("pcr-alloc-test/calibration").unwrap();
    let s = cn.subscriber::<u64>("pcr-alloc-test/calibration").unwrap();
    let n = cn.notifier("pcr-alloc-test/calibration").unwrap();
    let l = cn.listener("pcr-alloc-test/calibration").unwrap();
    let ws = WaitSetBuilder::new().create::<ipc::Service>().unwrap();
    let _g = ws.attach_notification(&l).unwrap();
    let wake = || {
        ws.wait_and_process_once_with_timeout(
            |_| {
                let _ = l.try_wait(|_| {});
                CallbackProgression::Continue
            },
            Duration::from_secs(1),
        )
        .unwrap();
    };
    for i in 0..20 {
        publish(&p, i).unwrap();
        n.notify().unwrap();
        wake();
        while let Ok(Some(_)) = s.receive() {}
    }
    let k = 100;
    let ((), loans) = counted(|| {
        for i in 0..k {
            publish(&p, i).unwrap();
        }
    });
    while let Ok(Some(_)) = s.receive() {}
    let mut wakes = 0;
    for i in 0..k {
        publish(&p, i).unwrap();
        n.notify().unwrap();
        wakes += counted(wake).1;
        while let Ok(Some(_)) = s.receive() {}
    }
    assert_eq!(loans % k as usize, 0, "{loans} allocations in {k} loans");
    assert_eq!(wakes % k as usize, 0, "{wakes} allocations in {k} wake-ups");
    (loans / k as usize, wakes / k as usize)
}

fn run(prefix: &str) {
    let cn = ChainNode::new("pcr-alloc-test", prefix, PROTOCOL_VERSION).unwrap();
    let (per_loan, per_wake) = iceoryx2_allocations(&cn);
    for b in &BY_PART {
        b.store(0, Ordering::SeqCst);
    }
    let guard = ProtocolGuard::new(&cn, NodeKind::Ik).unwrap();
    // planner
    let pub_sp = cn.publisher::<TaskSetpoint>(s::TASK_SETPOINT).unwrap();
    let notify_sp = cn.hop_notifier(s::TASK_SETPOINT).unwrap();
    let sub_cmd = cn.subscriber::<Command>(s::COMMAND).unwrap();
    let sub_corr = cn.subscriber::<Correction>(s::CORRECTION).unwrap();
    let sub_state_p = cn.subscriber::<DriverStateMsg>(s::DRIVER_STATE).unwrap();
    // ik
    let sub_sp = cn.subscriber::<TaskSetpoint>(s::TASK_SETPOINT).unwrap();
    let lis_sp = cn.hop_listener(s::TASK_SETPOINT).unwrap();
    let pub_j = cn.publisher::<JointSetpoint>(s::JOINT_SETPOINT).unwrap();
    let notify_j = cn.hop_notifier(s::JOINT_SETPOINT).unwrap();
    // driver
    let sub_j = cn.subscriber::<JointSetpoint>(s::JOINT_SETPOINT).unwrap();
    let lis_j = cn.hop_listener(s::JOINT_SETPOINT).unwrap();
    let pub_st = cn.publisher::<DriverStateMsg>(s::DRIVER_STATE).unwrap();
    let notify_st = cn.notifier(s::DRIVER_STATE).unwrap();
    // mocap
    let sub_st = cn.subscriber::<DriverStateMsg>(s::DRIVER_STATE).unwrap();
    let lis_st = cn.listener(s::DRIVER_STATE).unwrap();
    let pub_m = cn.publisher::<MeasuredPose>(s::MEASURED_POSE).unwrap();
    let pub_c = cn.publisher::<Correction>(s::CORRECTION).unwrap();
    // heartbeats (and a reader, as the supervisor)
    let pub_hb = cn.publisher::<Heartbeat>(s::HEARTBEAT).unwrap();
    let sub_hb = cn.subscriber::<Heartbeat>(s::HEARTBEAT).unwrap();
    let pub_cmd = cn.publisher::<Command>(s::COMMAND).unwrap();

    // The IK step compensates the friction it declares (a pass of the friction's history
    // every cycle): that too allocates nothing.
    let mut cfg = pcr_robot::RobotConfig::nominal();
    cfg.effects.friction = Some(pcr_robot::effects::Friction {
        joint_torque_n_mm: 2.0,
        support_force_n: 0.04,
        joint_presliding_rad: 1e-3,
        support_presliding_mm: 5e-3,
        ei_n_mm2: 6.5e4,
    });
    let robot = Robot::new(&cfg).unwrap();
    let period = 0.02;
    let template = PlannerSource::new(robot.clone(), MotionLimits::default());
    let mut interp = InterpolatorStep::new(template.clone(), Pose::default());
    let cmd = simple_command(command_kind::RUN, program_id::PAPER, 1);
    let prepared = prepare_run(template, &cmd, interp.hold()).expect("plan the paper program");
    let (r, _unused) = interp.install(prepared);
    r.expect("install the program");
    let mut ik = IkStep::new(robot.clone());
    let home: [i32; 3] = std::array::from_fn(|i| {
        robot
            .kappa_to_steps(i, robot.home_kappa[i])
            .map_or(0, |s| s.round() as i32)
    });
    let drv = safety_stack(IdealDrive::new(home, max_step_rate(&robot)), &robot, 1.0);
    let mut step = DriverStep::new(drv, FkPoseSensor::new(robot.clone()), period);
    let mut corr = CorrectionStep::new(CorrectionConfig {
        gain: 0.2,
        limit_mm: 5.0,
        latency_s: 0.0,
    });
    let mut stats = CycleStats::new(NodeKind::Ik, PROTOCOL_VERSION, 20_000_000);

    let ws_mocap = WaitSetBuilder::new().create::<ipc::Service>().unwrap();
    let g_mocap = ws_mocap.attach_notification(&lis_st).unwrap();

    let mut t = 0.0;
    let mut served = [0u64; 3];
    let mut cycle = |count_commands: bool, served: &mut [u64; 3]| {
        // planner: inputs, then the setpoint
        part(0);
        while let Ok(Some(c)) = sub_cmd.receive() {
            assert!(count_commands || c.payload().kind != command_kind::RUN);
        }
        if let Ok(Some(c)) = latest(&sub_corr) {
            interp.set_correction(&c);
        }
        let _ = latest(&sub_state_p);
        t += period;
        part(1);
        planner_emit(&mut interp, t, &pub_sp, &notify_sp);
        // ik, woken on its hop listener (the planner notified it just now)
        part(2);
        let w = hop::wait(&lis_sp).unwrap();
        if w.sample {
            if let Some((rx, latency)) = ik_on_setpoint(&sub_sp, &mut ik, &pub_j, &notify_j) {
                stats.record(pcr_messages::monotonic_ns() - rx, latency);
                served[0] += 1;
            }
        }
        // driver
        part(3);
        let w = hop::wait(&lis_j).unwrap();
        if w.sample {
            if let Some((_, _, r)) = driver_on_setpoint(&sub_j, &mut step, &pub_st, &notify_st) {
                r.unwrap();
                served[1] += 1;
            }
        }
        // mocap
        part(4);
        let _ = ws_mocap.wait_and_process_once_with_timeout(
            |id| {
                if id.has_event_from(&g_mocap)
                    && mocap_on_state(&lis_st, &sub_st, &mut corr, &pub_m, &pub_c).is_some()
                {
                    served[2] += 1;
                }
                CallbackProgression::Continue
            },
            Duration::from_secs(1),
        );
        // heartbeat and protocol check (every process, each heartbeat period)
        part(5);
        let _ = publish(&pub_hb, stats.heartbeat(false));
        part(6);
        pcr_nodes::recheck(&guard);
        part(7);
        while let Ok(Some(_)) = sub_hb.receive() {}
    };

    // A command on the command path too (as the supervisor sends it), then warm up.
    publish(&pub_cmd, simple_command(command_kind::RESUME, 0, 1)).unwrap();
    for _ in 0..50 {
        cycle(true, &mut served);
    }
    assert_eq!(served, [50; 3], "every node served every warm-up cycle");
    let n = 500;
    let ((), allocs) = counted(|| {
        for _ in 0..n {
            cycle(false, &mut served);
        }
    });
    assert_eq!(served, [50 + n; 3], "every node served every counted cycle");
    assert!(
        interp.status(t).state == pcr_messages::planner_state::RUNNING,
        "the program still runs (a steady state with motion)"
    );
    let by_part: Vec<String> = PARTS
        .iter()
        .zip(&BY_PART)
        .map(|(p, c)| format!("{p}: {}", c.load(Ordering::SeqCst)))
        .collect();
    // Per cycle: 7 samples loaned and sent (planner setpoint, IK joint setpoint, driver
    // state, mocap measured pose and correction, heartbeat, protocol announcement) and one
    // WaitSet wake-up (mocap); the hop waits (IK, driver) allocate nothing.
    let iceoryx2_own = n as usize * (7 * per_loan + per_wake);
    assert_eq!(
        allocs,
        iceoryx2_own,
        "{allocs} heap allocations in {n} steady-state cycles, iceoryx2 0.10's own are \
         {iceoryx2_own} ({per_loan} per loan, {per_wake} per WaitSet wake-up); by part: {}",
        by_part.join(", ")
    );
    eprintln!(
        "{n} cycles: {allocs} allocations, all iceoryx2 0.10's own ({per_loan} per loan, \
         {per_wake} per WaitSet wake-up); none in the chain's code"
    );
}
