#!/usr/bin/env python3
"""Validation sweep of `pcr residuals`: the analysis as a measuring instrument.

Runs the residual analysis on recordings of the simulated plant with known effects at known
strengths and reports how well it finds them (docs/residuals.md, "Validation"). Called by
scripts/validate_residuals.sh, which documents the options; standard library only.

For every case (one or more effects at given strengths, or an effect outside the library) and
plant seed it
  1. writes the plant file (configs/plant-ideal.toml, capture noise on, the 10 ms capture
     latency configs/sim.toml declares, the case's effects) and its noise-free twin;
  2. records, once (cached in the output folder, re-recorded only when the plant file changes),
     a calibration recording and a holdout with `pcr experiment calibration`, and the holdout
     again on the noise-free twin;
  3. writes the second timing convention of both recordings (a logger of the position reached:
     each row's q is the command of the row before, no `command_delay_s` declaration);
  4. runs `pcr residuals --data cal.csv --holdout holdout.csv --json ...` on both conventions,
     pinned to one core (`taskset -c`), timing wall and cpu (and once more on two cores for the
     chain's convention of the first seed); a run over the time budget is timed again at the
     end, alone, pinned, with the other cores idle, ALONE_RUNS times, and judged on the median
     of those; with several jobs the two-core runs are made at the end too, one at a time;
  5. compares what was named with the truth: per parameter the estimate, its stated standard
     error, |est - truth| / std; the held-out RMS after the analysis against the floor, the
     held-out RMS of the noisy holdout against its noise-free twin (the capture noise as it fell
     on those rows).
Then it writes runs.csv, validation.json and validation.md (aggregate per case, then per run)
and, with --check, exits 1 when a rule fails (printing every failure).
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import csv
import json
import math
import os
import queue
import re
import statistics
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# ---------------------------------------------------------------------------------------------
# The plant's effects, their strengths and the parameters the analysis should find.

# The robot's numbers the truth of creep needs (configs/robot.toml): EI, l_C, tendon offset a.
EI_N_MM2 = 6.5e4
L_C_MM = 125.0
A_MM = 7.0
# Creep: the plant's elongation e relaxes to c x tension with time constant T, tension =
# EI phi_b / (l_C a), phi_b = (dl - e) / a: the elongation feeds back on the tension that makes
# it. With k = EI / (l_C a^2) (tension per mm of effective displacement), e relaxes to
# c k / (1 + c k) of the commanded displacement, with time constant T / (1 + c k): those are the
# library's gain (elongation per mm of displacement) and time constant.
CREEP_K_N_PER_MM = EI_N_MM2 / (L_C_MM * A_MM * A_MM)
CREEP_T_S = 20.0


def creep_truth(compliance):
    ck = compliance * CREEP_K_N_PER_MM
    g = ck / (1.0 + ck)
    return {"gain leg 1": g, "gain leg 2": g, "gain leg 3": g,
            "time constant": CREEP_T_S / (1.0 + ck)}

# Physical effects of the residual library and its recalibrations (which absorb, not explain).
LIBRARY = ["backlash", "latency", "creep", "drift", "joint_springs", "external_load", "frame",
           "periodic", "friction", "friction_supports"]
RECALIBRATIONS = ["geometry", "tendon_map"]
# Library effects the calibration's own parameters can take in whole: a rigid error of the
# capture frame is, to within the noise, a change of the legs' base angles and lengths within
# the drawing's tolerance. Not named and the held-out error within --max-after-floor of the
# floor, such an effect is "absorbed by the calibration" (reported, not a failure): there is
# nothing left to explain, and a model without a prior on the geometry cannot tell the two apart.
ABSORBABLE = {"frame"}


def arr(v):
    return "[" + ", ".join(repr(float(x)) for x in v) + "]"


def fmt_num(x: float) -> str:
    return f"{x:.4g}"


@dataclass
class Effect:
    """An effect the plant can hold: its edits of the plant file and its truth per factor of
    today's test strength."""

    name: str           # the library's name (or the out-of-vocabulary effect's)
    test: str           # today's test strength, in words
    edits: object       # factor -> [(section, key, value)]
    truth: object       # factor -> {parameter: value} (library effects)
    describe: object    # factor -> the strength in words
    in_library: bool = True


def _backlash(f):
    return [("stepper", "backlash", "true"),
            ("stepper", "backlash_steps", arr([3 * f, 4 * f, 3 * f]))]


def _periodic(f):
    return [("stepper", "periodic",
             "[{ motor = 3, period_steps = 64.0, amplitude_steps = %r, phase_deg = 30.0 }]"
             % float(f))]


