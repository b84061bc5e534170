//! The designs: the paper's calibration set (189 poses, 126/63 split, stratified, feasible,
//! evenly spaced by arc length), the repeatability and backlash designs, refusals.

use pcr_experiments::{
    BacklashDesign, BacklashOptions, CalibrationOptions, CalibrationSet, Design, DesignError,
    ExperimentKind, StaticDesign, VisitTiming,
};
use pcr_kinematics::Robot;
use pcr_recording::Split;

#[test]
fn the_papers_calibration_set_has_189_feasible_poses_split_126_63_by_group() {
    let robot = Robot::nominal();
    let opt = CalibrationOptions::default();
    let set = CalibrationSet::design(&robot, &opt).unwrap();
    assert_eq!(set.poses.len(), 189);
    for (k, p) in set.poses.iter().enumerate() {
        assert_eq!(p.pose_id, k as u64);
    }
    let train = set.poses.iter().filter(|p| p.set == Split::Train).count();
    assert_eq!((train, 189 - train), (126, 63));
    let thr = robot.limits.singularity_threshold;
    for (ip, &phi) in [0.0, 10.0, -10.0].iter().enumerate() {
        let unit = &set.boundaries[ip];
        let check = unit.check.unwrap();
        println!(
            "phi {phi:+}: {check:?}, perimeter {:.1} mm",
            unit.perimeter()
        );
        // the traced boundary encloses the grid workspace: nothing of it lies beyond
        assert!(check.outside_area_mm2 < 1e-9, "{check:?}");
        assert!(
            (check.polygon_area_mm2 - check.grid_area_mm2).abs() < 0.01 * check.grid_area_mm2,
            "{check:?}"
        );
        for (is, &scale) in [0.75, 0.5, 0.2].iter().enumerate() {
            let g: Vec<_> = set.poses[(ip * 3 + is) * 21..(ip * 3 + is + 1) * 21].to_vec();
            assert!(g.iter().all(|p| p.phi_deg == phi && p.scale == scale));
            assert_eq!(g.iter().filter(|p| p.set == Split::Test).count(), 7);
            // the first point is at polar angle 0, the others counter-clockwise, evenly spaced
            // by arc length along the scaled boundary (positions are rounded to 0.1 um)
            assert!(g[0].pose.y.abs() < 1e-4 && g[0].pose.x > 0.0);
            let scaled = unit.scaled(scale);
            let spacing = scaled.perimeter() / 21.0;
            for (k, p) in g.iter().enumerate() {
                assert_eq!(p.point, k);
                let s = scaled.arc_length_of([p.pose.x, p.pose.y]);
                // (point 0 is at arc length 0 = the perimeter)
                let l = scaled.perimeter();
                let d = (s - k as f64 * spacing + 0.5 * l).rem_euclid(l) - 0.5 * l;
                assert!(
                    d.abs() < 1e-3,
                    "phi {phi} scale {scale} point {k}: {s} vs {}",
                    k as f64 * spacing
                );
                assert!((p.pose.phi.to_degrees() - phi).abs() < 1e-12);
                assert!(p.conditioning >= 2.0 * thr, "{p:?}");
                // checked again here with the model
                assert!(pcr_kinematics::workspace::feasible(&robot, &p.pose));
            }
            let polar: Vec<f64> = g
                .iter()
                .map(|p| p.pose.y.atan2(p.pose.x).rem_euclid(std::f64::consts::TAU))
                .collect();
            assert!(polar.windows(2).all(|w| w[1] > w[0]), "{polar:?}");
        }
    }
    // The poses file lists every pose with its split.
    let csv = set.to_csv();
    assert_eq!(csv.lines().count(), 190);
    assert!(csv.starts_with("pose_id,x_mm,y_mm,phi_deg,scale,point,set\n0,"));
}

#[test]
fn the_split_depends_on_the_seed_only() {
    let robot = Robot::nominal();
    let small = |seed| CalibrationOptions {
        phis_deg: vec![0.0],
        scales: vec![0.5, 0.2],
        seed,
        ..CalibrationOptions::default()
    };
    let sets = |seed| {
        CalibrationSet::design(&robot, &small(seed))
            .unwrap()
            .poses
            .iter()
            .map(|p| p.set)
            .collect::<Vec<_>>()
    };
    assert_eq!(sets(5), sets(5));
    assert_ne!(sets(5), sets(6));
}

