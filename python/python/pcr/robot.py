"""``pcr.Robot``: the constant-curvature model of a robot file with batch kinematics.

Every row is computed as ``pcr ik`` / ``pcr fk`` compute it; the batch runs in Rust with the
GIL released. Units are in the names: mm, deg, 1/mm (curvatures), steps (motor positions).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Optional, Tuple, Union

import numpy as np
import pandas as pd

from pcr import _pcr
from pcr._arrays import rows3
from pcr.errors import InvalidArgument

#: The status words of the kinematic rows (``pcr ik`` / ``pcr fk``), by code.
STATUSES: Tuple[str, ...] = tuple(_pcr.STATUSES)
_STATUS_ARRAY = np.array(STATUSES)

PathLike = Union[str, "os.PathLike[str]"]


def _status(codes: np.ndarray) -> np.ndarray:
    return _STATUS_ARRAY[codes]


def _legs(name: str) -> list:
    return [name.replace("{i}", str(i)) for i in (1, 2, 3)]


@dataclass(frozen=True, repr=False)
class IkResult:
    """The IK of N poses; every array has one row per pose, NaN where the pose has no solution.

    Attributes:
        kappa_per_mm: curvatures kappa_i, 1/mm, (N, 3).
        dl_mm: tendon displacements through the inverse tendon maps, mm, (N, 3).
        steps: motor positions, steps (whole numbers; NaN without a solution), (N, 3).
        gamma_deg: passive joint angles at M_i, deg, (N, 3).
        zeta_deg: passive joint angles at P_i, deg, (N, 3).
        status: ``ok``, ``singular``, ``unreachable``, ``joint_limit`` or ``bending_limit``, (N,).
    """

    kappa_per_mm: np.ndarray
    dl_mm: np.ndarray
    steps: np.ndarray
    gamma_deg: np.ndarray
    zeta_deg: np.ndarray
    status: np.ndarray

    @property
    def ok(self) -> np.ndarray:
        """Rows whose status is ``ok``."""
        return self.status == "ok"

    def __len__(self) -> int:
        return len(self.status)

    def to_frame(self) -> pd.DataFrame:
        """The columns of ``pcr ik``'s output (kappa1_per_mm .. zeta3_deg, status); q1..q3
        as nullable integers."""
        cols = {}
        for name, a in (("kappa{i}_per_mm", self.kappa_per_mm), ("dl{i}_mm", self.dl_mm)):
            cols.update(zip(_legs(name), a.T))
        for n, a in zip(_legs("q{i}"), self.steps.T):
            cols[n] = pd.Series(a).astype("Int64")
        for name, a in (("gamma{i}_deg", self.gamma_deg), ("zeta{i}_deg", self.zeta_deg)):
            cols.update(zip(_legs(name), a.T))
        cols["status"] = self.status
        return pd.DataFrame(cols)

    def __repr__(self) -> str:
        cols = _legs("q{i}") + _legs("kappa{i}_per_mm") + ["status"]
        text = self.to_frame()[cols].to_string(max_rows=20, min_rows=10)
        return f"IkResult of {len(self)} poses (steps, curvatures 1/mm; to_frame() for every column)\n{text}"


@dataclass(frozen=True, repr=False)
class FkResult:
    """The FK of N rows: poses (N, 3: x_mm, y_mm, phi_deg; NaN where no pose in the working
    and assembly mode closes the loops) and the status of each (as ``pcr fk``)."""

    poses: np.ndarray
    status: np.ndarray

    def to_frame(self) -> pd.DataFrame:
        """Columns x_mm, y_mm, phi_deg, status."""
        return pd.DataFrame(
            {"x_mm": self.poses[:, 0], "y_mm": self.poses[:, 1], "phi_deg": self.poses[:, 2], "status": self.status}
        )

    def __len__(self) -> int:
        return len(self.status)

    def __repr__(self) -> str:
        return f"FkResult of {len(self)} rows\n{self.to_frame().to_string(max_rows=20, min_rows=10)}"


@dataclass(frozen=True)
class Singularity:
    """Singularity measures of N poses (dimensionless, 0 at a singularity, 1 best; NaN where
    the pose has no IK solution).

    Attributes:
        a: inverse condition number of A with its orientation column scaled by the platform
            radius (parallel singularity, det A = 0).
        b: smallest normalised |B_ii| (serial singularity, det B = 0).
        value: min(a, b), compared with the robot's ``singularity_threshold``.
        status: the IK status of each pose.
    """

    a: np.ndarray
    b: np.ndarray
    value: np.ndarray
    status: np.ndarray


@dataclass(frozen=True)
class Workspace:
    """The constant-orientation workspace on a grid (IK feasible and not singular).

    Attributes:
        phi_deg: the platform orientation, deg.
        area_mm2: area, mm^2.
        bounds_mm: (xmin, xmax, ymin, ymax) of the cells inside, mm, or None if empty.
        centroid_mm: area centroid (x, y), mm, or None.
        inside: (ny, nx) booleans; cell (j, i) is centred at
            (x0_mm + (i + 0.5) res_mm, y0_mm + (j + 0.5) res_mm).
        x0_mm, y0_mm, res_mm: the grid.
        contour_mm: the boundary as (M, 2, 2) segments (start and end point, mm).
    """

    phi_deg: float
    area_mm2: float
    bounds_mm: Optional[Tuple[float, float, float, float]]
    centroid_mm: Optional[Tuple[float, float]]
    inside: np.ndarray
    x0_mm: float
    y0_mm: float
    res_mm: float
    contour_mm: np.ndarray

    @property
    def extent_mm(self) -> Tuple[float, float, float, float]:
        """(left, right, bottom, top) of the grid, mm (for ``imshow(extent=...)``)."""
        ny, nx = self.inside.shape
        return (self.x0_mm, self.x0_mm + nx * self.res_mm, self.y0_mm, self.y0_mm + ny * self.res_mm)


class Robot:
    """The constant-curvature model of one robot (a robot file, ``configs/robot.toml``'s shape).

    Build it with :meth:`load`, :meth:`nominal` or :meth:`from_toml`.
    """

    def __init__(self, native: Any) -> None:
        self._native = native

    @classmethod
    def load(cls, path: PathLike) -> "Robot":
        """Loads a robot file; a bad file raises :class:`pcr.ConfigError` naming the key."""
        return cls(_pcr.Robot.load(os.fspath(path)))

    @classmethod
    def nominal(cls) -> "Robot":
        """The built-in nominal robot (geometry.md; the same as configs/robot.toml)."""
        return cls(_pcr.Robot.nominal())

    @classmethod
    def from_toml(cls, text: str, origin: str = "<string>") -> "Robot":
        """A robot from the text of a robot file (``origin`` names it in errors)."""
        return cls(_pcr.Robot.from_toml(text, origin))

    @property
    def name(self) -> str:
        """The file it was loaded from, or what it is."""
        return self._native.name

    @property
    def mm_per_step(self) -> Tuple[float, float, float]:
        """Tendon displacement per motor step of each leg, mm."""
        return tuple(self._native.mm_per_step)

    @property
    def home_kappa_per_mm(self) -> Tuple[float, float, float]:
        """Curvatures of the home pose (0, 0, 0), 1/mm."""
        return tuple(self._native.home_kappa_per_mm)

    @property
    def singularity_threshold(self) -> float:
        """The robot file's singularity threshold: a conditioning below it is singular."""
        return self._native.singularity_threshold

    def to_toml(self) -> str:
        """The robot file's text."""
        return self._native.to_toml()

    def ik(self, poses: Any) -> IkResult:
        """IK of poses: (N, 3) rows of x_mm, y_mm, phi_deg (array-like or a DataFrame with
        those columns). Vectorised; the GIL is released."""
        a = rows3(poses, "poses", ("x_mm", "y_mm", "phi_deg"))
        kappa, dl, steps, gamma, zeta, codes = self._native.ik(a)
        return IkResult(kappa, dl, steps, gamma, zeta, _status(codes))

    def fk(self, kappa_per_mm: Any = None, *, steps: Any = None) -> FkResult:
        """FK of (N, 3) curvatures (1/mm; DataFrame columns kappa1_per_mm..) or, with
        ``steps=``, of motor positions (steps; DataFrame columns q1, q2, q3)."""
        if (kappa_per_mm is None) == (steps is None):
            raise InvalidArgument("fk needs either kappa_per_mm or steps (not both)")
        if steps is not None:
            poses, codes = self._native.fk(rows3(steps, "steps", ("q1", "q2", "q3")), True)
        else:
            a = rows3(kappa_per_mm, "kappa_per_mm", tuple(_legs("kappa{i}_per_mm")))
            poses, codes = self._native.fk(a, False)
        return FkResult(poses, _status(codes))

    def jacobian(self, poses: Any, wrt: str = "kappa") -> np.ndarray:
        """Jacobians at (N, 3) poses, (N, 3, 3): rows d x_mm, d y_mm, d phi_deg; columns per
        curvature kappa_i (1/mm), or with ``wrt="steps"`` per motor step. NaN where the pose
        has no IK solution or is a parallel singularity."""
        a = rows3(poses, "poses", ("x_mm", "y_mm", "phi_deg"))
        j, _ = self._native.jacobian(a, wrt)
        return j

    def singularity(self, poses: Any) -> Singularity:
        """Singularity measures at (N, 3) poses (see :class:`Singularity`)."""
        a = rows3(poses, "poses", ("x_mm", "y_mm", "phi_deg"))
        sa, sb, v, codes = self._native.singularity(a)
        return Singularity(sa, sb, v, _status(codes))

    def workspace(self, phi_deg: float = 0.0, res_mm: float = 1.0) -> Workspace:
        """The workspace at orientation ``phi_deg`` on a grid of ``res_mm`` (``pcr workspace
        --method grid``); the GIL is released."""
        d = self._native.workspace(float(phi_deg), float(res_mm))
        return Workspace(
            phi_deg=d["phi_deg"],
            area_mm2=d["area_mm2"],
            bounds_mm=None if d["bounds_mm"] is None else tuple(d["bounds_mm"]),
            centroid_mm=None if d["centroid_mm"] is None else tuple(d["centroid_mm"]),
            inside=d["inside"],
            x0_mm=d["x0_mm"],
            y0_mm=d["y0_mm"],
            res_mm=d["res_mm"],
            contour_mm=d["contour_mm"],
        )

    def __repr__(self) -> str:
        return f"pcr.Robot({self.name!r})"