EFFECTS = {
    "backlash": Effect(
        "backlash", "plays 3 / 4 / 3 steps", _backlash,
        lambda f: {"play motor 1": 3 * f, "play motor 2": 4 * f, "play motor 3": 3 * f},
        lambda f: "plays %s / %s / %s steps" % (fmt_num(3 * f), fmt_num(4 * f), fmt_num(3 * f))),
    "latency": Effect(
        "latency", "40 ms beyond the declared capture latency",
        # configs/sim.toml declares the plant's 10 ms capture latency: the rest is latency.
        lambda f: [("capture", "latency_s", repr(0.01 + 0.04 * f))],
        lambda f: {"latency": 0.04 * f},
        lambda f: "%s ms" % fmt_num(40 * f)),
    "creep": Effect(
        "creep", "2e-3 mm/N, T = 20 s",
        lambda f: [("creep", "enabled", "true"), ("creep", "compliance_mm_per_n", repr(2e-3 * f)),
                   ("creep", "time_constant_s", "20.0")],
        lambda f: creep_truth(2e-3 * f),
        lambda f: "%s mm/N, T 20 s" % fmt_num(2e-3 * f)),
    "drift": Effect(
        "drift", "3e-4 mm/s on leg 2",
        lambda f: [("drift", "enabled", "true"), ("drift", "rate_mm_per_s", arr([0, 3e-4 * f, 0]))],
        lambda f: {"rate leg 1": 0.0, "rate leg 2": 3e-4 * f, "rate leg 3": 0.0},
        lambda f: "%s mm/s on leg 2" % fmt_num(3e-4 * f)),
    "joint_springs": Effect(
        "joint_springs", "k_M 300, k_P 200 N mm/rad",
        lambda f: [("mechanics", "k_m_n_mm_per_rad", repr(300.0 * f)),
                   ("mechanics", "k_p_n_mm_per_rad", repr(200.0 * f))],
        lambda f: {"k_M": 300.0 * f, "k_P": 200.0 * f},
        lambda f: "k_M %s, k_P %s N mm/rad" % (fmt_num(300 * f), fmt_num(200 * f))),
    "external_load": Effect(
        "external_load", "(0.4, -0.3) N",
        lambda f: [("external_wrench", "fx_n", repr(0.4 * f)),
                   ("external_wrench", "fy_n", repr(-0.3 * f))],
        lambda f: {"force x": 0.4 * f, "force y": -0.3 * f, "couple": 0.0},
        lambda f: "(%s, %s) N" % (fmt_num(0.4 * f), fmt_num(-0.3 * f))),
    "frame": Effect(
        "frame", "0.8 mm / 0.3 deg",
        # The correction that undoes a registration error (e_dx, e_dy, e_dphi) of the plant's
        # identity capture frame is (e_dx, e_dy, e_dphi): docs/residuals.md, "Validation".
        lambda f: [("capture", "registration_error_dx_mm", repr(0.8 * f)),
                   ("capture", "registration_error_dphi_deg", repr(0.3 * f))],
        lambda f: {"dx": 0.8 * f, "dy": 0.0, "dphi": 0.3 * f},
        lambda f: "%s mm / %s deg" % (fmt_num(0.8 * f), fmt_num(0.3 * f))),
    "periodic": Effect(
        "periodic", "motor 3, 1 step, period 64 steps",
        _periodic,
        lambda f: {"motor": 3, "period": 64.0, "amplitude": 1.0 * f, "phase": 30.0},
        lambda f: "motor 3, %s steps, period 64" % fmt_num(f)),
    "friction": Effect(
        "friction", "the prototype's: joints 2 N mm, supports 0.04 N",
        lambda f: [("friction", "joints", "true"), ("friction", "joint_torque_n_mm", repr(2.0 * f)),
                   ("friction", "supports", "true"), ("friction", "support_force_n", repr(0.04 * f))],
        lambda f: {"joint torque": 2.0 * f, "support force": 0.04 * f},
        lambda f: "joints %s N mm, supports %s N" % (fmt_num(2 * f), fmt_num(0.04 * f))),
    # The supports alone (the joints turn freely): a hysteresis of the pose at each reversal
    # that a gear play imitates (docs/residuals.md, "Friction"). The library names it friction,
    # the joints' limit held at zero.
    "friction_supports": Effect(
        "friction", "the prototype's supports alone: 0.04 N",
        lambda f: [("friction", "joints", "false"),
                   ("friction", "supports", "true"), ("friction", "support_force_n", repr(0.04 * f))],
        lambda f: {"joint torque": 0.0, "support force": 0.04 * f},
        lambda f: "supports alone %s N" % fmt_num(0.04 * f)),
    # Outside the library.
    "cross_coupling": Effect(
        "cross_coupling", "15 %",
        lambda f: [("tendon_map", "cross_coupling", repr(f))],
        lambda f: {}, lambda f: "%s %%" % fmt_num(100 * f), in_library=False),
    "thermal": Effect(
        "thermal", "0.03 mm, period 600 s",
        lambda f: [("thermal", "enabled", "true"), ("thermal", "amplitude_mm", arr([f, f, f])),
                   ("thermal", "period_s", "600.0"), ("thermal", "phase_deg", "0.0")],
        lambda f: {}, lambda f: "%s mm on every tendon, period 600 s" % fmt_num(f),
        in_library=False),
}

# Strengths per library effect (factors of today's test value): one below detection, the test
# value, 3x and 10x. Where the plant cannot hold 10x in its working range the sweep steps down
# through FALLBACK and says which it used.
# Known failures: per case, the rule today's analysis does not hold there (a part of the failure's
# text) and why (docs/residuals.md, "Validation"). --check reports such failures as expected
# instead of failing on them, and says so when the case passes; every other rule of the case, and
# every other case, must hold.
EXPECTED_FAILURES: dict = {}


def unexpected_failures(r):
    """A run's failures that EXPECTED_FAILURES does not expect."""
    rule = EXPECTED_FAILURES.get(r["case"], (None,))[0]
    return [f for f in r["failures"] if rule is None or rule not in f]

LOW = {"backlash": 0.1, "latency": 0.1, "creep": 0.1, "drift": 0.1, "joint_springs": 0.1,
       "external_load": 0.1, "frame": 0.1, "periodic": 0.1, "friction": 0.1,
       "friction_supports": 0.1}
FALLBACK = [7.0, 5.0, 4.0]


@dataclass
class Case:
    """One plant: effects at factors of their test strength (library effects) or at their own
    strengths (outside the library)."""

    id: str
    effects: list           # [(effect name, factor)]
    kind: str               # single, drift-long, pair, triple, outside, clean
    fallback: list = field(default_factory=list)  # factors to try when the first fails
    full_size: bool = False  # the full-size recordings even in --reduced
    cal_options: list = field(default_factory=list)  # added to the calibration recording's

    def library_effects(self):
        return [(e, f) for e, f in self.effects if EFFECTS[e].in_library]

    def outside_effects(self):
        return [(e, f) for e, f in self.effects if not EFFECTS[e].in_library]


def factor_name(f):
    return ("%gx" % f).replace(".", "p") if f != int(f) else "%dx" % f


def single(effect, f, fallback=()):
    return Case("%s-%s" % (effect, factor_name(f)), [(effect, f)], "single", list(fallback))


def cases(reduced: bool) -> list:
    out = [Case("clean", [], "clean")]
    for e in LIBRARY:
        factors = [1.0, 3.0] if reduced else [LOW[e], 1.0, 3.0, 10.0]
        for f in factors:
            out.append(single(e, f, FALLBACK if f == 10.0 else ()))
    # Drift at 0.002 mm/s over a recording of more than 700 s: the calibration set at phi = 0
    # and +10 deg with 2 s of settling (712 s). Over the whole set (881 s) the leg-2 tendon's
    # elongation turns the platform past -28 deg on the phi = -10 deg poses and the plant
    # faults at t = 588 s (no equilibrium in the assembly mode).
    out.append(Case("drift-0.002", [("drift", 0.002 / 3e-4)], "drift-long", full_size=True,
                    cal_options=["--phis-deg", "0,10", "--settle", "2.0"]))
    pairs = [("backlash", "latency"), ("joint_springs", "external_load"), ("drift", "creep"),
             ("backlash", "friction"), ("backlash", "external_load"), ("periodic", "frame"),
             ("backlash", "friction_supports")]
    triples = [("backlash", "latency", "creep"), ("external_load", "drift", "periodic"),
               ("joint_springs", "frame", "backlash")]
    if reduced:
        pairs = pairs[:1]
        triples = triples[:1]
    # At 3x, a drift with creep or with a load takes the plant out of its working range over
    # the calibration recording: then 2x.
    for p in pairs:
        for f in ([1.0] if reduced else [1.0, 3.0]):
            out.append(Case("+".join(p) + "-" + factor_name(f), [(e, f) for e in p], "pair",
                            [2.0] if f == 3.0 else []))
    for t in triples:
        for f in ([1.0] if reduced else [1.0, 3.0]):
            out.append(Case("+".join(t) + "-" + factor_name(f), [(e, f) for e in t], "triple",
                            [2.0] if f == 3.0 else []))
    if reduced:
        # What the loaded models' calibration columns and the re-linearised kineto-static fit
        # hold: springs strong enough to bend the first calibration by millimetres, and springs
        # beside a load at 3x.
        out.append(single("joint_springs", 10.0, FALLBACK))
        out.append(Case("joint_springs+external_load-3x",
                        [("joint_springs", 3.0), ("external_load", 3.0)], "pair", [2.0]))
    for c in ([0.07] if reduced else [0.03, 0.07, 0.15]):
        out.append(Case("cross_coupling-%g" % (100 * c), [("cross_coupling", c)], "outside"))
    for a in ([0.03] if reduced else [0.01, 0.03, 0.1]):
        out.append(Case("thermal-%gmm" % a, [("thermal", a)], "outside"))
    return out


