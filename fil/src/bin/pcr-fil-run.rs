//! Runs the firmware-in-the-loop stack for a number of 20 ms cycles (three motors following
//! sines around home, as the driver bench) and prints throughput and coupling numbers.
//!
//!     cargo run --release -p pcr-fil --bin pcr-fil-run -- --cycles 500

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::Parser;
use pcr_driver::{Driver, MotorCommand};
use pcr_fil::{FilOptions, FirmwareInTheLoop};
use pcr_plant::PlantConfig;
use pcr_robot::RobotConfig;

#[derive(Parser, Debug)]
#[command(about = "Firmware-in-the-loop run: serial driver -> firmware in simavr -> plant")]
struct Args {
    /// Plant configuration.
    #[arg(long, default_value = "configs/plant.toml")]
    plant: PathBuf,
    /// Robot configuration.
    #[arg(long, default_value = "configs/robot.toml")]
    robot: PathBuf,
    /// Number of 20 ms cycles.
    #[arg(long, default_value_t = 500)]
    cycles: usize,
    /// Sine amplitude around home, steps.
    #[arg(long, default_value_t = 60.0)]
    amplitude: f64,
    /// Sine period, s.
    #[arg(long, default_value_t = 4.0)]
    sine_period: f64,
    /// Firmware build and PTY folder.
    #[arg(long)]
    work_dir: Option<PathBuf>,
    /// Firmware host watchdog, ms (default: the firmware's 200).
    #[arg(long)]
    watchdog_ms: Option<u16>,
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

fn main() -> Result<()> {
    tracing_subscriber_init();
    let args = Args::parse();
    let robot = RobotConfig::load(&args.robot).with_context(|| format!("{:?}", args.robot))?;
    let plant = PlantConfig::load(&args.plant).with_context(|| format!("{:?}", args.plant))?;
    let mut opts = FilOptions::default();
    if let Some(d) = args.work_dir {
        opts.work_dir = d;
    }
    if let Some(ms) = args.watchdog_ms {
        let mut fw = FilOptions::firmware_for(&robot);
        fw.watchdog_ms = ms;
        opts.firmware = Some(fw);
    }
    let t_build = Instant::now();
    let mut fil = FirmwareInTheLoop::start(&robot, &plant, opts).context("starting the FIL")?;
    let start_s = t_build.elapsed().as_secs_f64();
    let home = fil.plant().home_steps();
    let period = Duration::from_millis(20);
    let mut next = Instant::now();
    let wall0 = Instant::now();
    let plant_t0 = fil.plant().time();
    let mut rt = Vec::with_capacity(args.cycles);
    let mut faults = 0;
    for k in 0..args.cycles {
        if let Some(w) = next.checked_duration_since(Instant::now()) {
            std::thread::sleep(w);
        }
        next += period;
        let t = (k + 1) as f64 * 0.02;
        let w = std::f64::consts::TAU * t / args.sine_period;
        let phase = [0.0, 2.1, 4.2];
        let steps = std::array::from_fn(|i| {
            home[i] + (args.amplitude * (w + phase[i]).sin()).round() as i32
        });
        let t_io = Instant::now();
        fil.write(
            t,
            0.02,
            &MotorCommand {
                steps,
                enable: true,
            },
        )?;
        let s = fil.read(t, 0.02)?;
        rt.push(t_io.elapsed().as_secs_f64() * 1e3);
        faults += usize::from(s.fault);
    }
    let wall = wall0.elapsed().as_secs_f64();
    let plant_dt = fil.plant().time() - plant_t0;
    let c = fil.counters();
    let n_meas = fil.drain_measurements().len();
    println!("start (build check, emulator, handshake, plant): {start_s:.2} s");
    println!(
        "cycles: {}  wall: {wall:.2} s  => {:.1} cycles per wall-clock second",
        args.cycles,
        args.cycles as f64 / wall
    );
    println!(
        "plant (emulated) time advanced: {plant_dt:.2} s ({:.3} x wall)",
        plant_dt / wall
    );
    println!(
        "write+read+plant per cycle, ms: mean {:.2}  p50 {:.2}  p90 {:.2}  p99 {:.2}  max {:.2}",
        rt.iter().sum::<f64>() / rt.len() as f64,
        percentile(&mut rt, 0.5),
        percentile(&mut rt, 0.9),
        percentile(&mut rt, 0.99),
        percentile(&mut rt, 1.0)
    );
    println!(
        "steps applied {}  late {}  sync timeouts {}  plant faults {}  illegal patterns {}  fault reports {}",
        c.steps_applied, c.late_steps, c.sync_timeouts, c.plant_faults, c.illegal_patterns, faults
    );
    println!("capture samples: {n_meas}");
    let ts = fil.true_state();
    println!(
        "end: firmware/plant motors {:?}, platform ({:.3} mm, {:.3} mm, {:.3} deg)",
        ts.counter,
        ts.eq.pose[0],
        ts.eq.pose[1],
        ts.eq.pose[2].to_degrees()
    );
    Ok(())
}

fn tracing_subscriber_init() {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .try_init();
}
