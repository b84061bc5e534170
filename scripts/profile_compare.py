#!/usr/bin/env python3
"""Compares `pcr profile` against the reference implementation ruckig (PyPI, 0.19.4).

Generates seeded random case sets, solves them with ruckig and with `pcr profile`, and checks
for every case: solved; duration equal to ruckig's within 1e-8 relative (never faster);
velocity/acceleration limits respected to 1e-9 relative at every 20 ms sample (after the brake
pre-trajectory, if any); final state reached to 1e-8 (relative to max(1, |value|), and for
velocity and acceleration also to the limit). Prints a summary per case set, the exact
pass rate and the failing case ids; exits non-zero on any failure.

Information only (not checked): for single-DoF position cases, the largest difference between
our and ruckig's sampled positions (the time-optimal trajectory is unique, so they coincide; for
synchronised DoFs the profiles legitimately differ).

Binary: $PCR_BIN if set, else `cargo run --release -q --bin pcr --`.
Usage: profile_compare.py [--seed N] [--scale K] [--keep DIR] [--only SET]
"""

import argparse
import json
import math
import os
import random
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path

import ruckig
from ruckig import ControlInterface, InputParameter, Result, Ruckig, Synchronization, Trajectory

ROOT = Path(__file__).resolve().parent.parent
DT = 0.02
DUR_TOL = 1e-8
LIM_TOL = 1e-9
FINAL_TOL = 1e-8


def rnd_limits(rng, dofs, asym):
    lim = {"vmax": [], "amax": [], "jmax": [], "vmin": [], "amin": []}
    for _ in range(dofs):
        vmax = rng.uniform(0.2, 3.0)
        amax = rng.uniform(0.2, 4.0)
        jmax = rng.uniform(0.5, 10.0)
        lim["vmax"].append(vmax)
        lim["amax"].append(amax)
        lim["jmax"].append(jmax)
        lim["vmin"].append(-vmax * (rng.uniform(0.3, 2.0) if asym else 1.0))
        lim["amin"].append(-amax * (rng.uniform(0.3, 2.0) if asym else 1.0))
    return lim


def rnd_state_inside(rng, lim, i, zero=False, pos_range=3.0):
    """A state within the limits that does not inevitably violate them."""
    p = rng.uniform(-pos_range, pos_range)
    if zero:
        return p, 0.0, 0.0
    j = lim["jmax"][i]
    for _ in range(100):
        v = rng.uniform(lim["vmin"][i], lim["vmax"][i])
        a = rng.uniform(lim["amin"][i], lim["amax"][i]) if rng.random() < 0.8 else 0.0
        v_at_a0 = v + a * abs(a) / (2 * j)
        if lim["vmin"][i] <= v_at_a0 <= lim["vmax"][i]:
            return p, v, a
    return p, 0.0, 0.0


def rnd_target(rng, lim, i, kind):
    p = rng.uniform(-3.0, 3.0)
    if kind == "rest":
        return p, 0.0, 0.0
    j = lim["jmax"][i]
    for _ in range(100):
        v = rng.uniform(lim["vmin"][i], lim["vmax"][i])
        a = rng.uniform(lim["amin"][i], lim["amax"][i]) if rng.random() < 0.6 else 0.0
        # Arrive from within the limits (ruckig rejects other targets).
        if lim["vmin"][i] <= v - a * abs(a) / (2 * j) <= lim["vmax"][i]:
            return p, v, a
    return p, 0.0, 0.0


def make_case(cid, dofs, cur, tgt, lim, ci="position", sync="time", min_dur=None):
    c = {
        "id": cid,
        "dofs": dofs,
        "control_interface": ci,
        "synchronization": sync,
        "current": {"p": [s[0] for s in cur], "v": [s[1] for s in cur], "a": [s[2] for s in cur]},
        "target": {"p": [s[0] for s in tgt], "v": [s[1] for s in tgt], "a": [s[2] for s in tgt]},
        "limits": lim,
    }
    if min_dur is not None:
        c["minimum_duration"] = min_dur
    return c