# ---------------------------------------------------------------------------------------------
# Plant files.

def set_key(text: str, section: str, key: str, value: str) -> str:
    """Sets `key = value` in `[section]` of a TOML text (as scripts/bench_residuals.sh's
    set_key); fails when the key is not there."""
    out, cur, done = [], None, False
    for line in text.splitlines(keepends=True):
        s = line.strip()
        if s.startswith("["):
            cur = s.split()[0]
        if cur == "[%s]" % section and re.match(r"^%s\s*=" % re.escape(key), s):
            line = "%s = %s\n" % (key, value)
            done = True
        out.append(line)
    if not done:
        raise KeyError("no key %s in [%s] of the plant file" % (key, section))
    return "".join(out)


def plant_text(case: Case, factors: dict, noise: bool) -> str:
    text = (ROOT / "configs/plant-ideal.toml").read_text()
    text = set_key(text, "capture", "noise", "true" if noise else "false")
    # configs/sim.toml declares a 10 ms capture latency (its recordings align each measurement
    # with its capture time): the plant has it, so that only the case's effects are left.
    text = set_key(text, "capture", "latency_s", "0.01")
    for e, _ in case.effects:
        for sec, key, val in EFFECTS[e].edits(factors[e]):
            text = set_key(text, sec, key, val)
    return text.replace('name = "ideal plant"', 'name = "validation case %s"' % case.id)


# ---------------------------------------------------------------------------------------------
# Recordings and the second timing convention.

RECORDINGS = {
    # name: (options of `pcr experiment calibration`, plant-seed offset, noise)
    "full": {
        "cal": ([], 0, True),
        "holdout": (["--points", "8", "--test-per-group", "3", "--seed", "2"], 6, True),
        "twin": (["--points", "8", "--test-per-group", "3", "--seed", "2"], 6, False),
    },
    "reduced": {
        "cal": (["--points", "6", "--test-per-group", "2"], 0, True),
        "holdout": (["--points", "4", "--test-per-group", "1", "--seed", "2"], 6, True),
        "twin": (["--points", "4", "--test-per-group", "1", "--seed", "2"], 6, False),
    },
}


def position_reached(src: Path, dst: Path) -> None:
    """The recording as a logger of the position reached writes it: each row's q1..q3 are the
    command of the row before (the one its pose answers in this chain), the first row keeps its
    own, and no `command_delay_s` is declared (D = 0). As `as_position_reached` in
    tests/tests/residuals_plant.rs."""
    lines = src.read_text().splitlines()
    meta = [ln for ln in lines if ln.startswith("#")]
    body = [ln for ln in lines if not ln.startswith("#")]
    meta = [ln for ln in meta if not re.match(r"^#\s*command_delay_s\s*=", ln)]
    header = body[0].split(",")
    qi = [header.index(c) for c in ("q1", "q2", "q3")]
    rows = [ln.split(",") for ln in body[1:] if ln]
    out = [rows[0]]
    for k in range(1, len(rows)):
        r = list(rows[k])
        for i in qi:
            r[i] = rows[k - 1][i]
        out.append(r)
    dst.write_text("\n".join(meta + [body[0]] + [",".join(r) for r in out]) + "\n")


def data_rows(path: Path) -> int:
    with open(path) as f:
        return sum(1 for ln in f if not ln.startswith("#")) - 1


def floor_rms(noisy: Path, twin: Path) -> float | None:
    """Held-out floor: RMS over the holdout's rows of the noisy measured position against the
    noise-free twin's, mm."""
    def read(p):
        rows = {}
        with open(p) as f:
            r = csv.DictReader(ln for ln in f if not ln.startswith("#"))
            for row in r:
                if row.get("x_mm") and row.get("y_mm"):
                    rows[row["t_s"]] = (float(row["x_mm"]), float(row["y_mm"]))
        return rows
    a, b = read(noisy), read(twin)
    s2, n = 0.0, 0
    for t, (x, y) in a.items():
        if t in b:
            s2 += (x - b[t][0]) ** 2 + (y - b[t][1]) ** 2
            n += 1
    return math.sqrt(s2 / n) if n else None


# ---------------------------------------------------------------------------------------------
# Running.

class Cores:
    """One core per running job (taskset), handed out and taken back."""

    def __init__(self, jobs: int):
        n = os.cpu_count() or 1
        # One job: core 1 (the one-core figure of BENCHMARKS.md); more: spread.
        order = [1 % n] + [c for c in range(n) if c != 1 % n]
        self.q = queue.Queue()
        for k in range(jobs):
            self.q.put(order[k % n])

    def take(self) -> int:
        return self.q.get()

    def give(self, c: int) -> None:
        self.q.put(c)


def run_timed(cmd, cwd, log: Path, core: int | None):
    """Runs `cmd` (pinned to `core` when given); returns (exit code, wall s, cpu s, peak MiB)."""
    if core is not None:
        cmd = ["taskset", "-c", str(core)] + cmd
    t0 = time.perf_counter()
    with open(log, "a") as lf:
        lf.write("$ " + " ".join(str(c) for c in cmd) + "\n")
        lf.flush()
        p = subprocess.Popen(cmd, cwd=cwd, stdout=lf, stderr=subprocess.STDOUT)
        _, status, ru = os.wait4(p.pid, 0)
        p.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - t0
    return p.returncode, wall, ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024.0


def last_lines(log: Path, n=2) -> str:
    try:
        lines = [ln for ln in log.read_text().splitlines()
                 if ln.strip() and not ln.startswith("$ ")]
    except OSError:
        return ""
    return " | ".join(lines[-n:])


