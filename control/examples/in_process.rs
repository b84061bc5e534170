//! Runs a program on the in-process runtime (simulated clock, interim plant) and writes the
//! recording: `cargo run --release -p pcr-control --example in_process -- paper out.csv`.

use pcr_control::{simple_command, InterimChain, Recorder};
use pcr_kinematics::Robot;
use pcr_messages::{command_kind, program_id};
use pcr_robot::RobotConfig;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let program = args.next().unwrap_or_else(|| "paper".into());
    let out = args
        .next()
        .unwrap_or_else(|| format!("{program}-inprocess.csv"));
    let id = match program.as_str() {
        "paper" => program_id::PAPER,
        "circle" => program_id::CIRCLE,
        "square" => program_id::SQUARE,
        o => return Err(format!("unknown program {o} (paper, circle, square)").into()),
    };
    let robot = Robot::new(&RobotConfig::load("configs/robot.toml")?)?;
    let mut chain = InterimChain::interim(robot, 0.02);
    let mut rec = Recorder::new(
        std::io::BufWriter::new(std::fs::File::create(&out)?),
        &[
            ("robot", "configs/robot.toml"),
            (
                "source",
                "pcr-control in-process runtime, interim ideal drive",
            ),
            ("program", program.as_str()),
        ],
    )?;
    let wall = std::time::Instant::now();
    let acc = chain.run(&simple_command(command_kind::RUN, id, 1), 600.0, |s| {
        let _ = rec.row(s);
    })?;
    rec.finish()?;
    println!(
        "{program}: {:.1} s simulated in {:.3} s wall; {acc}; recording {out}",
        chain.time_s(),
        wall.elapsed().as_secs_f64()
    );
    Ok(())
}
