"""``pcr.experiment``: the paper's experiments recorded on the in-process chain against the
simulated plant, as ``pcr experiment`` records them (docs/experiments.md)."""

from __future__ import annotations

import os
from typing import Optional, Sequence, Union

import pandas as pd

from pcr import _pcr
from pcr.recording import frame_of

PathLike = Union[str, "os.PathLike[str]"]


def calibration(
    config: PathLike = "configs/sim.toml",
    *,
    out: Optional[PathLike] = None,
    robot: Optional[PathLike] = None,
    plant: Optional[PathLike] = None,
    seed: int = 1,
    plant_seed: Optional[int] = None,
    points: int = 21,
    scales: Sequence[float] = (0.75, 0.5, 0.2),
    phis_deg: Sequence[float] = (0.0, 10.0, -10.0),
    test_per_group: int = 7,
    singularity_margin: float = 2.0,
    speed_mm_s: float = 30.0,
    settle_s: float = 1.0,
    measure_s: float = 0.5,
) -> pd.DataFrame:
    """Records the calibration set (``pcr experiment calibration``): the poses on the scaled
    workspace boundaries of each orientation, each approached from the origin, settled and
    measured, on the simulated plant of the supervisor configuration ``config`` (its robot and
    its driver's plant, paths relative to the working directory; ``robot`` replaces the model
    that drives, ``plant`` the plant file, ``plant_seed`` the plant's seed). Returns the
    annotated recording (pose_id, rep, settled, set); with ``out`` it is also written there.
    The GIL is released."""
    native = _pcr.experiment_calibration(
        os.fspath(config),
        None if out is None else os.fspath(out),
        None if robot is None else os.fspath(robot),
        None if plant is None else os.fspath(plant),
        int(seed),
        plant_seed,
        int(points),
        [float(s) for s in scales],
        [float(p) for p in phis_deg],
        int(test_per_group),
        float(singularity_margin),
        float(speed_mm_s),
        float(settle_s),
        float(measure_s),
    )
    return frame_of(native)