class Sweep:
    def __init__(self, args):
        self.a = args
        self.out = Path(args.out).resolve()
        self.pcr = str(Path(args.pcr).resolve())
        self.recorder = str(Path(args.recorder or args.pcr).resolve())
        self.size = "reduced" if args.reduced else "full"
        self.cores = Cores(args.jobs)
        self.lock = threading.Lock()
        self.factors = {}   # case id -> {effect: factor used}
        self.notes = {}     # case id -> why the factor differs from the case's
        self.two_core_cmds = {}  # (case id, seed) -> the chain analysis, timed on two cores last
        self.done = 0

    def say(self, msg):
        with self.lock:
            print(msg, flush=True)

    def case_dir(self, case):
        return self.out / "cases" / case.id

    def record(self, case, seed, factors, core):
        """Records the case's three recordings for `seed` (cached); returns an error text or
        None."""
        d = self.case_dir(case) / ("s%d" % seed)
        d.mkdir(parents=True, exist_ok=True)
        size = "full" if case.full_size else self.size
        noisy, quiet = plant_text(case, factors, True), plant_text(case, factors, False)
        stamp = "%s %s\n%s\n%s" % (size, " ".join(case.cal_options), noisy, quiet)
        if (d / "plant.stamp").exists() and (d / "plant.stamp").read_text() == stamp and all(
                (d / (n + ".csv")).exists() for n in ("cal", "holdout", "twin")):
            return None
        for n in ("cal", "holdout", "twin", "cal-reached", "holdout-reached"):
            (d / (n + ".csv")).unlink(missing_ok=True)
        (d / "plant.stamp").unlink(missing_ok=True)
        (d / "plant.toml").write_text(noisy)
        (d / "plant-twin.toml").write_text(quiet)
        log = d / "record.log"
        log.write_text("")
        for name, (opts, offset, noise) in RECORDINGS[size].items():
            plant = d / ("plant.toml" if noise else "plant-twin.toml")
            cmd = [self.recorder, "experiment", "calibration", "--config", "configs/sim.toml",
                   "--plant", str(plant), "--plant-seed", str(seed + offset)] + opts + (
                   case.cal_options if name == "cal" else []) + [
                   "--out", str(d / (name + ".part.csv"))]
            rc, wall, _, _ = run_timed(cmd, ROOT, log, core)
            if rc != 0:
                return "recording %s failed: %s" % (name, last_lines(log))
            text = log.read_text()
            if re.search(r"(?i)\bfault|no equilibrium|cannot follow", text):
                return "the plant faulted while recording %s: %s" % (
                    name, re.findall(r"(?i).*(?:fault|no equilibrium|cannot follow).*", text)[0][:200])
            os.replace(d / (name + ".part.csv"), d / (name + ".csv"))
        (d / "plant.stamp").write_text(stamp)
        return None

    def analyse(self, case, seed, core, two_cores: bool, alone: bool = False):
        """Analyses the case's recordings for `seed` in both conventions (pinned to `core`);
        with `alone`, the timings of the first pass are read back and a run over the time
        budget is timed again, pinned, while nothing else runs (`Sweep.run`)."""
        d = self.case_dir(case) / ("s%d" % seed)
        for n in ("cal", "holdout"):
            if not (d / (n + "-reached.csv")).exists():
                position_reached(d / (n + ".csv"), d / (n + "-reached.csv"))
        floor = floor_rms(d / "holdout.csv", d / "twin.csv")
        runs = []
        for conv, suffix in (("chain", ""), ("reached", "-reached")):
            js = d / ("res-%s.json" % conv)
            log = d / ("residuals-%s.log" % conv)
            log.write_text("")
            cmd = [self.pcr, "residuals", "--robot", str(ROOT / "configs/robot.toml"),
                   "--data", str(d / ("cal%s.csv" % suffix)),
                   "--holdout", str(d / ("holdout%s.csv" % suffix)), "--json", str(js)]
            if (self.a.reuse or alone) and js.exists() and (d / ("time-%s.json" % conv)).exists():
                t = json.loads((d / ("time-%s.json" % conv)).read_text())
                if alone and over_budget(t, self.a) and t.get("cpu_alone_s") is None:
                    if time_alone(cmd, d, log, core, t):
                        (d / ("time-%s.json" % conv)).write_text(json.dumps(t))
            else:
                js.unlink(missing_ok=True)
                rc, wall, cpu, peak = run_timed(cmd, d, log, core)
                t = {"rc": rc, "wall_s": wall, "cpu_s": cpu, "peak_mib": peak, "wall2_s": None}
                # With one job, nothing else runs: the two-core time is taken here; with more,
                # after every analysis, one case at a time (`Sweep.time_two_cores`).
                if rc == 0 and two_cores and conv == "chain" and self.a.jobs == 1:
                    rc2, wall2, _, _ = run_timed(cmd, d, log, None)
                    t["wall2_s"] = wall2 if rc2 == 0 else None
                (d / ("time-%s.json" % conv)).write_text(json.dumps(t))
            if two_cores and conv == "chain" and self.a.jobs > 1 and t["rc"] == 0:
                with self.lock:
                    self.two_core_cmds[(case.id, seed)] = (cmd, d, log)
            res = json.loads(js.read_text()) if t["rc"] == 0 and js.exists() else None
            runs.append(evaluate(case, seed, conv, self.factors[case.id], res, t, floor,
                                 [data_rows(d / ("cal%s.csv" % suffix)),
                                  data_rows(d / ("holdout%s.csv" % suffix))],
                                 last_lines(log) if res is None else "", self.a))
        return runs

    def task(self, case, seed):
        core = self.cores.take()
        try:
            if seed == self.seeds[0] and case.id not in self.factors:
                tried = []
                options = [dict(case.effects)] + [
                    {e: (f2 if f == case.effects[0][1] else f) for e, f in case.effects}
                    for f2 in case.fallback]
                # The strength an earlier run settled on (the plant does not change its mind).
                settled = self.case_dir(case) / "strength.json"
                if settled.exists():
                    st = json.loads(settled.read_text())
                    if st["options"] == options and st["factors"] in options:
                        options = [st["factors"]]
                        tried = st["tried"]
                for factors in options:
                    err = self.record(case, seed, factors, core)
                    if err is None:
                        settled.write_text(json.dumps({"options": [dict(case.effects)] + [
                            {e: (f2 if f == case.effects[0][1] else f) for e, f in case.effects}
                            for f2 in case.fallback], "factors": factors, "tried": tried}))
                        with self.lock:
                            self.factors[case.id] = factors
                            if tried:
                                self.notes[case.id] = "; ".join(tried) + "; used %s" % (
                                    "/".join(sorted({"%gx" % f for f in factors.values()})))
                        break
                    tried.append("%s: %s" % ("/".join(sorted({"%gx" % f for f in factors.values()})),
                                             err))
                else:
                    with self.lock:
                        self.notes[case.id] = "; ".join(tried)
                    self.say("!! %s: no strength the plant holds: %s" % (case.id, "; ".join(tried)))
                    return []
            elif case.id not in self.factors:
                return []
            else:
                err = self.record(case, seed, self.factors[case.id], core)
                if err:
                    self.say("!! %s seed %d: %s" % (case.id, seed, err))
                    return [failed_run(case, seed, conv, self.factors[case.id], err)
                            for conv in ("chain", "reached")]
            runs = self.analyse(case, seed, core, self.a.two_cores and seed == self.seeds[0])
            with self.lock:
                self.done += 1
            for r in runs:
                self.say("%-44s s%d %-7s %-6s %5.1f s  %s" % (
                    case.id, seed, r["convention"], "ok" if not r["failures"] else "FAIL",
                    r["wall_s"] or 0.0, r["summary"]))
            return runs
        finally:
            self.cores.give(core)

    def run(self, case_list):
        self.seeds = self.a.seeds
        runs = []
        with cf.ThreadPoolExecutor(max_workers=self.a.jobs) as pool:
            # The first seed first: it settles the strength of cases the plant may not hold.
            for seeds in (self.seeds[:1], self.seeds[1:]):
                futs = [pool.submit(self.task, c, s) for c in case_list for s in seeds]
                for f in futs:
                    runs.extend(f.result())
        if self.a.time_budget_s > 0:
            runs = self.retime_alone(case_list, runs)
        if self.two_core_cmds:
            runs = self.time_two_cores(runs)
        return runs

    def time_two_cores(self, runs):
        """Times the chain convention of each case's first seed on every core (unpinned), one
        case at a time, after the sweep's analyses: beside another job, as it was timed before,
        the second core was the other job's. With --reuse nothing is timed: the times stored
        stand."""
        todo = []
        for (cid, seed), (cmd, d, log) in self.two_core_cmds.items():
            t = json.loads((d / "time-chain.json").read_text())
            if not self.a.reuse and (t.get("wall2_s") is None or not t.get("wall2_alone")):
                todo.append((cid, seed, cmd, d, log, t))
        if todo:
            self.say("timing %d case(s) on two cores, one at a time" % len(todo))
        for cid, seed, cmd, d, log, t in todo:
            rc, wall2, _, _ = run_timed(cmd, d, log, None)
            t["wall2_s"], t["wall2_alone"] = (wall2 if rc == 0 else None), True
            (d / "time-chain.json").write_text(json.dumps(t))
        walls = {(cid, seed): json.loads((d / "time-chain.json").read_text()).get("wall2_s")
                 for (cid, seed), (_, d, _) in self.two_core_cmds.items()}
        for r in runs:
            if r["convention"] == "chain" and (r["case"], r["seed"]) in walls:
                r["wall2_s"] = walls[(r["case"], r["seed"])]
        return runs

    def retime_alone(self, case_list, runs):
        """Times the runs that went over the budget again, one at a time, pinned to one core
        with the other cores idle, ALONE_RUNS times: two analyses at a time share the caches and
        the memory bus (20-30 % on one case), the budget is the time of one core, and one timing
        on this shared machine says little (the same analysis, alone and pinned, took 8.95 to
        10.62 s in four runs within two minutes). The figures are reported; the time rule reads
        their median."""
        over = [(r["case"], r["seed"]) for r in runs
                if r["cpu_s"] is not None and r["cpu_s"] > self.a.time_budget_s]
        over = list(dict.fromkeys(over))
        if not over:
            return runs
        self.say("timing %d case(s) over %g s again, one at a time, %d times each" % (
            len(over), self.a.time_budget_s, ALONE_RUNS))
        by_id = {c.id: c for c in case_list}
        core = Cores(1).take()
        redone = {}
        for cid, seed in over:
            for r in self.analyse(by_id[cid], seed, core, False, alone=True):
                redone[(cid, seed, r["convention"])] = r
                self.say("%-44s s%d %-7s %-6s %s" % (
                    cid, seed, r["convention"], "ok" if not r["failures"] else "FAIL",
                    "alone: %.1f s cpu%s" % (r["cpu_alone_s"], alone_runs(r["cpu_alone_runs_s"]))
                    if r.get("cpu_alone_s") is not None
                    else "within the budget in the sweep: not timed again"))
        return [redone.get((r["case"], r["seed"], r["convention"]), r) for r in runs]


