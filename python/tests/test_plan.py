"""Planning from Python equals `pcr plan` (the same rows) and the profiler equals
`pcr profile` on one multi-DoF case."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

import pcr
from conftest import REPO, run_pcr

ROBOT = str(REPO / "configs" / "robot.toml")
COLS = ["xp_mm", "yp_mm", "phip_deg", "speed_mm_s", "kappa1_per_mm", "kappa2_per_mm", "kappa3_per_mm"]


def cli_plan(tmp_path, *args):
    out = tmp_path / "plan.csv"
    run_pcr("plan", *args, "--robot", ROBOT, "--output", str(out))
    return pd.read_csv(out)


def same(py: pd.DataFrame, cli: pd.DataFrame):
    assert list(py.columns) == list(cli.columns)
    assert len(py) == len(cli)
    np.testing.assert_allclose(py["t_s"], cli["t_s"], atol=1e-9)
    np.testing.assert_allclose(py[COLS].to_numpy(), cli[COLS].to_numpy(), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(py[["q1", "q2", "q3"]].to_numpy(), cli[["q1", "q2", "q3"]].to_numpy())


@pytest.mark.parametrize(
    "py_call, cli_args",
    [
        (lambda r: pcr.plan.circle(50, 50, robot=r), ["circle", "--radius", "50", "--speed", "50"]),
        (lambda r: pcr.plan.square(40, 30, blend_radius_mm=8, robot=r), ["square", "--side", "40", "--speed", "30", "--blend-radius", "8"]),
        (lambda r: pcr.plan.line((20, 10, 5), 25, robot=r, stop_at=0.5), ["line", "--to", "20,10,5", "--speed", "25", "--stop-at", "0.5"]),
        (lambda r: pcr.plan.program(REPO / "configs/programs/slot.toml", robot=r), ["program", "--file", str(REPO / "configs/programs/slot.toml")]),
        (lambda r: pcr.plan.joint((260, 140, 176), robot=r), ["joint", "--steps", "260,140,176"]),
    ],
)
def test_plans_equal_the_cli(tmp_path, py_call, cli_args):
    same(py_call(pcr.Robot.load(ROBOT)), cli_plan(tmp_path, *cli_args))


def test_the_paper_program_has_its_speed_limits():
    df = pcr.plan.paper()
    assert df.attrs["moves"] > 10
    assert len(df.attrs["speed_limit_mm_s"]) == len(df)
    assert df["speed_mm_s"].max() == pytest.approx(50.0, rel=1e-6)


def test_the_profiler_equals_pcr_profile(tmp_path):
    case = {
        "id": "three axes",
        "dofs": 3,
        "current": {"p": [0.0, -1.0, 0.5], "v": [0.0, 0.2, 0.0], "a": [0.0, 0.0, -0.1]},
        "target": {"p": [1.0, 2.0, -0.5], "v": [0.0, 0.0, 0.1], "a": [0.0, 0.0, 0.0]},
        "limits": {"vmax": [1.0, 1.5, 0.8], "amax": [2.0, 2.0, 1.0], "jmax": [10.0, 8.0, 5.0]},
    }
    (tmp_path / "cases.json").write_text(json.dumps({"cases": [case]}))
    run_pcr("profile", "--cases", str(tmp_path / "cases.json"), "--out", str(tmp_path / "answers.json"))
    ans = json.loads((tmp_path / "answers.json").read_text())["answers"][0]
    c, t, lim = case["current"], case["target"], case["limits"]
    prof = pcr.profile(
        c["p"], t["p"], current_v=c["v"], current_a=c["a"], target_v=t["v"], target_a=t["a"],
        vmax=lim["vmax"], amax=lim["amax"], jmax=lim["jmax"],
    )
    assert prof.duration_s == ans["duration"]
    np.testing.assert_array_equal(prof.p, np.array(ans["p"]))
    np.testing.assert_array_equal(prof.v, np.array(ans["v"]))
    np.testing.assert_array_equal(prof.final_p, np.array(ans["final"]["p"]))