#[test]
fn infeasible_poses_are_reported_not_dropped() {
    let robot = Robot::nominal();
    // On the boundary itself the conditioning is 0.24 to 0.47 (the boundary is made by the
    // joint limits, not by singularities); requiring 0.3 (300 x the threshold 1e-3) fails some
    // of the poses, and each one is named.
    let opt = CalibrationOptions {
        phis_deg: vec![0.0],
        scales: vec![1.0],
        points: 8,
        test_per_group: 2,
        singularity_margin: 300.0,
        ..CalibrationOptions::default()
    };
    let e = match CalibrationSet::design(&robot, &opt) {
        Ok(_) => panic!("the design should be refused"),
        Err(e) => e,
    };
    let DesignError::Infeasible(list) = &e else {
        panic!("{e}")
    };
    assert!(!list.is_empty() && list.len() < 8, "{e}");
    let text = e.to_string();
    for p in list {
        assert!(text.contains(&format!("pose_id {} ", p.pose_id)), "{text}");
    }
    assert!(
        text.contains("conditioning") && text.contains("scale 1"),
        "{text}"
    );
}

#[test]
fn bad_options_are_refused_naming_the_option() {
    let robot = Robot::nominal();
    for (opt, name) in [
        (
            CalibrationOptions {
                points: 0,
                ..CalibrationOptions::default()
            },
            "points",
        ),
        (
            CalibrationOptions {
                test_per_group: 22,
                ..CalibrationOptions::default()
            },
            "test_per_group",
        ),
        (
            CalibrationOptions {
                scales: vec![0.5, 1.5],
                ..CalibrationOptions::default()
            },
            "scales",
        ),
        (
            CalibrationOptions {
                phis_deg: vec![f64::NAN],
                ..CalibrationOptions::default()
            },
            "phis_deg",
        ),
    ] {
        let e = CalibrationSet::design(&robot, &opt)
            .unwrap_err()
            .to_string();
        assert!(e.contains(name), "{e}");
    }
    let timing = VisitTiming {
        speed_mm_s: -1.0,
        ..VisitTiming::default()
    };
    let e = StaticDesign::calibration(&robot, &CalibrationOptions::default(), timing)
        .unwrap_err()
        .to_string();
    assert!(e.contains("speed_mm_s"), "{e}");
    let e = BacklashDesign::new(
        &robot,
        &BacklashOptions {
            motors: vec![4],
            ..BacklashOptions::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("motors"), "{e}");
}

#[test]
fn repeatability_visits_the_phi0_poses_20_times_in_a_row() {
    let robot = Robot::nominal();
    let d = StaticDesign::repeatability(
        &robot,
        &CalibrationOptions::default(),
        0.0,
        20,
        VisitTiming::default(),
    )
    .unwrap();
    assert_eq!(d.visits.len(), 63 * 20);
    for (k, v) in d.visits.iter().enumerate() {
        assert_eq!((v.pose_id, v.rep), ((k / 20) as u64, (k % 20) as u64));
        assert_eq!(v.target.phi, 0.0);
        assert_eq!(v.target, d.set.poses[k / 20].pose);
        assert_eq!(v.set, d.set.poses[k / 20].set);
    }
    let e = StaticDesign::repeatability(
        &robot,
        &CalibrationOptions::default(),
        5.0,
        20,
        VisitTiming::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("phi_deg"), "{e}");
    let meta = Design::Static(d).metadata(1);
    let get = |k: &str| meta.iter().find(|(a, _)| a == k).map(|(_, v)| v.as_str());
    assert_eq!(get("experiment"), Some("repeatability"));
    assert_eq!(get("reps"), Some("20"));
    assert_eq!(get("visits"), Some("1260"));
    assert_eq!(get("settle_s"), Some("1"));
    assert_eq!(get("phis_deg"), Some("0 10 -10"));
}

#[test]
fn backlash_blocks_run_motor_by_motor_from_home() {
    let robot = Robot::nominal();
    let d = BacklashDesign::new(&robot, &BacklashOptions::default()).unwrap();
    assert_eq!(d.home_steps, [176; 3]);
    assert_eq!(d.blocks.len(), 24);
    assert_eq!((d.blocks[0].motor, d.blocks[0].amplitude_steps), (1, 1));
    assert_eq!((d.blocks[23].motor, d.blocks[23].amplitude_steps), (3, 8));
    let design = Design::Backlash(d);
    assert_eq!(design.kind(), ExperimentKind::Backlash);
    let meta = design.metadata(3);
    assert!(meta.contains(&("home_steps".into(), "176 176 176".into())));
    assert!(meta.contains(&("freq_hz".into(), "0.5".into())));
}