# ---------------------------------------------------------------------------------------------
# Comparing with the truth.

def norm_periodic(amp, phase):
    """(A, phase) and (-A, phase + 180) are the same term: positive amplitude, phase in
    (-180, 180]."""
    if amp < 0:
        amp, phase = -amp, phase + 180.0
    phase = (phase + 180.0) % 360.0 - 180.0
    return amp, phase


def wrap180(x):
    return (x + 180.0) % 360.0 - 180.0


def failed_run(case, seed, conv, factors, err):
    return {"case": case.id, "kind": case.kind, "seed": seed, "convention": conv,
            "truth": truth_text(case, factors), "named": [], "recalibrations": [],
            "params": [], "after_mm": None, "before_mm": None, "floor_mm": None,
            "after_floor": None, "noise_floor_mm": None, "verdict": None, "wall_s": None,
            "cpu_s": None, "wall2_s": None, "cpu_alone_s": None, "peak_mib": None,
            "rows": [None, None],
            "failures": ["error: " + err], "summary": "error: " + err, "detected": {},
            "factors": factors}


def truth_text(case, factors):
    if not case.effects:
        return "noise only"
    return "; ".join("%s %s" % (e, EFFECTS[e].describe(factors[e])) for e, _ in case.effects)


# Times a run over the time budget is timed again alone (`Sweep.retime_alone`).
ALONE_RUNS = 3


def time_alone(cmd, cwd, log, core, t) -> bool:
    """Times `cmd` ALONE_RUNS times pinned to `core` and writes into the run's times `t` the
    cpu times (`cpu_alone_runs_s`) and their median (`cpu_alone_s`, what `judged_cpu` reads),
    and the median wall time; False (and `t` as it was) where a run fails."""
    timed = [run_timed(cmd, cwd, log, core) for _ in range(ALONE_RUNS)]
    if any(rc != 0 for rc, _, _, _ in timed):
        return False
    cpus = [cpu for _, _, cpu, _ in timed]
    t["cpu_alone_runs_s"] = cpus
    t["cpu_alone_s"] = statistics.median(cpus)
    t["wall_alone_s"] = statistics.median(w for _, w, _, _ in timed)
    return True


def alone_runs(cpus) -> str:
    """', the median of a, b, c' for the timings alone of a run (none from an earlier sweep
    that timed a run alone once)."""
    return ", the median of %s" % ", ".join("%.1f" % c for c in cpus) if cpus else ""


def judged_cpu(t):
    """The cpu time on one core a run is judged on: the median of the times it took alone where
    it was timed again alone (`Sweep.retime_alone`), else its time in the sweep (None without
    one)."""
    cpu = t.get("cpu_alone_s")
    return t.get("cpu_s") if cpu is None else cpu


def over_budget(t, args) -> bool:
    """Whether a run's judged cpu time (`judged_cpu`) is over the time budget."""
    cpu = judged_cpu(t)
    return args.time_budget_s > 0 and cpu is not None and cpu > args.time_budget_s


