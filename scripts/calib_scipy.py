#!/usr/bin/env python3
"""SciPy anchor for `pcr calibrate`: the paper's two-step calibration with all 13 Table I
functions, solved by scipy.optimize.least_squares (trust-region reflective, x_scale='jac'),
on the same recording, the same models, the same starting points and bounds as the Rust
implementation (pcr-calibration). Written independently from the description in
docs/calibration.md, not translated from the Rust code.

usage: calib_scipy.py REC.csv [--json OUT.json] [--params paper|extended]
                        [--reading symmetric|asymmetric]

--reading asymmetric fits each form with separate coefficients per bending direction sharing
the offset k0 (docs/calibration.md, "Table I in two readings").

The recording must carry a `set` column (train/test) so both tools use the same split.
Prints Table I (train/test RMS of M_i), the selected function, the platform errors after
step 2, and the time of the fits (file reading excluded).
"""
import argparse
import csv
import json
import math
import sys
import time

import numpy as np
from scipy.optimize import least_squares

KINDS = ["linear", "affine", "poly2", "poly3", "root2", "root3", "root4", "root5",
         "root6", "log", "log_affine", "lin_log", "poly_log"]
NCOEF = {"linear": 1, "affine": 2, "poly2": 3, "poly3": 4, "root2": 3, "root3": 4,
         "root4": 5, "root5": 6, "root6": 7, "log": 1, "log_affine": 2, "lin_log": 3,
         "poly_log": 4}
# Nominal robot (geometry.md).
NOMINAL = [dict(r_base=285.0, beta=210.0 + 120.0 * i, psi=120.0 * i, l_c=125.0, l_ce=36.0,
                l_st=164.0, r_p=59.0, theta_p=210.0 + 120.0 * i) for i in range(3)]
MM_PER_STEP = 2.0 * math.pi * 5.0 / 2048.0


def basis(kind, dl, reading="symmetric"):
    """Columns of the basis functions (odd extension), without the constant for the
    families without an offset. Asymmetric: the constant, then every other column once for
    dl >= 0 and once for dl < 0."""
    cols = odd_basis(kind, dl)
    if reading == "symmetric":
        return cols
    offset = kind not in ("linear", "log")
    shared, terms = (cols[:1], cols[1:]) if offset else ([], cols)
    pos = (np.asarray(dl) >= 0).astype(float)
    return shared + [c * pos for c in terms] + [c * (1.0 - pos) for c in terms]


def odd_basis(kind, dl):
    a = np.abs(dl)
    s = np.sign(dl)
    lg = s * np.log1p(a)
    root = lambda n: s * a ** (1.0 / n)
    one = np.ones_like(dl)
    if kind == "linear":
        return [dl]
    if kind == "affine":
        return [one, dl]
    if kind == "poly2":
        return [one, dl, dl * a]
    if kind == "poly3":
        return [one, dl, dl * a, dl ** 3]
    if kind.startswith("root"):
        n = int(kind[4:])
        return [one, dl] + [root(j) for j in range(2, n + 1)]
    if kind == "log":
        return [lg]
    if kind == "log_affine":
        return [one, lg]
    if kind == "lin_log":
        return [one, dl, lg]
    if kind == "poly_log":
        return [one, dl, dl * a, lg]
    raise ValueError(kind)


def kappa(kind, k, dl, reading="symmetric"):
    return sum(c * b for c, b in zip(k, basis(kind, dl, reading)))


def arc(theta):
    """(1 - cos t)/t and sin t / t, with series near 0."""
    t = np.asarray(theta, dtype=float)
    small = np.abs(t) < 1e-4
    ts = np.where(small, 1.0, t)
    f1 = np.where(small, t / 2.0 - t ** 3 / 24.0, (1.0 - np.cos(ts)) / ts)
    f2 = np.where(small, 1.0 - t ** 2 / 6.0, np.sin(ts) / ts)
    return f1, f2


def joint_m(leg, kap):
    theta = kap * leg["l_c"]
    f1, f2 = arc(theta)
    lx = leg["l_c"] * f1 + leg["l_ce"] * np.sin(theta)
    ly = leg["l_c"] * f2 + leg["l_ce"] * np.cos(theta)
    p = math.radians(leg["psi"])
    b = math.radians(leg["beta"])
    bx, by = leg["r_base"] * math.cos(b), leg["r_base"] * math.sin(b)
    return bx + math.cos(p) * lx - math.sin(p) * ly, by + math.sin(p) * lx + math.cos(p) * ly


