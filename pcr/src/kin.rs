//! `pcr ik`, `pcr fk`, `pcr workspace`: the kinematic model on CSV files and workspace analysis.

use crate::csvio::{self, column, fmt, next_record, number, optional_column};
use crate::figures_kin;
use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use pcr_kinematics::workspace::{self, Workspace};
use pcr_kinematics::{Pose, Robot};
use pcr_offline::kinematics_rows::{fk_row, ik_row, kappa_of_steps};
use pcr_robot::RobotConfig;

fn load_robot(path: &Option<String>) -> Result<Robot> {
    crate::robot_arg::robot(path.as_deref())
}

fn spinner(what: &str) -> ProgressBar {
    let pb = ProgressBar::new_spinner();
    pb.set_style(
        ProgressStyle::with_template("{spinner} {msg} {pos} rows ({per_sec})")
            .expect("valid template"),
    );
    pb.set_message(what.to_string());
    pb
}

/// Arguments of `pcr ik`.
#[derive(Args)]
pub struct IkArgs {
    /// Robot configuration (TOML); default: configs/robot.toml if present, else the built-in
    /// nominal robot.
    #[arg(long)]
    robot: Option<String>,
    /// Input CSV with columns x_mm, y_mm, phi_deg ("-" for standard input).
    #[arg(long)]
    input: String,
    /// Output CSV (standard output if omitted).
    #[arg(long)]
    output: Option<String>,
}

/// Runs `pcr ik`: streams poses to curvatures, tendon displacements, motor steps, joint angles
/// and a status (ok, unreachable, joint_limit, bending_limit, singular).
pub fn run_ik(a: IkArgs) -> Result<()> {
    let robot = load_robot(&a.robot)?;
    let mut rdr = csvio::reader(&a.input)?;
    let headers = rdr
        .headers()
        .with_context(|| format!("{}: cannot read the header", a.input))?
        .clone();
    let cx = column(&headers, "x_mm", &a.input)?;
    let cy = column(&headers, "y_mm", &a.input)?;
    let cp = column(&headers, "phi_deg", &a.input)?;
    let mut w = csvio::writer(a.output.as_deref())?;
    let mut added: Vec<String> = Vec::new();
    for name in [
        "kappa{i}_per_mm",
        "dl{i}_mm",
        "q{i}",
        "gamma{i}_deg",
        "zeta{i}_deg",
    ] {
        added.extend((1..=3).map(|i| name.replace("{i}", &i.to_string())));
    }
    added.push("status".into());
    let layout = csvio::Layout::new(&headers, &added);
    let out_h = &layout.header;
    w.write_record(out_h)?;
    let pb = spinner("ik");
    let mut rec = csv::StringRecord::new();
    let mut row: Vec<String> = Vec::with_capacity(out_h.len());
    let mut vals: Vec<String> = Vec::with_capacity(16);
    while next_record(&mut rdr, &mut rec, &a.input)? {
        let pose = Pose::from_mm_deg(
            number(&rec, cx, "x_mm", &a.input)?,
            number(&rec, cy, "y_mm", &a.input)?,
            number(&rec, cp, "phi_deg", &a.input)?,
        );
        vals.clear();
        let r = ik_row(&robot, &pose);
        match r.values {
            Some(v) => {
                vals.extend(v.kappa_per_mm.iter().map(|k| fmt(*k)));
                vals.extend(v.dl_mm.iter().map(|d| fmt(*d)));
                vals.extend(v.steps.iter().map(|q| q.to_string()));
                vals.extend(v.gamma_rad.iter().map(|g| fmt(g.to_degrees())));
                vals.extend(v.zeta_rad.iter().map(|z| fmt(z.to_degrees())));
            }
            None => vals.extend(std::iter::repeat_n(String::new(), 15)),
        }
        vals.push(r.status.into());
        layout.fill(&mut row, &rec, vals.drain(..));
        w.write_record(&row)?;
        pb.inc(1);
    }
    pb.finish_and_clear();
    w.flush()?;
    Ok(())
}

/// Arguments of `pcr fk`.
#[derive(Args)]
pub struct FkArgs {
    /// Robot configuration (TOML); default: configs/robot.toml if present, else the built-in
    /// nominal robot.
    #[arg(long)]
    robot: Option<String>,
    /// Input CSV with kappa1_per_mm, kappa2_per_mm, kappa3_per_mm, or q1, q2, q3 (motor steps).
    #[arg(long)]
    input: String,
    /// Output CSV (standard output if omitted).
    #[arg(long)]
    output: Option<String>,
}

