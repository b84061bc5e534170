#!/usr/bin/env python3
"""Scale-invariance check: the case sets of profile_compare.py with every length multiplied by
K and every time by TK (p*K, v*K/TK, a*K/TK^2, j*K/TK^3, durations*TK), compared with ruckig
with the same checks. Not part of check_profile.sh: at extreme scales ruckig itself sometimes
returns clearly non-time-optimal profiles (long plateaus at a tiny acceleration), which then show
up here as "faster than ruckig" while our profile respects every limit.

Usage: profile_scaled.py K TK [SEED] [--show ID]
"""

import json
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import profile_compare as pc  # noqa: E402


def scaled_cases(k, tk, seed):
    out = []
    for cs in pc.generate(seed, 2.0).values():
        for c in cs:
            c = json.loads(json.dumps(c))
            for st in ("current", "target"):
                c[st]["p"] = [x * k for x in c[st]["p"]]
                c[st]["v"] = [x * k / tk for x in c[st]["v"]]
                c[st]["a"] = [x * k / tk ** 2 for x in c[st]["a"]]
            lim = c["limits"]
            for key, pw in (("vmax", 1), ("vmin", 1), ("amax", 2), ("amin", 2), ("jmax", 3)):
                lim[key] = [x * k / tk ** pw for x in lim[key]]
            if "minimum_duration" in c:
                c["minimum_duration"] *= tk
            out.append(c)
    return out


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    k, tk = float(args[0]), float(args[1])
    seed = int(args[2]) if len(args) > 2 else 20261122
    cases = []
    for c in scaled_cases(k, tk, seed):
        r = pc.solve_ruckig(c)
        if r is not None:
            cases.append((c, r))
    tmp = Path(tempfile.mkdtemp(prefix="profile_scaled_"))
    (tmp / "c.json").write_text(json.dumps({"cases": [c for c, _ in cases]}))
    subprocess.run(pc.find_binary() + ["profile", "--cases", str(tmp / "c.json"), "--out", str(tmp / "a.json")],
                   check=True, cwd=pc.ROOT)
    ans = {a["id"]: a for a in json.loads((tmp / "a.json").read_text())["answers"]}
    fails = [(c["id"], f) for c, r in cases for f in [pc.check(c, r, ans[c["id"]])] if f]
    print(f"lengths x{k}, times x{tk}, seed {seed}: {len(cases) - len(fails)}/{len(cases)} passed")
    for cid, f in fails:
        print(f"  FAIL {cid}: {'; '.join(f)}")
    return 0 if not fails else 1


if __name__ == "__main__":
    sys.exit(main())
