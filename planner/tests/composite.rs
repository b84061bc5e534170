//! Composite paths: continuous speed through smooth junctions, stops at corners, limits along
//! the path (speed, acceleration, jerk, centripetal), exact end pose. Sampled every 1 ms.

use pcr_planner::composite::{
    CompositeError, CompositeLimits, CompositeMotion, CompositePath, SegmentGeometry,
};
use pcr_planner::path::Pose;
use std::f64::consts::PI;

const DT: f64 = 1e-3;
const REL: f64 = 1e-9;

fn lim(vmax: f64) -> CompositeLimits {
    CompositeLimits {
        vmax,
        amax: 200.0,
        jmax: 2000.0,
    }
}

/// A slot: line along +x, half circle, line back along -x, half circle (G1 everywhere).
fn slot(half_len: f64, r: f64) -> CompositePath {
    let mut c = CompositePath::new(Pose::new(-half_len, -r, 0.0)).unwrap();
    c.line_to(Pose::new(half_len, -r, 0.0), None).unwrap();
    c.arc_around(half_len, 0.0, PI, 0.0, None).unwrap();
    c.line_to(Pose::new(-half_len, r, 0.0), None).unwrap();
    c.arc_around(-half_len, 0.0, PI, 0.0, None).unwrap();
    c
}

/// Samples every 1 ms and checks the limits; returns the samples (t, sample).
fn check_limits(m: &CompositeMotion) -> Vec<(f64, pcr_planner::composite::CompositeSample)> {
    let l = *m.limits();
    let n = (m.duration() / DT).ceil() as usize;
    let mut out = Vec::with_capacity(n + 2);
    let mut prev: Option<(f64, pcr_planner::composite::CompositeSample)> = None;
    for k in 0..=n + 1 {
        let t = (k as f64 * DT).min(m.duration());
        let sp = m.sample(t);
        let vlim = m.segment_speed_limit(sp.segment);
        assert!(
            sp.speed >= 0.0 && sp.speed <= vlim * (1.0 + REL) + 1e-9,
            "speed {} > {vlim} at t = {t}",
            sp.speed
        );
        assert!(
            sp.acceleration.abs() <= l.amax * (1.0 + REL),
            "a {} at {t}",
            sp.acceleration
        );
        assert!(
            sp.jerk.abs() <= l.jmax * (1.0 + REL),
            "j {} at {t}",
            sp.jerk
        );
        // Centripetal acceleration on arcs.
        let seg = &m.path().segments()[sp.segment];
        if let Some(r) = seg.radius() {
            let vxy = sp.speed * seg.planar_fraction();
            assert!(
                vxy * vxy / r <= l.amax * (1.0 + 1e-6),
                "centripetal {} at {t}",
                vxy * vxy / r
            );
        }
        if let Some((tp, p)) = prev {
            if t > tp {
                let h = t - tp;
                // Continuity: speed and acceleration change at most by the acceleration / jerk
                // limit times the step (no jumps at junctions or section boundaries).
                assert!(
                    (sp.speed - p.speed).abs() <= l.amax * h * (1.0 + 1e-6) + 1e-9,
                    "speed jump at {t}"
                );
                assert!(
                    (sp.acceleration - p.acceleration).abs() <= l.jmax * h * (1.0 + 1e-6) + 1e-9,
                    "accel jump at {t}"
                );
                // Position moves by at most the speed times the step (combined metric).
                let d = ((sp.pose.x - p.pose.x).powi(2)
                    + (sp.pose.y - p.pose.y).powi(2)
                    + (m.path().rotation_radius() * (sp.pose.phi - p.pose.phi)).powi(2))
                .sqrt();
                assert!(d <= l.vmax * h * (1.0 + 1e-6) + 1e-9, "jump {d} at {t}");
                assert!(sp.s >= p.s - 1e-12, "backwards at {t}");
            }
        }
        prev = Some((t, sp));
        out.push((t, sp));
    }
    out
}

#[test]
fn slot_is_traversed_without_stopping_at_its_g1_junctions() {
    let path = slot(20.0, 10.0);
    for j in 1..path.len() {
        assert!(path.junction_is_smooth(j), "junction {j}");
    }
    let m = CompositeMotion::plan(&path, &lim(30.0)).unwrap();
    assert_eq!(m.sections(), 1, "one section: same limit, all smooth");
    let samples = check_limits(&m);
    // The speed is never zero between start and end; at every junction it is the cruise speed.
    let interior: Vec<_> = samples
        .iter()
        .filter(|(t, _)| *t > 0.3 && *t < m.duration() - 0.3)
        .collect();
    assert!(interior.iter().all(|(_, s)| s.speed > 5.0));
    for j in 1..path.len() {
        let v = m.speed_at_segment_start(j);
        assert!((v - 30.0).abs() < 1e-6, "junction {j}: {v}");
    }
    // End exactly at the end pose (the start of the slot), at rest.
    let end = m.sample(m.duration());
    assert_eq!(end.pose, path.end());
    assert!(end.pose.max_diff(&path.start()) < 1e-12);
    assert_eq!(end.speed, 0.0);
}