def generate(seed, scale):
    rng = random.Random(seed)
    sets = {}

    def n(k):
        return max(1, int(k * scale))

    sets["rest_to_rest"] = [
        make_case(f"rest-{k}", 1, [rnd_state_inside(rng, lim, 0, zero=True)],
                  [rnd_target(rng, lim, 0, "rest")], lim)
        for k in range(n(60)) for lim in [rnd_limits(rng, 1, False)]
    ]
    sets["arbitrary"] = [
        make_case(f"arb-{k}", 1, [rnd_state_inside(rng, lim, 0)], [rnd_target(rng, lim, 0, "any")], lim)
        for k in range(n(100)) for lim in [rnd_limits(rng, 1, False)]
    ]
    sets["multi_dof_time"] = [
        make_case(f"sync-{k}", 3, [rnd_state_inside(rng, lim, i) for i in range(3)],
                  [rnd_target(rng, lim, i, "any" if k % 2 else "rest") for i in range(3)], lim)
        for k in range(n(60)) for lim in [rnd_limits(rng, 3, False)]
    ]
    outside = []
    for k in range(n(40)):
        lim = rnd_limits(rng, 1, k % 2 == 1)
        v = rng.choice([1, -1]) * lim["vmax"][0] * rng.uniform(0.5, 2.0)
        a = rng.choice([1, -1]) * lim["amax"][0] * rng.uniform(0.0, 2.0)
        outside.append(make_case(f"brake-{k}", 1, [(rng.uniform(-3, 3), v, a)],
                                 [rnd_target(rng, lim, 0, "any" if k % 3 else "rest")], lim))
    sets["outside_limits"] = outside
    vel = []
    for k in range(n(40)):
        lim = rnd_limits(rng, 2, k % 2 == 1)
        cur = [(0.0, rng.uniform(-2, 2), rng.uniform(lim["amin"][i], lim["amax"][i])) for i in range(2)]
        tgt = [(0.0, rng.uniform(-2, 2), rng.uniform(lim["amin"][i], lim["amax"][i]) if k % 2 else 0.0)
               for i in range(2)]
        vel.append(make_case(f"vel-{k}", 2, cur, tgt, lim, ci="velocity"))
    sets["velocity_interface"] = vel
    sets["asymmetric"] = [
        make_case(f"asym-{k}", 2, [rnd_state_inside(rng, lim, i) for i in range(2)],
                  [rnd_target(rng, lim, i, "any") for i in range(2)], lim)
        for k in range(n(60)) for lim in [rnd_limits(rng, 2, True)]
    ]
    phase = []
    for k in range(n(20)):
        lim = rnd_limits(rng, 3, False)
        direction = [rng.uniform(-1, 1) for _ in range(3)]
        p0 = [rng.uniform(-1, 1) for _ in range(3)]
        dist = rng.uniform(0.1, 3.0)
        cur = [(p0[i], 0.0, 0.0) for i in range(3)]
        tgt = [(p0[i] + dist * direction[i], 0.0, 0.0) for i in range(3)]
        phase.append(make_case(f"phase-{k}", 3, cur, tgt, lim, sync="phase"))
    sets["phase_sync"] = phase
    sets["no_sync"] = [
        make_case(f"nosync-{k}", 3, [rnd_state_inside(rng, lim, i) for i in range(3)],
                  [rnd_target(rng, lim, i, "rest") for i in range(3)], lim, sync="none")
        for k in range(n(20)) for lim in [rnd_limits(rng, 3, False)]
    ]
    sets["no_sync"] += [
        make_case(f"nosync-mindur-{k}", 2, [rnd_state_inside(rng, lim, i) for i in range(2)],
                  [rnd_target(rng, lim, i, "rest") for i in range(2)], lim, sync="none",
                  min_dur=rng.uniform(0.5, 8.0))
        for k in range(n(5)) for lim in [rnd_limits(rng, 2, False)]
    ]
    sets["minimum_duration"] = [
        make_case(f"mindur-{k}", 2, [rnd_state_inside(rng, lim, i) for i in range(2)],
                  [rnd_target(rng, lim, i, "any") for i in range(2)], lim,
                  min_dur=rng.uniform(0.5, 8.0))
        for k in range(n(20)) for lim in [rnd_limits(rng, 2, False)]
    ]
    stress = []
    for k in range(n(80)):
        kind = k % 8
        dofs = 3
        lim = rnd_limits(rng, dofs, k % 3 == 0)
        if kind == 0:  # wide scale spread of the limits
            for i in range(dofs):
                lim["jmax"][i] *= rng.choice([0.01, 100.0])
                lim["amax"][i] *= rng.choice([0.1, 10.0])
                lim["amin"][i] = -lim["amax"][i]
        cur = [rnd_state_inside(rng, lim, i) for i in range(dofs)]
        tgt = [rnd_target(rng, lim, i, "any") for i in range(dofs)]
        if kind == 1:  # zero displacement, moving
            tgt = [(cur[i][0], tgt[i][1], tgt[i][2]) for i in range(dofs)]
        elif kind == 2:  # starting exactly on the limits
            cur = [(cur[i][0], lim["vmax"][i], 0.0) if i % 2 == 0 else
                   (cur[i][0], lim["vmin"][i] + lim["amax"][i] ** 2 / (2 * lim["jmax"][i]) * 0.0, 0.0)
                   for i in range(dofs)]
        elif kind == 3:  # long distances
            tgt = [(rng.uniform(-1000, 1000), t[1], t[2]) for t in tgt]
        elif kind == 4:  # tiny distances
            tgt = [(cur[i][0] + rng.uniform(-1e-4, 1e-4), 0.0, 0.0) for i in range(dofs)]
        elif kind == 5:  # several DoFs outside the limits
            cur = [(c[0], rng.choice([1, -1]) * lim["vmax"][i] * rng.uniform(0.5, 1.5),
                    rng.choice([1, -1]) * lim["amax"][i] * rng.uniform(0.0, 1.5)) for i, c in enumerate(cur)]
        elif kind == 6:  # phase synchronisation of a collinear moving state
            direction = [rng.uniform(-1, 1) for _ in range(dofs)]
            s = rng.uniform(0.1, 0.5)
            cur = [(0.0, s * direction[i] * 0.3, 0.0) for i in range(dofs)]
            tgt = [(2.0 * direction[i], 0.0, 0.0) for i in range(dofs)]
        sync = "phase" if kind == 6 else rng.choice(["time", "time", "phase"])
        stress.append(make_case(f"stress-{k}", dofs, cur, tgt, lim, sync=sync,
                                min_dur=rng.uniform(0.0, 3.0) if kind == 7 else None))
    for k in range(n(20)):
        lim = rnd_limits(rng, 2, True)
        cur = [(0.0, rng.uniform(-2, 2), rng.uniform(lim["amin"][i], lim["amax"][i])) for i in range(2)]
        tgt = [(0.0, rng.uniform(-2, 2), 0.0) for i in range(2)]
        stress.append(make_case(f"stress-vel-{k}", 2, cur, tgt, lim, ci="velocity",
                                sync=rng.choice(["time", "none", "phase"])))
    sets["stress"] = stress
    return sets


