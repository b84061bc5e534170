"""IK, FK, Jacobians, singularity and workspace from Python equal the CLI's (`pcr ik`, `pcr fk`,
`pcr workspace`) on the same inputs, row by row to 1e-12."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import pcr
from conftest import REPO, run_pcr

ROBOT = str(REPO / "configs" / "robot.toml")


def poses() -> np.ndarray:
    """A grid over and beyond the workspace, three orientations: ok, singular and every limit."""
    x, y, phi = np.meshgrid(np.linspace(-90, 90, 13), np.linspace(-90, 90, 13), [-12.0, 0.0, 7.5])
    return np.column_stack([x.ravel(), y.ravel(), phi.ravel()])


def test_ik_equals_the_cli(tmp_path):
    p = poses()
    inp = tmp_path / "poses.csv"
    pd.DataFrame(p, columns=["x_mm", "y_mm", "phi_deg"]).to_csv(inp, index=False, float_format="%.17g")
    run_pcr("ik", "--robot", ROBOT, "--input", str(inp), "--output", str(tmp_path / "ik.csv"))
    cli = pd.read_csv(tmp_path / "ik.csv", keep_default_na=False, na_values=[""])
    r = pcr.Robot.load(ROBOT).ik(p)
    assert list(r.status) == list(cli["status"])
    assert len(set(r.status)) >= 3, set(r.status)
    for name, a in [
        ("kappa{i}_per_mm", r.kappa_per_mm),
        ("dl{i}_mm", r.dl_mm),
        ("q{i}", r.steps),
        ("gamma{i}_deg", r.gamma_deg),
        ("zeta{i}_deg", r.zeta_deg),
    ]:
        for i in range(3):
            col = cli[name.replace("{i}", str(i + 1))].to_numpy(dtype=float)
            np.testing.assert_allclose(a[:, i], col, rtol=0, atol=1e-12, equal_nan=True, err_msg=name)
    frame = r.to_frame()
    assert list(frame.columns) == [c for c in cli.columns if c not in ("x_mm", "y_mm", "phi_deg")]


@pytest.mark.parametrize("by_steps", [False, True])
def test_fk_equals_the_cli(tmp_path, by_steps):
    robot = pcr.Robot.load(ROBOT)
    ik = robot.ik(poses())
    rows = ik.steps[ik.ok] if by_steps else ik.kappa_per_mm[ik.ok]
    # and some beyond the workspace
    rows = np.vstack([rows, rows[:5] * 3.0])
    cols = ["q1", "q2", "q3"] if by_steps else ["kappa1_per_mm", "kappa2_per_mm", "kappa3_per_mm"]
    inp = tmp_path / "joints.csv"
    pd.DataFrame(rows, columns=cols).to_csv(inp, index=False, float_format="%.17g")
    run_pcr("fk", "--robot", ROBOT, "--input", str(inp), "--output", str(tmp_path / "fk.csv"))
    cli = pd.read_csv(tmp_path / "fk.csv", keep_default_na=False, na_values=[""])
    r = robot.fk(steps=rows) if by_steps else robot.fk(rows)
    assert list(r.status) == list(cli["status"])
    np.testing.assert_allclose(r.poses, cli[["x_mm", "y_mm", "phi_deg"]].to_numpy(dtype=float), rtol=0, atol=1e-12, equal_nan=True)


def test_dataframes_in_and_ik_fk_round_trip():
    robot = pcr.Robot.nominal()
    df = pd.DataFrame({"phi_deg": [0.0, 5.0], "x_mm": [0.0, 10.0], "y_mm": [0.0, -5.0]})
    ik = robot.ik(df)
    assert list(ik.status) == ["ok", "ok"]
    back = robot.fk(ik.kappa_per_mm)
    np.testing.assert_allclose(back.poses, df[["x_mm", "y_mm", "phi_deg"]].to_numpy(), atol=1e-9)


def test_jacobian_matches_finite_differences_of_fk():
    robot = pcr.Robot.nominal()
    pose = np.array([[12.0, -7.0, 3.0]])
    j = robot.jacobian(pose)[0]
    k0 = robot.ik(pose).kappa_per_mm[0]
    h = 1e-7
    for c in range(3):
        dk = np.zeros(3)
        dk[c] = h
        plus = robot.fk((k0 + dk)[None, :]).poses[0]
        minus = robot.fk((k0 - dk)[None, :]).poses[0]
        np.testing.assert_allclose(j[:, c], (plus - minus) / (2 * h), rtol=1e-5, atol=1e-6)
    js = robot.jacobian(pose, wrt="steps")[0]
    assert np.all(np.isfinite(js)) and abs(js[0]).max() < 1.0  # mm per step
    with pytest.raises(pcr.InvalidArgument, match="wrt"):
        robot.jacobian(pose, wrt="tendons")


def test_singularity_and_workspace_agree_with_the_cli(tmp_path):
    robot = pcr.Robot.load(ROBOT)
    s = robot.singularity(poses())
    ik = robot.ik(poses())
    solved = ~np.isnan(ik.kappa_per_mm[:, 0])
    assert np.all(np.isfinite(s.value[solved])) and np.all(np.isnan(s.value[~solved]))
    assert np.array_equal(s.value[solved] < robot.singularity_threshold, ik.status[solved] == "singular")
    ws = robot.workspace(phi_deg=0.0, res_mm=2.0)
    r = run_pcr("workspace", "--robot", ROBOT, "--phi-deg", "0", "--res", "2", "--method", "grid",
                "--json", str(tmp_path / "ws.json"))
    import json

    cli = json.loads((tmp_path / "ws.json").read_text())["grid"]
    assert ws.area_mm2 == cli["area_mm2"]
    assert list(ws.bounds_mm) == cli["bounds_mm"]
    assert len(ws.contour_mm) == len(cli["contour_segments_mm"])
    assert ws.inside.sum() * 4.0 == ws.area_mm2
    assert r.stdout.strip().splitlines()[-1] == f"{ws.area_mm2:.1f}"


def test_the_done_when_example():
    r = pcr.Robot.nominal().ik([[0, 0, 0]])
    assert r.status[0] == "ok"
    text = repr(r)
    assert "q1" in text and "status" in text


def test_batch_ik_releases_the_gil():
    """Another Python thread runs while the batch IK runs."""
    import threading

    robot = pcr.Robot.nominal()
    big = np.tile(poses(), (600, 1))  # about 300 000 poses
    done = threading.Event()

    def work():
        robot.ik(big)
        done.set()

    t = threading.Thread(target=work)
    ticks = 0
    t.start()
    while not done.is_set():
        ticks += 1
    t.join()
    assert ticks > 10_000, ticks
