//! The in-process runner on the simulated plant (reduced designs: small and fast).
#![cfg(feature = "chain")]

use pcr_experiments::{
    program_of, run_in_process, Annotator, BacklashDesign, BacklashOptions, CalibrationOptions,
    Design, PathShape, PathsDesign, RunSetup, StaticDesign, Tolerances, VisitTiming, EXTRA_COLUMNS,
};
use pcr_kinematics::Robot;
use pcr_plant::PlantConfig;
use pcr_recording::{settled_poses, Recording, Split};
use pcr_robot::RobotConfig;

fn setup(plant: PlantConfig) -> RunSetup {
    RunSetup {
        model: RobotConfig::nominal(),
        plant_robot: RobotConfig::nominal(),
        plant,
        period_s: 0.02,
        seed: 9,
        metadata: vec![
            ("robot".into(), "nominal".into()),
            ("plant".into(), "ideal".into()),
            ("source".into(), "test".into()),
            ("created".into(), "2026-01-01T00:00:00Z".into()),
        ],
        tolerances: Tolerances::default(),
        capture_latency_s: None,
    }
}

fn small_options() -> CalibrationOptions {
    CalibrationOptions {
        phis_deg: vec![0.0, 10.0],
        scales: vec![0.5],
        points: 3,
        test_per_group: 1,
        seed: 9,
        ..CalibrationOptions::default()
    }
}

fn timing() -> VisitTiming {
    VisitTiming {
        speed_mm_s: 40.0,
        settle_s: 0.4,
        measure_s: 0.2,
    }
}

fn run(design: &Design, s: &RunSetup) -> (Vec<u8>, Recording) {
    let mut buf = Vec::new();
    let summary = run_in_process(design, s, &mut buf, &mut |_| {}).unwrap();
    let rec = Recording::read(&buf[..], "run.csv").unwrap();
    assert_eq!(summary.rows, rec.rows.len());
    (buf, rec)
}

#[test]
fn a_calibration_run_on_the_ideal_plant_gives_one_settled_group_per_visit() {
    let robot = Robot::nominal();
    let d = StaticDesign::calibration(&robot, &small_options(), timing()).unwrap();
    let visits = d.visits.clone();
    let design = Design::Static(d);
    let s = setup(PlantConfig::ideal());
    let (bytes, rec) = run(&design, &s);
    assert_eq!(rec.meta("commands"), Some("1"));
    // the format: every known column, the extra columns, the metadata
    assert_eq!(rec.columns, pcr_recording::KNOWN_COLUMNS);
    assert_eq!(rec.extra_columns, EXTRA_COLUMNS);
    for k in [
        "experiment",
        "robot",
        "plant",
        "source",
        "created",
        "seed",
        "settle_s",
        "measure_s",
        "speed_mm_s",
        "phis_deg",
        "scales",
    ] {
        assert!(rec.meta(k).is_some(), "metadata {k}");
    }
    assert_eq!(rec.metadata[0].0, "experiment");
    assert_eq!(rec.meta("experiment"), Some("calibration"));
    assert_eq!(rec.meta("seed"), Some("9"));
    // The timing contract: each row's command is executed over the next cycle.
    assert_eq!(rec.command_delay_s().unwrap(), 0.02);
    // one row per 20 ms cycle
    for w in rec.rows.windows(2) {
        assert!((w[1].t_s - w[0].t_s - 0.02).abs() < 1e-9);
    }
    let groups = settled_poses(&rec, "run.csv").unwrap();
    assert_eq!(groups.len(), visits.len());
    for (g, v) in groups.iter().zip(&visits) {
        assert_eq!(
            (g.pose_id, g.rep, g.set),
            (Some(v.pose_id), Some(0), Some(v.set))
        );
        // 0.2 s of measurement at 20 ms
        assert!((9..=11).contains(&g.rows), "{} rows", g.rows);
        // On the ideal plant (= the model) the robot stands at the target up to the step
        // quantisation.
        let p = g.pose.unwrap();
        let e = (p[0] - v.target.x).hypot(p[1] - v.target.y);
        assert!(e < 0.3, "{}: {e} mm", g.label());
        assert!(
            (p[2] - v.target.phi.to_degrees()).abs() < 0.2,
            "{}",
            g.label()
        );
        // the M_i are measured too, and the planned pose is the target
        assert!(g.m.iter().all(Option::is_some) && g.m_rows == [g.rows; 3]);
        let pl = g.planned.unwrap();
        assert!((pl[0] - v.target.x).abs() < 1e-3 && (pl[1] - v.target.y).abs() < 1e-3);
    }
    assert_eq!(
        groups.iter().filter(|g| g.set == Some(Split::Test)).count(),
        2
    );
    // Re-annotating the recording (labels stripped) from its rows alone gives the same labels.
    let mut ann = Annotator::new(&design, Tolerances::default());
    for r in &rec.rows {
        let mut bare = r.clone();
        bare.pose_id = None;
        bare.rep = None;
        bare.set = None;
        bare.settled = None;
        let l = ann.annotate(&mut bare);
        assert_eq!(bare, *r, "t = {}", r.t_s);
        assert_eq!(l.extra_cells(), [None, None, None]);
    }
    // deterministic: the same bytes again
    let (again, _) = run(&design, &s);
    assert!(bytes == again, "two runs differ");
}