def evaluate(case, seed, conv, factors, res, t, floor, rows, err, args):
    run = failed_run(case, seed, conv, factors, err or "analysis failed")
    run.update({"wall_s": t["wall_s"], "cpu_s": t["cpu_s"], "wall2_s": t.get("wall2_s"),
                "cpu_alone_s": t.get("cpu_alone_s"),
                "cpu_alone_runs_s": t.get("cpu_alone_runs_s") or [],
                "peak_mib": t["peak_mib"], "rows": rows, "floor_mm": floor})
    if res is None:
        return run
    named = [e["name"] for e in res.get("effects", [])]
    physical = [n for n in named if n not in RECALIBRATIONS]
    run["named"] = physical
    run["recalibrations"] = [n for n in named if n in RECALIBRATIONS]
    run["verdict"] = res.get("verdict")
    after = (res.get("after") or {}).get("position_rms_mm")
    run["after_mm"] = after
    run["before_mm"] = (res.get("before") or {}).get("position_rms_mm")
    noise = res.get("noise")
    run["noise_floor_mm"] = math.hypot(noise[0], noise[1]) if noise else None
    run["after_floor"] = after / floor if after is not None and floor else None
    failures = []
    lib = case.library_effects()
    truth_names = {EFFECTS[e].name for e, _ in lib}
    for e, _ in lib:
        f = factors[e]
        found = EFFECTS[e].name in physical
        run["detected"][e] = found
        at_test = f >= 1.0 - 1e-9
        if not found:
            if e in ABSORBABLE and run["after_floor"] is not None and \
                    run["after_floor"] <= args.max_after_floor:
                run.setdefault("absorbed", []).append(e)
            elif at_test:
                failures.append("missed %s" % e)
            continue
        for p in compare_params(e, f, res, factors):
            run["params"].append(p)
            if at_test and (p["z"] is None or p["z"] > args.max_z):
                failures.append("%s %s %s" % (
                    e, p["name"], "off by %.1f std" % p["z"] if p["z"] is not None else
                    ("no stated std" if p.get("est") is not None else "not reported")))
    extra = sorted({n for n in physical if n not in truth_names})
    if extra:
        if case.kind in ("outside",):
            failures.append("named outside the vocabulary: %s" % ", ".join(extra))
        else:
            failures.append("named, not in the data: %s" % ", ".join(extra))
    all_in_library = not case.outside_effects()
    at_test = all(factors[e] >= 1.0 - 1e-9 for e, _ in lib)
    if all_in_library and at_test and run["after_floor"] is not None and \
            run["after_floor"] > args.max_after_floor:
        failures.append("after/floor %.2f" % run["after_floor"])
    # The time on one core: the cpu time of the pinned run (its wall time also counts the
    # other jobs of a shared machine), timed again alone where it went over
    # (`Sweep.retime_alone`: the median of ALONE_RUNS), for the full-size recordings.
    if over_budget(t, args) and (case.full_size or args.size == "full"):
        if t.get("cpu_alone_s") is not None:
            failures.append("%.1f s cpu on one core (alone%s; %.1f s in the sweep)" % (
                t["cpu_alone_s"], alone_runs(t.get("cpu_alone_runs_s") or []), t["cpu_s"]))
        else:
            failures.append("%.1f s cpu on one core" % t["cpu_s"])
    run["failures"] = failures
    run["summary"] = "%s; named %s%s%s; after/floor %s" % (
        run["verdict"], ", ".join(physical) or "nothing",
        (" (absorbed by the calibration: %s)" % ", ".join(run["absorbed"])) if run.get("absorbed") else "",
        (" (+%s)" % ", ".join(run["recalibrations"])) if run["recalibrations"] else "",
        "%.2f" % run["after_floor"] if run["after_floor"] else "?") + (
        " -- " + "; ".join(failures) if failures else "")
    return run


def compare_params(e, f, res, factors=None):
    truth = EFFECTS[e].truth(f)
    if e == "drift" and factors and "creep" in factors:
        # With creep, a tendon that lengthens slackens, and its creep gives back c k / (1 + c k)
        # of it: the elongation grows at rate / (1 + c k) (the creep's feedback, above).
        ck = 2e-3 * factors["creep"] * CREEP_K_N_PER_MM
        truth = {k: v / (1.0 + ck) for k, v in truth.items()}
    entries = [x for x in res.get("effects", []) if x["name"] == EFFECTS[e].name]
    params = {}
    if e == "periodic":
        # The term on the true motor with the largest amplitude (periodic may be named twice).
        best = None
        for x in entries:
            ps = {p["name"]: p for p in x.get("params", [])}
            if "amplitude" in ps and (best is None or abs(ps["amplitude"]["value"]) >
                                      abs(best["amplitude"]["value"])):
                if ps.get("motor", {}).get("value") == truth["motor"] or best is None:
                    best = ps
        params = best or {}
    else:
        for x in entries:
            for p in x.get("params", []):
                params[p["name"]] = p
    out = []
    for name, tv in truth.items():
        p = params.get(name)
        row = {"effect": e, "name": name, "truth": tv, "est": None, "std": None, "z": None}
        if p is not None:
            est, std = p.get("value"), p.get("std")
            if e == "periodic" and name in ("amplitude", "phase"):
                a, ph = norm_periodic(params["amplitude"]["value"], params["phase"]["value"])
                est = a if name == "amplitude" else ph
            row["est"], row["std"] = est, std
            diff = wrap180(est - tv) if (e == "periodic" and name == "phase") else est - tv
            row["diff"] = diff
            if name in ("motor", "period"):
                # Discrete choices: right or wrong.
                row["z"] = 0.0 if abs(diff) < 0.5 else float("inf")
            elif std:
                row["z"] = abs(diff) / std
            elif diff == 0.0:
                # A limit held at its bound (zero, no error) where the truth is that bound.
                row["z"] = 0.0
        out.append(row)
    return out


# ---------------------------------------------------------------------------------------------
# Tables.

def fmt(x, spec="%.3g"):
    if x is None:
        return "-"
    if isinstance(x, float) and math.isinf(x):
        return "inf"
    return spec % x


def aggregate(case_list, runs, factors, notes):
    by_case = {}
    for r in runs:
        by_case.setdefault(r["case"], []).append(r)
    aggs = []
    for c in case_list:
        rs = by_case.get(c.id, [])
        if not rs:
            aggs.append({"case": c.id, "kind": c.kind, "n": 0, "truth": truth_text(c, factors.get(
                c.id, dict(c.effects))), "note": notes.get(c.id, "not run")})
            continue
        n = len(rs)
        det = {e: sum(1 for r in rs if r["detected"].get(e)) for e, _ in c.library_effects()}
        absorbed = {e: sum(1 for r in rs if e in r.get("absorbed", [])) for e, _ in c.library_effects()}
        false = {}
        for r in rs:
            truth_names = {EFFECTS[e].name for e, _ in c.library_effects()}
            for nme in set(r["named"]) - truth_names:
                false[nme] = false.get(nme, 0) + 1
        params = {}
        for r in rs:
            for p in r["params"]:
                params.setdefault((p["effect"], p["name"]), []).append((r["convention"], p))
        pstats = []
        for (e, name), cps in params.items():
            ps = [p for _, p in cps]
            # Bias and spread over the seeds of the chain's convention (the other convention
            # repeats them when the two agree: see `conventions_agree`).
            diffs = [p["diff"] for c, p in cps if c == "chain" and p.get("diff") is not None]
            cover = sum(1 for p in ps if p["z"] is not None and p["z"] <= 2.0)
            stds = [p["std"] for p in ps if p["std"]]
            pstats.append({"effect": e, "param": name, "truth": ps[0]["truth"],
                           "bias": statistics.mean(diffs) if diffs else None,
                           "spread": statistics.stdev(diffs) if len(diffs) > 1 else None,
                           "stated_std": statistics.median(stds) if stds else None,
                           "covered": cover, "n": len(ps)})
        ratios = [r["after_floor"] for r in rs if r["after_floor"] is not None]
        walls = [r["wall_s"] for r in rs if r["wall_s"] is not None]
        cpus = [r["cpu_s"] for r in rs if r["cpu_s"] is not None]
        # The time each run is judged on: alone where it was timed again alone.
        judged = [judged_cpu(r) for r in rs if r["cpu_s"] is not None]
        wall2 = [r["wall2_s"] for r in rs if r.get("wall2_s") is not None]
        by_seed = {}
        for r in rs:
            by_seed.setdefault(r["seed"], {})[r["convention"]] = r
        agree, worst = 0, 0.0
        for v in by_seed.values():
            if len(v) != 2 or sorted(v["chain"]["named"]) != sorted(v["reached"]["named"]):
                continue
            agree += 1
            pr = {(p["effect"], p["name"]): p for p in v["reached"]["params"]}
            for p in v["chain"]["params"]:
                q = pr.get((p["effect"], p["name"]))
                if q and p["est"] is not None and q["est"] is not None and p["std"]:
                    worst = max(worst, abs(p["est"] - q["est"]) / p["std"])
        aggs.append({
            "case": c.id, "kind": c.kind, "n": n, "truth": rs[0]["truth"],
            "factors": rs[0]["factors"], "detected": det, "absorbed": absorbed, "false": false, "params": pstats,
            "after_floor_median": statistics.median(ratios) if ratios else None,
            "after_floor_max": max(ratios) if ratios else None,
            "wall_max_s": max(walls) if walls else None, "cpu_max_s": max(cpus) if cpus else None,
            "cpu_judged_max_s": max(judged) if judged else None,
            "wall2_max_s": max(wall2) if wall2 else None,
            "rows": rs[0]["rows"],
            "conventions_agree": "%d/%d" % (agree, len(by_seed)) + (
                " (params within %.2f std)" % worst if worst else ""),
            "passed": sum(1 for r in rs if not r["failures"]),
            "verdicts": sorted({str(r["verdict"]) for r in rs}),
            "note": notes.get(c.id, ""),
        })
    return aggs


