"""read_recording reads the format exactly as the tools read it (timing declaration
included); write_recording writes what reads back the same."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import pcr


TEXT = """# source = another lab
# command_delay_s = 0.04
# a free comment
t_s,q1,q2,q3,x_mm,y_mm,phi_deg,pose_id,settled,set,temperature_c,label
0,176,176,176,0.01,-0.02,0.003,0,1,train,21.5,a
0.02,177,176,175,,,,0,1,train,21.5,
0.04,180,170,175,1.5,2.5,0.25,1,0,test,,b
"""


def test_read_keeps_metadata_timing_and_unknown_columns(tmp_path):
    p = tmp_path / "r.csv"
    p.write_text(TEXT)
    df = pcr.read_recording(p)
    assert list(df.columns) == ["t_s", "q1", "q2", "q3", "x_mm", "y_mm", "phi_deg", "pose_id", "settled", "set", "temperature_c", "label"]
    assert df.attrs["command_delay_s"] == 0.04 and df.attrs["declares_command_delay"]
    assert df.attrs["metadata"] == {"source": "another lab", "command_delay_s": "0.04"}
    assert df.attrs["comments"] == ["a free comment"]
    assert df["q1"].dtype == np.int64
    assert np.isnan(df["x_mm"][1]) and df["pose_id"].tolist() == [0, 0, 1]
    assert df["temperature_c"].dtype == np.float64 and np.isnan(df["temperature_c"][2])
    assert df["label"].tolist()[0] == "a" and df["label"].isna().tolist() == [False, True, False]
    assert df["set"].tolist() == ["train", "train", "test"]


def test_without_declaration_the_delay_is_zero(tmp_path):
    p = tmp_path / "r.csv"
    p.write_text("t_s,q1,q2,q3\n0,1,2,3\n0.02,1,2,3\n")
    df = pcr.read_recording(p)
    assert df.attrs["command_delay_s"] == 0.0 and not df.attrs["declares_command_delay"]


def test_write_reads_back_the_same(tmp_path):
    p = tmp_path / "r.csv"
    p.write_text(TEXT)
    df = pcr.read_recording(p)
    q = tmp_path / "w.csv"
    pcr.write_recording(q, df)
    back = pcr.read_recording(q)
    pd.testing.assert_frame_equal(df, back)
    assert back.attrs["metadata"] == df.attrs["metadata"]
    # the known columns in the format's order, then the unknown ones
    assert q.read_text().splitlines()[3] == "t_s,q1,q2,q3,x_mm,y_mm,phi_deg,pose_id,settled,set,temperature_c,label"


def test_write_refuses_what_the_format_forbids(tmp_path):
    df = pd.DataFrame({"t_s": [0.0, 0.0], "q1": [1, 1], "q2": [1, 1], "q3": [1, 1]})
    with pytest.raises(pcr.InvalidArgument, match="increase"):
        pcr.write_recording(tmp_path / "x.csv", df)
    df = pd.DataFrame({"t_s": [0.0, 0.02], "q1": [1.5, 1], "q2": [1, 1], "q3": [1, 1]})
    with pytest.raises(pcr.InvalidArgument, match="whole number"):
        pcr.write_recording(tmp_path / "x.csv", df)
    df = pd.DataFrame({"t_s": [0.0, 0.02], "q1": [1, 1], "q2": [1, 1]})
    with pytest.raises(pcr.InvalidArgument, match="q3"):
        pcr.write_recording(tmp_path / "x.csv", df)
    df = pd.DataFrame({"t_s": [0.0, 0.02], "q1": [1, 1], "q2": [1, 1], "q3": [1, 1]})
    with pytest.raises(pcr.InvalidArgument, match="command_delay_s"):
        pcr.write_recording(tmp_path / "x.csv", df, metadata={"command_delay_s": "soon"})


def test_a_recording_of_the_plant_reads_as_the_cli_wrote_it(cal_recording):
    df = pcr.read_recording(cal_recording)
    assert df.attrs["command_delay_s"] == 0.02
    assert df["settled"].sum() > 0 and set(df["set"].dropna()) == {"train", "test"}
    text_rows = sum(1 for l in cal_recording.read_text().splitlines() if not l.startswith("#")) - 1
    assert len(df) == text_rows
