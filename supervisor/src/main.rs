//! `pcr-supervisor`: starts, watches and restarts the chain's processes.
//!
//! * `pcr-supervisor --config configs/sim.toml` stays up and takes commands;
//! * `pcr-supervisor --config configs/sim.toml --run paper` runs the paper's circle and square,
//!   prints the path accuracy and exits 0; `--run-file configs/programs/slot.toml` runs a program
//!   file the same way;
//! * `pcr-supervisor ctl --config configs/sim.toml status|run paper|pause|resume|stop|reset|shutdown`.

use clap::{Parser, Subcommand};
use pcr_supervisor::supervisor::{program_command, run, Options};
use pcr_supervisor::{ctl, SupervisorConfig};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(about = "pcr-supervisor: runs the control chain")]
struct Cli {
    /// Supervisor configuration (e.g. configs/sim.toml).
    #[arg(long, global = true)]
    config: Option<PathBuf>,
    /// Run a program (paper, circle, square), print the summary and exit.
    #[arg(long, conflicts_with = "run_file")]
    run: Option<String>,
    /// Run a program file (TOML: lines, arcs, dwells, joint moves), print the summary and exit.
    #[arg(long)]
    run_file: Option<PathBuf>,
    #[command(subcommand)]
    cmd: Option<Sub>,
}

#[derive(Subcommand, Debug)]
enum Sub {
    /// Sends a command to a running supervisor: status, run paper|circle|square,
    /// run moves "line X Y PHI_DEG SPEED; circle CX CY R SPEED; dwell S", run program FILE,
    /// pause, resume, stop, reset, shutdown.
    Ctl {
        /// The command words.
        #[arg(required = true, trailing_var_arg = true)]
        words: Vec<String>,
    },
}

fn main() -> ExitCode {
    pcr_nodes::init_logging();
    let cli = Cli::parse();
    let Some(cfg_path) = cli.config else {
        eprintln!("pcr-supervisor: error: --config <file> is required");
        return ExitCode::from(64);
    };
    let cfg = match SupervisorConfig::load(&cfg_path) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("pcr-supervisor: config error: {e}");
            return ExitCode::from(78);
        }
    };
    if let Some(Sub::Ctl { mut words }) = cli.cmd {
        // The supervisor reads a program file from its own working directory: send it absolute.
        if words.len() >= 3 && words[0] == "run" && words[1] == "program" {
            let file = words[2..].join(" ");
            if let Ok(abs) = std::path::absolute(&file) {
                words.truncate(2);
                words.push(abs.display().to_string());
            }
        }
        return match ctl::request(&cfg.socket_path(), &words.join(" ")) {
            Ok(reply) => {
                print!("{reply}");
                if reply.starts_with("error") {
                    return ExitCode::FAILURE;
                }
                match ctl::started_run(&reply) {
                    // `run`: wait for the planner's verdict; a refusal fails with its reason.
                    Some(n) => wait_verdict(&cfg.socket_path(), n),
                    None => ExitCode::SUCCESS,
                }
            }
            Err(e) => {
                eprintln!(
                    "pcr-supervisor ctl: cannot reach the supervisor at {}: {e}",
                    cfg.socket_path().display()
                );
                ExitCode::FAILURE
            }
        };
    }
    if let Some(file) = &cli.run_file {
        // Refuse a bad program file before starting the chain.
        if let Err(e) = program_command(file) {
            eprintln!("pcr-supervisor: program error: {e}");
            return ExitCode::from(65);
        }
    }
    let bin_dir = match &cfg.bin_dir {
        Some(d) => PathBuf::from(d),
        None => std::env::current_exe()
            .ok()
            .and_then(|p| p.parent().map(PathBuf::from))
            .unwrap_or_else(|| PathBuf::from(".")),
    };
    match run(
        cfg,
        Options {
            run: cli.run,
            run_file: cli.run_file,
            bin_dir,
        },
    ) {
        Ok(code) => ExitCode::from(code as u8),
        Err(e) => {
            eprintln!("pcr-supervisor: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Waits (at most 2 minutes) until the planner has planned run `n` or refused it; prints the
/// verdict and fails on a refusal.
fn wait_verdict(socket: &std::path::Path, n: u32) -> ExitCode {
    let end = std::time::Instant::now() + std::time::Duration::from_secs(120);
    loop {
        let v = match ctl::request(socket, &format!("verdict {n}")) {
            Ok(v) => v.trim().to_string(),
            Err(e) => {
                eprintln!("pcr-supervisor ctl: run {n}: lost the supervisor: {e}");
                return ExitCode::FAILURE;
            }
        };
        if v != "planning" {
            println!("run {n}: {v}");
            return if v.starts_with("refused") || v.starts_with("error") {
                ExitCode::FAILURE
            } else {
                ExitCode::SUCCESS
            };
        }
        if std::time::Instant::now() > end {
            println!("run {n}: still planning after 2 minutes (see `ctl status`)");
            return ExitCode::SUCCESS;
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}