/// Runs `pcr fk`: streams curvatures (or motor steps) to platform poses with a status.
pub fn run_fk(a: FkArgs) -> Result<()> {
    let robot = load_robot(&a.robot)?;
    let mut rdr = csvio::reader(&a.input)?;
    let headers = rdr
        .headers()
        .with_context(|| format!("{}: cannot read the header", a.input))?
        .clone();
    let kappa_cols: Option<Vec<usize>> = (1..=3)
        .map(|i| optional_column(&headers, &format!("kappa{i}_per_mm")))
        .collect();
    let q_cols: Option<Vec<usize>> = (1..=3)
        .map(|i| optional_column(&headers, &format!("q{i}")))
        .collect();
    let (cols, steps) = match (kappa_cols, q_cols) {
        (Some(k), _) => (k, false),
        (None, Some(q)) => (q, true),
        _ => bail!(
            "{}: needs columns kappa1_per_mm, kappa2_per_mm, kappa3_per_mm or q1, q2, q3 (header has: {})",
            a.input,
            headers.iter().collect::<Vec<_>>().join(", ")
        ),
    };
    let names: Vec<String> = (1..=3)
        .map(|i| {
            if steps {
                format!("q{i}")
            } else {
                format!("kappa{i}_per_mm")
            }
        })
        .collect();
    let mut w = csvio::writer(a.output.as_deref())?;
    let layout = csvio::Layout::new(
        &headers,
        &["x_mm", "y_mm", "phi_deg", "status"].map(String::from),
    );
    w.write_record(&layout.header)?;
    let mut row: Vec<String> = Vec::with_capacity(layout.header.len());
    let pb = spinner("fk");
    let mut rec = csv::StringRecord::new();
    while next_record(&mut rdr, &mut rec, &a.input)? {
        let mut v = [0.0; 3];
        for i in 0..3 {
            v[i] = number(&rec, cols[i], &names[i], &a.input)?;
        }
        let kappa = if steps { kappa_of_steps(&robot, &v) } else { v };
        let r = fk_row(&robot, &kappa);
        let vals: [String; 4] = match r.pose {
            Some(p) => [fmt(p.x), fmt(p.y), fmt(p.phi_deg()), r.status.into()],
            None => [String::new(), String::new(), String::new(), r.status.into()],
        };
        layout.fill(&mut row, &rec, vals);
        w.write_record(&row)?;
        pb.inc(1);
    }
    pb.finish_and_clear();
    w.flush()?;
    Ok(())
}

/// Arguments shared by `pcr workspace` and `pcr workspace sweep`.
#[derive(Args)]
pub struct WsCommon {
    /// Robot configuration (TOML); default: configs/robot.toml if present, else the built-in
    /// nominal robot.
    #[arg(long, global = true)]
    robot: Option<String>,
    /// Platform orientation, degrees.
    #[arg(
        long = "phi-deg",
        default_value_t = 0.0,
        global = true,
        allow_hyphen_values = true
    )]
    phi_deg: f64,
    /// Grid resolution, mm.
    #[arg(long, default_value_t = 1.0, global = true)]
    res: f64,
    /// Write a JSON summary here.
    #[arg(long, global = true)]
    json: Option<String>,
    /// Write an SVG figure here.
    #[arg(long, global = true)]
    svg: Option<String>,
}

/// Arguments of `pcr workspace`.
#[derive(Args)]
pub struct WorkspaceArgs {
    #[command(subcommand)]
    cmd: Option<WsCmd>,
    #[command(flatten)]
    common: WsCommon,
    /// Base radius override for all legs, mm.
    #[arg(long = "r-base")]
    r_base: Option<f64>,
    /// Method: grid (IK feasibility), alpha (the paper's alpha shapes) or both.
    #[arg(long, default_value = "both")]
    method: Method,
    /// Joint-space sampling step of the alpha method, degrees.
    #[arg(long = "step-deg", default_value_t = 1.0)]
    step_deg: f64,
    /// Alpha of the alpha shapes, mm.
    #[arg(long, default_value_t = 5.0)]
    alpha: f64,
    /// Write an SVG map of the accuracy figure (mm of platform motion per motor step) here.
    #[arg(long = "accuracy-svg")]
    accuracy_svg: Option<String>,
}

