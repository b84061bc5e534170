//! The annotator on synthetic rows: it marks exactly the dwell windows, survives pauses, and
//! needs nothing but the rows (any start time, jittery periods, values read back from a file).

use pcr_experiments::{
    Annotator, BacklashBlock, BacklashDesign, BacklashOptions, CalibrationOptions, CalibrationSet,
    Design, ExperimentKind, PathShape, PathsDesign, StaticDesign, Tolerances, Visit, VisitTiming,
};
use pcr_kinematics::Pose;
use pcr_recording::{Recording, RecordingWriter, Row, Split};

/// A tiny pseudo-random sequence (jitter of the row times), in [-1, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1);
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

fn static_design(visits: Vec<Visit>, timing: VisitTiming) -> Design {
    Design::Static(StaticDesign {
        kind: ExperimentKind::Calibration,
        set: CalibrationSet {
            options: CalibrationOptions::default(),
            boundaries: Vec::new(),
            poses: Vec::new(),
        },
        reps: 1,
        visits,
        timing,
        origin: Pose::default(),
        phi_deg: None,
    })
}

/// What a synthetic row is, for the expected labels.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Truth {
    Moving,
    /// In the dwell of visit k; `first` on the first row at rest there (the one that arrives).
    AtRest {
        visit: usize,
        first: bool,
    },
    Paused,
}

/// Rows of a static program sampled every ~20 ms (with jitter) from `t0`: constant-speed lines
/// from the origin to each target, a dwell of `dwell_s` (plus `extra_dwell` for some visits, a
/// pause), a line back; `pause_mid_approach` holds the planned pose halfway for 2 s.
fn static_rows(
    visits: &[Visit],
    dwell_s: f64,
    t0: f64,
    jitter_s: f64,
    extra_dwell: &[(usize, f64)],
    pause_mid_approach: Option<usize>,
) -> Vec<(Row, Truth)> {
    let mut rng = Lcg(42);
    let mut out = Vec::new();
    let mut t = t0;
    let mut push = |p: [f64; 3], truth: Truth, t: &mut f64| {
        let mut r = Row::new(*t, [176, 176, 176]);
        r.planned = [Some(p[0]), Some(p[1]), Some(p[2])];
        out.push((r, truth));
        *t += 0.02 + jitter_s * rng.next();
    };
    let speed = 40.0; // mm/s: 0.8 mm per row, far above the tolerance
    for (k, v) in visits.iter().enumerate() {
        let target = [v.target.x, v.target.y, v.target.phi.to_degrees()];
        let len = target[0].hypot(target[1]);
        let n = (len / (speed * 0.02)).ceil() as usize;
        let line = |u: f64| [u * target[0], u * target[1], u * target[2]];
        for j in 0..n {
            if pause_mid_approach == Some(k) && j == n / 2 {
                for _ in 0..100 {
                    push(line(j as f64 / n as f64), Truth::Paused, &mut t);
                }
            }
            push(line(j as f64 / n as f64), Truth::Moving, &mut t);
        }
        let extra = extra_dwell
            .iter()
            .find(|(i, _)| *i == k)
            .map_or(0.0, |e| e.1);
        let rest = ((dwell_s + extra) / 0.02).round() as usize;
        for j in 0..rest {
            push(
                target,
                Truth::AtRest {
                    visit: k,
                    first: j == 0,
                },
                &mut t,
            );
        }
        for j in 1..=n {
            push(line(1.0 - j as f64 / n as f64), Truth::Moving, &mut t);
        }
    }
    out
}

fn visits() -> Vec<Visit> {
    let v = |id, rep, set, x, y, phi: f64| Visit {
        pose_id: id,
        rep,
        set,
        target: Pose::new(x, y, phi.to_radians()),
    };
    vec![
        v(0, 0, Split::Train, 30.0, 5.0, 0.0),
        v(1, 0, Split::Test, -20.0, 40.0, 10.0),
        v(1, 1, Split::Test, -20.0, 40.0, 10.0),
        v(2, 0, Split::Train, 10.0, -35.0, -10.0),
    ]
}

/// Checks the labels against the truth: the dwell is every row at rest but the arriving one;
/// settled once settle_s has passed since the dwell's first row.
fn check(rows: &[(Row, Truth)], design: &Design, visits: &[Visit], settle_s: f64) {
    let mut ann = Annotator::new(design, Tolerances::default());
    let mut dwell_start: Option<f64> = None;
    let mut settled_per_visit = vec![0usize; visits.len()];
    for (row, truth) in rows {
        let l = ann.label(row);
        match *truth {
            Truth::AtRest { visit, first } if !first => {
                let v = &visits[visit];
                let t0 = *dwell_start.get_or_insert(row.t_s);
                assert_eq!(
                    (l.pose_id, l.rep, l.set),
                    (Some(v.pose_id), Some(v.rep), Some(v.set)),
                    "t = {}",
                    row.t_s
                );
                assert_eq!(
                    l.settled,
                    row.t_s - t0 >= settle_s - 1e-9,
                    "t = {}",
                    row.t_s
                );
                settled_per_visit[visit] += usize::from(l.settled);
            }
            _ => {
                dwell_start = None;
                assert_eq!(l.pose_id, None, "{truth:?} at t = {}", row.t_s);
                assert!(!l.settled);
                assert_eq!((l.segment, l.motor), (None, None));
            }
        }
    }
    assert!(ann.finished(), "{:?}", ann.waiting_for());
    assert_eq!(ann.found(), visits.len());
    assert!(
        settled_per_visit.iter().all(|n| *n > 0),
        "{settled_per_visit:?}"
    );
}