#[test]
fn repeatability_labels_each_rep_of_each_pose() {
    let robot = Robot::nominal();
    let mut opt = small_options();
    opt.points = 2;
    let d = StaticDesign::repeatability(&robot, &opt, 0.0, 3, timing()).unwrap();
    let design = Design::Static(d);
    let (_, rec) = run(&design, &setup(PlantConfig::ideal()));
    let groups = settled_poses(&rec, "run.csv").unwrap();
    let ids: Vec<_> = groups
        .iter()
        .map(|g| (g.pose_id.unwrap(), g.rep.unwrap()))
        .collect();
    assert_eq!(ids, [(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (1, 2)]);
    assert_eq!(rec.meta("experiment"), Some("repeatability"));
}

#[test]
fn the_paths_run_labels_the_circle_and_the_square() {
    let design = Design::Paths(PathsDesign::default());
    let (_, rec) = run(&design, &setup(PlantConfig::ideal()));
    let seg = rec.extra_index("segment").unwrap();
    let mut count = [0usize; 2];
    for r in &rec.rows {
        let p = [
            r.planned[0].unwrap(),
            r.planned[1].unwrap(),
            r.planned[2].unwrap(),
        ];
        match r.extra[seg].as_deref() {
            Some("circle") => {
                count[0] += 1;
                assert!(PathShape::PAPER_CIRCLE.contains(p, 1e-3, 1e-3));
            }
            Some("square") => {
                count[1] += 1;
                assert!(PathShape::PAPER_SQUARE.contains(p, 1e-3, 1e-3));
            }
            None => {}
            Some(o) => panic!("segment {o}"),
        }
        assert_eq!(r.settled, Some(false));
    }
    // the circle takes 2 pi 50 mm / 50 mm/s = 6.3 s plus its ramps; the square's four 50 mm
    // sides at up to 50 mm/s, 4 s or more
    println!("circle rows {}, square rows {}", count[0], count[1]);
    assert!(count[0] > 314 && count[0] < 450, "{count:?}");
    assert!(count[1] > 200 && count[1] < 400, "{count:?}");
    // the path rows are consecutive: one block per path
    let labels: Vec<_> = rec.rows.iter().map(|r| r.extra[seg].clone()).collect();
    let blocks = labels
        .windows(2)
        .filter(|w| w[0].is_none() && w[1].is_some())
        .count();
    assert_eq!(blocks, 2);
}

#[test]
fn the_backlash_run_moves_the_right_motor_forth_and_back_at_the_frequency() {
    let robot = Robot::nominal();
    let opt = BacklashOptions {
        motors: vec![2],
        max_steps: 3,
        periods: 3,
        rest_s: 0.5,
        ..BacklashOptions::default()
    };
    let d = BacklashDesign::new(&robot, &opt).unwrap();
    let home = d.home_steps;
    let design = Design::Backlash(d);
    let (_, rec) = run(&design, &setup(PlantConfig::ideal()));
    let motor = rec.extra_index("motor").unwrap();
    let amp = rec.extra_index("amplitude_steps").unwrap();
    for n in 1..=3i32 {
        let rows: Vec<_> = rec
            .rows
            .iter()
            .filter(|r| r.extra[amp].as_deref() == Some(&n.to_string()))
            .collect();
        assert!(rows.iter().all(|r| r.extra[motor].as_deref() == Some("2")));
        // only motor 2 moves, between home and home + n
        assert!(rows.iter().all(|r| r.q[0] == home[0] && r.q[2] == home[2]));
        assert!(rows
            .iter()
            .all(|r| r.q[1] >= home[1] && r.q[1] <= home[1] + n));
        // forth moves 1/f = 2 s apart
        let ups: Vec<f64> = rows
            .windows(2)
            .filter(|w| w[0].q[1] == home[1] && w[1].q[1] > home[1])
            .map(|w| w[1].t_s)
            .collect();
        let first = rows[0].t_s;
        assert_eq!(ups.len() + 1, 3, "periods of n = {n}");
        for (k, t) in std::iter::once(first).chain(ups).enumerate() {
            assert!(
                (t - first - 2.0 * k as f64).abs() < 0.021,
                "n = {n}: forth {k} at {t}"
            );
        }
        // The captured M_2 moves with the motor (ideal plant: no backlash), M_1 and M_3 stay:
        // their spread is far below M_2's.
        let spread = |i: usize| {
            let xs: Vec<f64> = rows.iter().filter_map(|r| r.m[i][0]).collect();
            let ys: Vec<f64> = rows.iter().filter_map(|r| r.m[i][1]).collect();
            let r = |v: &[f64]| {
                v.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
                    - v.iter().cloned().fold(f64::INFINITY, f64::min)
            };
            r(&xs).hypot(r(&ys))
        };
        let (m1, m2, m3) = (spread(0), spread(1), spread(2));
        println!("n = {n}: M_i motion {m1:.4} {m2:.4} {m3:.4} mm");
        assert!(m2 > 0.05 * n as f64, "n = {n}: M_2 moved {m2} mm");
        assert!(m1 < 0.2 * m2 && m3 < 0.2 * m2, "{m1} {m2} {m3}");
    }
    // the program: the lead-in and the move home, then one command per block
    let prog = program_of(&design, &RobotConfig::nominal()).unwrap();
    assert_eq!(prog.commands.len(), 1 + 3);
    assert_eq!(prog.commands[0].moves.len(), 2);
    assert!(prog.commands[1..].iter().all(|c| c.moves.len() == 12));
}

#[test]
fn a_calibrated_model_drives_the_same_plant() {
    // The truth is the plant's own robot: a different driving model changes where the robot
    // goes (the model error), not the plant.
    let robot = Robot::nominal();
    let mut opt = small_options();
    opt.phis_deg = vec![0.0];
    let d = StaticDesign::calibration(&robot, &opt, timing()).unwrap();
    let design = Design::Static(d);
    let nominal = setup(PlantConfig::ideal());
    let mut changed = nominal.clone();
    changed.model.legs[0].l_c_mm += 3.0;
    let g = |s: &RunSetup| settled_poses(&run(&design, s).1, "run.csv").unwrap();
    let (a, b) = (g(&nominal), g(&changed));
    let err = |x: &pcr_recording::SettledPose| {
        let p = x.pose.unwrap();
        let t = x.planned.unwrap();
        (p[0] - t[0]).hypot(p[1] - t[1])
    };
    let ea = a.iter().map(err).fold(0.0, f64::max);
    let eb = b.iter().map(err).fold(0.0, f64::max);
    println!("max settled error: model = plant {ea:.3} mm, model off by 3 mm in l_C {eb:.3} mm");
    assert!(ea < 0.3 && eb > 0.3 && eb > 4.0 * ea, "{ea} {eb}");
}

#[test]
fn an_unreachable_target_is_refused_naming_the_visit() {
    let robot = Robot::nominal();
    let mut d = StaticDesign::calibration(&robot, &small_options(), timing()).unwrap();
    d.visits[2].target = pcr_kinematics::Pose::new(150.0, 0.0, 0.0);
    let id = d.visits[2].pose_id;
    let mut buf = Vec::new();
    let e = run_in_process(
        &Design::Static(d),
        &setup(PlantConfig::ideal()),
        &mut buf,
        &mut |_| {},
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains(&format!("pose_id {id} rep 0: approach")) && e.contains("refused"),
        "{e}"
    );
}

#[test]
fn the_prototype_plant_is_labelled_the_same_way() {
    // Capture noise, dropouts, backlash, friction, deviations: the labels come from the
    // planned pose only, so every visit still gives one settled group, and the model error of
    // the uncalibrated robot shows in the measured poses.
    let robot = Robot::nominal();
    let mut opt = small_options();
    opt.phis_deg = vec![0.0];
    let d = StaticDesign::calibration(&robot, &opt, timing()).unwrap();
    let n = d.visits.len();
    let (_, rec) = run(&Design::Static(d), &setup(PlantConfig::prototype()));
    let groups = settled_poses(&rec, "run.csv").unwrap();
    assert_eq!(groups.len(), n);
    for g in &groups {
        let p = g.pose.unwrap();
        let t = g.planned.unwrap();
        let e = (p[0] - t[0]).hypot(p[1] - t[1]);
        assert!(e > 0.2 && e < 10.0, "{}: {e} mm", g.label());
        // capture noise (sigma 0.05 mm) shows in the spread of the settled rows
        let s = g.pose_std.unwrap();
        assert!(s[0] > 0.01 && s[0] < 0.2, "{s:?}");
    }
}
