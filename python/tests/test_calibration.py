"""`pcr.calibrate` and `pcr.residuals` give the CLI's results on the same recordings: the same
JSON (Table I, every parameter with its uncertainty, before and after; the effects and the
verdict) and the same robot file."""

from __future__ import annotations

import json

import pcr
from conftest import REPO, run_pcr


def without_volatile(text: str) -> str:
    """A robot file without its time stamp line."""
    return "\n".join(l for l in text.splitlines() if "written by" not in l)


def test_calibrate_equals_the_cli(tmp_path, cal_recording):
    data = str(cal_recording)
    run_pcr("calibrate", "--data", data, "--out", str(tmp_path / "cal.toml"), "--json", str(tmp_path / "cal.json"))
    cli = json.loads((tmp_path / "cal.json").read_text())
    cal = pcr.calibrate(data)
    assert cal.json == cli
    assert without_volatile(cal.to_toml()) == without_volatile((tmp_path / "cal.toml").read_text())
    assert len(cal.table1) == 13 and cal.selected in cal.table1.index
    assert {"name", "value", "std", "unit"} <= set(cal.parameters.columns)
    assert cal.after.loc["test", "position_rms_mm"] < cal.before.loc["test", "position_rms_mm"]
    # the calibrated robot is a robot
    assert cal.robot.ik([[0, 0, 0]]).status[0] == "ok"
    # a DataFrame in gives the same result
    df = pcr.read_recording(data)
    assert pcr.calibrate(df).json["table1"] == cli["table1"]


def test_calibrate_options_equal_the_cli(tmp_path, cal_recording):
    data = str(cal_recording)
    run_pcr("calibrate", "--data", data, "--method", "paper", "--function", "3", "--seed", "4",
            "--robot", str(REPO / "configs/robot.toml"), "--json", str(tmp_path / "cal.json"))
    cal = pcr.calibrate(data, pcr.Robot.load(REPO / "configs/robot.toml"), method="paper", function=3, seed=4)
    assert cal.json == json.loads((tmp_path / "cal.json").read_text())


def test_residuals_equal_the_cli(tmp_path, cal_recording):
    data = str(cal_recording)
    run_pcr("residuals", "--data", data, "--json", str(tmp_path / "res.json"), "--out", str(tmp_path / "ext.toml"))
    cli = json.loads((tmp_path / "res.json").read_text())
    res = pcr.residuals(data)
    assert res.json == cli
    assert res.verdict == cli["verdict"]
    assert res.effect_names == [e["name"] for e in cli["effects"]]
    assert without_volatile(res.to_toml()) == without_volatile((tmp_path / "ext.toml").read_text())
    assert res.calibration is not None and res.calibration["selected"] >= 1
    assert len(res.timing) == 1 and res.timing["declared_s"][0] == 0.02
