#!/usr/bin/env python3
"""Calculation time of the in-house profiler vs ruckig on the same 3-DoF synchronised cases.

ruckig: its own `OutputParameter.calculation_duration` (microseconds, measured inside the C++
library, so without Python overhead), median of repeated calculations per case.
pcr-planner: `cargo bench -p pcr-planner --bench profiler` with PROFILE_BENCH_CASES set, which
times `calculate()` per case (median of 21 runs).

Usage: profile_bench.py [--cases N] [--seed S] [--repeats R] [--write-cases PATH]
       profile_bench.py --ruckig-loop PATH [--repeats R]

--ruckig-loop only calls ruckig's `calculate` R times per case of a cases file (for counting its
instructions with callgrind, see BENCHMARKS.md).
"""

import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from ruckig import InputParameter, OutputParameter, Ruckig

sys.path.insert(0, str(Path(__file__).resolve().parent))
import profile_compare as pc  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def gen_cases(n, seed):
    rng = random.Random(seed)
    cases = []
    while len(cases) < n:
        k = len(cases)
        lim = pc.rnd_limits(rng, 3, False)
        case = pc.make_case(
            f"bench-{k}", 3,
            [pc.rnd_state_inside(rng, lim, i) for i in range(3)],
            [pc.rnd_target(rng, lim, i, "any" if k % 2 else "rest") for i in range(3)],
            lim)
        if pc.solve_ruckig(case) is not None:
            cases.append(case)
    return cases


def ruckig_times(cases, repeats):
    times = []
    for c in cases:
        runs = []
        for _ in range(repeats):
            otg = Ruckig(3, 0.001)
            out = OutputParameter(3)
            otg.update(pc.ruckig_input(c), out)
            runs.append(out.calculation_duration)
        times.append(statistics.median(runs))
    return times


def stats(xs):
    s = sorted(xs)

    def pct(p):
        return s[min(len(s) - 1, int(round(p / 100.0 * (len(s) - 1))))]

    return {"median": pct(50), "p90": pct(90), "p99": pct(99), "max": s[-1], "mean": statistics.fmean(s)}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=4242)
    ap.add_argument("--repeats", type=int, default=21)
    ap.add_argument("--write-cases", metavar="PATH",
                    help="only write the cases file (for instruction counting) and exit")
    ap.add_argument("--ruckig-loop", metavar="PATH",
                    help="only call ruckig's calculate --repeats times per case of PATH and exit")
    args = ap.parse_args()

    if args.ruckig_loop:
        cases = json.loads(Path(args.ruckig_loop).read_text())["cases"]
        inputs = [pc.ruckig_input(c) for c in cases]
        otg = Ruckig(3)
        traj = pc.Trajectory(3)
        for inp in inputs:
            for _ in range(args.repeats):
                otg.calculate(inp, traj)
        return 0

    cases = gen_cases(args.cases, args.seed)
    if args.write_cases:
        Path(args.write_cases).write_text(json.dumps({"cases": cases}))
        return 0
    tmp = Path(tempfile.mkdtemp(prefix="profile_bench_"))
    path = tmp / "cases.json"
    path.write_text(json.dumps({"cases": cases}))

    rk = ruckig_times(cases, args.repeats)
    env = dict(os.environ, PROFILE_BENCH_CASES=str(path))
    proc = subprocess.run(["cargo", "bench", "-q", "-p", "pcr-planner", "--bench", "profiler"],
                          cwd=ROOT, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        print(proc.stderr)
        return 1
    line = next(ln for ln in proc.stdout.splitlines() if ln.startswith("PCR_BENCH_JSON "))
    ours = json.loads(line.split(" ", 1)[1])["times_us"]
    path.unlink()
    tmp.rmdir()

    print(f"{len(cases)} random 3-DoF time-synchronised cases (seed {args.seed}), "
          f"per-case median of {args.repeats} runs, microseconds")
    print(f"{'':14s} {'median':>8s} {'p90':>8s} {'p99':>8s} {'worst':>8s} {'mean':>8s}")
    for name, xs in (("ruckig 0.19.4", rk), ("pcr-planner", ours)):
        s = stats(xs)
        print(f"{name:14s} {s['median']:8.2f} {s['p90']:8.2f} {s['p99']:8.2f} {s['max']:8.2f} {s['mean']:8.2f}")
    ratio = [o / max(r, 1e-9) for o, r in zip(ours, rk)]
    print(f"ratio pcr/ruckig per case: median {statistics.median(ratio):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
