//! `pcr-bench-latency`: latency of the process chain, iceoryx2 vs a Unix-domain-socket baseline,
//! measured in the same run on the same machine.
//!
//! iceoryx2: starts `pcr-driver` (sim), `pcr-ik` and `pcr-planner` with a private prefix, runs the
//! paper program (re-sent when it ends) and reads the latency stamps carried by every driver
//! state: planner publish -> IK receive -> IK publish -> driver receive -> driver command.
//! UDS baseline: the same three roles and the same step code (interim source, IK, ideal drive)
//! as three processes (this binary re-executed with `--uds-role`), connected by Unix datagram
//! sockets, the messages copied through the kernel.
//!
//! The period defaults to 2 ms (10x faster than the 20 ms control period) so that 10,000 cycles
//! take 20 s per transport. A deadline miss is a cycle whose end-to-end latency exceeds the
//! period, or a cycle lost (a gap in the sequence numbers seen at the driver's output).

use anyhow::{anyhow, bail, Context, Result};
use clap::Parser;
use hdrhistogram::Histogram;
use iceoryx2::prelude::*;
use pcr_control::{
    max_step_rate, safety_stack, simple_command, DriverStep, FkPoseSensor, IdealDrive, IkStep,
    InterimPathSource, InterpolatorStep,
};
use pcr_kinematics::{Pose, Robot};
use pcr_messages::{
    command_kind, monotonic_ns, planner_state, program_id, services as s, Command, DriverStateMsg,
    Heartbeat, JointSetpoint, PlannerStatus, TaskSetpoint, PROTOCOL_VERSION,
};
use pcr_nodes::ChainNode;
use pcr_robot::RobotConfig;
use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

#[derive(Parser, Debug, Clone)]
#[command(about = "Per-hop and end-to-end latency of the chain: iceoryx2 vs Unix sockets")]
struct Args {
    /// Cycles to measure per transport.
    #[arg(long, default_value_t = 10_000)]
    cycles: u64,
    /// Cycle period, ms (faster than the 20 ms control period to gather cycles quickly).
    #[arg(long, default_value_t = 2.0)]
    period_ms: f64,
    /// Robot configuration.
    #[arg(long, default_value = "configs/robot.toml")]
    robot: String,
    /// SCHED_FIFO priority of the driver of both transports (0 = normal scheduling); the IK runs
    /// `--priority-step` below it and the planner (the UDS baseline's interpolator and collector)
    /// twice that below, as `configs/sim.toml` places them (80, 75, 70).
    #[arg(long, default_value_t = 0)]
    rt_priority: i32,
    /// Priority step between the chain's stages (downstream higher, so that a woken stage
    /// preempts the one that woke it); 0 = every process at `--rt-priority`.
    #[arg(long, default_value_t = 5)]
    priority_step: i32,
    /// Pin every chain process of both transports to this CPU (as configs/sim.toml does).
    #[arg(long)]
    cpu: Option<usize>,
    /// Hold the CPUs' tolerated wake-up latency at this many microseconds during the bench
    /// (`/dev/cpu_dma_latency`; 0 = no deep idle states), as `[realtime] cpu_dma_latency_us`.
    #[arg(long)]
    cpu_dma_latency: Option<i32>,
    /// Lock every chain process's memory (mlockall), as a real-time deployment would.
    #[arg(long)]
    mlockall: bool,
    /// Skip the UDS baseline.
    #[arg(long)]
    no_uds: bool,
    /// Measure in this many alternating blocks (iceoryx2, sockets, iceoryx2, ...) of
    /// `--cycles / --rounds` cycles each and merge them, so that both transports see the same
    /// drift of the machine's load; 1 = one block each.
    #[arg(long, default_value_t = 1)]
    rounds: u64,
    /// Instead of the chain: profile the user-space parts of one hop, this many times per
    /// transport, in one process (publish, notify, wake-up and event drain as it was with a
    /// WaitSet and as the chain does it now on the hop listener, receive; vs the
    /// socket's send and receive), one hop every `--period-ms` so that the load between hops
    /// cools the caches as it does in the chain. The kernel's wake-up of the blocked receiver
    /// is not in it (both transports wake it through a Unix datagram socket).
    #[arg(long)]
    hop_profile: Option<u64>,
    /// Internal: run as a UDS relay role (ik, driver) in directory --dir.
    #[arg(long, hide = true)]
    uds_role: Option<String>,
    #[arg(long, hide = true)]
    dir: Option<PathBuf>,
}

