#!/usr/bin/env python3
"""Which part of the plant's friction biases the plays found beside it (docs/residuals.md,
"Where it fails today").

The sweep's case backlash+friction-1x (plays 3 / 4 / 3 steps, joints 2 N mm, supports 0.04 N)
recorded again with its friction split, each variant through `pcr residuals`:

  both        the sweep's case
  joints      the joints' couples only (supports off)
  supports    the supports' forces only (joints off)
  stiff       both, the elements ten times stiffer while stuck (the plant's tanh law squeezed
              towards the library's elastic-perfectly plastic one)
  supports10  the supports alone at ten times their force (0.4 N)
  supports-noplay  the supports alone, no play (the plays' truth is then none)

For each, the plays and the friction found, each with its error from the truth in stated
errors. The plant files are the sweep's (scripts/validate_residuals.py's plant_text) with the
[friction] keys changed; recordings and results go to OUT/<variant>/ (reused when the plant
file is unchanged). --reduced records the reduced sweep's smaller recordings.

Usage: python3 scripts/friction_split.py [--reduced] [--jobs N] [--out DIR] [--pcr PATH]
                                         [--only a,b]
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import json
import os
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import validate_residuals as vr  # noqa: E402

ROOT = vr.ROOT

# variant: ([friction] key = value edits, the truth of the parameters it should find, whether
# the plant has the case's plays)
VARIANTS = {
    "both": ({}, {"joint torque": 2.0, "support force": 0.04}, True),
    "joints": ({"supports": "false"}, {"joint torque": 2.0, "support force": 0.0}, True),
    "supports": ({"joints": "false"}, {"joint torque": 0.0, "support force": 0.04}, True),
    "stiff": ({"joint_stick_stiffness_n_mm_per_rad": "1.0e5",
               "support_stick_stiffness_n_per_mm": "200.0"},
              {"joint torque": 2.0, "support force": 0.04}, True),
    "supports10": ({"joints": "false", "support_force_n": "0.4"},
                   {"joint torque": 0.0, "support force": 0.4}, True),
    "supports-noplay": ({"joints": "false"}, {"joint torque": 0.0, "support force": 0.04},
                        False),
}
PLAYS = {"play motor 1": 3.0, "play motor 2": 4.0, "play motor 3": 3.0}


def plant(variant: str) -> str:
    case = vr.Case("backlash+friction-1x", [("backlash", 1.0), ("friction", 1.0)], "pair")
    text = vr.plant_text(case, {"backlash": 1.0, "friction": 1.0}, True)
    edits, _, plays = VARIANTS[variant]
    for key, value in edits.items():
        text = vr.set_key(text, "friction", key, value)
    if not plays:
        text = vr.set_key(text, "stepper", "backlash", "false")
    return text.replace("validation case backlash+friction-1x",
                        "friction split %s (scripts/friction_split.py)" % variant)


def run(cmd: list, log: Path) -> None:
    with open(log, "a") as f:
        f.write("$ " + " ".join(cmd) + "\n")
        f.flush()
        rc = subprocess.run(cmd, cwd=ROOT, stdout=f, stderr=subprocess.STDOUT).returncode
    if rc != 0:
        raise RuntimeError("%s failed (exit %d): %s" % (cmd[1], rc, vr.last_lines(log)))


def variant(name: str, args) -> dict:
    d = Path(args.out) / name
    d.mkdir(parents=True, exist_ok=True)
    text = plant(name)
    size = "reduced" if args.reduced else "full"
    stamp = size + "\n" + text
    log = d / "run.log"
    res = d / "res.json"
    if not ((d / "plant.stamp").exists() and (d / "plant.stamp").read_text() == stamp
            and res.exists()):
        (d / "plant.stamp").unlink(missing_ok=True)
        log.write_text("")
        (d / "plant.toml").write_text(text)
        for rec in ("cal", "holdout"):
            opts, offset, _ = vr.RECORDINGS[size][rec]
            run([args.pcr, "experiment", "calibration", "--config", "configs/sim.toml",
                 "--plant", str(d / "plant.toml"), "--plant-seed", str(1 + offset)] + opts +
                ["--out", str(d / (rec + ".csv"))], log)
        run([args.pcr, "residuals", "--robot", "configs/robot.toml", "--data", str(d / "cal.csv"),
             "--holdout", str(d / "holdout.csv"), "--json", str(res)], log)
        (d / "plant.stamp").write_text(stamp)
    return json.loads(res.read_text())


def row(name: str, result: dict) -> str:
    _, params, plays = VARIANTS[name]
    truth = dict(PLAYS if plays else {}, **params)
    found = {}
    for e in result.get("effects", []):
        for p in e.get("params", []):
            if p["name"] in truth and p["name"] not in found:
                found[p["name"]] = (p["value"], p.get("std"))
    cells = []
    for key, t in truth.items():
        if key not in found:
            cells.append("%s: not found" % key)
            continue
        v, s = found[key]
        z = " (%+.1f std)" % ((v - t) / s) if s else ""
        cells.append("%s %.4g +- %s%s" % (key, v, "%.2g" % s if s else "-", z))
    names = ", ".join(e["name"] for e in result.get("effects", [])) or "nothing"
    return "| %s | %s | %s |" % (name, names, "; ".join(cells))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reduced", action="store_true", help="the reduced sweep's recordings")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", default=str(ROOT / "out/friction-split"))
    ap.add_argument("--pcr", default=None, help="default: the release build, made first")
    ap.add_argument("--only", default=None, help="comma-separated variants (default: all)")
    args = ap.parse_args()
    names = list(VARIANTS)
    if args.only:
        names = [n.strip() for n in args.only.split(",") if n.strip()]
        unknown = [n for n in names if n not in VARIANTS]
        if unknown:
            print("error: --only: unknown variant(s) %s; known: %s"
                  % (", ".join(unknown), ", ".join(VARIANTS)), file=sys.stderr)
            return 2
    if args.jobs < 1:
        print("error: --jobs must be at least 1", file=sys.stderr)
        return 2
    if args.pcr is None:
        if subprocess.run(["cargo", "build", "--release", "-q", "-p", "pcr"], cwd=ROOT).returncode:
            print("error: the release build of pcr failed (give --pcr PATH to use another)",
                  file=sys.stderr)
            return 1
        target = Path(os.environ.get("CARGO_TARGET_DIR") or ROOT / "target")
        args.pcr = str(target / "release/pcr")
    with cf.ThreadPoolExecutor(max_workers=args.jobs) as pool:
        futures = {n: pool.submit(variant, n, args) for n in names}
        results = {}
        failed = False
        for n in names:
            try:
                results[n] = futures[n].result()
            except (RuntimeError, OSError, json.JSONDecodeError) as e:
                print("error: variant %s: %s" % (n, e), file=sys.stderr)
                failed = True
    print("| variant | named | found (error from the truth in stated errors) |")
    print("|---|---|---|")
    for n in names:
        if n in results:
            print(row(n, results[n]))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
