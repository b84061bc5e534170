//! Benchmarks of the profiler.
//!
//! * Criterion: one 3-DoF time-synchronised case from arbitrary states (`calculate_3dof_sync`)
//!   and a rest-to-rest one (`calculate_3dof_rest`).
//! * With `PROFILE_BENCH_CASES=cases.json` (the format of `pcr profile`, written by
//!   `scripts/profile_bench.py`): every case is timed individually (median of repeated runs) and
//!   one line `PCR_BENCH_JSON {...}` with the per-case times in microseconds is printed.

use std::hint::black_box;
use std::time::Instant;

use criterion::{criterion_group, Criterion};
use pcr_planner::profiler::{calculate, Input, Limits, State, Synchronization};

fn sync_case() -> Input {
    let mut inp = Input::new(3);
    inp.synchronization = Synchronization::Time;
    let cur = [(0.0, 0.3, -0.5), (1.0, -0.2, 0.4), (-0.5, 0.1, 0.0)];
    let tgt = [(1.5, 0.2, 0.1), (-1.0, 0.0, 0.0), (0.8, -0.3, -0.2)];
    let lim = [(1.0, 2.0, 5.0), (1.5, 1.0, 3.0), (0.8, 1.5, 8.0)];
    for k in 0..3 {
        inp.current[k] = State::new(cur[k].0, cur[k].1, cur[k].2);
        inp.target[k] = State::new(tgt[k].0, tgt[k].1, tgt[k].2);
        inp.limits[k] = Limits::symmetric(lim[k].0, lim[k].1, lim[k].2);
    }
    inp
}

fn rest_case() -> Input {
    let mut inp = sync_case();
    for k in 0..3 {
        inp.current[k].v = 0.0;
        inp.current[k].a = 0.0;
        inp.target[k].v = 0.0;
        inp.target[k].a = 0.0;
    }
    inp
}

fn bench(c: &mut Criterion) {
    let sync = sync_case();
    c.bench_function("calculate_3dof_sync", |b| {
        b.iter(|| calculate(black_box(&sync)).unwrap())
    });
    let rest = rest_case();
    c.bench_function("calculate_3dof_rest", |b| {
        b.iter(|| calculate(black_box(&rest)).unwrap())
    });
}

fn arr(v: &serde_json::Value, a: &str, b: &str) -> Vec<f64> {
    v[a][b]
        .as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

/// Times every case of a `pcr profile` cases file; prints one JSON line.
fn time_cases(path: &str) {
    let text = std::fs::read_to_string(path).expect("cases file");
    let root: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    let cases = root["cases"].as_array().expect("cases");
    let mut times = Vec::with_capacity(cases.len());
    for case in cases {
        let n = case["dofs"].as_u64().expect("dofs") as usize;
        let mut inp = Input::new(n);
        let (cp, cv, ca) = (
            arr(case, "current", "p"),
            arr(case, "current", "v"),
            arr(case, "current", "a"),
        );
        let (tp, tv, ta) = (
            arr(case, "target", "p"),
            arr(case, "target", "v"),
            arr(case, "target", "a"),
        );
        let (vmax, vmin, amax, amin, jmax) = (
            arr(case, "limits", "vmax"),
            arr(case, "limits", "vmin"),
            arr(case, "limits", "amax"),
            arr(case, "limits", "amin"),
            arr(case, "limits", "jmax"),
        );
        for k in 0..n {
            inp.current[k] = State::new(cp[k], cv[k], ca[k]);
            inp.target[k] = State::new(tp[k], tv[k], ta[k]);
            inp.limits[k] = Limits {
                vmax: vmax[k],
                vmin: vmin[k],
                amax: amax[k],
                amin: amin[k],
                jmax: jmax[k],
            };
        }
        // Median of 21 runs, each timed individually.
        let mut runs = [0.0f64; 21];
        for r in runs.iter_mut() {
            let t0 = Instant::now();
            let res = calculate(black_box(&inp));
            *r = t0.elapsed().as_secs_f64() * 1e6;
            black_box(res.is_ok());
        }
        runs.sort_by(f64::total_cmp);
        times.push(runs[runs.len() / 2]);
    }
    println!(
        "PCR_BENCH_JSON {}",
        serde_json::json!({ "times_us": times })
    );
}

criterion_group!(benches, bench);

fn main() {
    if let Ok(path) = std::env::var("PROFILE_BENCH_CASES") {
        time_cases(&path);
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