def ruckig_input(case):
    d = case["dofs"]
    inp = InputParameter(d)
    inp.current_position = case["current"]["p"]
    inp.current_velocity = case["current"]["v"]
    inp.current_acceleration = case["current"]["a"]
    inp.target_position = case["target"]["p"]
    inp.target_velocity = case["target"]["v"]
    inp.target_acceleration = case["target"]["a"]
    lim = case["limits"]
    inp.max_velocity = lim["vmax"]
    inp.min_velocity = lim["vmin"]
    inp.max_acceleration = lim["amax"]
    inp.min_acceleration = lim["amin"]
    inp.max_jerk = lim["jmax"]
    inp.control_interface = {"position": ControlInterface.Position,
                             "velocity": ControlInterface.Velocity}[case["control_interface"]]
    inp.synchronization = {"time": Synchronization.Time, "none": Synchronization.No,
                           "phase": Synchronization.Phase}[case["synchronization"]]
    if "minimum_duration" in case:
        inp.minimum_duration = case["minimum_duration"]
    return inp


def solve_ruckig(case):
    """(duration, final state, brake durations per DoF) or None if ruckig fails."""
    d = case["dofs"]
    otg = Ruckig(d)
    traj = Trajectory(d)
    try:
        res = otg.calculate(ruckig_input(case), traj)
    except Exception:  # ruckig.RuckigError: input rejected
        return None
    if res not in (Result.Working, Result.Finished):
        return None
    p, v, a = traj.at_time(traj.duration)
    brakes = [traj.profiles[0][i].brake.duration for i in range(d)]
    n = min(int(math.floor(traj.duration / DT)), 499) + 1
    samples = [list(traj.at_time(k * DT)[0]) for k in range(n)]
    return traj.duration, (list(p), list(v), list(a)), brakes, samples


def find_binary():
    env = os.environ.get("PCR_BIN")
    if env:
        return shlex.split(env)
    return ["cargo", "run", "--release", "-q", "--bin", "pcr", "--"]