def detection_limits(case_list, aggs):
    """Per library effect: the smallest strength found in every run, with every larger one
    found in every run too."""
    out = {}
    ag = {a["case"]: a for a in aggs}
    for e in LIBRARY:
        singles = [c for c in case_list if c.kind == "single" and c.effects[0][0] == e]
        pts = []
        for c in singles:
            a = ag.get(c.id)
            if not a or not a["n"]:
                continue
            f = a["factors"][e]
            pts.append((f, a["detected"][e] == a["n"], "%d/%d" % (a["detected"][e], a["n"])))
        pts.sort()
        limit = None
        for k in range(len(pts)):
            if all(ok for _, ok, _ in pts[k:]):
                limit = pts[k][0]
                break
        out[e] = {"limit_factor": limit,
                  "limit": EFFECTS[e].describe(limit) if limit is not None else None,
                  "points": [(f, d) for f, _, d in pts]}
    return out


def markdown(case_list, runs, aggs, limits, args, meta):
    L = []
    L.append("# Validation sweep of `pcr residuals`\n")
    L.append("%s sweep, %s; seeds %s; both timing conventions (chain: `command_delay_s` declared;"
             " reached: q of the row before, no declaration); pcr `%s`; %s.\n" % (
                 meta["size"], meta["created"], ", ".join(map(str, args.seeds)), meta["pcr"],
                 meta["commit"]))
    L.append("Floor: the held-out RMS of the noisy holdout against its noise-free twin (the "
             "capture noise as it fell on the held-out rows). Coverage: runs with |est - truth| "
             "<= 2 stated std. Times: `pcr residuals` (calibration + analysis) pinned to one core "
             "(`taskset`), wall, beside another job when the sweep runs two at a time; [cpu alone]: a run "
             "over the time budget timed again pinned with the other cores idle, %d times, their "
             "median (the time rule reads it); two cores: the chain convention of the first seed, unpinned, alone (after "
             "the other analyses when the sweep runs two at a time). Bias and "
             "spread of a parameter: over the seeds, chain convention; conventions agree: seeds "
             "where both name the same effects, and the largest difference of a parameter "
             "between them in its stated std.\n" % ALONE_RUNS)
    L.append("## Detection limit per effect\n")
    L.append("| effect | today's test strength | found in every run from | runs found per strength |")
    L.append("|---|---|---|---|")
    for e, v in limits.items():
        L.append("| %s | %s | %s | %s |" % (
            e, EFFECTS[e].test,
            ("%s (%gx)" % (v["limit"], v["limit_factor"])) if v["limit"] else "not at any strength",
            ", ".join("%gx: %s" % (f, d) for f, d in v["points"])))
    L.append("")
    L.append("## Per case (aggregated over seeds and both conventions)\n")
    L.append("| case | truth | runs passing | detected | named, not in the data | parameter: bias +- spread "
             "over seeds (median stated std) [runs covered] | after/floor median (max) | verdicts | conventions agree | "
             "max wall 1 core / cpu (s) [cpu alone] | wall 2 cores (s) | note |")
    L.append("|---|---|---:|---|---|---|---|---|---|---|---|---|")
    for a in aggs:
        if not a["n"]:
            L.append("| %s | %s | 0 | | | | | | | | | %s |" % (a["case"], a["truth"], a["note"]))
            continue
        det = ", ".join("%s %d/%d%s" % (e, k, a["n"], (" (absorbed by the calibration %d/%d)" % (
            a["absorbed"][e], a["n"])) if a.get("absorbed", {}).get(e) else "")
            for e, k in a["detected"].items()) or "-"
        false = ", ".join("%s %d/%d" % (e, k, a["n"]) for e, k in sorted(a["false"].items())) or "-"
        ps = "<br>".join("%s %s: %s +- %s (%s) [%d/%d]" % (
            p["effect"], p["param"], fmt(p["bias"], "%+.3g"), fmt(p["spread"]), fmt(p["stated_std"]),
            p["covered"], p["n"]) for p in a["params"]) or "-"
        L.append("| %s | %s | %d/%d | %s | %s | %s | %s (%s) | %s | %s | %s / %s | %s | %s |" % (
            a["case"], a["truth"], a["passed"], a["n"], det, false, ps,
            fmt(a["after_floor_median"], "%.2f"), fmt(a["after_floor_max"], "%.2f"),
            ", ".join(a["verdicts"]), a["conventions_agree"], fmt(a["wall_max_s"], "%.1f"),
            fmt(a["cpu_max_s"], "%.1f") + (
                " [%s]" % fmt(a["cpu_judged_max_s"], "%.1f")
                if a.get("cpu_judged_max_s") != a["cpu_max_s"] else ""),
            fmt(a["wall2_max_s"], "%.1f"), a["note"]))
    L.append("")
    L.append("## Per run\n")
    L.append("| case | seed | convention | rows (cal + holdout) | named (+ recalibrations) | parameters: est +- std "
             "(truth) \\|est - truth\\|/std | before / after / floor (mm) | after/floor | verdict | "
             "wall / cpu 1 core (s) [cpu alone] | failures |")
    L.append("|---|---:|---|---|---|---|---|---:|---|---|---|")
    for r in runs:
        ps = "<br>".join("%s %s: %s +- %s (%s) %s" % (
            p["effect"], p["name"], fmt(p["est"], "%.4g"), fmt(p["std"], "%.2g"),
            fmt(p["truth"], "%.4g"), fmt(p["z"], "%.1f")) for p in r["params"]) or "-"
        named = ", ".join(r["named"]) or "nothing"
        if r["recalibrations"]:
            named += " (+ %s)" % ", ".join(r["recalibrations"])
        L.append("| %s | %d | %s | %s + %s | %s | %s | %s / %s / %s | %s | %s | %s / %s | %s |" % (
            r["case"], r["seed"], r["convention"], r["rows"][0], r["rows"][1], named, ps,
            fmt(r["before_mm"], "%.3f"), fmt(r["after_mm"], "%.3f"), fmt(r["floor_mm"], "%.4f"),
            fmt(r["after_floor"], "%.2f"), r["verdict"], fmt(r["wall_s"], "%.1f"),
            fmt(r["cpu_s"], "%.1f") + (
                " [%s]" % fmt(r["cpu_alone_s"], "%.1f") if r.get("cpu_alone_s") is not None else ""),
            "; ".join(r["failures"]) or "-"))
    L.append("")
    return "\n".join(L)


