"""The simulated plant from Python equals `pcr plant pose` and `pcr plant run`."""

from __future__ import annotations

import numpy as np
import pandas as pd

import pcr
from conftest import REPO, run_pcr

PLANT = str(REPO / "configs" / "plant.toml")


def test_pose_equals_the_cli(tmp_path):
    q = np.array([[176, 176, 176], [400, 60, 250], [100, 300, 180]], dtype=float)
    pd.DataFrame(q.astype(int), columns=["q1", "q2", "q3"]).to_csv(tmp_path / "q.csv", index=False)
    run_pcr("plant", "pose", "--plant", PLANT, "--input", str(tmp_path / "q.csv"), "--output", str(tmp_path / "p.csv"))
    cli = pd.read_csv(tmp_path / "p.csv")
    py = pcr.Plant.load(PLANT).pose(q)
    assert list(py.columns) == list(cli.columns)
    # the CLI writes 6 decimals
    np.testing.assert_allclose(py.to_numpy(), cli.to_numpy(), rtol=0, atol=5.1e-7)


def test_run_equals_the_cli(tmp_path):
    sp = pcr.plan.line((15, -10, 4), 30)
    sp.to_csv(tmp_path / "sp.csv", index=False, float_format="%.17g")
    run_pcr("plant", "run", "--plant", PLANT, "--input", str(tmp_path / "sp.csv"), "--output", str(tmp_path / "rec.csv"))
    cli = pcr.read_recording(tmp_path / "rec.csv")
    py = pcr.Plant.load(PLANT).run(sp)
    pd.testing.assert_frame_equal(py, cli, check_exact=True)
    meta = dict(py.attrs["metadata"])
    assert meta["command_delay_s"] == "0.02" and meta["plant"] == PLANT
    for k in ("seed", "frame", "command_delay_s", "source"):
        assert meta[k] == cli.attrs["metadata"][k]


def test_a_plan_runs_through_the_ideal_plant_onto_its_poses():
    sp = pcr.plan.circle(20, 20)
    rec = pcr.Plant.ideal().run(sp)
    moving = rec.dropna(subset=["x_mm"])
    # the ideal plant is the nominal model: the measured pose is the planned one a cycle later
    err = np.hypot(moving["x_mm"].to_numpy()[1:] - moving["xp_mm"].to_numpy()[:-1],
                   moving["y_mm"].to_numpy()[1:] - moving["yp_mm"].to_numpy()[:-1])
    assert np.median(err) < 0.5
