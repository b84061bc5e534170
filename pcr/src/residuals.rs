//! `pcr residuals`: find what the calibrated model lacks, from recordings alone.
//!
//! `pcr residuals --robot R --data rec.csv [--data more.csv] [--holdout other.csv]
//!  --report DIR --json out.json --out extended.toml [--no-calibrate]`

use crate::calibrate::load_robot;
use anyhow::{bail, Context as _};
use indicatif::{ProgressBar, ProgressStyle};
use pcr_offline::clock::utc_now;
use pcr_offline::residuals_run;
use pcr_residuals::{attribute, Options};
use std::path::PathBuf;

/// Arguments of `pcr residuals`.
#[derive(clap::Args)]
pub struct Args {
    /// Robot configuration the recordings were made with; default: the built-in nominal robot.
    #[arg(long, value_name = "ROBOT.toml")]
    robot: Option<PathBuf>,
    /// Recordings to analyse (repeatable). The first one with static poses calibrates the
    /// robot first, as `pcr calibrate` does.
    #[arg(long, value_name = "REC.csv", required = true)]
    data: Vec<PathBuf>,
    /// Recordings on which `before` and `after` are measured and nothing is fitted
    /// (repeatable); without it, every third block of about `--block-s` of `--data` is held out.
    #[arg(long, value_name = "REC.csv")]
    holdout: Vec<PathBuf>,
    /// Take the robot file as it is (no calibration first).
    #[arg(long)]
    no_calibrate: bool,
    /// Solve every row on its own (no reuse of rows at rest, no warm starts, no interpolated
    /// load responses): slower, the reference the default path is tested against.
    #[arg(long)]
    exact: bool,
    /// Length of the held-out time blocks, s.
    #[arg(long, default_value_t = 4.0)]
    block_s: f64,
    /// Family-wise significance level of a round.
    #[arg(long, default_value_t = 1e-2)]
    alpha: f64,
    /// Smallest held-out RMS gain worth claiming, mm.
    #[arg(long, default_value_t = 0.01)]
    min_effect_mm: f64,
    /// Only these candidates (comma separated; default: all).
    #[arg(long, value_delimiter = ',')]
    candidates: Vec<String>,
    /// The extended robot configuration to write.
    #[arg(long, value_name = "EXTENDED.toml")]
    out: Option<PathBuf>,
    /// Everything as JSON.
    #[arg(long, value_name = "OUT.json")]
    json: Option<PathBuf>,
    /// Folder for the Markdown report and its figures.
    #[arg(long, value_name = "DIR")]
    report: Option<PathBuf>,
}

/// The extended robot file of an analysis, with a header naming the effects.
pub(crate) fn extended_file(res: &pcr_residuals::Attribution, created: &str) -> String {
    residuals_run::extended_file(res, created)
}

/// Runs `pcr residuals`.
pub fn run(a: Args) -> anyhow::Result<()> {
    // The calibration and the reading too on a thread of rayon's pool.
    pcr_residuals::on_the_pool(move || analyse(a))
}