#[test]
fn the_dwell_windows_are_marked_exactly() {
    let timing = VisitTiming {
        speed_mm_s: 40.0,
        settle_s: 0.4,
        measure_s: 0.3,
    };
    let v = visits();
    let d = static_design(v.clone(), timing);
    let rows = static_rows(&v, 0.7, 0.0, 0.0, &[], None);
    check(&rows, &d, &v, 0.4);
    // 0.7 s at rest = 35 rows: 34 in the dwell, of which those 0.4 s after its first are
    // settled: 14 rows
    let mut ann = Annotator::new(&d, Tolerances::default());
    let n = rows.iter().filter(|(r, _)| ann.label(r).settled).count();
    assert_eq!(n, 4 * 14);
}

#[test]
fn pauses_and_a_foreign_clock_do_not_break_it() {
    let timing = VisitTiming::default();
    let v = visits();
    let d = static_design(v.clone(), timing);
    // A live clock far from 0 with +-4 ms jitter, a 2 s pause mid-approach of visit 1 and a
    // dwell of visit 2 held 3 s longer (paused at the target).
    let rows = static_rows(&v, 1.5, 86_400.25, 0.004, &[(2, 3.0)], Some(1));
    check(&rows, &d, &v, timing.settle_s);
    // The longer dwell has more settled rows.
    let mut ann = Annotator::new(&d, Tolerances::default());
    let mut per = [0usize; 4];
    for (r, t) in &rows {
        if let (true, Truth::AtRest { visit, .. }) = (ann.label(r).settled, t) {
            per[*visit] += 1;
        }
    }
    assert!(per[2] > per[0] + 100, "{per:?}");
}

#[test]
fn rows_read_back_from_a_file_are_labelled_alike() {
    let timing = VisitTiming::default();
    let v = visits();
    let d = static_design(v.clone(), timing);
    let rows = static_rows(&v, 1.5, 12.0, 0.002, &[], None);
    // Through the recording format with the planned pose rounded as a live recorder writes it
    // (4 decimals in mm, 5 in degrees).
    let mut buf = Vec::new();
    let mut w = RecordingWriter::new(&mut buf, &[], &["xp_mm", "yp_mm", "phip_deg"], &[]).unwrap();
    for (r, _) in &rows {
        let mut r = r.clone();
        for (k, p) in r.planned.iter_mut().enumerate() {
            let d = if k < 2 { 1e4 } else { 1e5 };
            *p = p.map(|x| (x * d).round() / d);
        }
        w.write_row(&r, &[]).unwrap();
    }
    drop(w);
    let rec = Recording::read(&buf[..], "live.csv").unwrap();
    assert_eq!(rec.rows.len(), rows.len());
    let mut a = Annotator::new(&d, Tolerances::default());
    let mut b = Annotator::new(&d, Tolerances::default());
    for (read, (orig, _)) in rec.rows.iter().zip(&rows) {
        assert_eq!(a.label(read), b.label(orig), "t = {}", read.t_s);
    }
    assert!(a.finished());
}

#[test]
fn path_rows_are_labelled_by_the_path_they_lie_on() {
    let d = Design::Paths(PathsDesign::default());
    let mut rows = Vec::new();
    let mut t = 3.0;
    let mut push = |x: f64, y: f64, want: Option<&'static str>| {
        let mut r = Row::new(t, [0; 3]);
        r.planned = [Some(x), Some(y), Some(0.0)];
        rows.push((r, want));
        t += 0.02;
    };
    // approach to (50, 0), the circle (held a while at a pause), rest, back to the origin
    for k in 0..50 {
        push(k as f64, 0.0, None);
    }
    for k in 0..=400 {
        let a = std::f64::consts::TAU * k as f64 / 400.0;
        push(50.0 * a.cos(), 50.0 * a.sin(), Some("circle"));
        if k == 100 {
            for _ in 0..30 {
                push(50.0 * a.cos(), 50.0 * a.sin(), Some("circle"));
            }
        }
    }
    // (the return to the origin crosses the square's side at (25, 0): not a square row)
    for k in 1..=50 {
        push(50.0 - k as f64, 0.0, None);
    }
    // the square: approach to (25, -25), its four sides, back
    for k in 0..25 {
        push(k as f64, -(k as f64), None);
    }
    let corners = [
        (25.0, -25.0),
        (25.0, 25.0),
        (-25.0, 25.0),
        (-25.0, -25.0),
        (25.0, -25.0),
    ];
    for w in corners.windows(2) {
        for k in 0..50 {
            let u = k as f64 / 50.0;
            push(
                w[0].0 + u * (w[1].0 - w[0].0),
                w[0].1 + u * (w[1].1 - w[0].1),
                Some("square"),
            );
        }
    }
    push(25.0, -25.0, Some("square"));
    for k in 1..=25 {
        push(25.0 - k as f64, -25.0 + k as f64, None);
    }
    let mut ann = Annotator::new(&d, Tolerances::default());
    for (r, want) in &rows {
        let l = ann.label(r);
        assert_eq!(l.segment, *want, "t = {} at {:?}", r.t_s, r.planned);
        assert_eq!((l.pose_id, l.settled), (None, false));
    }
    assert!(ann.finished());
    // the circle's geometry is the paper's
    assert_eq!(
        PathShape::PAPER_CIRCLE,
        PathShape::Circle {
            centre: [0.0, 0.0],
            radius_mm: 50.0,
            phi_deg: 0.0
        }
    );
}