def write_csv(path, runs):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["case", "kind", "seed", "convention", "truth", "rows_cal", "rows_holdout",
                    "named", "recalibrations", "effect", "param", "truth_value", "estimate",
                    "std", "abs_err_over_std", "before_mm", "after_mm", "floor_mm",
                    "after_over_floor", "noise_floor_mm", "verdict", "wall_1core_s",
                    "cpu_1core_s", "wall_2cores_s", "cpu_1core_alone_s", "peak_mib", "failures"])
        for r in runs:
            base = [r["case"], r["kind"], r["seed"], r["convention"], r["truth"], r["rows"][0],
                    r["rows"][1], " ".join(r["named"]), " ".join(r["recalibrations"])]
            tail = [r["before_mm"], r["after_mm"], r["floor_mm"], r["after_floor"],
                    r["noise_floor_mm"], r["verdict"], r["wall_s"], r["cpu_s"], r["wall2_s"],
                    r.get("cpu_alone_s"), r["peak_mib"], "; ".join(r["failures"])]
            if not r["params"]:
                w.writerow(base + ["", "", "", "", "", ""] + tail)
            for p in r["params"]:
                w.writerow(base + [p["effect"], p["name"], p["truth"], p["est"], p["std"],
                                   p["z"]] + tail)


def git(*a):
    try:
        return subprocess.run(["git", *a], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "?"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pcr", default=str(ROOT / "target/release/pcr"))
    ap.add_argument("--recorder", help="the pcr that records (default --pcr)")
    ap.add_argument("--out")
    ap.add_argument("--reduced", action="store_true")
    ap.add_argument("--check", action="store_true")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--seeds", type=lambda s: [int(x) for x in s.split(",")])
    ap.add_argument("--only", help="regular expression on the case ids")
    ap.add_argument("--two-cores", dest="two_cores", action="store_true", default=None)
    ap.add_argument("--no-two-cores", dest="two_cores", action="store_false")
    ap.add_argument("--reuse", action="store_true",
                    help="reuse the analyses' JSON of an earlier run (report again)")
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    ap.add_argument("--max-z", type=float, default=3.0)
    ap.add_argument("--max-after-floor", type=float, default=1.5)
    ap.add_argument("--time-budget-s", type=float,
                    default=float(os.environ.get("PCR_VALIDATION_TIME_BUDGET_S", "10")))
    a = ap.parse_args(argv)
    a.size = "reduced" if a.reduced else "full"
    if a.seeds is None:
        a.seeds = [1] if a.reduced else [1, 2, 3]
    if a.two_cores is None:
        a.two_cores = not a.reduced
    if a.out is None:
        a.out = str(ROOT / ("out/validate-residuals" + ("-reduced" if a.reduced else "")))
    case_list = cases(a.reduced)
    if a.only:
        case_list = [c for c in case_list if re.search(a.only, c.id)]
    if a.list:
        for c in case_list:
            print("%-48s %-10s %s" % (c.id, c.kind, truth_text(c, dict(c.effects))))
        return 0
    Path(a.out).mkdir(parents=True, exist_ok=True)
    sweep = Sweep(a)
    t0 = time.time()
    print("validate_residuals: %d cases x %d seeds x 2 conventions, %s recordings, %d job(s) -> %s"
          % (len(case_list), len(a.seeds), sweep.size, a.jobs, sweep.out), flush=True)
    runs = sweep.run(case_list)
    aggs = aggregate(case_list, runs, sweep.factors, sweep.notes)
    limits = detection_limits(case_list, aggs)
    meta = {"size": sweep.size, "created": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "pcr": os.path.relpath(sweep.pcr, ROOT) if sweep.pcr.startswith(str(ROOT)) else sweep.pcr,
            "commit": "commit %s%s" % (git("rev-parse", "--short", "HEAD"),
                                       " (modified)" if git("status", "--porcelain", "--",
                                                            "residuals", "calibration",
                                                            "kinematics", "robot") else ""),
            "seconds": time.time() - t0}
    out = Path(a.out)
    (out / "validation.md").write_text(markdown(case_list, runs, aggs, limits, a, meta))
    (out / "validation.json").write_text(json.dumps(
        {"meta": meta, "limits": limits, "cases": aggs, "runs": runs}, indent=1, default=str))
    write_csv(out / "runs.csv", runs)
    expected = [r for r in runs if r["failures"] and not unexpected_failures(r)]
    failing = [r for r in runs if unexpected_failures(r)]
    passing_expected = sorted({r["case"] for r in runs if not r["failures"]} &
                              set(EXPECTED_FAILURES) - {r["case"] for r in expected})
    missing = [a_ for a_ in aggs if not a_["n"]]
    print("validate_residuals: %d runs in %.0f s, %d with a failed rule; tables in %s" % (
        len(runs), meta["seconds"], len(failing), out / "validation.md"))
    for e, v in limits.items():
        print("  detection limit %-14s %s" % (e, ("%s (%gx)" % (v["limit"], v["limit_factor"]))
                                              if v["limit"] else "none"))
    for r in expected:
        print("  expected failure: %s s%d %s: %s (%s)" % (
            r["case"], r["seed"], r["convention"], "; ".join(r["failures"]),
            EXPECTED_FAILURES[r["case"]][1]))
    for c in passing_expected:
        print("  %s holds every rule now: take it off EXPECTED_FAILURES" % c)
    if a.check:
        rules = {}
        for r in failing:
            for f in unexpected_failures(r):
                key = re.sub(r"[-+]?\d+(\.\d+)?", "#", f)
                rules.setdefault(key, []).append("%s s%d %s: %s" % (
                    r["case"], r["seed"], r["convention"], f))
        for c in missing:
            rules.setdefault("case not run", []).append("%s: %s" % (c["case"], c["note"]))
        if rules:
            print("\nvalidate_residuals --check: FAILED rules (%d runs of %d):" % (
                len(failing), len(runs)))
            for key, items in sorted(rules.items(), key=lambda kv: -len(kv[1])):
                print("  rule '%s': %d" % (key, len(items)))
                for it in items:
                    print("      " + it)
            return 1
        print("validate_residuals --check: every rule holds")
    return 0


if __name__ == "__main__":
    sys.exit(main())
