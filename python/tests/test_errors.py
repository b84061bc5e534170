"""Bad inputs raise Python exceptions (never a panic) with the CLI's message; arrays of the
wrong shape are refused with a message."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import pcr
from conftest import REPO, cli_error, run_pcr


def bad_robot(tmp_path):
    text = (REPO / "configs" / "robot.toml").read_text()
    assert "l_c_mm" in text
    # a negative segment length on the first leg
    lines = text.splitlines()
    k = next(i for i, l in enumerate(lines) if l.strip().startswith("l_c_mm"))
    lines[k] = "l_c_mm = -5.0"
    p = tmp_path / "bad.toml"
    p.write_text("\n".join(lines) + "\n")
    return p


def test_a_bad_robot_file_names_the_key_as_the_cli_does(tmp_path):
    p = bad_robot(tmp_path)
    with pytest.raises(pcr.ConfigError) as e:
        pcr.Robot.load(str(p))
    assert "l_c_mm" in str(e.value)
    (tmp_path / "poses.csv").write_text("x_mm,y_mm,phi_deg\n0,0,0\n")
    r = run_pcr("ik", "--robot", str(p), "--input", str(tmp_path / "poses.csv"), check=False)
    assert r.returncode != 0
    assert cli_error(r) == str(e.value)
    assert isinstance(e.value, pcr.PcrError)


def test_missing_files_raise():
    with pytest.raises(pcr.ConfigError, match="nonexistent.toml"):
        pcr.Robot.load("nonexistent.toml")
    with pytest.raises(pcr.RecordingError, match="nonexistent.csv"):
        pcr.read_recording("nonexistent.csv")
    with pytest.raises(pcr.ConfigError, match="nonexistent_plant.toml"):
        pcr.Plant.load("nonexistent_plant.toml")


def test_a_bad_recording_names_line_and_column_as_the_cli_does(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("# command_delay_s = 0.02\nt_s,q1,q2,q3,x_mm\n0,1,2,3,0.5\n0.02,1,2,x,0.5\n")
    with pytest.raises(pcr.RecordingError) as e:
        pcr.read_recording(p)
    assert "line 4" in str(e.value) and "`q3`" in str(e.value)
    r = run_pcr("calibrate", "--data", str(p), check=False)
    assert cli_error(r) == str(e.value)
    p.write_text("# command_delay_s = -1\nt_s,q1,q2,q3\n0,1,2,3\n")
    with pytest.raises(pcr.RecordingError, match="command_delay_s"):
        pcr.read_recording(p)


@pytest.mark.parametrize(
    "bad",
    [[0, 0, 0], [[0, 0]], np.zeros((2, 4)), np.zeros((2, 3, 1)), [["a", "b", "c"]]],
)
def test_arrays_of_the_wrong_shape_are_refused(bad):
    with pytest.raises(ValueError, match="shape|numbers") as e:
        pcr.Robot.nominal().ik(bad)
    assert isinstance(e.value, pcr.InvalidArgument)


def test_a_dataframe_without_the_columns_is_refused():
    with pytest.raises(pcr.InvalidArgument, match="phi_deg"):
        pcr.Robot.nominal().ik(pd.DataFrame({"x_mm": [0.0], "y_mm": [0.0]}))
    with pytest.raises(pcr.InvalidArgument, match="kappa_per_mm or steps"):
        pcr.Robot.nominal().fk()


def test_a_refused_plan_names_the_move():
    with pytest.raises(pcr.PlanningError, match="`line`.*unreachable|unreachable.*`line`"):
        pcr.plan.line((150.0, 0.0, 0.0), speed_mm_s=20.0)
    with pytest.raises(pcr.InvalidArgument, match="side"):
        pcr.plan.square(side_mm=-1.0)


def test_bad_calibration_and_residual_options_raise(cal_recording):
    with pytest.raises(pcr.InvalidArgument, match="method"):
        pcr.calibrate(cal_recording, method="magic")
    with pytest.raises(pcr.InvalidArgument, match="function = 14"):
        pcr.calibrate(cal_recording, function=14)
    with pytest.raises(pcr.InvalidArgument, match="unknown effect `gremlins`"):
        pcr.residuals(cal_recording, candidates=["backlash", "gremlins"])
    with pytest.raises(pcr.InvalidArgument, match="block length"):
        pcr.residuals(cal_recording, block_s=0)


def test_an_unsolvable_profile_raises():
    with pytest.raises(pcr.PlanningError):
        pcr.profile([0.0], [1.0], vmax=[1.0], amax=[1.0], jmax=[1.0], minimum_duration_s=float("nan"), current_v=[50.0], target_v=[-50.0], control_interface="position", synchronization="time", vmin=[-1.0])
