"""Batch IK from Python against the Rust loop (BENCHMARKS.md, "Python bindings").

Draws N poses (default 100 000; seeded) over the nominal robot's workspace and beyond it (a
mix of solved and refused rows), writes them for the Rust loop
(`offline/examples/ik_rows.rs`: the same `ik_row` per pose, timed in Rust), times
`pcr.Robot.nominal().ik(poses)` (the whole call: input conversion, the loop, output arrays,
status words) and prints both per pose and their ratio. Median of RUNS alternating runs.

Usage: .venv/bin/python python/bench/bench_ik.py [N] [RUNS]
(build first: .venv/bin/pip install ./python; cargo build --release -p pcr-offline --example ik_rows)
"""

from __future__ import annotations

import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import pcr

REPO = Path(__file__).resolve().parents[2]


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 100_000
    runs = int(sys.argv[2]) if len(sys.argv) > 2 else 7
    rng = np.random.default_rng(7)
    poses = np.column_stack(
        [rng.uniform(-70, 70, n), rng.uniform(-70, 70, n), rng.uniform(-12, 12, n)]
    )
    robot = pcr.Robot.nominal()
    exe = REPO / "target" / "release" / "examples" / "ik_rows"
    if not exe.is_file():
        sys.exit(f"{exe} missing: cargo build --release -p pcr-offline --example ik_rows")
    with tempfile.TemporaryDirectory() as d:
        f = Path(d) / "poses.csv"
        np.savetxt(f, poses, delimiter=",", header="x_mm,y_mm,phi_deg", comments="", fmt="%.17g")
        py_ns, rust_ns = [], []
        for _ in range(runs):
            t = time.perf_counter()
            r = robot.ik(poses)
            py_ns.append((time.perf_counter() - t) * 1e9 / n)
            out = subprocess.run([str(exe), str(f), "1"], capture_output=True, text=True, check=True).stdout
            rust_ns.append(float(re.search(r"median ([0-9.]+) ns/pose", out).group(1)))
    ok = int((r.status == "ok").sum())
    py, rust = float(np.median(py_ns)), float(np.median(rust_ns))
    print(f"{n} poses ({ok} ok, {n - ok} refused), {runs} runs, medians:")
    print(f"  python  pcr.Robot.ik: {py:8.1f} ns/pose  ({py * n / 1e6:.1f} ms per call)")
    print(f"  rust    ik_row loop : {rust:8.1f} ns/pose")
    print(f"  ratio python / rust : {py / rust:.3f}")


if __name__ == "__main__":
    main()