#[test]
fn backlash_blocks_are_recognised_from_the_commanded_steps() {
    let robot = pcr_kinematics::Robot::nominal();
    let opt = BacklashOptions {
        motors: vec![2, 3],
        max_steps: 2,
        periods: 3,
        ..BacklashOptions::default()
    };
    let d = BacklashDesign::new(&robot, &opt).unwrap();
    assert_eq!(
        d.blocks,
        [
            BacklashBlock {
                motor: 2,
                amplitude_steps: 1
            },
            BacklashBlock {
                motor: 2,
                amplitude_steps: 2
            },
            BacklashBlock {
                motor: 3,
                amplitude_steps: 1
            },
            BacklashBlock {
                motor: 3,
                amplitude_steps: 2
            },
        ]
    );
    let home = d.home_steps;
    let design = Design::Backlash(d.clone());
    let mut rows: Vec<(Row, Option<(u8, u32)>)> = Vec::new();
    let mut t = 100.0;
    let mut push = |q: [i32; 3], want| {
        rows.push((Row::new(t, q), want));
        t += 0.02;
    };
    for _ in 0..10 {
        push(home, None);
    }
    for b in &d.blocks {
        let i = usize::from(b.motor - 1);
        let n = b.amplitude_steps as i32;
        let want = Some((b.motor, b.amplitude_steps));
        for p in 0..3 {
            // forth over two cycles for n = 2 (intermediate step), hold, back, hold
            for s in 1..=n {
                let mut q = home;
                q[i] += s;
                push(q, want);
            }
            for _ in 0..(if p == 1 { 120 } else { 49 }) {
                let mut q = home;
                q[i] += n;
                push(q, want);
            }
            push(home, want);
            if p < 2 {
                for _ in 0..49 {
                    push(home, want);
                }
            }
        }
        for _ in 0..50 {
            push(home, None);
        }
    }
    let mut ann = Annotator::new(&design, Tolerances::default());
    for (r, want) in &rows {
        let l = ann.label(r);
        assert_eq!(
            l.motor.zip(l.amplitude_steps),
            *want,
            "t = {} q = {:?}",
            r.t_s,
            r.q
        );
        assert_eq!(l.segment, None);
    }
    assert!(ann.finished());
    assert_eq!(ann.found(), 4);
}

#[test]
fn a_command_that_moves_during_the_dwell_ends_the_measurement() {
    let timing = VisitTiming {
        speed_mm_s: 40.0,
        settle_s: 0.4,
        measure_s: 0.3,
    };
    let v = visits();
    let d = static_design(v.clone(), timing);
    let mut rows = static_rows(&v, 0.7, 0.0, 0.0, &[], None);
    // In visit 0's dwell, the commanded motors step once 0.6 s after the dwell began (the next
    // move's first step, commanded one period ahead of the plan), with the planned pose still
    // at the target.
    let first = rows
        .iter()
        .position(|(_, t)| {
            *t == Truth::AtRest {
                visit: 0,
                first: true,
            }
        })
        .unwrap();
    for (r, _) in rows.iter_mut().skip(first + 30).take(5) {
        r.q[1] += 1;
    }
    let mut ann = Annotator::new(&d, Tolerances::default());
    let settled: Vec<bool> = rows.iter().map(|(r, _)| ann.label(r).settled).collect();
    // Visit 0 (its dwell begins on the row after the arriving one): settled from 0.4 s into
    // the dwell up to the row before the step; none after it, even where the command comes
    // back.
    let in_dwell0: Vec<usize> = (first..first + 35).filter(|i| settled[*i]).collect();
    assert_eq!(in_dwell0, (first + 21..first + 30).collect::<Vec<_>>());
    // The other visits are untouched.
    let n: usize = settled.iter().filter(|s| **s).count();
    assert_eq!(n, 9 + 3 * 14);
}