const HOPS: [&str; 5] = [
    "planner -> ik (transport)",
    "ik step",
    "ik -> driver (transport)",
    "driver step to command",
    "end to end (planner publish -> driver command)",
];

struct Hists {
    h: Vec<Histogram<u64>>,
    cycles: u64,
    late: u64,
    lost: u64,
    last_seq: Option<u64>,
}

impl Hists {
    fn new() -> Self {
        Self {
            h: (0..HOPS.len())
                .map(|_| Histogram::new_with_bounds(1, 10_000_000_000, 3).unwrap())
                .collect(),
            cycles: 0,
            late: 0,
            lost: 0,
            last_seq: None,
        }
    }
    fn add(&mut self, st: &pcr_messages::Stamps, seq: u64, period_ns: u64) {
        let v = [
            st.ik_rx_ns.saturating_sub(st.interp_pub_ns),
            st.ik_pub_ns.saturating_sub(st.ik_rx_ns),
            st.drv_rx_ns.saturating_sub(st.ik_pub_ns),
            st.drv_cmd_ns.saturating_sub(st.drv_rx_ns),
            st.drv_cmd_ns.saturating_sub(st.interp_pub_ns),
        ];
        for (h, x) in self.h.iter_mut().zip(v) {
            h.saturating_record(x.max(1));
        }
        if v[4] > period_ns {
            self.late += 1;
        }
        if let Some(l) = self.last_seq {
            if seq > l + 1 {
                self.lost += seq - l - 1;
            }
        }
        self.last_seq = Some(seq);
        self.cycles += 1;
    }
    /// Adds another block's figures.
    fn merge(&mut self, o: &Hists) {
        for (h, x) in self.h.iter_mut().zip(&o.h) {
            let _ = h.add(x);
        }
        self.cycles += o.cycles;
        self.late += o.late;
        self.lost += o.lost;
    }
    fn print(&self, title: &str, extra: &str) {
        println!("\n## {title}\n");
        println!(
            "cycles {}, late (end to end > period) {}, lost {}{extra}\n",
            self.cycles, self.late, self.lost
        );
        println!("| hop | p50 us | p99 us | p99.9 us | max us |");
        println!("|---|---:|---:|---:|---:|");
        for (name, h) in HOPS.iter().zip(&self.h) {
            let q = |p: f64| h.value_at_quantile(p) as f64 / 1e3;
            println!(
                "| {name} | {:.1} | {:.1} | {:.1} | {:.1} |",
                q(0.5),
                q(0.99),
                q(0.999),
                h.max() as f64 / 1e3
            );
        }
    }
}