#[derive(Clone, Copy, PartialEq, clap::ValueEnum)]
enum Method {
    Grid,
    Alpha,
    Both,
}

#[derive(Subcommand)]
enum WsCmd {
    /// Workspace area and shape over a range of base radii (the paper's Fig. 4).
    Sweep {
        /// Range of base radii as start:stop:step, mm.
        #[arg(long = "r-base")]
        r_base: String,
    },
}

fn with_r_base(robot: &RobotConfig, r: f64) -> RobotConfig {
    let mut c = robot.clone();
    for l in &mut c.legs {
        l.r_base_mm = r;
    }
    c
}

fn check_res(res: f64) -> Result<()> {
    if !(0.05..=50.0).contains(&res) {
        bail!("--res must be between 0.05 and 50 mm, got {res}");
    }
    Ok(())
}

fn progress_bar(len: u64, msg: &str) -> ProgressBar {
    let pb = ProgressBar::new(len);
    pb.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} rows ({eta})")
            .expect("valid template")
            .progress_chars("=> "),
    );
    pb.set_message(msg.to_string());
    pb
}

fn grid_ws(robot: &Robot, phi: f64, res: f64, msg: &str) -> Workspace {
    // The fine grid's size is known only after the coarse pass; estimate it for the bar.
    let pb = progress_bar((200.0 / res) as u64, msg);
    let ws = workspace::grid_workspace(robot, phi, res, &|n| pb.inc(n as u64));
    pb.finish_and_clear();
    ws
}

/// Runs `pcr workspace` (or its `sweep`).
pub fn run_workspace(a: WorkspaceArgs) -> Result<()> {
    let c = &a.common;
    check_res(c.res)?;
    let (cfg, robot_name) = crate::robot_arg::load(c.robot.as_deref())?;
    if let Some(WsCmd::Sweep { r_base }) = &a.cmd {
        return run_sweep(&cfg, c, r_base);
    }
    let cfg = match a.r_base {
        Some(r) => {
            let c2 = with_r_base(&cfg, r);
            c2.validate("--r-base")?;
            c2
        }
        None => cfg,
    };
    let robot = Robot::new(&cfg).with_context(|| format!("robot {robot_name}"))?;
    let phi = c.phi_deg.to_radians();
    let grid = (a.method != Method::Alpha).then(|| grid_ws(&robot, phi, c.res, "grid workspace"));
    let alpha = (a.method != Method::Grid)
        .then(|| workspace::alpha_workspace(&robot, phi, a.step_deg, a.alpha, c.res));
    let main: &Workspace = grid
        .as_ref()
        .unwrap_or_else(|| &alpha.as_ref().expect("one method runs").workspace);
    let mut summary = serde_json::json!({
        "robot": robot_name,
        "phi_deg": c.phi_deg,
        "res_mm": c.res,
        "r_base_mm": cfg.legs.iter().map(|l| l.r_base_mm).collect::<Vec<_>>(),
    });
    if let Some(g) = &grid {
        summary["grid"] = ws_json(g);
        println!(
            "grid (IK feasibility): area {:.1} mm^2, bounds {}",
            g.area(),
            bounds_text(g)
        );
    }
    if let Some(al) = &alpha {
        summary["alpha"] = ws_json(&al.workspace);
        summary["alpha"]["alpha_mm"] = a.alpha.into();
        summary["alpha"]["leg_areas_mm2"] =
            al.legs.iter().map(|l| l.area).collect::<Vec<_>>().into();
        println!(
            "alpha shapes (alpha {} mm): area {:.1} mm^2, bounds {}",
            a.alpha,
            al.workspace.area(),
            bounds_text(&al.workspace)
        );
    }
    if let Some(path) = &a.accuracy_svg {
        let acc = workspace::accuracy_map(&robot, main);
        let vals: Vec<f64> = acc.iter().flatten().copied().collect();
        if !vals.is_empty() {
            let mean = vals.iter().sum::<f64>() / vals.len() as f64;
            let max = vals.iter().copied().fold(0.0, f64::max);
            let min = vals.iter().copied().fold(f64::INFINITY, f64::min);
            summary["accuracy_mm_per_step"] =
                serde_json::json!({"min": min, "mean": mean, "max": max});
            println!("accuracy: platform motion per motor step min {min:.4} mean {mean:.4} max {max:.4} mm");
        }
        figures_kin::accuracy_svg(path, main, &acc)?;
    }
    if let Some(path) = &c.svg {
        figures_kin::workspace_svg(path, &robot, grid.as_ref(), alpha.as_ref())?;
    }
    if let Some(path) = &c.json {
        std::fs::write(path, serde_json::to_string_pretty(&summary)?)
            .with_context(|| format!("cannot write {path}"))?;
    }
    println!("{:.1}", main.area());
    Ok(())
}

