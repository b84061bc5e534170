//! `pcr-driver`: the driver process. Wakes on the joint-setpoint event and writes the setpoint
//! to the drive at once; a periodic interval (the control period) notices missing setpoints: after
//! two cycles without one it holds position (stops the motors). Publishes the driver state (+
//! event) with the measured pose when the backend has one.
//!
//! Backends: `sim` (ideal drive + FK pose sensor), `plant` (the simulated plant; with
//! `--qtm-port` it also serves its capture view as a simulated Qualisys QTM), `fil` and `serial`
//! (the Arduino firmware), both inside the safety stack Watchdog(PositionLimit(RateLimit(..))).

use anyhow::{anyhow, Context, Result};
use clap::{Parser, ValueEnum};
use pcr_control::{
    max_step_rate, plant_backend, safety_stack, DriverStep, FkPoseSensor, IdealDrive, NoPoseSensor,
    PlantDrive, PoseSensor, SafeDriver,
};
use pcr_driver::{Driver, SerialConfig, SerialDriver};
use pcr_fil::{FilOptions, FirmwareInTheLoop};
use pcr_kinematics::Robot;
use pcr_messages::{
    monotonic_ns, services as s, DriverStateMsg, Heartbeat, JointSetpoint, NodeKind,
};
use pcr_mocap_bridge::{QtmServer, ServerConfig};
use pcr_nodes::cycle::{driver_on_setpoint, driver_run};
use pcr_nodes::hop;
use pcr_nodes::{ports::latest, publish, ChainNode, CommonArgs, CycleStats, ProtocolGuard};
use pcr_plant::PlantConfig;
use pcr_robot::RobotConfig;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Backend {
    /// Ideal drive with an FK pose sensor (fast, deterministic).
    Sim,
    /// The simulated plant (pcr-plant) with its motion-capture view.
    Plant,
    /// Firmware in the loop: the serial driver -> the real firmware in simavr -> the plant.
    Fil,
    /// The stepper firmware over a serial port.
    Serial,
}

#[derive(Parser, Debug)]
#[command(about = "pcr-driver: joint setpoints to the drive")]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// Drive backend.
    #[arg(long, value_enum, default_value = "sim")]
    backend: Backend,
    /// Serial port of the `serial` backend.
    #[arg(long, default_value = "/dev/ttyACM0")]
    port: String,
    /// Plant configuration of the `plant` backend (default: the built-in prototype plant).
    #[arg(long)]
    plant: Option<String>,
    /// `plant` backend: serve a simulated QTM (QTM RT protocol) with the plant's capture view
    /// on this port (0: off). SIGUSR1 restarts it (connections closed, refused for 1 s).
    #[arg(long, default_value_t = 0)]
    qtm_port: u16,
    /// Address the simulated QTM listens on.
    #[arg(long, default_value = "127.0.0.1")]
    qtm_bind: String,
}

/// Set by SIGUSR1: simulate a QTM restart.
static QTM_RESTART: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

extern "C" fn on_sigusr1(_: libc::c_int) {
    QTM_RESTART.store(true, std::sync::atomic::Ordering::SeqCst);
}