fn analyse(a: Args) -> anyhow::Result<()> {
    if !(a.block_s > 0.0 && a.block_s.is_finite()) {
        bail!(
            "--block-s {}: must be a positive number of seconds",
            a.block_s
        );
    }
    if !(a.alpha > 0.0 && a.alpha < 1.0) {
        bail!("--alpha {}: must be in (0, 1)", a.alpha);
    }
    for c in &a.candidates {
        if pcr_residuals::effects::named(c).is_none() {
            bail!(
                "--candidates: unknown effect `{c}` (known: {})",
                pcr_residuals::effects::names().join(", ")
            );
        }
    }
    let progress = ProgressDisplay::new();
    let start = load_robot(a.robot.as_deref())?;
    let drawing = start.clone();
    progress.sink.stage(0, "reading the recordings", 0, 0);
    // Every recording at once, the data's first.
    let paths: Vec<std::path::PathBuf> = a.data.iter().chain(&a.holdout).cloned().collect();
    let mut data = residuals_run::read_all(&paths)?;
    let holdout = data.split_off(a.data.len());
    if !a.no_calibrate {
        progress
            .sink
            .stage(0, "calibrating on the static poses of the data", 0, 0);
    }
    // Calibrate first on the static poses of the data (never of the holdout).
    let prepared = residuals_run::prepare(
        &start,
        &data,
        &holdout,
        a.no_calibrate,
        a.block_s,
        &|line| progress.say(line),
    )?;
    let (robot, series, blocks) = (prepared.robot, prepared.series, prepared.blocks);
    let recalibration = prepared.recalibration;
    let opts = Options {
        alpha: a.alpha,
        min_effect_mm: a.min_effect_mm,
        candidates: if a.candidates.is_empty() {
            Options::default().candidates
        } else {
            a.candidates.clone()
        },
        exact: a.exact,
        progress: progress.sink.clone(),
        recalibration,
        ..Options::default()
    };
    if let Some(dir) = &a.report {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let p = dir.join("residuals_before.csv");
        progress
            .sink
            .stage(0, "writing the starting model's residuals", 0, 0);
        let mut f = std::io::BufWriter::new(
            std::fs::File::create(&p).with_context(|| format!("cannot write {}", p.display()))?,
        );
        pcr_residuals::attribution::residual_table(&robot, &series, &blocks, &mut f)?;
    }
    let wall = std::time::Instant::now();
    let res = attribute(&robot, &drawing, &series, &blocks, &opts);
    progress.done();
    let res = res?;
    eprintln!("analysed in {:.2} s", wall.elapsed().as_secs_f64());
    for t in &res.timing {
        println!("timing: {}", t.message);
    }
    println!(
        "held out: {} rows in {} blocks; before: position mean {:.3} / max {:.3} / RMS {:.3} mm, orientation RMS {:.3} deg",
        res.rows[1], res.blocks[1], res.before.position_mean_mm, res.before.position_max_mm,
        res.before.position_rms_mm, res.before.orientation_rms_deg
    );
    for e in &res.effects {
        let p: Vec<String> = e.params.iter().map(|p| p.text("+-")).collect();
        println!(
            "added {}: {} (held-out gain {:.3} mm, p = {:.1e})",
            e.name,
            p.join(", "),
            e.evidence.effect_mm,
            e.evidence.p_value
        );
    }
    for r in &res.removed {
        println!(
            "removed {} in the backward pass: with every other effect in it no longer earns its place (held-out RMS {:.4} mm without it, {:.4} with it: {})",
            r.name, r.held_out_rms_without_mm, r.held_out_rms_with_mm, r.note
        );
    }
    let mut imitations: Vec<&str> = res
        .candidates
        .iter()
        .filter(|c| c.note.starts_with("acts partly like"))
        .map(|c| c.note.as_str())
        .collect();
    imitations.dedup();
    for n in imitations {
        println!("not named: {n}");
    }
    println!(
        "after: position mean {:.3} / max {:.3} / RMS {:.3} mm, orientation RMS {:.3} deg; verdict: {:?}",
        res.after.position_mean_mm,
        res.after.position_max_mm,
        res.after.position_rms_mm,
        res.after.orientation_rms_deg,
        res.verdict
    );
    if let Some(f) = &res.timing_finding {
        println!("verdict: {f}");
    }
    for f in &res.correlated_features {
        println!(
            "  remaining residual follows {} (held-out R^2 {:.2}, correlation {:+.2} with {})",
            f.feature, f.held_out_r2, f.correlation, f.component
        );
    }
    if let Some(o) = &a.out {
        let text = extended_file(&res, &utc_now());
        std::fs::write(o, text).with_context(|| format!("cannot write {}", o.display()))?;
        println!("extended robot: {}", o.display());
    }
    if let Some(j) = &a.json {
        std::fs::write(j, serde_json::to_string_pretty(&res)?)
            .with_context(|| format!("cannot write {}", j.display()))?;
        println!("json: {}", j.display());
    }
    if let Some(dir) = &a.report {
        let inputs = a
            .data
            .iter()
            .map(|p| format!("`{}`", p.display()))
            .chain(
                a.holdout
                    .iter()
                    .map(|p| format!("`{}` (holdout)", p.display())),
            )
            .collect::<Vec<_>>()
            .join(", ");
        let p = pcr_residuals::report::write_report(dir, &res, &inputs)?;
        println!("report: {}", p.display());
    }
    Ok(())
}

/// The analysis's progress on stderr (candidate, round, rows), when stderr is a terminal.
struct Bar(ProgressBar);

impl pcr_residuals::Progress for Bar {
    fn stage(&self, round: usize, what: &str, rows: usize, steps: usize) {
        let template = if steps == 0 {
            "{spinner} {msg} ({elapsed})"
        } else {
            "{spinner} {msg} [{bar:20}] {pos}/{len} ({elapsed})"
        };
        self.0.set_style(
            ProgressStyle::with_template(template)
                .expect("valid template")
                .progress_chars("=> "),
        );
        self.0.set_length(steps as u64);
        self.0.set_position(0);
        let round = if round == 0 {
            String::new()
        } else {
            format!("round {round}: ")
        };
        let rows = if rows == 0 {
            String::new()
        } else {
            format!(", {rows} rows")
        };
        self.0.set_message(format!("{round}{what}{rows}"));
    }

    fn step(&self) {
        self.0.inc(1);
    }
}

/// What `pcr residuals` shows while it works: a progress bar on stderr (reading, calibrating,
/// then the attribution's candidates, rounds and rows) when stderr is a terminal, nothing
/// otherwise; its messages are printed above the bar.
struct ProgressDisplay {
    /// What the attribution reports to.
    sink: pcr_residuals::ProgressSink,
    bar: Option<ProgressBar>,
}

impl ProgressDisplay {
    fn new() -> ProgressDisplay {
        use std::io::IsTerminal;
        if !std::io::stderr().is_terminal() {
            return ProgressDisplay {
                sink: pcr_residuals::ProgressSink::default(),
                bar: None,
            };
        }
        let pb = ProgressBar::new(0);
        pb.enable_steady_tick(std::time::Duration::from_millis(100));
        ProgressDisplay {
            sink: pcr_residuals::ProgressSink::new(std::sync::Arc::new(Bar(pb.clone()))),
            bar: Some(pb),
        }
    }

    /// A line on stderr, above the bar if there is one.
    fn say(&self, line: &str) {
        match &self.bar {
            Some(b) => b.suspend(|| eprintln!("{line}")),
            None => eprintln!("{line}"),
        }
    }

    /// Clears the bar.
    fn done(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}
