//! `pcr`: the offline tools of the 3-FbRR control stack.
//!
//! Each subcommand group lives in its own module with an `Args` type and a `run` function.

use clap::{Parser, Subcommand};

mod calibrate;
mod convert;
mod csvio;
mod evaluate;
mod experiment;
mod figures_kin;
mod figures_plan;
mod kin;
mod loop_cmd;
mod plan;
mod plant;
mod profile;
mod qtm;
mod residuals;
mod robot_arg;

/// Offline tools for the 3-FbRR planar parallel continuum robot.
#[derive(Parser)]
#[command(name = "pcr", version, about, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Inverse kinematics: poses (x_mm, y_mm, phi_deg) to curvatures and motor steps.
    Ik(kin::IkArgs),
    /// Forward kinematics: curvatures (or motor steps) to platform poses.
    Fk(kin::FkArgs),
    /// Constant-orientation workspace, base-radius sweep and accuracy map.
    Workspace(kin::WorkspaceArgs),
    /// Solve jerk-limited profiling cases from a JSON file.
    Profile(profile::Args),
    /// Plan a checked 20 ms setpoint sequence along a task-space path.
    Plan(plan::Args),
    /// Static poses and time-stepped runs of the simulated plant.
    Plant(plant::Args),
    /// Calibrate the robot (Table I maps, two-step parameters) from a recording; `leg` for
    /// one continuum segment.
    Calibrate(calibrate::Args),
    /// Evaluate recordings: ISO 9283 repeatability and pose accuracy, path accuracy (Table II),
    /// gear backlash and the eq. 10 error map.
    Evaluate(evaluate::Args),
    /// Find what the calibrated model lacks: residuals, candidate effects, held-out attribution,
    /// and the extended robot file.
    Residuals(residuals::Args),
    /// The whole loop on the simulated plant: record, calibrate, analyse the residuals,
    /// extend the model, re-run with every model and report the error on the robot.
    Loop(loop_cmd::Args),
    /// The paper's experiments (calibration, repeatability, paths, backlash) on the in-process
    /// chain against the simulated plant, and the calibration pose set.
    Experiment(experiment::Args),
    /// Qualisys QTM RT tools: server parameters, streaming to CSV, registration, simulator.
    Qtm(qtm::Args),
    /// A recording (CSV) to MCAP, for Foxglove, PlotJuggler and `ros2 bag`: every column on
    /// `/recording/row`, poses, the robot drawn with `--robot`.
    Convert(convert::Args),
}

fn main() -> std::process::ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("PCR_LOG")
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Ik(a) => kin::run_ik(a),
        Command::Fk(a) => kin::run_fk(a),
        Command::Workspace(a) => kin::run_workspace(a),
        Command::Profile(a) => profile::run(a),
        Command::Plan(a) => plan::run(a),
        Command::Plant(a) => plant::run(a),
        Command::Calibrate(a) => calibrate::run(a),
        Command::Evaluate(a) => evaluate::run(a),
        Command::Residuals(a) => residuals::run(a),
        Command::Loop(a) => loop_cmd::run(a),
        Command::Experiment(a) => experiment::run(a),
        Command::Qtm(a) => qtm::run(a),
        Command::Convert(a) => convert::run(a),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            // The chain of causes, each said once (an error often quotes its cause already).
            let mut msg = e.to_string();
            for cause in e.chain().skip(1) {
                let c = cause.to_string();
                if !msg.contains(&c) {
                    msg.push_str(": ");
                    msg.push_str(&c);
                }
            }
            eprintln!("error: {msg}");
            std::process::ExitCode::FAILURE
        }
    }
}