fn main() -> std::process::ExitCode {
    pcr_nodes::init_logging();
    match run(Args::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("pcr-driver: error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(a: Args) -> Result<()> {
    let c = &a.common;
    let robot_cfg = RobotConfig::load(&c.robot).with_context(|| format!("robot {}", c.robot))?;
    let robot = Robot::new(&robot_cfg).map_err(|e| anyhow!("robot model: {e}"))?;
    let (cn, guard) = pcr_nodes::startup(NodeKind::Driver, c)?;
    let period = c.period().as_secs_f64();
    let watchdog_s = 5.0 * period;
    match a.backend {
        Backend::Sim => {
            let home: [i32; 3] = std::array::from_fn(|i| {
                robot
                    .kappa_to_steps(i, robot.home_kappa[i])
                    .map_or(0, |s| s.round() as i32)
            });
            let start = sim_start(&cn, home)?;
            let drv = safety_stack(
                IdealDrive::new(start, max_step_rate(&robot)),
                &robot,
                watchdog_s,
            );
            let step = DriverStep::new(drv, FkPoseSensor::new(robot), period);
            serve(c, cn, guard, step, None)
        }
        Backend::Plant => {
            let plant_cfg = match &a.plant {
                Some(p) => PlantConfig::load(p).with_context(|| format!("plant {p}"))?,
                None => PlantConfig::prototype(),
            };
            // The plant deviates from its own drawing, never from the model that drives it.
            let drawing = plant_cfg.drawing().map_err(|e| anyhow!("plant: {e}"))?;
            let (mut drive, sensor) =
                plant_backend(&drawing, &plant_cfg).map_err(|e| anyhow!("plant: {e}"))?;
            let home = drive.home_steps();
            let start = sim_start(&cn, home)?;
            if start != home {
                // The physical robot keeps its pose across a driver restart: bring the new plant
                // to the held setpoint before serving.
                bring_to(&mut drive, start, period)?;
            }
            let qtm = if a.qtm_port != 0 {
                let params = pcr_control::sim_parameters(plant_rate_hz(&drive));
                let addr = format!("{}:{}", a.qtm_bind, a.qtm_port);
                let server = std::sync::Arc::new(
                    QtmServer::bind(ServerConfig::new(&addr, params))
                        .with_context(|| format!("simulated QTM on {addr}"))?,
                );
                drive.serve_qtm(server.clone());
                tracing::info!(%addr, "simulated QTM serving the plant's capture view");
                Some(server)
            } else {
                None
            };
            let drv = safety_stack(drive, &robot, watchdog_s);
            let mut step = DriverStep::new(drv, sensor, period);
            step.set_frame_correction(robot_cfg.effects.frame.clone());
            serve(c, cn, guard, step, qtm)
        }
        Backend::Fil => {
            let plant_cfg = match &a.plant {
                Some(p) => PlantConfig::load(p).with_context(|| format!("plant {p}"))?,
                None => PlantConfig::prototype(),
            };
            let drawing = plant_cfg.drawing().map_err(|e| anyhow!("plant: {e}"))?;
            let fil = FirmwareInTheLoop::start(&drawing, &plant_cfg, FilOptions::default())
                .map_err(|e| anyhow!("firmware in the loop: {e}"))?;
            let frame = fil.plant().capture_model().registered;
            let last = std::rc::Rc::new(std::cell::Cell::new(None));
            let drv = safety_stack(
                FilDrive {
                    fil,
                    frame,
                    last: last.clone(),
                },
                &robot,
                watchdog_s,
            );
            let mut step = DriverStep::new(drv, SharedPose { last }, period);
            step.set_frame_correction(robot_cfg.effects.frame.clone());
            serve(c, cn, guard, step, None)
        }
        Backend::Serial => {
            let serial = SerialDriver::open(SerialConfig::new(a.port.clone()))
                .with_context(|| format!("serial port {}", a.port))?;
            let drv = safety_stack(serial, &robot, watchdog_s);
            let step = DriverStep::new(drv, NoPoseSensor, period);
            serve(c, cn, guard, step, None)
        }
    }
}

/// Where the simulated motors are when this process starts. Real motors keep their position
/// when the driver process restarts; the interim plant lives inside this process, so after a
/// restart it adopts the setpoint the chain is holding (the supervisor pauses the program at the
/// setpoint the previous driver executed last). On a fresh chain nobody publishes yet: home.
fn sim_start(cn: &ChainNode, home: [i32; 3]) -> Result<[i32; 3]> {
    let sub = cn.subscriber::<JointSetpoint>(s::JOINT_SETPOINT)?;
    let end = std::time::Instant::now() + std::time::Duration::from_millis(200);
    while std::time::Instant::now() < end {
        if let Ok(Some(j)) = latest(&sub) {
            tracing::info!(steps = ?j.steps, "sim: adopting the chain's held setpoint as the motor positions");
            return Ok(j.steps);
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    Ok(home)
}

/// The firmware-in-the-loop backend with the plant's capture view kept for [`SharedPose`].
struct FilDrive {
    fil: FirmwareInTheLoop,
    frame: pcr_plant::Frame,
    last: std::rc::Rc<std::cell::Cell<Option<pcr_kinematics::Pose>>>,
}

impl Driver for FilDrive {
    fn name(&self) -> &str {
        "fil"
    }
    fn write(
        &mut self,
        time_s: f64,
        period_s: f64,
        cmd: &pcr_driver::MotorCommand,
    ) -> Result<(), pcr_driver::DriverError> {
        self.fil.write(time_s, period_s, cmd)
    }
    fn read(
        &mut self,
        time_s: f64,
        period_s: f64,
    ) -> Result<pcr_driver::DriverState, pcr_driver::DriverError> {
        let s = self.fil.read(time_s, period_s)?;
        for m in self.fil.drain_measurements() {
            if let Some(p) = m.in_robot_frame(&self.frame).pose {
                self.last
                    .set(Some(pcr_kinematics::Pose::new(p[0], p[1], p[2])));
            }
        }
        Ok(s)
    }
    fn diagnostics(&self) -> Vec<(String, u64)> {
        self.fil.diagnostics()
    }
}

/// The latest capture sample of the FIL's plant as the measured pose.
struct SharedPose {
    last: std::rc::Rc<std::cell::Cell<Option<pcr_kinematics::Pose>>>,
}

impl PoseSensor for SharedPose {
    fn name(&self) -> &str {
        "fil-plant-capture"
    }
    fn measure(
        &mut self,
        _time_s: f64,
        _state: &pcr_driver::DriverState,
    ) -> Option<pcr_kinematics::Pose> {
        self.last.take()
    }
}

/// The plant's capture rate, Hz.
fn plant_rate_hz(drive: &PlantDrive) -> f64 {
    1.0 / drive.plant().capture_model().period
}

/// Steps a fresh plant to `target` (rate-limited by the plant itself), at most 30 s.
fn bring_to(drive: &mut PlantDrive, target: [i32; 3], period: f64) -> Result<()> {
    let cmd = pcr_driver::MotorCommand {
        steps: target,
        enable: true,
    };
    let mut t = 0.0;
    while t < 30.0 {
        drive.write(t, period, &cmd)?;
        t += period;
        if drive.read(t, period)?.steps == target {
            return Ok(());
        }
    }
    Err(anyhow!(
        "the plant did not reach the held setpoint {target:?}"
    ))
}

fn serve<D: Driver, P: PoseSensor>(
    c: &CommonArgs,
    cn: ChainNode,
    guard: ProtocolGuard,
    mut step: DriverStep<SafeDriver<D>, P>,
    qtm: Option<std::sync::Arc<QtmServer>>,
) -> Result<()> {
    let kind = NodeKind::Driver;
    let sub = cn.subscriber::<JointSetpoint>(s::JOINT_SETPOINT)?;
    let listener = cn.hop_listener(s::JOINT_SETPOINT)?;
    let pub_st = cn.publisher::<DriverStateMsg>(s::DRIVER_STATE)?;
    let notify = cn.notifier(s::DRIVER_STATE)?;
    let pub_hb = cn.publisher::<Heartbeat>(s::HEARTBEAT)?;
    pcr_nodes::realtime::apply(c.rt_priority, c.cpu, c.mlockall);

    let period_ns = c.period().as_nanos() as u64;
    let mut stats = CycleStats::new(kind, c.protocol_version, period_ns);
    let mut fresh_since_tick = false;
    let mut fatal: Option<anyhow::Error> = None;

    if qtm.is_some() {
        // SIGUSR1 restarts the simulated QTM (seen at the next heartbeat).
        // SAFETY: the handler only stores to an atomic.
        unsafe {
            libc::signal(
                libc::SIGUSR1,
                on_sigusr1 as extern "C" fn(libc::c_int) as libc::sighandler_t,
            )
        };
    }
    let _ticker = hop::start("pcr-driver", c, s::JOINT_SETPOINT, Some(c.period()))?;

    loop {
        let w = hop::wait(&listener)?;
        if w.terminate {
            break;
        }
        if w.sample {
            if let Some((rx, latency, r)) = driver_on_setpoint(&sub, &mut step, &pub_st, &notify) {
                fresh_since_tick = true;
                if let Err(e) = r {
                    fatal = Some(e);
                    break;
                }
                stats.record(monotonic_ns() - rx, latency);
            }
        }
        if w.tick {
            if !fresh_since_tick {
                stats.stale_input();
                if let Err(e) = driver_run(&mut step, None, &pub_st, &notify) {
                    fatal = Some(e);
                    break;
                }
            }
            fresh_since_tick = false;
        }
        if w.heartbeat {
            if QTM_RESTART.swap(false, std::sync::atomic::Ordering::SeqCst) {
                if let Some(q) = &qtm {
                    tracing::warn!("SIGUSR1: the simulated QTM restarts (down for 1 s)");
                    q.simulate_restart(std::time::Duration::from_secs(1));
                }
            }
            let _ = publish(&pub_hb, stats.heartbeat(step.holding()));
            pcr_nodes::recheck(&guard);
        }
    }
    tracing::info!(kind = kind.name(), "loop ended");
    if fatal.is_none() {
        // Terminated (the supervisor stops the chain, or died: SIGTERM by PR_SET_PDEATHSIG):
        // the last command to the drive holds the motors where they are.
        let (t, period) = (pcr_nodes::chain_time_s(), c.period().as_secs_f64());
        let held = step.driver_mut().read(t, period).and_then(|st| {
            let cmd = pcr_driver::MotorCommand {
                steps: st.steps,
                enable: true,
            };
            step.driver_mut().write(t, period, &cmd).map(|()| st.steps)
        });
        match held {
            Ok(steps) => eprintln!("pcr-driver: terminated; the drive holds at steps {steps:?}"),
            Err(e) => eprintln!("pcr-driver: terminated; could not command the hold: {e}"),
        }
    }
    eprintln!("{}", stats.summary());
    match fatal {
        Some(e) => Err(e),
        None => Ok(()),
    }
}