#[test]
fn the_centripetal_limit_slows_down_on_a_tight_arc() {
    // 200 mm/s^2 on a 2 mm radius: at most 20 mm/s on the arcs, 60 on the lines.
    let path = slot(30.0, 2.0);
    let m = CompositeMotion::plan(&path, &lim(60.0)).unwrap();
    assert!((m.segment_speed_limit(1) - 20.0).abs() < 1e-12);
    assert!((m.segment_speed_limit(0) - 60.0).abs() < 1e-12);
    let samples = check_limits(&m);
    // The arc is entered at its limit (not at rest) and the lines reach their own speed.
    let v1 = m.speed_at_segment_start(1);
    assert!((v1 - 20.0).abs() < 1e-6, "{v1}");
    assert!(samples
        .iter()
        .any(|(_, s)| s.segment == 0 && s.speed > 59.9));
    let on_arc = samples.iter().filter(|(_, s)| s.segment == 1);
    assert!(on_arc
        .clone()
        .all(|(_, s)| s.speed > 19.99 && s.speed <= 20.0 + 1e-9));
}

#[test]
fn a_sharp_corner_stops_and_a_blend_radius_keeps_moving() {
    let v = [
        Pose::new(0.0, 0.0, 0.0),
        Pose::new(30.0, 0.0, 0.0),
        Pose::new(30.0, 30.0, 0.0),
    ];
    let sharp =
        CompositeMotion::plan(&CompositePath::polyline(&v, 0.0).unwrap(), &lim(40.0)).unwrap();
    let samples = check_limits(&sharp);
    assert_eq!(sharp.speed_at_segment_start(1), 0.0);
    // Around the corner time the speed goes down to 0.
    let tc = sharp.time_at_length(30.0);
    let near: f64 = samples
        .iter()
        .filter(|(t, _)| (t - tc).abs() < 0.01)
        .map(|(_, s)| s.speed)
        .fold(f64::INFINITY, f64::min);
    assert!(near < 0.2, "{near}");
    assert!(sharp.sample(tc).pose.max_diff(&v[1]) < 1e-6);
    let blended =
        CompositeMotion::plan(&CompositePath::polyline(&v, 5.0).unwrap(), &lim(40.0)).unwrap();
    let path = blended.path();
    assert_eq!(path.len(), 3);
    let r = path.segments()[1].radius().unwrap();
    assert_eq!(r, 5.0);
    let samples = check_limits(&blended);
    let vc = (200.0f64 * 5.0).sqrt();
    assert!(samples
        .iter()
        .filter(|(t, _)| *t > 0.3 && *t < blended.duration() - 0.3)
        .all(|(_, s)| s.speed > 5.0));
    // Through the blend arc at its centripetal limit.
    assert!((blended.speed_at_segment_start(1) - vc).abs() < 1e-6);
    assert!(blended.duration() < sharp.duration());
    assert_eq!(blended.sample(1e9).pose, v[2]);
}

#[test]
fn rounded_rectangle_keeps_its_speed_around_the_loop() {
    let c = CompositePath::rectangle(Pose::new(0.0, 0.0, 0.1), 60.0, 40.0, 0.3, 8.0).unwrap();
    assert_eq!(c.len(), 9);
    for j in 1..c.len() {
        assert!(c.junction_is_smooth(j));
    }
    assert!(c.end().max_diff(&c.start()) < 1e-12);
    let m = CompositeMotion::plan(&c, &lim(30.0)).unwrap();
    let samples = check_limits(&m);
    assert!(samples
        .iter()
        .filter(|(t, _)| *t > 0.3 && *t < m.duration() - 0.3)
        .all(|(_, s)| s.speed > 5.0));
    assert!(samples
        .iter()
        .all(|(_, s)| (s.pose.phi - 0.1).abs() < 1e-12));
    let sharp = CompositeMotion::plan(
        &CompositePath::rectangle(Pose::new(0.0, 0.0, 0.1), 60.0, 40.0, 0.3, 0.0).unwrap(),
        &lim(30.0),
    )
    .unwrap();
    assert_eq!(sharp.sections(), 5);
    check_limits(&sharp);
}

