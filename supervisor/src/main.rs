//! `pcr-supervisor`: starts, watches and restarts the chain's processes.
//!
//! * `pcr-supervisor --config configs/sim.toml` stays up and takes commands;
//! * `pcr-supervisor --config configs/sim.toml --run paper` runs the paper's circle and square,
//!   prints the path accuracy and exits 0;
//! * `pcr-supervisor ctl --config configs/sim.toml status|run paper|pause|resume|stop|reset|shutdown`.

use clap::{Parser, Subcommand};
use pcr_supervisor::supervisor::{run, Options};
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
    #[arg(long)]
    run: Option<String>,
    #[command(subcommand)]
    cmd: Option<Sub>,
}

#[derive(Subcommand, Debug)]
enum Sub {
    /// Sends a command to a running supervisor: status, run paper|circle|square,
    /// run moves "line X Y PHI_DEG SPEED; circle CX CY R SPEED; dwell S", pause, resume, stop,
    /// reset, shutdown.
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
    if let Some(Sub::Ctl { words }) = cli.cmd {
        return match ctl::request(&cfg.socket_path(), &words.join(" ")) {
            Ok(reply) => {
                print!("{reply}");
                if reply.starts_with("error") {
                    ExitCode::FAILURE
                } else {
                    ExitCode::SUCCESS
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
