//! `pcr convert`: a recording (`shared/spec/recording.md`, from the supervisor or any other
//! program) to the MCAP the supervisor writes beside its CSV, for Foxglove, PlotJuggler and
//! `ros2 bag` (`pcr_telemetry::convert`).

use anyhow::{bail, Context, Result};
use clap::Args as ClapArgs;
use std::path::PathBuf;

/// `pcr convert`.
#[derive(ClapArgs)]
pub struct Args {
    /// The recording (CSV of the recording format).
    csv: PathBuf,
    /// The MCAP file to write (replaced if it exists).
    #[arg(long)]
    mcap: PathBuf,
    /// Robot configuration: draws the robot (legs of the commanded steps) on `/robot`.
    #[arg(long)]
    robot: Option<PathBuf>,
}

/// Runs `pcr convert`.
pub fn run(a: Args) -> Result<()> {
    if a.mcap.extension().is_none_or(|e| e != "mcap") {
        bail!(
            "--mcap {}: the output must be an .mcap file (refusing to overwrite anything else)",
            a.mcap.display()
        );
    }
    if a.mcap == a.csv {
        bail!("--mcap {}: is the input recording", a.mcap.display());
    }
    let s = pcr_telemetry::convert(&a.csv, &a.mcap, a.robot.as_deref())
        .with_context(|| format!("converting {}", a.csv.display()))?;
    println!(
        "{}: {} rows ({} planned, {} measured poses){}",
        a.mcap.display(),
        s.rows,
        s.planned,
        s.measured,
        if s.scene { ", robot drawn" } else { "" }
    );
    Ok(())
}