#[test]
fn short_segments_and_speed_changes_are_planned_consistently() {
    // Alternating per-segment speeds on short smooth segments: the passes must lower the
    // junction speeds so that every section is feasible.
    let mut c = CompositePath::new(Pose::default()).unwrap();
    let mut x = 0.0;
    for k in 0..20 {
        x += 0.5 + (k % 3) as f64;
        c.line_to(
            Pose::new(x, 0.0, 0.0),
            Some(if k % 2 == 0 { 50.0 } else { 5.0 }),
        )
        .unwrap();
    }
    // Rotation and a small arc at the end.
    c.line_to(Pose::new(x + 5.0, 0.0, 0.2), None).unwrap();
    c.arc_around(x + 5.0, 5.0, 1.0, 0.0, Some(8.0)).unwrap();
    let m = CompositeMotion::plan(&c, &lim(60.0)).unwrap();
    let samples = check_limits(&m);
    let last = samples.last().unwrap().1;
    assert_eq!(last.pose, c.end());
    assert!((last.s - c.length()).abs() < 1e-12);
}

#[test]
fn phi_changes_on_arcs_count_in_the_combined_metric() {
    let mut c = CompositePath::new(Pose::new(10.0, 0.0, 0.0)).unwrap();
    c.arc_around(0.0, 0.0, PI / 2.0, 0.3, None).unwrap();
    let seg = c.segments()[0];
    let SegmentGeometry::Arc { r, .. } = *seg.geometry() else {
        panic!()
    };
    assert_eq!(r, 10.0);
    let xy = 10.0 * PI / 2.0;
    assert!((seg.length() - (xy * xy + 15.0f64 * 15.0).sqrt()).abs() < 1e-12);
    let m = CompositeMotion::plan(&c, &lim(100.0)).unwrap();
    // The planar speed obeys the centripetal limit; the combined one is larger.
    let k = seg.planar_fraction();
    assert!((m.segment_speed_limit(0) - (200.0f64 * 10.0).sqrt() / k).abs() < 1e-9);
    check_limits(&m);
}

#[test]
fn bad_input_is_an_error() {
    let c = slot(10.0, 5.0);
    for l in [
        lim(0.0),
        lim(f64::NAN),
        CompositeLimits {
            jmax: -1.0,
            ..lim(1.0)
        },
    ] {
        assert!(matches!(
            CompositeMotion::plan(&c, &l),
            Err(CompositeError::NotPositive(..))
        ));
    }
    assert_eq!(
        CompositeMotion::plan(&CompositePath::new(Pose::default()).unwrap(), &lim(1.0))
            .unwrap_err(),
        CompositeError::Empty
    );
    assert!(CompositePath::polyline(&[Pose::default()], 0.0).is_err());
    assert!(CompositePath::polyline(&[Pose::default(), Pose::new(1.0, 0.0, 0.0)], -1.0).is_err());
    assert!(CompositePath::rectangle(Pose::default(), 0.0, 1.0, 0.0, 0.0).is_err());
    let mut many = CompositePath::new(Pose::default()).unwrap();
    let mut r = Ok(());
    for k in 0..70 {
        r = many.line_to(Pose::new(k as f64 + 1.0, (k % 2) as f64, 0.0), None);
        if r.is_err() {
            break;
        }
    }
    assert_eq!(r, Err(CompositeError::TooManySegments));
}

#[test]
fn random_polylines_with_blends_and_speeds_respect_every_limit() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    for case in 0..40 {
        let n = rng.random_range(2..12);
        let mut v = vec![Pose::new(0.0, 0.0, 0.0)];
        for _ in 1..n {
            let last = *v.last().unwrap();
            v.push(Pose::new(
                last.x + rng.random_range(-20.0..20.0),
                last.y + rng.random_range(-20.0..20.0),
                if rng.random_bool(0.2) {
                    last.phi + rng.random_range(-0.2..0.2)
                } else {
                    last.phi
                },
            ));
        }
        let blend = if rng.random_bool(0.3) {
            0.0
        } else {
            rng.random_range(0.5..10.0)
        };
        let Ok(path) = CompositePath::polyline(&v, blend) else {
            continue;
        };
        // Some arcs at the end, with their own speeds.
        let mut path = path;
        for _ in 0..rng.random_range(0..3) {
            let e = path.end();
            let (cx, cy) = (
                e.x + rng.random_range(-10.0..10.0),
                e.y + rng.random_range(-10.0..10.0),
            );
            let speed = rng.random_bool(0.5).then(|| rng.random_range(2.0..40.0));
            let _ = path.arc_around(cx, cy, rng.random_range(-4.0..4.0), e.phi, speed);
        }
        let l = CompositeLimits {
            vmax: rng.random_range(5.0..80.0),
            amax: rng.random_range(50.0..500.0),
            jmax: rng.random_range(300.0..5000.0),
        };
        let m = CompositeMotion::plan(&path, &l).unwrap_or_else(|e| panic!("case {case}: {e}"));
        let samples = check_limits(&m);
        let last = samples.last().unwrap().1;
        assert_eq!(last.pose, path.end(), "case {case}");
        // At every corner the planned speed is zero; with smooth junctions it is not.
        for j in 1..path.len() {
            let vj = m.speed_at_segment_start(j);
            if !path.junction_is_smooth(j) {
                assert!(vj < 1e-6, "case {case} junction {j}: {vj}");
            }
        }
    }
}
