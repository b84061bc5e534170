//! `pcr qtm`: tools for any QTM RT server (the lab's Qualisys system or the simulator):
//! `params` (what it declares), `stream` (frames to CSV), `register` (the capture-to-robot
//! transform from the base markers), and `serve` (a simulated QTM fed by the plant).

use anyhow::{anyhow, bail, Context, Result};
use clap::{Args as ClapArgs, Subcommand};
use pcr_control::capture_feed::{sim_parameters, CaptureFeed};
use pcr_driver::{Driver, MotorCommand};
use pcr_mocap_bridge::client::Item;
use pcr_mocap_bridge::wire::DEFAULT_PORT;
use pcr_mocap_bridge::{
    ClientConfig, Frame, Mapper, MarkerLabels, QtmClient, QtmServer, Registration, ServerConfig,
    StreamRate,
};
use pcr_plant::{Plant, PlantConfig};
use std::io::Write;
use std::time::{Duration, Instant};

/// `pcr qtm`.
#[derive(ClapArgs)]
pub struct Args {
    #[command(subcommand)]
    command: QtmCommand,
}

/// Where the server is.
#[derive(ClapArgs, Clone)]
struct Server {
    /// QTM host name or address.
    #[arg(long, default_value = "127.0.0.1")]
    host: String,
    /// QTM RT port (little-endian).
    #[arg(long, default_value_t = DEFAULT_PORT)]
    port: u16,
}

impl Server {
    fn config(&self) -> ClientConfig {
        ClientConfig::new(&self.host, self.port)
    }
}

#[derive(Subcommand)]
enum QtmCommand {
    /// Print what the server declares: protocol version, frequency, labels, 6DOF bodies.
    Params {
        #[command(flatten)]
        server: Server,
    },
    /// Stream frames to CSV: frame,timestamp_us,x_mm,y_mm,phi_deg then <label>_x_mm,
    /// <label>_y_mm,<label>_z_mm per labelled marker (empty cells: not measured).
    Stream {
        #[command(flatten)]
        server: Server,
        /// Frames to write.
        #[arg(long)]
        frames: u64,
        /// Registration file (`pcr qtm register`): robot frame instead of the capture frame.
        #[arg(long)]
        registration: Option<String>,
        /// The 6DOF body of the pose columns (default: the first).
        #[arg(long)]
        body: Option<String>,
        /// Ask for about this many frames per second (`Frequency:n`; default: all frames).
        #[arg(long)]
        frequency: Option<u32>,
        /// Give up when no frame arrives for this long, s.
        #[arg(long, default_value_t = 5.0)]
        timeout_s: f64,
        /// Output CSV.
        #[arg(long)]
        output: String,
    },
    /// Fit the capture-to-robot transform to the base markers and write it.
    Register {
        #[command(flatten)]
        server: Server,
        /// Robot configuration (its base points B_i); default: configs/robot.toml if present,
        /// else the built-in nominal robot.
        #[arg(long)]
        robot: Option<String>,
        /// Frames averaged.
        #[arg(long, default_value_t = 100)]
        frames: usize,
        /// Labels of the base markers B1,B2,B3.
        #[arg(long, default_value = "B1,B2,B3")]
        base_labels: String,
        /// Refuse when a marker's residual exceeds this, mm.
        #[arg(long, default_value_t = pcr_mocap_bridge::registration::DEFAULT_MAX_RESIDUAL_MM)]
        max_residual_mm: f64,
        /// Output registration file (TOML).
        #[arg(long)]
        out: String,
    },
    /// Serve a simulated QTM fed by the simulated plant's capture view (runs the plant in
    /// real time; prints `listening on ADDR` when ready).
    Serve {
        /// Address to listen on (port 0: any free port).
        #[arg(long, default_value = "127.0.0.1")]
        bind: String,
        /// Port.
        #[arg(long, default_value_t = DEFAULT_PORT)]
        port: u16,
        /// Robot configuration; default: configs/robot.toml if present, else the built-in
        /// nominal robot.
        #[arg(long)]
        robot: Option<String>,
        /// Plant configuration (default: the built-in prototype-like plant).
        #[arg(long)]
        plant: Option<String>,
        /// Capture without noise, dropouts and latency (the frames are the plant's truth).
        #[arg(long)]
        ideal_capture: bool,
        /// Motion: `sweep` (slow sinusoids of the motors around home) or `home`.
        #[arg(long, default_value = "sweep")]
        motion: String,
        /// Stop after this many seconds (default: run until killed).
        #[arg(long)]
        seconds: Option<f64>,
        /// Write the plant's true state per cycle (capture frame) to this CSV.
        #[arg(long)]
        truth: Option<String>,
    },
}