fn bounds_text(w: &Workspace) -> String {
    match w.bounds() {
        Some(b) => format!(
            "x [{:.1}, {:.1}] y [{:.1}, {:.1}] mm",
            b[0], b[1], b[2], b[3]
        ),
        None => "(empty)".into(),
    }
}

fn ws_json(w: &Workspace) -> serde_json::Value {
    let contour: Vec<[[f64; 2]; 2]> = w.contour();
    serde_json::json!({
        "area_mm2": w.area(),
        "bounds_mm": w.bounds(),
        "centroid_mm": w.centroid(),
        "contour_segments_mm": contour,
    })
}

fn parse_range(s: &str) -> Result<Vec<f64>> {
    let p: Vec<&str> = s.split(':').collect();
    if p.len() != 3 {
        bail!("--r-base must be start:stop:step in mm, e.g. 200:400:20; got `{s}`");
    }
    let v: Vec<f64> = p
        .iter()
        .map(|x| {
            x.trim()
                .parse::<f64>()
                .with_context(|| format!("--r-base: `{x}` is not a number"))
        })
        .collect::<Result<_>>()?;
    let (a, b, st) = (v[0], v[1], v[2]);
    if !(st > 0.0 && b >= a && a > 0.0 && ((b - a) / st) < 10_000.0) {
        bail!("--r-base {s}: need 0 < start <= stop and step > 0 (at most 10000 values)");
    }
    let n = ((b - a) / st + 1e-9).floor() as usize;
    Ok((0..=n).map(|k| a + st * k as f64).collect())
}

fn run_sweep(cfg: &RobotConfig, c: &WsCommon, range: &str) -> Result<()> {
    let radii = parse_range(range)?;
    let phi = c.phi_deg.to_radians();
    let pb = progress_bar(radii.len() as u64, "base-radius sweep");
    pb.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} radii ({eta})")
            .expect("valid template"),
    );
    let mut rows = Vec::new();
    let mut shapes = Vec::new();
    println!("r_base_mm,area_mm2,xmin_mm,xmax_mm,ymin_mm,ymax_mm,centroid_x_mm,centroid_y_mm");
    for r in radii {
        let c2 = with_r_base(cfg, r);
        let entry = match c2.validate("sweep").ok().and_then(|_| Robot::new(&c2).ok()) {
            Some(robot) => {
                let ws = workspace::grid_workspace(&robot, phi, c.res, &|_| {});
                let b = ws.bounds();
                let cen = ws.centroid();
                let line = match (b, cen) {
                    (Some(b), Some(cn)) => format!(
                        "{r},{:.1},{:.1},{:.1},{:.1},{:.1},{:.2},{:.2}",
                        ws.area(),
                        b[0],
                        b[1],
                        b[2],
                        b[3],
                        cn[0],
                        cn[1]
                    ),
                    _ => format!("{r},0,,,,,,"),
                };
                pb.suspend(|| println!("{line}"));
                let j = serde_json::json!({"r_base_mm": r, "area_mm2": ws.area(), "bounds_mm": b, "centroid_mm": cen});
                shapes.push((r, ws));
                j
            }
            None => {
                pb.suspend(|| println!("{r},0,,,,,,"));
                serde_json::json!({"r_base_mm": r, "area_mm2": 0.0, "note": "home pose unreachable"})
            }
        };
        rows.push(entry);
        pb.inc(1);
    }
    pb.finish_and_clear();
    if let Some(path) = &c.svg {
        figures_kin::sweep_svg(path, &shapes)?;
    }
    if let Some(path) = &c.json {
        std::fs::write(
            path,
            serde_json::to_string_pretty(
                &serde_json::json!({"phi_deg": c.phi_deg, "sweep": rows}),
            )?,
        )
        .with_context(|| format!("cannot write {path}"))?;
    }
    Ok(())
}