def check(case, ref, ans):
    """List of failure reasons (empty if the case passes)."""
    if "error" in ans:
        return [f"error: {ans['error']}"]
    fails = []
    dur_ref, final_ref, brakes, _ = ref
    dur = ans["duration"]
    rel = (dur - dur_ref) / max(dur_ref, 1e-9)
    if abs(rel) > DUR_TOL and abs(dur - dur_ref) > 1e-12:
        fails.append(f"duration {dur!r} vs ruckig {dur_ref!r} (rel {rel:+.3e})")
    lim = case["limits"]
    vel_if = case["control_interface"] == "velocity"
    worst = 0.0
    # A brake pre-trajectory may leave the velocity outside the limits; it is exempt until it
    # first enters them.
    entered = [False] * case["dofs"]
    for k, (vs, as_) in enumerate(zip(ans["v"], ans["a"])):
        t = k * DT
        for i in range(case["dofs"]):
            if t < brakes[i] + 1e-9:
                continue
            a = as_[i]
            worst = max(worst, (a - lim["amax"][i]) / abs(lim["amax"][i]),
                        (lim["amin"][i] - a) / abs(lim["amin"][i]))
            if not vel_if:
                v = vs[i]
                if not entered[i]:
                    entered[i] = brakes[i] == 0.0 or lim["vmin"][i] <= v <= lim["vmax"][i]
                    if not entered[i]:
                        continue
                worst = max(worst, (v - lim["vmax"][i]) / abs(lim["vmax"][i]),
                            (lim["vmin"][i] - v) / abs(lim["vmin"][i]))
    if worst > LIM_TOL:
        fails.append(f"limits violated by {worst:.3e} relative")
    ferr = 0.0
    # Relative to max(1, |value|) for positions, to max(1, velocity / acceleration limit) for
    # velocities / accelerations (matters only for cases in scaled units).
    scales = {
        "p": [1.0] * case["dofs"],
        "v": [max(lim["vmax"][i], -lim["vmin"][i]) for i in range(case["dofs"])],
        "a": [max(lim["amax"][i], -lim["amin"][i]) for i in range(case["dofs"])],
    }
    for key, ref_vals in zip(("p", "v", "a"), final_ref):
        if vel_if and key == "p":
            continue
        for x, r, sc in zip(ans["final"][key], ref_vals, scales[key]):
            ferr = max(ferr, abs(x - r) / max(1.0, abs(r), sc))
    if ferr > FINAL_TOL:
        fails.append(f"final state off by {ferr:.3e}")
    return fails


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=20261122)
    ap.add_argument("--scale", type=float, default=1.0, help="multiplies the number of cases per set")
    ap.add_argument("--keep", type=Path, help="write cases.json / answers.json into this folder")
    ap.add_argument("--only", help="run only this case set")
    args = ap.parse_args()

    sets = generate(args.seed, args.scale)
    if args.only:
        sets = {args.only: sets[args.only]}
    refs = {}
    skipped = []
    cases = []
    for name, cs in sets.items():
        for c in cs:
            r = solve_ruckig(c)
            if r is None:
                skipped.append(c["id"])
                continue
            refs[c["id"]] = r
            cases.append((name, c))

    workdir = args.keep or Path(tempfile.mkdtemp(prefix="profile_compare_"))
    workdir.mkdir(parents=True, exist_ok=True)
    cases_path = workdir / "cases.json"
    out_path = workdir / "answers.json"
    cases_path.write_text(json.dumps({"cases": [c for _, c in cases]}))
    cmd = find_binary() + ["profile", "--cases", str(cases_path), "--out", str(out_path)]
    proc = subprocess.run(cmd, cwd=ROOT)
    if proc.returncode != 0:
        print(f"FAIL: `{' '.join(cmd)}` exited with {proc.returncode}")
        return 1
    answers = {a["id"]: a for a in json.loads(out_path.read_text())["answers"]}

    total_pass = 0
    failing = []
    print(f"{'case set':22s} {'cases':>6s} {'passed':>7s} {'max |dT|/T':>12s} {'max |dp| 1-DoF':>15s}")
    for name in sets:
        n = passed = 0
        worst_dt = 0.0
        worst_dp = -1.0
        for sname, c in cases:
            if sname != name:
                continue
            n += 1
            ans = answers.get(c["id"], {"error": "missing answer"})
            fails = check(c, refs[c["id"]], ans)
            if "duration" in ans:
                dref = refs[c["id"]][0]
                worst_dt = max(worst_dt, abs(ans["duration"] - dref) / max(dref, 1e-9))
                if c["dofs"] == 1 and c["control_interface"] == "position":
                    for row, ref_row in zip(ans["p"], refs[c["id"]][3]):
                        worst_dp = max(worst_dp, abs(row[0] - ref_row[0]))
            if fails:
                failing.append((c["id"], fails))
            else:
                passed += 1
        total_pass += passed
        dp = f"{worst_dp:15.3e}" if worst_dp >= 0 else f"{'-':>15s}"
        print(f"{name:22s} {n:6d} {passed:7d} {worst_dt:12.3e} {dp}")
    total = len(cases)
    rate = 100.0 * total_pass / max(total, 1)
    print(f"TOTAL: {total_pass}/{total} passed ({rate:.2f} %), "
          f"{len(skipped)} generated cases rejected by ruckig and skipped"
          + (f": {', '.join(skipped)}" if skipped else ""))
    for cid, fails in failing:
        print(f"  FAIL {cid}: {'; '.join(fails)}")
    if not args.keep:
        for p in (cases_path, out_path):
            p.unlink(missing_ok=True)
        workdir.rmdir()
    return 0 if not failing and total > 0 else 1


if __name__ == "__main__":
    sys.exit(main())
