"""Shared fixtures: the repository, the release `pcr` binary the results are compared with,
and small recordings made with it on the simulated plant (once per session)."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def pcr_binary() -> Path:
    env = os.environ.get("PCR_BIN")
    p = Path(env) if env else REPO / "target" / "release" / "pcr"
    if not p.is_file():
        pytest.skip(f"the pcr binary ({p}) is not built: cargo build --release -p pcr, or set PCR_BIN")
    return p


def run_pcr(*args: str, check: bool = True, cwd: Path = REPO) -> subprocess.CompletedProcess:
    """Runs the CLI; with `check`, fails the test on a non-zero exit."""
    r = subprocess.run([str(pcr_binary()), *args], cwd=cwd, capture_output=True, text=True)
    if check and r.returncode != 0:
        raise AssertionError(f"pcr {' '.join(args)} failed:\n{r.stderr}")
    return r


def cli_error(r: subprocess.CompletedProcess) -> str:
    """The message of the CLI's `error: ...` line."""
    lines = [l for l in r.stderr.splitlines() if l.startswith("error: ")]
    assert lines, r.stderr
    return lines[-1][len("error: "):]


@pytest.fixture(scope="session")
def pcr_bin() -> Path:
    return pcr_binary()


@pytest.fixture(scope="session")
def cal_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small calibration recording of the prototype plant (5 points per scaled boundary,
    2 test poses per group: 45 static poses), made by `pcr experiment calibration`."""
    out = tmp_path_factory.mktemp("rec") / "cal.csv"
    run_pcr(
        "experiment", "calibration", "--config", "configs/sim.toml", "--points", "5",
        "--test-per-group", "2", "--out", str(out),
    )
    return out