def read_static(path):
    """Settled groups: (set, q[3], pose[3] or None, m[3][2] or None each)."""
    with open(path) as f:
        lines = [l for l in f if not l.startswith("#") and l.strip()]
    rows = list(csv.DictReader(lines))
    groups = []
    cur = None
    for r in rows:
        if r.get("settled") != "1":
            cur = None
            continue
        key = (r.get("pose_id"), r.get("rep"), r["q1"], r["q2"], r["q3"])
        if cur is None or cur["key"] != key:
            cur = dict(key=key, set=r.get("set"), q=[float(r["q1"]), float(r["q2"]), float(r["q3"])],
                       pose=[], m=[[], [], []])
            groups.append(cur)
        if r.get("x_mm") and r.get("y_mm") and r.get("phi_deg"):
            cur["pose"].append([float(r["x_mm"]), float(r["y_mm"]), float(r["phi_deg"])])
        for i in range(3):
            x, y = r.get(f"m{i+1}x_mm"), r.get(f"m{i+1}y_mm")
            if x and y:
                cur["m"][i].append([float(x), float(y)])
    out = []
    for g in groups:
        if g["set"] not in ("train", "test"):
            sys.exit(f"{path}: every settled row needs set = train/test for a comparable split")
        pose = None
        if g["pose"]:
            p = np.array(g["pose"])
            phi = math.degrees(math.atan2(np.sin(np.radians(p[:, 2])).sum(),
                                          np.cos(np.radians(p[:, 2])).sum()))
            pose = [p[:, 0].mean(), p[:, 1].mean(), phi]
        m = [np.array(v).mean(axis=0) if v else None for v in g["m"]]
        out.append(dict(set=g["set"], q=g["q"], pose=pose, m=m))
    return out


def theta_of_m(leg, m):
    """Bending angle whose M is closest to m: scan and Gauss-Newton (as the Rust start)."""
    ths = -math.pi + np.arange(181) * 2.0 * math.pi / 180.0
    best = None
    for th in ths:
        x, y = joint_m(leg, th / leg["l_c"])
        d = (x - m[0]) ** 2 + (y - m[1]) ** 2
        if best is None or d < best[1]:
            best = (th, d)
    th = best[0]
    for _ in range(30):
        h = 1e-7
        x, y = joint_m(leg, th / leg["l_c"])
        x2, y2 = joint_m(leg, (th + h) / leg["l_c"])
        dx, dy = (x2 - x) / h, (y2 - y) / h
        jj = dx * dx + dy * dy
        if jj == 0:
            break
        step = ((x - m[0]) * dx + (y - m[1]) * dy) / jj
        th -= step
        if abs(step) < 1e-14:
            break
    return th


def fit_leg(i, kind, train, test, extended, reading):
    nom = NOMINAL[i]
    names = ["psi", "l_c"] + (["r_base", "beta"] if extended else [])
    x0 = [nom[n] for n in names]
    lo = [nom["psi"] - 15.0, 0.7 * nom["l_c"]] + ([nom["r_base"] - 20.0, nom["beta"] - 10.0] if extended else [])
    hi = [nom["psi"] + 15.0, 1.3 * nom["l_c"]] + ([nom["r_base"] + 20.0, nom["beta"] + 10.0] if extended else [])
    dl = np.array([o[0] for o in train])
    mm = np.array([o[1] for o in train])
    kap = np.array([theta_of_m(nom, m) / nom["l_c"] for m in mm])
    A = np.column_stack(basis(kind, dl, reading))
    sc = np.linalg.norm(A, axis=0)
    sc[sc == 0.0] = 1.0
    coef = np.linalg.lstsq(A / sc, kap, rcond=None)[0] / sc
    x0 = np.array(x0 + list(coef))
    lo = np.array(lo + [-np.inf] * len(coef))
    hi = np.array(hi + [np.inf] * len(coef))

    def leg_of(x):
        leg = dict(nom)
        for n, v in zip(names, x):
            leg[n] = v
        return leg, x[len(names):]

    def res(x):
        leg, k = leg_of(x)
        mx, my = joint_m(leg, kappa(kind, k, dl, reading))
        return np.concatenate([mx - mm[:, 0], my - mm[:, 1]])

    r = least_squares(res, x0, bounds=(lo, hi), method="trf", x_scale="jac")
    leg, k = leg_of(r.x)

    def rms(obs):
        if not obs:
            return None
        d = np.array([o[0] for o in obs])
        m = np.array([o[1] for o in obs])
        mx, my = joint_m(leg, kappa(kind, k, d, reading))
        return float(np.sqrt(np.mean((mx - m[:, 0]) ** 2 + (my - m[:, 1]) ** 2)))

    return dict(leg=leg, k=k, train=rms(train), test=rms(test), nfev=int(r.nfev))