/// Runs `pcr qtm`.
pub fn run(a: Args) -> Result<()> {
    match a.command {
        QtmCommand::Params { server } => params(&server),
        QtmCommand::Stream {
            server,
            frames,
            registration,
            body,
            frequency,
            timeout_s,
            output,
        } => stream(
            &server,
            frames,
            registration.as_deref(),
            body.as_deref(),
            frequency,
            timeout_s,
            &output,
        ),
        QtmCommand::Register {
            server,
            robot,
            frames,
            base_labels,
            max_residual_mm,
            out,
        } => register(
            &server,
            robot.as_deref(),
            frames,
            &base_labels,
            max_residual_mm,
            &out,
        ),
        QtmCommand::Serve {
            bind,
            port,
            robot,
            plant,
            ideal_capture,
            motion,
            seconds,
            truth,
        } => serve(
            &format!("{bind}:{port}"),
            robot.as_deref(),
            plant.as_deref(),
            ideal_capture,
            &motion,
            seconds,
            truth.as_deref(),
        ),
    }
}

fn connect(server: &Server, rate: StreamRate) -> Result<QtmClient> {
    let mut cfg = server.config();
    cfg.rate = rate;
    QtmClient::connect(&cfg).with_context(|| format!("QTM at {}:{}", server.host, server.port))
}

fn params(server: &Server) -> Result<()> {
    let mut c = connect(server, StreamRate::AllFrames)?;
    let p = c.parameters().context("GetParameters")?;
    println!("server: {}:{}", server.host, server.port);
    println!("protocol version: {}", c.version());
    match p.frequency_hz {
        Some(f) => println!("frequency: {f} Hz"),
        None => println!("frequency: not declared"),
    }
    println!(
        "labelled markers ({}): {}",
        p.labels.len(),
        p.labels.join(", ")
    );
    println!("6DOF bodies ({}): {}", p.bodies.len(), p.bodies.join(", "));
    Ok(())
}

/// Collects `n` frames (events and no-more-data are skipped; `timeout` without a frame is an
/// error), calling `each` on every frame.
fn collect(
    c: &mut QtmClient,
    n: u64,
    timeout: Duration,
    mut each: impl FnMut(&Frame) -> Result<()>,
) -> Result<()> {
    let mut got = 0;
    let mut last = Instant::now();
    while got < n {
        match c.next(last + timeout).context("streaming")? {
            Some(Item::Frame) => {
                got += 1;
                last = Instant::now();
                each(c.frame())?;
            }
            Some(Item::NoMoreData) | Some(Item::Event(_)) => {}
            None => bail!(
                "no frame for {:.1} s after {got} of {n} frames (is QTM capturing?)",
                timeout.as_secs_f64()
            ),
        }
    }
    Ok(())
}

fn stream(
    server: &Server,
    frames: u64,
    registration: Option<&str>,
    body: Option<&str>,
    frequency: Option<u32>,
    timeout_s: f64,
    output: &str,
) -> Result<()> {
    let reg = match registration {
        Some(f) => Registration::load(f)?,
        None => Registration::identity(),
    };
    let rate = frequency.map_or(StreamRate::AllFrames, StreamRate::Frequency);
    let mut c = connect(server, rate)?;
    let p = c.parameters().context("GetParameters")?;
    // Checks that the body exists.
    Mapper::new(&p, body, &MarkerLabels::default(), reg.clone())?;
    let body_idx = match body {
        Some(b) => p.body_index(b),
        None => (!p.bodies.is_empty()).then_some(0),
    };
    let file = std::fs::File::create(output).with_context(|| format!("output {output}"))?;
    let mut w = std::io::BufWriter::new(file);
    let mut header = String::from("frame,timestamp_us,x_mm,y_mm,phi_deg");
    for l in &p.labels {
        header.push_str(&format!(",{l}_x_mm,{l}_y_mm,{l}_z_mm"));
    }
    writeln!(w, "{header}")?;
    c.start_streaming()?;
    collect(&mut c, frames, Duration::from_secs_f64(timeout_s), |f| {
        let mut line = format!("{},{}", f.frame_number, f.timestamp_us);
        match body_idx.and_then(|i| f.bodies.get(i).copied().flatten()) {
            Some(b) => {
                let q = reg.pose(&b);
                line.push_str(&format!(
                    ",{:.4},{:.4},{:.5}",
                    q[0],
                    q[1],
                    q[2].to_degrees()
                ));
            }
            None => line.push_str(",,,"),
        }
        for k in 0..p.labels.len() {
            match f.markers.get(k).copied().flatten() {
                Some(m) => {
                    let q = reg.point(m.position_mm);
                    line.push_str(&format!(",{:.4},{:.4},{:.4}", q[0], q[1], q[2]));
                }
                None => line.push_str(",,,"),
            }
        }
        writeln!(w, "{line}")?;
        Ok(())
    })?;
    w.flush()?;
    let _ = c.stop_streaming();
    eprintln!(
        "{frames} frames from {}:{} (protocol {}) to {output}{}",
        server.host,
        server.port,
        c.version(),
        if registration.is_some() {
            " (robot frame)"
        } else {
            " (capture frame)"
        }
    );
    Ok(())
}

