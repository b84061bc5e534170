"""``pcr.Plant``: the simulated plant (a kineto-static elastica truth model with switchable
effects, ``docs/plant.md``) on a robot's drawing: static poses for motor positions and a
setpoint series through the time-stepped plant as a recording."""

from __future__ import annotations

import os
from typing import Any, Optional, Union

import numpy as np
import pandas as pd

from pcr import _pcr
from pcr._arrays import rows1, rows3
from pcr.errors import InvalidArgument
from pcr.recording import frame_of
from pcr.robot import Robot

PathLike = Union[str, "os.PathLike[str]"]

_PASS_THROUGH = ("xp_mm", "yp_mm", "phip_deg", "pose_id", "rep", "settled")


class Plant:
    """A plant file (the shape of configs/plant.toml) on a robot's drawing (its geometry
    deviations, true tendon map and effects apply on top of the robot file's nominal
    geometry). Build it with :meth:`load`, :meth:`prototype` or :meth:`ideal`."""

    def __init__(self, native: Any) -> None:
        self._native = native

    @classmethod
    def load(cls, path: PathLike, robot: Optional[Robot] = None) -> "Plant":
        """Loads a plant file on ``robot``'s drawing (default: the nominal robot); a bad file
        raises :class:`pcr.ConfigError` naming the key."""
        return cls(_pcr.Plant.load(os.fspath(path), None if robot is None else robot._native))

    @classmethod
    def prototype(cls, robot: Optional[Robot] = None) -> "Plant":
        """The built-in prototype-like plant (the same as configs/plant.toml)."""
        return cls(_pcr.Plant.prototype(None if robot is None else robot._native))

    @classmethod
    def ideal(cls, robot: Optional[Robot] = None) -> "Plant":
        """The built-in ideal plant: no effects (the same as configs/plant-ideal.toml)."""
        return cls(_pcr.Plant.ideal(None if robot is None else robot._native))

    @property
    def name(self) -> str:
        """The plant file's name."""
        return self._native.name

    @property
    def seed(self) -> int:
        """Seed of the random effects (capture noise, missed steps, dropouts)."""
        return self._native.seed

    @seed.setter
    def seed(self, value: int) -> None:
        self._native.seed = int(value)

    def to_toml(self) -> str:
        """The plant file's text."""
        return self._native.to_toml()

    def pose(self, steps: Any) -> pd.DataFrame:
        """Static equilibria for (N, 3) motor positions (steps; DataFrame columns q1..q3), with
        the effects that have no history (``pcr plant pose``): columns q1..q3, x_mm, y_mm,
        phi_deg, m1x_mm .. m3y_mm, f1_n .. f3_n (axial link forces, N). A row without
        equilibrium raises :class:`pcr.PlantError` naming it. The GIL is released."""
        q = rows3(steps, "steps", ("q1", "q2", "q3"))
        d = self._native.pose(q)
        cols = {"q1": q[:, 0], "q2": q[:, 1], "q3": q[:, 2]}
        for k, n in enumerate(("x_mm", "y_mm", "phi_deg")):
            cols[n] = d["pose"][:, k]
        for k, n in enumerate(("m1x_mm", "m1y_mm", "m2x_mm", "m2y_mm", "m3x_mm", "m3y_mm")):
            cols[n] = d["m_mm"][:, k]
        for k, n in enumerate(("f1_n", "f2_n", "f3_n")):
            cols[n] = d["link_force_n"][:, k]
        return pd.DataFrame(cols)

    def run(
        self,
        setpoints: Optional[pd.DataFrame] = None,
        *,
        t_s: Any = None,
        q: Any = None,
        capture_frame: bool = False,
        stop_on_fault: bool = False,
    ) -> pd.DataFrame:
        """Runs 20 ms setpoints through the time-stepped plant (``pcr plant run``) and returns
        the recording (see :func:`pcr.read_recording`): the measured pose, the planned pose
        and bookkeeping columns copied from the setpoints, and the true state in extra
        columns. ``setpoints`` is a DataFrame with t_s, q1, q2, q3 (e.g. a ``pcr.plan``
        result) and optionally xp_mm, yp_mm, phip_deg, pose_id, rep, settled; or give ``t_s``
        (N,) and ``q`` (N, 3). The GIL is released."""
        columns = []
        if setpoints is not None:
            if t_s is not None or q is not None:
                raise InvalidArgument("give setpoints or t_s and q, not both")
            if not isinstance(setpoints, pd.DataFrame):
                raise InvalidArgument(f"setpoints must be a DataFrame, got {type(setpoints).__name__}")
            if "t_s" not in setpoints.columns:
                raise InvalidArgument("setpoints: the DataFrame has no column t_s")
            t = rows1(setpoints["t_s"].to_numpy(dtype=np.float64), "t_s")
            qq = rows3(setpoints, "setpoints", ("q1", "q2", "q3"))
            for c in _PASS_THROUGH:
                if c in setpoints.columns:
                    columns.append((c, np.ascontiguousarray(setpoints[c].astype("Float64").to_numpy(dtype=np.float64, na_value=np.nan))))
        else:
            if t_s is None or q is None:
                raise InvalidArgument("run needs setpoints, or t_s and q")
            t = rows1(t_s, "t_s")
            qq = rows3(q, "q", ("q1", "q2", "q3"))
        return frame_of(self._native.run(t, qq, columns, capture_frame, stop_on_fault))

    def __repr__(self) -> str:
        return repr(self._native)
