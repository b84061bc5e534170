"""`pcr.experiment.calibration` records what `pcr experiment calibration` records."""

from __future__ import annotations

import pandas as pd

import pcr
from conftest import REPO, run_pcr


def test_the_calibration_experiment_equals_the_cli(tmp_path, monkeypatch):
    monkeypatch.chdir(REPO)  # the configuration names its robot relative to the repository
    run_pcr("experiment", "calibration", "--config", "configs/sim.toml", "--points", "3",
            "--test-per-group", "1", "--seed", "3", "--out", str(tmp_path / "cli.csv"))
    cli = pcr.read_recording(tmp_path / "cli.csv")
    py = pcr.experiment.calibration("configs/sim.toml", points=3, test_per_group=1, seed=3, out=tmp_path / "py.csv")
    pd.testing.assert_frame_equal(py, cli, check_exact=True)
    for k, v in cli.attrs["metadata"].items():
        if k not in ("created", "source"):
            assert py.attrs["metadata"][k] == v, k
    assert pcr.read_recording(tmp_path / "py.csv").shape == py.shape


def test_a_bad_configuration_is_named(tmp_path, monkeypatch):
    monkeypatch.chdir(REPO)
    bad = tmp_path / "sim.toml"
    bad.write_text('robot = "configs/robot.toml"\n[[process]]\nname = "driver"\nbackend = "serial"\n')
    try:
        pcr.experiment.calibration(bad, points=3)
    except pcr.ConfigError as e:
        assert "serial backend" in str(e) and str(bad) in str(e)
    else:
        raise AssertionError("no error")
