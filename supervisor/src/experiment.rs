//! `ctl run experiment KIND [key=value ...]`: the paper's experiments (docs/experiments.md) run
//! live through the chain, as in the lab. The design and its chain commands are those of
//! `pcr experiment` (`pcr_experiments::program_of`); the supervisor sends the commands one after
//! the other (each continues from where the previous one ended) and labels every recorded row
//! with the experiment's annotator (`pose_id, rep, settled, set, segment, motor,
//! amplitude_steps`), so that the recording goes to `pcr calibrate` / `pcr evaluate` as it is.

use pcr_experiments::{
    program_of, BacklashDesign, BacklashOptions, CalibrationOptions, Design, PathsDesign,
    ProgramCommand, StaticDesign, VisitTiming,
};
use pcr_kinematics::Robot;
use pcr_robot::RobotConfig;

/// The options `key=value` of each kind, with their meaning (as `pcr experiment`'s flags).
pub const OPTIONS: &str = "calibration|repeatability: points=N scales=A,B phis-deg=A,B \
     test-per-group=N seed=N speed=MM_S settle=S measure=S (repeatability: reps=N phi-deg=D); \
     paths: seed=N; backlash: motors=1,2,3 max-steps=N periods=N freq-hz=F rest=S seed=N";

/// A planned experiment: its design, the chain commands and the split seed.
#[derive(Debug, Clone)]
pub struct Experiment {
    /// The design (the annotator's reference).
    pub design: Design,
    /// The chain commands, in order.
    pub commands: Vec<ProgramCommand>,
    /// Seed of the train/test split.
    pub seed: u64,
}

fn parse<T: std::str::FromStr>(key: &str, v: &str) -> Result<T, String> {
    v.parse()
        .map_err(|_| format!("experiment option {key}={v:?}: not a valid value"))
}

fn list<T: std::str::FromStr>(key: &str, v: &str) -> Result<Vec<T>, String> {
    v.split(',').map(|x| parse(key, x.trim())).collect()
}

/// An experiment's kind and options, checked (cheap: nothing designed yet).
#[derive(Debug, Clone)]
pub struct Spec {
    kind: String,
    set: CalibrationOptions,
    timing: VisitTiming,
    seed: u64,
    reps: u64,
    phi_deg: f64,
    backlash: BacklashOptions,
}

/// Builds the experiment `kind` with `options` for the robot that drives.
pub fn build(
    kind: &str,
    options: &[(String, String)],
    robot: &RobotConfig,
) -> Result<Experiment, String> {
    spec(kind, options)?.build(robot)
}

/// Checks the kind and the options of an experiment.
pub fn spec(kind: &str, options: &[(String, String)]) -> Result<Spec, String> {
    let mut set = CalibrationOptions::default();
    let mut timing = VisitTiming {
        speed_mm_s: 30.0,
        settle_s: 1.0,
        measure_s: 0.5,
    };
    let mut seed = 1u64;
    let (mut reps, mut phi_deg) = (20u64, 0.0f64);
    let mut b = BacklashOptions::default();
    let allowed: &[&str] = match kind {
        "calibration" => &[
            "points",
            "scales",
            "phis-deg",
            "test-per-group",
            "seed",
            "speed",
            "settle",
            "measure",
        ],
        "repeatability" => &[
            "points",
            "scales",
            "phis-deg",
            "test-per-group",
            "seed",
            "speed",
            "settle",
            "measure",
            "reps",
            "phi-deg",
        ],
        "paths" => &["seed"],
        "backlash" => &["motors", "max-steps", "periods", "freq-hz", "rest", "seed"],
        o => {
            return Err(format!(
                "unknown experiment {o:?} (calibration, repeatability, paths, backlash)"
            ))
        }
    };
    for (k, v) in options {
        if !allowed.contains(&k.as_str()) {
            return Err(format!(
                "experiment {kind}: unknown option {k:?} (options: {})",
                allowed.join(", ")
            ));
        }
        match k.as_str() {
            "points" => set.points = parse(k, v)?,
            "scales" => set.scales = list(k, v)?,
            "phis-deg" => set.phis_deg = list(k, v)?,
            "test-per-group" => set.test_per_group = parse(k, v)?,
            "seed" => seed = parse(k, v)?,
            "speed" => timing.speed_mm_s = parse(k, v)?,
            "settle" => timing.settle_s = parse(k, v)?,
            "measure" => timing.measure_s = parse(k, v)?,
            "reps" => reps = parse(k, v)?,
            "phi-deg" => phi_deg = parse(k, v)?,
            "motors" => b.motors = list(k, v)?,
            "max-steps" => b.max_steps = parse(k, v)?,
            "periods" => b.periods = parse(k, v)?,
            "freq-hz" => b.freq_hz = parse(k, v)?,
            "rest" => b.rest_s = parse(k, v)?,
            _ => unreachable!("checked against the allowed options"),
        }
    }
    set.seed = seed;
    Ok(Spec {
        kind: kind.to_string(),
        set,
        timing,
        seed,
        reps,
        phi_deg,
        backlash: b,
    })
}

impl Spec {
    /// Designs the experiment for the robot that drives and turns it into chain commands.
    pub fn build(&self, robot: &RobotConfig) -> Result<Experiment, String> {
        let model = Robot::new(robot).map_err(|e| format!("robot: {e}"))?;
        let (set, timing, seed) = (&self.set, self.timing, self.seed);
        let (reps, phi_deg, b) = (self.reps, self.phi_deg, &self.backlash);
        let design = match self.kind.as_str() {
            "calibration" => Design::Static(
                StaticDesign::calibration(&model, set, timing).map_err(|e| e.to_string())?,
            ),
            "repeatability" => Design::Static(
                StaticDesign::repeatability(&model, set, phi_deg, reps, timing)
                    .map_err(|e| e.to_string())?,
            ),
            "paths" => Design::Paths(PathsDesign::default()),
            _ => Design::Backlash(BacklashDesign::new(&model, b).map_err(|e| e.to_string())?),
        };
        let commands = program_of(&design, robot)
            .map_err(|e| e.to_string())?
            .commands;
        Ok(Experiment {
            design,
            commands,
            seed,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts(s: &[(&str, &str)]) -> Vec<(String, String)> {
        s.iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    }

    #[test]
    fn a_small_calibration_set_becomes_chain_commands() {
        let e = build(
            "calibration",
            &opts(&[
                ("points", "3"),
                ("phis-deg", "0"),
                ("scales", "0.5"),
                ("test-per-group", "1"),
            ]),
            &RobotConfig::nominal(),
        )
        .unwrap();
        let Design::Static(d) = &e.design else {
            panic!("static design")
        };
        assert_eq!(d.visits.len(), 3);
        // Lead-in dwell, then three moves per visit.
        let moves: usize = e.commands.iter().map(|c| c.moves.len()).sum();
        assert_eq!(moves, 1 + 3 * 3);
    }

    #[test]
    fn bad_options_are_refused_by_name() {
        let r = RobotConfig::nominal();
        let e = build("calibration", &opts(&[("pionts", "3")]), &r).unwrap_err();
        assert!(e.contains("pionts"), "{e}");
        let e = build("calibration", &opts(&[("points", "x")]), &r).unwrap_err();
        assert!(e.contains("points"), "{e}");
        assert!(build("dance", &[], &r)
            .unwrap_err()
            .contains("unknown experiment"));
        assert!(build("paths", &opts(&[("reps", "2")]), &r).is_err());
    }
}