fn register(
    server: &Server,
    robot: Option<&str>,
    n: usize,
    base_labels: &str,
    max_residual_mm: f64,
    out: &str,
) -> Result<()> {
    let (rc, robot) = crate::robot_arg::load(robot)?;
    let base: [[f64; 2]; 3] = std::array::from_fn(|i| rc.legs[i].base_point());
    let parts: Vec<&str> = base_labels.split(',').map(str::trim).collect();
    let [b1, b2, b3] = parts[..] else {
        bail!("--base-labels needs three labels, got {base_labels:?}");
    };
    let labels = MarkerLabels {
        base: [b1.into(), b2.into(), b3.into()],
        ..MarkerLabels::default()
    };
    let mut c = connect(server, StreamRate::AllFrames)?;
    let p = c.parameters().context("GetParameters")?;
    c.start_streaming()?;
    let mut frames = Vec::with_capacity(n);
    collect(&mut c, n as u64, Duration::from_secs(5), |f| {
        frames.push(f.clone());
        Ok(())
    })?;
    let reg = Registration::from_frames(&p, &frames, &labels, &base, max_residual_mm)?;
    let (dx, dy, dphi) = reg.planar_capture_frame();
    reg.save(
        out,
        &format!(
            "pcr qtm register --host {} --port {} --robot {robot}: {n} frames averaged",
            server.host, server.port
        ),
    )?;
    println!("residuals: {}", reg.residuals_text());
    println!(
        "capture frame (robot point p seen at R(dphi) p + d): dx {dx:.3} mm, dy {dy:.3} mm, dphi \
         {:.4} deg",
        dphi.to_degrees()
    );
    println!("registration: {out}");
    Ok(())
}

fn serve(
    bind: &str,
    robot: Option<&str>,
    plant: Option<&str>,
    ideal_capture: bool,
    motion: &str,
    seconds: Option<f64>,
    truth: Option<&str>,
) -> Result<()> {
    let (rc, _) = crate::robot_arg::load(robot)?;
    let mut pc = match plant {
        Some(p) => PlantConfig::load(p).with_context(|| format!("plant {p}"))?,
        None => PlantConfig::prototype(),
    };
    if ideal_capture {
        pc.capture.noise = false;
        pc.capture.dropout_probability = 0.0;
        pc.capture.latency_s = 0.0;
    }
    let sweep = match motion {
        "sweep" => true,
        "home" => false,
        o => bail!("--motion {o:?}: sweep or home"),
    };
    let mut plant = Plant::new(&rc, &pc).map_err(|e| anyhow!("plant: {e}"))?;
    let server = QtmServer::bind(ServerConfig::new(bind, sim_parameters(pc.capture.rate_hz)))
        .with_context(|| format!("cannot listen on {bind}"))?;
    let mut feed = CaptureFeed::new(&plant);
    let frame = plant.capture_model().frame;
    let true_base: Vec<[f64; 2]> = (0..3)
        .map(|i| frame.to_capture(plant.truth().robot.legs[i].base))
        .collect();
    let mut truth_out = match truth {
        Some(f) => {
            let mut w = std::io::BufWriter::new(
                std::fs::File::create(f).with_context(|| format!("truth {f}"))?,
            );
            let mut h = String::from("frame,timestamp_us,x_mm,y_mm,phi_deg");
            for l in ["B1", "B2", "B3", "M1", "M2", "M3"] {
                h.push_str(&format!(",{l}_x_mm,{l}_y_mm"));
            }
            writeln!(w, "{h}")?;
            Some(w)
        }
        None => None,
    };
    println!("listening on {}", server.local_addr());
    std::io::stdout().flush()?;
    let home = plant.home_steps();
    let period = pc.simulation.cycle_s;
    let start = Instant::now();
    let mut t = 0.0;
    loop {
        if seconds.is_some_and(|s| t >= s) {
            break;
        }
        let steps = std::array::from_fn(|i| {
            if sweep {
                let ph = i as f64 * 2.1;
                home[i] + (40.0 * (std::f64::consts::TAU * 0.2 * t + ph).sin()).round() as i32
            } else {
                home[i]
            }
        });
        let cmd = MotorCommand {
            steps,
            enable: true,
        };
        plant
            .write(t, period, &cmd)
            .map_err(|e| anyhow!("plant: {e}"))?;
        t += period;
        plant.read(t, period).map_err(|e| anyhow!("plant: {e}"))?;
        let ms = plant.drain_measurements();
        for m in &ms {
            let f = feed.frame_of(m);
            server.push(f);
            if let Some(w) = truth_out.as_mut() {
                if (m.t_s - t).abs() < 1e-9 {
                    // the sample at the cycle's end: the plant's true state now
                    let eq = &plant.true_state().eq;
                    let p = frame.pose_to_capture(eq.pose);
                    let mut line = format!(
                        "{},{},{:.6},{:.6},{:.6}",
                        f.frame_number,
                        f.timestamp_us,
                        p[0],
                        p[1],
                        p[2].to_degrees()
                    );
                    for b in &true_base {
                        line.push_str(&format!(",{:.6},{:.6}", b[0], b[1]));
                    }
                    for mi in eq.m {
                        let q = frame.to_capture(mi);
                        line.push_str(&format!(",{:.6},{:.6}", q[0], q[1]));
                    }
                    writeln!(w, "{line}")?;
                    w.flush()?;
                }
            }
        }
        let due = start + Duration::from_secs_f64(t);
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
    }
    Ok(())
}