def fk(legs, kinds, ks, q, guess, reading):
    """Platform pose for motor positions q: Newton on the loop closures from `guess`."""
    m = []
    for i in range(3):
        kap = kappa(kinds, ks[i], np.array([q[i] * MM_PER_STEP]), reading)[0]
        m.append(joint_m(legs[i], kap))
    x = np.array([guess[0], guess[1], math.radians(guess[2])])
    for _ in range(30):
        h = np.zeros(3)
        A = np.zeros((3, 3))
        for i in range(3):
            tp = math.radians(legs[i]["theta_p"])
            pe = np.array([legs[i]["r_p"] * math.cos(tp), legs[i]["r_p"] * math.sin(tp)])
            c, s = math.cos(x[2]), math.sin(x[2])
            rpe = np.array([c * pe[0] - s * pe[1], s * pe[0] + c * pe[1]])
            d = x[:2] + rpe - np.array(m[i])
            h[i] = d @ d - legs[i]["l_st"] ** 2
            A[i] = [2 * d[0], 2 * d[1], 2 * (d[0] * -rpe[1] + d[1] * rpe[0])]
        dx = np.linalg.solve(A, -h)
        x += dx
        if np.max(np.abs(dx)) < 1e-11:
            break
    return x[0], x[1], math.degrees(x[2])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("recording")
    ap.add_argument("--json")
    ap.add_argument("--params", default="paper", choices=["paper", "extended"])
    ap.add_argument("--reading", default="symmetric", choices=["symmetric", "asymmetric"])
    a = ap.parse_args()
    data = read_static(a.recording)
    t0 = time.perf_counter()
    extended = a.params == "extended"
    table = []
    for kind in KINDS:
        legs = []
        for i in range(3):
            tr = [(g["q"][i] * MM_PER_STEP, g["m"][i]) for g in data if g["set"] == "train" and g["m"][i] is not None]
            te = [(g["q"][i] * MM_PER_STEP, g["m"][i]) for g in data if g["set"] == "test" and g["m"][i] is not None]
            if a.reading == "asymmetric":
                # As pcr: each direction needs more points than its coefficients.
                need = NCOEF[kind] - (0 if kind in ("linear", "log") else 1) + 1
                if min(sum(o[0] < 0 for o in tr), sum(o[0] > 0 for o in tr)) < need:
                    break
            f = fit_leg(i, kind, tr, te, extended, a.reading)
            f["n_train"], f["n_test"] = len(tr), len(te)
            legs.append(f)
        if len(legs) < 3:
            continue
        pool = lambda key, n: math.sqrt(sum(f[key] ** 2 * f[n] for f in legs) / sum(f[n] for f in legs))
        table.append(dict(index=KINDS.index(kind) + 1, name=kind, reading=a.reading,
                          train_rms_mm=pool("train", "n_train"),
                          test_rms_mm=pool("test", "n_test"), legs=legs))
    best = min(table, key=lambda r: r["test_rms_mm"])
    kind = best["name"]
    legs = [dict(f["leg"]) for f in best["legs"]]
    ks = [f["k"] for f in best["legs"]]
    w = sum(l["r_p"] for l in legs) / 3.0 * math.pi / 180.0
    train = [g for g in data if g["set"] == "train" and g["pose"] is not None]
    test = [g for g in data if g["set"] == "test" and g["pose"] is not None]
    names = [(i, n) for i in range(3) for n in ("r_p", "theta_p")] + ([(i, "l_st") for i in range(3)] if extended else [])
    x0 = np.array([legs[i][n] for i, n in names])
    lo = np.array([0.7 * legs[i][n] if n == "r_p" else legs[i][n] - 15.0 for i, n in names])
    hi = np.array([1.3 * legs[i][n] if n == "r_p" else legs[i][n] + 15.0 for i, n in names])

    def with_x(x):
        ls = [dict(l) for l in legs]
        for (i, n), v in zip(names, x):
            ls[i][n] = v
        return ls

    def errors(ls, poses):
        out = []
        for g in poses:
            p = fk(ls, kind, ks, g["q"], g["pose"], a.reading)
            dphi = (p[2] - g["pose"][2] + 180.0) % 360.0 - 180.0
            out.append((p[0] - g["pose"][0], p[1] - g["pose"][1], dphi))
        return np.array(out)

    def res(x):
        e = errors(with_x(x), train)
        return np.concatenate([e[:, 0], e[:, 1], w * e[:, 2]])

    r2 = least_squares(res, x0, bounds=(lo, hi), method="trf", x_scale="jac")
    elapsed = time.perf_counter() - t0
    e = errors(with_x(r2.x), test)
    pos_rms = float(np.sqrt(np.mean(e[:, 0] ** 2 + e[:, 1] ** 2))) if len(e) else None
    out = dict(table1=[{k: v for k, v in r.items() if k != "legs"} for r in table], selected=best["index"],
               step2=dict(zip([f"{n}[{i+1}]" for i, n in names], map(float, r2.x))),
               test_position_rms_mm=pos_rms, seconds=elapsed)
    for r in table:
        print(f"{r['index']:2} {r['name']:11} train {r['train_rms_mm']:.4f} test {r['test_rms_mm']:.4f}")
    print(f"selected {best['index']} ({kind}); test platform position RMS {pos_rms:.4f} mm; fits {elapsed:.3f} s")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