fn main() -> std::process::ExitCode {
    pcr_nodes::init_logging();
    let a = Args::parse();
    let r = match a.uds_role.as_deref() {
        Some(role) => uds_role(role, a.dir.as_deref().unwrap_or(Path::new(".")), &a),
        None => match a.hop_profile {
            Some(n) => hop_profile(&a, n),
            None => bench(&a),
        },
    };
    match r {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("pcr-bench-latency: error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

struct Kids(Vec<Child>);
impl Drop for Kids {
    fn drop(&mut self) {
        for c in &mut self.0 {
            // SAFETY: kill(2) on our own child.
            unsafe { libc::kill(c.id() as i32, libc::SIGTERM) };
        }
        for c in &mut self.0 {
            let _ = c.wait();
        }
    }
}

fn bin_dir() -> PathBuf {
    std::env::current_exe()
        .ok()
        .and_then(|p| p.parent().map(PathBuf::from))
        .unwrap_or_default()
}

fn robot(path: &str) -> Result<Robot> {
    let cfg = RobotConfig::load(path).with_context(|| format!("robot {path}"))?;
    Robot::new(&cfg).map_err(|e| anyhow!("robot model: {e}"))
}

/// SCHED_FIFO priority of a stage `below` steps under the driver (0 stays normal scheduling).
fn stage_priority(a: &Args, below: i32) -> i32 {
    if a.rt_priority <= 0 {
        0
    } else {
        (a.rt_priority - below * a.priority_step).max(1)
    }
}

fn bench(a: &Args) -> Result<()> {
    let period_ns = (a.period_ms * 1e6) as u64;
    let _pm_qos = a
        .cpu_dma_latency
        .and_then(pcr_nodes::realtime::hold_cpu_dma_latency);
    println!(
        "# pcr-bench-latency: {} cycles per transport at a {} ms period, SCHED_FIFO priorities \
         driver {}, IK {}, planner {} (0 = normal scheduling), chain pinned to CPU {}, CPU \
         wake-up latency held at {} us, {} CPUs",
        a.cycles,
        a.period_ms,
        stage_priority(a, 0),
        stage_priority(a, 1),
        stage_priority(a, 2),
        a.cpu.map_or("-".to_string(), |c| c.to_string()),
        a.cpu_dma_latency.map_or("-".to_string(), |c| c.to_string()),
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    let rounds = a.rounds.max(1);
    let block = Args {
        cycles: a.cycles.div_ceil(rounds),
        ..a.clone()
    };
    let (mut ice, mut ice_misses) = (Hists::new(), 0);
    let (mut uds, mut uds_late) = (Hists::new(), 0);
    for r in 0..rounds {
        if rounds > 1 {
            eprintln!("round {} of {rounds}", r + 1);
        }
        let (h, m) = bench_iceoryx2(&block, period_ns)?;
        ice.merge(&h);
        ice_misses += m;
        if !a.no_uds {
            let (h, l) = bench_uds(&block, period_ns)?;
            uds.merge(&h);
            uds_late += l;
        }
    }
    let blocks = if rounds > 1 {
        format!(" ({rounds} blocks alternating with the other transport)")
    } else {
        String::new()
    };
    ice.print(
        "iceoryx2 (zero-copy shared memory, event-driven)",
        &format!(", process deadline misses (heartbeats) {ice_misses}{blocks}"),
    );
    if !a.no_uds {
        uds.print(
            "Unix-domain datagram sockets (baseline, same steps)",
            &format!(", planner wake-ups late by > period/2: {uds_late}{blocks}"),
        );
    }
    Ok(())
}

fn bench_iceoryx2(a: &Args, period_ns: u64) -> Result<(Hists, u64)> {
    let prefix = format!("pcrbench{}_", std::process::id());
    let r = bench_iceoryx2_in(a, period_ns, &prefix);
    // Every node of the prefix is gone now: remove what iceoryx2 leaves behind.
    pcr_nodes::ports::remove_leftovers(&prefix);
    r
}

fn bench_iceoryx2_in(a: &Args, period_ns: u64, prefix: &str) -> Result<(Hists, u64)> {
    let prefix = prefix.to_string();
    let common = [
        "--prefix".to_string(),
        prefix.clone(),
        "--period-ms".into(),
        a.period_ms.to_string(),
        "--robot".into(),
        a.robot.clone(),
    ];
    let lock = a.mlockall.then(|| "--mlockall".to_string());
    let cpu = a
        .cpu
        .map(|c| ["--cpu".to_string(), c.to_string()])
        .into_iter()
        .flatten();
    let common: Vec<String> = common.into_iter().chain(lock).chain(cpu).collect();
    let mut kids = Kids(Vec::new());
    for (below, b) in ["pcr-driver", "pcr-ik", "pcr-planner"]
        .into_iter()
        .enumerate()
    {
        kids.0.push(
            std::process::Command::new(bin_dir().join(b))
                .args(&common)
                .arg("--rt-priority")
                .arg(stage_priority(a, below as i32).to_string())
                .env("RUST_LOG", "warn")
                .stdin(Stdio::null())
                .spawn()
                .with_context(|| format!("start {b}"))?,
        );
    }
    let cn = ChainNode::new("pcr-bench", &prefix, PROTOCOL_VERSION)?;
    let sub = cn.subscriber::<DriverStateMsg>(s::DRIVER_STATE)?;
    let listener = cn.listener(s::DRIVER_STATE)?;
    let sub_hb = cn.subscriber::<Heartbeat>(s::HEARTBEAT)?;
    let pub_cmd = cn.publisher::<Command>(s::COMMAND)?;
    let sub_status = cn.subscriber::<PlannerStatus>(s::STATUS)?;
    let mut planner_busy = false;
    let mut h = Hists::new();
    let mut misses = std::collections::HashMap::new();
    let ws = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .map_err(|e| anyhow!("{e:?}"))?;
    let ev = ws
        .attach_notification(&listener)
        .map_err(|e| anyhow!("{e:?}"))?;
    let tick = ws
        .attach_interval(Duration::from_millis(500))
        .map_err(|e| anyhow!("{e:?}"))?;
    let start = Instant::now();
    let mut run_id = 0u32;
    let mut warm = 0u64;
    let r = pcr_nodes::run_waitset(&ws, |id| {
        if id.has_event_from(&ev) {
            let _ = listener.try_wait(|_| {});
            while let Ok(Some(smp)) = sub.receive() {
                let m = smp.payload();
                if m.stamps.drv_cmd_ns != 0 && m.stamps.interp_pub_ns != 0 {
                    // Skip the first cycles (start-up, page faults).
                    warm += 1;
                    if warm > 100 {
                        h.add(&m.stamps, m.seq, period_ns);
                    }
                }
            }
            if h.cycles >= a.cycles {
                return CallbackProgression::Stop;
            }
        }
        if id.has_event_from(&tick) {
            while let Ok(Some(smp)) = sub_hb.receive() {
                misses.insert(smp.pid, smp.deadline_misses);
            }
            // (Re)start the paper program whenever the planner is free, so that the IK works
            // on a moving target.
            while let Ok(Some(smp)) = sub_status.receive() {
                let st = smp.payload();
                // (IDLE: the planner never got a command, e.g. sent before it subscribed.)
                if st.run_id == run_id || st.state == planner_state::IDLE {
                    planner_busy = matches!(
                        st.state,
                        planner_state::RUNNING | planner_state::PAUSED | planner_state::PLANNING
                    );
                }
            }
            if !planner_busy {
                run_id += 1;
                planner_busy = true;
                let _ = pcr_nodes::publish(
                    &pub_cmd,
                    simple_command(command_kind::RUN, program_id::PAPER, run_id),
                );
            }
            if start.elapsed()
                > Duration::from_secs(30) + Duration::from_nanos(period_ns * a.cycles * 3)
            {
                return CallbackProgression::Stop;
            }
        }
        CallbackProgression::Continue
    })
    .map_err(|e| anyhow!("{e:?}"))?;
    if !matches!(r, WaitSetRunResult::StopRequest) {
        bail!("interrupted");
    }
    while let Ok(Some(smp)) = sub_hb.receive() {
        misses.insert(smp.pid, smp.deadline_misses);
    }
    drop(kids);
    Ok((h, misses.values().sum()))
}

use iceoryx2::waitset::WaitSetRunResult;

fn as_bytes<T: Copy>(v: &T) -> &[u8] {
    // SAFETY: T is a repr(C) plain-data message; reading its bytes is fine.
    unsafe { std::slice::from_raw_parts(v as *const T as *const u8, std::mem::size_of::<T>()) }
}

fn from_bytes<T: Copy + Default>(b: &[u8]) -> T {
    if b.len() != std::mem::size_of::<T>() {
        return T::default();
    }
    // SAFETY: the size matches and the messages are plain data of one build.
    unsafe { std::ptr::read_unaligned(b.as_ptr() as *const T) }
}

fn uds_role(role: &str, dir: &Path, a: &Args) -> Result<()> {
    let robot = robot(&a.robot)?;
    // --rt-priority carries this role's own priority (set by bench_uds).
    pcr_nodes::realtime::apply(a.rt_priority, a.cpu, false);
    let mut buf = [0u8; 4096];
    match role {
        "ik" => {
            let sock = UnixDatagram::bind(dir.join("ik.sock"))?;
            let mut ik = IkStep::new(robot);
            loop {
                let n = sock.recv(&mut buf)?;
                let rx = monotonic_ns();
                let mut sp: TaskSetpoint = from_bytes(&buf[..n]);
                if sp.seq == u64::MAX {
                    let _ = sock.send_to(&buf[..n], dir.join("drv.sock"));
                    return Ok(());
                }
                sp.stamps.ik_rx_ns = rx;
                let mut j = ik.step(&sp);
                j.stamps.ik_pub_ns = monotonic_ns();
                let _ = sock.send_to(as_bytes(&j), dir.join("drv.sock"));
            }
        }
        "driver" => {
            let sock = UnixDatagram::bind(dir.join("drv.sock"))?;
            let home: [i32; 3] = std::array::from_fn(|i| {
                robot
                    .kappa_to_steps(i, robot.home_kappa[i])
                    .map_or(0, |s| s.round() as i32)
            });
            let period = a.period_ms * 1e-3;
            let drv = safety_stack(IdealDrive::new(home, max_step_rate(&robot)), &robot, 1.0);
            let mut step = DriverStep::new(drv, FkPoseSensor::new(robot), period);
            loop {
                let n = sock.recv(&mut buf)?;
                let rx = monotonic_ns();
                if n != std::mem::size_of::<JointSetpoint>() {
                    let _ = sock.send_to(&buf[..n], dir.join("col.sock"));
                    return Ok(());
                }
                let mut j: JointSetpoint = from_bytes(&buf[..n]);
                j.stamps.drv_rx_ns = rx;
                let st = step
                    .step(pcr_nodes::chain_time_s(), Some(&j))
                    .map_err(|e| anyhow!("{e}"))?;
                let _ = sock.send_to(as_bytes(&st), dir.join("col.sock"));
            }
        }
        o => bail!("unknown role {o}"),
    }
}

fn bench_uds(a: &Args, period_ns: u64) -> Result<(Hists, u64)> {
    let dir = std::env::temp_dir().join(format!("pcrbench-uds-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir)?;
    let col = UnixDatagram::bind(dir.join("col.sock"))?;
    col.set_nonblocking(true)?;
    let me = std::env::current_exe()?;
    let mut kids = Kids(Vec::new());
    for (below, role) in ["driver", "ik"].into_iter().enumerate() {
        kids.0.push(
            std::process::Command::new(&me)
                .args(["--uds-role", role, "--robot", &a.robot])
                .arg("--rt-priority")
                .arg(stage_priority(a, below as i32).to_string())
                .args(a.cpu.map(|c| format!("--cpu={c}")))
                .arg("--period-ms")
                .arg(a.period_ms.to_string())
                .arg("--dir")
                .arg(&dir)
                .stdin(Stdio::null())
                .spawn()?,
        );
    }
    let end = Instant::now() + Duration::from_secs(10);
    while !(dir.join("ik.sock").exists() && dir.join("drv.sock").exists()) {
        if Instant::now() > end {
            bail!("UDS roles did not start");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let tx = UnixDatagram::unbound()?;
    let rt = pcr_nodes::realtime::apply(stage_priority(a, 2), a.cpu, false);
    let mut interp = InterpolatorStep::new(InterimPathSource::new(), Pose::default());
    let mut h = Hists::new();
    let mut late_wakes = 0u64;
    let period = Duration::from_nanos(period_ns);
    let mut next = Instant::now() + period;
    let mut buf = [0u8; 4096];
    let mut sent = 0u64;
    let total = a.cycles + 100;
    let mut t_cmd = 0u64;
    while sent < total {
        if interp.can_start().is_ok() {
            t_cmd += 1;
            interp
                .command(&simple_command(
                    command_kind::RUN,
                    program_id::PAPER,
                    t_cmd as u32,
                ))
                .map_err(|e| anyhow!("{e}"))?;
        }
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        }
        let woke = Instant::now();
        if woke.duration_since(next) > period / 2 {
            late_wakes += 1;
        }
        next += period;
        let mut sp = interp.step(pcr_nodes::chain_time_s());
        sp.stamps.interp_pub_ns = monotonic_ns();
        let _ = tx.send_to(as_bytes(&sp), dir.join("ik.sock"));
        sent += 1;
        // Collect whatever came back (non-blocking; the stamps carry the latencies).
        while let Ok(n) = col.recv(&mut buf) {
            let st: DriverStateMsg = from_bytes(&buf[..n]);
            if st.seq > 100 {
                h.add(&st.stamps, st.seq, period_ns);
            }
        }
    }
    // Stop the roles: a sentinel travels through the chain.
    let stop = TaskSetpoint {
        seq: u64::MAX,
        ..Default::default()
    };
    let _ = tx.send_to(as_bytes(&stop), dir.join("ik.sock"));
    let end = Instant::now() + Duration::from_secs(2);
    'tail: while Instant::now() < end {
        while let Ok(n) = col.recv(&mut buf) {
            if n != std::mem::size_of::<DriverStateMsg>() {
                break 'tail;
            }
            let st: DriverStateMsg = from_bytes(&buf[..n]);
            h.add(&st.stamps, st.seq, period_ns);
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    drop(kids);
    if rt.priority > 0 {
        // Back to normal scheduling for the rest of the run.
        pcr_nodes::realtime::apply_normal();
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok((h, late_wakes))
}

/// `--hop-profile N`: where the user-space time of one hop goes, iceoryx2 vs the socket.
fn hop_profile(a: &Args, n: u64) -> Result<()> {
    let rt = pcr_nodes::realtime::apply(stage_priority(a, 0), a.cpu, false);
    let period = Duration::from_secs_f64(a.period_ms * 1e-3);
    let new_h = || Histogram::<u64>::new_with_bounds(1, 10_000_000_000, 3).unwrap();
    let row = |name: &str, h: &Histogram<u64>| {
        let q = |p: f64| h.value_at_quantile(p) as f64 / 1e3;
        println!(
            "| {name} | {:.1} | {:.1} | {:.1} | {:.1} |",
            q(0.5),
            q(0.99),
            q(0.999),
            h.max() as f64 / 1e3
        );
    };
    println!(
        "# hop profile: {n} hops per transport, one every {} ms, SCHED_FIFO {}, CPU {}; \
         TaskSetpoint ({} bytes)",
        a.period_ms,
        rt.priority,
        rt.cpu.map_or("-".to_string(), |c| c.to_string()),
        std::mem::size_of::<TaskSetpoint>()
    );
    // iceoryx2, with the chain's service settings (pcr_nodes::ports).
    let prefix = format!("pcrhop{}_", std::process::id());
    let names = [
        "publish (loan, write in place, send)",
        "notify",
        "WaitSet wake-up to the callback (epoll_wait returns at once)",
        "drain the event (listener try_wait)",
        "receive the newest sample (latest)",
        "total",
    ];
    let mut hs: Vec<Histogram<u64>> = names.iter().map(|_| new_h()).collect();
    {
        let cn = ChainNode::new("pcr-hop", &prefix, PROTOCOL_VERSION)?;
        let p = cn.publisher::<TaskSetpoint>("hop-profile")?;
        let sub = cn.subscriber::<TaskSetpoint>("hop-profile")?;
        let notifier = cn.notifier("hop-profile")?;
        let listener = cn.listener("hop-profile")?;
        let ws = WaitSetBuilder::new()
            .create::<ipc::Service>()
            .map_err(|e| anyhow!("{e:?}"))?;
        let g = ws
            .attach_notification(&listener)
            .map_err(|e| anyhow!("{e:?}"))?;
        for i in 0..n + 50 {
            std::thread::sleep(period);
            let sp = TaskSetpoint {
                seq: i,
                ..Default::default()
            };
            let t0 = monotonic_ns();
            let _ = pcr_nodes::publish(&p, sp);
            let t1 = monotonic_ns();
            let _ = notifier.notify();
            let t2 = monotonic_ns();
            let mut t = [0u64; 3];
            let _ = ws.wait_and_process_once(|id| {
                if id.has_event_from(&g) {
                    t[0] = monotonic_ns();
                    let _ = listener.try_wait(|_| {});
                    t[1] = monotonic_ns();
                    let _ = pcr_nodes::ports::latest(&sub);
                    t[2] = monotonic_ns();
                }
                CallbackProgression::Continue
            });
            if i >= 50 && t[2] != 0 {
                let v = [
                    t1 - t0,
                    t2 - t1,
                    t[0] - t2,
                    t[1] - t[0],
                    t[2] - t[1],
                    t[2] - t0,
                ];
                for (h, x) in hs.iter_mut().zip(v) {
                    h.saturating_record(x.max(1));
                }
            }
        }
    }
    pcr_nodes::ports::remove_leftovers(&prefix);
    println!("\n## iceoryx2 hop, user space, as it was: socket event (ipc::Service), WaitSet\n");
    println!("| part | p50 us | p99 us | p99.9 us | max us |");
    println!("|---|---:|---:|---:|---:|");
    for (name, h) in names.iter().zip(&hs) {
        row(name, h);
    }
    // The chain's hop now: semaphore event (pcr_nodes::hop::HopService), waited on alone.
    let hnames = [
        "publish (loan, write in place, send)",
        "notify (sem_post)",
        "wait on the hop listener and drain (hop::wait: sem_wait returns at once)",
        "receive the newest sample (latest)",
        "total",
    ];
    let mut hh: Vec<Histogram<u64>> = hnames.iter().map(|_| new_h()).collect();
    {
        let cn = ChainNode::new("pcr-hop", &prefix, PROTOCOL_VERSION)?;
        let p = cn.publisher::<TaskSetpoint>("hop-profile")?;
        let sub = cn.subscriber::<TaskSetpoint>("hop-profile")?;
        let notifier = cn.hop_notifier("hop-profile")?;
        let listener = cn.hop_listener("hop-profile")?;
        for i in 0..n + 50 {
            std::thread::sleep(period);
            let sp = TaskSetpoint {
                seq: i,
                ..Default::default()
            };
            let t0 = monotonic_ns();
            let _ = pcr_nodes::publish(&p, sp);
            let t1 = monotonic_ns();
            let _ = notifier.notify();
            let t2 = monotonic_ns();
            let w = pcr_nodes::hop::wait(&listener)?;
            let t3 = monotonic_ns();
            let _ = pcr_nodes::ports::latest(&sub);
            let t4 = monotonic_ns();
            if i >= 50 && w.sample {
                for (h, x) in hh
                    .iter_mut()
                    .zip([t1 - t0, t2 - t1, t3 - t2, t4 - t3, t4 - t0])
                {
                    h.saturating_record(x.max(1));
                }
            }
        }
    }
    pcr_nodes::ports::remove_leftovers(&prefix);
    println!("\n## iceoryx2 hop, user space, the chain's now: semaphore event, hop listener\n");
    println!("| part | p50 us | p99 us | p99.9 us | max us |");
    println!("|---|---:|---:|---:|---:|");
    for (name, h) in hnames.iter().zip(&hh) {
        row(name, h);
    }
    // The socket: send a datagram of the same size, receive it (blocking recv, data present).
    let dir = std::env::temp_dir().join(format!("pcrhop-uds-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir)?;
    let rx = UnixDatagram::bind(dir.join("rx.sock"))?;
    let tx = UnixDatagram::unbound()?;
    let unames = ["send_to", "recv (data present)", "total"];
    let mut uh: Vec<Histogram<u64>> = unames.iter().map(|_| new_h()).collect();
    let mut buf = [0u8; 4096];
    let target = dir.join("rx.sock");
    for i in 0..n + 50 {
        std::thread::sleep(period);
        let sp = TaskSetpoint {
            seq: i,
            ..Default::default()
        };
        let t0 = monotonic_ns();
        let _ = tx.send_to(as_bytes(&sp), &target);
        let t1 = monotonic_ns();
        let k = rx.recv(&mut buf)?;
        let _sp: TaskSetpoint = from_bytes(&buf[..k]);
        let t2 = monotonic_ns();
        if i >= 50 {
            for (h, x) in uh.iter_mut().zip([t1 - t0, t2 - t1, t2 - t0]) {
                h.saturating_record(x.max(1));
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    println!("\n## Unix datagram socket hop, user space\n");
    println!("| part | p50 us | p99 us | p99.9 us | max us |");
    println!("|---|---:|---:|---:|---:|");
    for (name, h) in unames.iter().zip(&uh) {
        row(name, h);
    }
    Ok(())
}
