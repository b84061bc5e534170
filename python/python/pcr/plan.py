"""``pcr.plan``: the paper's paths, program files and joint moves as the chain's 20 ms
setpoints (the rows of ``pcr plan``), and ``pcr.plan.profile``: the jerk-limited profiler on
one multi-DoF case.

Every planner returns a DataFrame with the columns of ``pcr plan``'s CSV: t_s, xp_mm, yp_mm,
phip_deg (the planned pose), speed_mm_s, kappa1_per_mm .. kappa3_per_mm and q1 .. q3 (the
motor setpoints, steps); ``df.attrs["speed_limit_mm_s"]`` holds the composite speed limit of
each row (NaN outside composites) and ``df.attrs["moves"]`` the number of moves. A refused
plan raises :class:`pcr.PlanningError` naming the move and the time. The GIL is released
while planning.

Common keyword arguments (as ``pcr plan``'s options): ``robot`` (default: the built-in
nominal robot), ``start`` (x_mm, y_mm, phi_deg: the robot's current pose; shapes lead from it
and back), ``amax`` (path acceleration, mm/s^2), ``jmax`` (path jerk, mm/s^3), ``pause_at``,
``resume_at``, ``stop_at`` (the chain's PAUSE, RESUME and STOP requested at a time, s),
``singularity_margin`` (required conditioning as a multiple of the robot's threshold) and
``rate_fraction`` (fraction of each drive's step-rate limit the motion may use).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Dict, Optional, Sequence, Tuple, Union

import numpy as np
import pandas as pd

from pcr import _pcr
from pcr.robot import Robot

PathLike = Union[str, "os.PathLike[str]"]

#: Default motor acceleration of joint moves, steps/s^2.
JOINT_AMAX = 2000.0
#: Default motor jerk of joint moves, steps/s^3.
JOINT_JMAX = 20000.0


def _run(kind: str, robot: Optional[Robot], args: Dict[str, Any], settings: Dict[str, Any]) -> pd.DataFrame:
    r = Robot.nominal() if robot is None else robot
    start = settings.pop("start")
    d = _pcr.plan(r._native, kind, {**args, **settings, "start": [float(v) for v in start]})
    pose, kappa, q = d["pose"], d["kappa_per_mm"], d["q"]
    df = pd.DataFrame(
        {
            "t_s": np.round(d["t_s"], 2),
            "xp_mm": pose[:, 0],
            "yp_mm": pose[:, 1],
            "phip_deg": pose[:, 2],
            "speed_mm_s": d["speed_mm_s"],
            "kappa1_per_mm": kappa[:, 0],
            "kappa2_per_mm": kappa[:, 1],
            "kappa3_per_mm": kappa[:, 2],
            "q1": q[:, 0],
            "q2": q[:, 1],
            "q3": q[:, 2],
        }
    )
    df.attrs["speed_limit_mm_s"] = d["speed_limit_mm_s"]
    df.attrs["moves"] = d["moves"]
    return df


def _settings(
    start: Sequence[float], amax: float, jmax: float, pause_at: Optional[float], resume_at: Optional[float],
    stop_at: Optional[float], singularity_margin: float, rate_fraction: float,
) -> Dict[str, Any]:
    return {
        "start": start, "amax": float(amax), "jmax": float(jmax), "pause_at": pause_at,
        "resume_at": resume_at, "stop_at": stop_at, "singularity_margin": float(singularity_margin),
        "rate_fraction": float(rate_fraction),
    }


def circle(
    radius_mm: float = 50.0, speed_mm_s: float = 50.0, *, centre_mm: Tuple[float, float] = (0.0, 0.0),
    phi_deg: float = 0.0, start_deg: float = 0.0, cw: bool = False, robot: Optional[Robot] = None,
    start: Sequence[float] = (0.0, 0.0, 0.0), amax: float = 200.0, jmax: float = 2000.0,
    pause_at: Optional[float] = None, resume_at: Optional[float] = None, stop_at: Optional[float] = None,
    singularity_margin: float = 1.0, rate_fraction: float = 1.0,
) -> pd.DataFrame:
    """A full circle at constant orientation (``pcr plan circle``; the paper's: 50 mm radius at
    50 mm/s): a dwell of 0.2 s, a line to the start point, the circle, a dwell and a line back."""
    args = {"radius_mm": float(radius_mm), "speed_mm_s": float(speed_mm_s), "centre_mm": [float(c) for c in centre_mm],
            "phi_deg": float(phi_deg), "start_deg": float(start_deg), "cw": bool(cw)}
    return _run("circle", robot, args, _settings(start, amax, jmax, pause_at, resume_at, stop_at, singularity_margin, rate_fraction))


def square(
    side_mm: float = 50.0, speed_mm_s: float = 50.0, *, centre_mm: Tuple[float, float] = (0.0, 0.0),
    phi_deg: float = 0.0, blend_radius_mm: Optional[float] = None, robot: Optional[Robot] = None,
    start: Sequence[float] = (0.0, 0.0, 0.0), amax: float = 200.0, jmax: float = 2000.0,
    pause_at: Optional[float] = None, resume_at: Optional[float] = None, stop_at: Optional[float] = None,
    singularity_margin: float = 1.0, rate_fraction: float = 1.0,
) -> pd.DataFrame:
    """A square of rest-to-rest sides (``pcr plan square``; the paper's: 50 mm at 50 mm/s); with
    ``blend_radius_mm`` one composite motion whose corners are rounded by arcs of that radius."""
    args = {"side_mm": float(side_mm), "speed_mm_s": float(speed_mm_s), "centre_mm": [float(c) for c in centre_mm],
            "phi_deg": float(phi_deg), "blend_radius_mm": None if blend_radius_mm is None else float(blend_radius_mm)}
    return _run("square", robot, args, _settings(start, amax, jmax, pause_at, resume_at, stop_at, singularity_margin, rate_fraction))


def line(
    to: Sequence[float], speed_mm_s: float, *, robot: Optional[Robot] = None,
    start: Sequence[float] = (0.0, 0.0, 0.0), amax: float = 200.0, jmax: float = 2000.0,
    pause_at: Optional[float] = None, resume_at: Optional[float] = None, stop_at: Optional[float] = None,
    singularity_margin: float = 1.0, rate_fraction: float = 1.0,
) -> pd.DataFrame:
    """A straight line to the pose ``to`` (x_mm, y_mm, phi_deg) and back (``pcr plan line``)."""
    args = {"to": [float(v) for v in to], "speed_mm_s": float(speed_mm_s)}
    return _run("line", robot, args, _settings(start, amax, jmax, pause_at, resume_at, stop_at, singularity_margin, rate_fraction))


def paper(
    speed_mm_s: float = 50.0, *, robot: Optional[Robot] = None, start: Sequence[float] = (0.0, 0.0, 0.0),
    amax: float = 200.0, jmax: float = 2000.0, pause_at: Optional[float] = None,
    resume_at: Optional[float] = None, stop_at: Optional[float] = None,
    singularity_margin: float = 1.0, rate_fraction: float = 1.0,
) -> pd.DataFrame:
    """The paper's test program (``pcr plan paper``, the chain's PAPER): the 50 mm circle, then
    the 50 mm square."""
    return _run("paper", robot, {"speed_mm_s": float(speed_mm_s)},
                _settings(start, amax, jmax, pause_at, resume_at, stop_at, singularity_margin, rate_fraction))


def program(
    file: PathLike, *, joint_amax: float = JOINT_AMAX, joint_jmax: float = JOINT_JMAX,
    robot: Optional[Robot] = None, start: Sequence[float] = (0.0, 0.0, 0.0), amax: float = 200.0,
    jmax: float = 2000.0, pause_at: Optional[float] = None, resume_at: Optional[float] = None,
    stop_at: Optional[float] = None, singularity_margin: float = 1.0, rate_fraction: float = 1.0,
) -> pd.DataFrame:
    """A program file (TOML: lines, arcs, dwells and joint moves; docs/planner.md), as
    ``pcr plan program --file``; a bad file raises :class:`pcr.ConfigError` naming the key."""
    args = {"file": os.fspath(file), "joint_amax": float(joint_amax), "joint_jmax": float(joint_jmax)}
    return _run("program", robot, args, _settings(start, amax, jmax, pause_at, resume_at, stop_at, singularity_margin, rate_fraction))


def joint(
    steps: Sequence[int], *, from_steps: Optional[Sequence[int]] = None, joint_amax: float = JOINT_AMAX,
    joint_jmax: float = JOINT_JMAX, robot: Optional[Robot] = None, amax: float = 200.0,
    jmax: float = 2000.0, pause_at: Optional[float] = None, resume_at: Optional[float] = None,
    stop_at: Optional[float] = None, singularity_margin: float = 1.0, rate_fraction: float = 1.0,
) -> pd.DataFrame:
    """A synchronised joint move of the three motors to ``steps`` (from ``from_steps``, default
    the home pose's), as ``pcr plan joint``."""
    args = {"steps": [float(v) for v in steps], "from_steps": None if from_steps is None else [float(v) for v in from_steps],
            "joint_amax": float(joint_amax), "joint_jmax": float(joint_jmax)}
    return _run("joint", robot, args, _settings((0.0, 0.0, 0.0), amax, jmax, pause_at, resume_at, stop_at, singularity_margin, rate_fraction))


@dataclass(frozen=True)
class Profile:
    """A jerk-limited profile sampled every ``dt_s``.

    Attributes:
        duration_s: its duration, s.
        t_s: sample times, s, (K,).
        p, v, a: position, velocity and acceleration of each degree of freedom, (K, n), in the
            units of the case.
        final_p, final_v, final_a: the state at the end, (n,).
    """

    duration_s: float
    t_s: np.ndarray
    p: np.ndarray
    v: np.ndarray
    a: np.ndarray
    final_p: np.ndarray
    final_v: np.ndarray
    final_a: np.ndarray


def profile(
    current_p: Sequence[float], target_p: Sequence[float], *, vmax: Sequence[float], amax: Sequence[float],
    jmax: Sequence[float], current_v: Optional[Sequence[float]] = None, current_a: Optional[Sequence[float]] = None,
    target_v: Optional[Sequence[float]] = None, target_a: Optional[Sequence[float]] = None,
    vmin: Optional[Sequence[float]] = None, amin: Optional[Sequence[float]] = None,
    synchronization: str = "time", control_interface: str = "position",
    minimum_duration_s: Optional[float] = None, dt_s: float = 0.02,
) -> Profile:
    """One jerk-limited profiling case of 1..8 degrees of freedom (the solver of ``pcr
    profile``, ruckig-style): from the current to the target state (velocities and
    accelerations default to 0) within the limits (``vmin`` and ``amin`` default to ``-vmax``
    and ``-amax``), ``synchronization`` ``"time"``, ``"phase"`` or ``"none"``,
    ``control_interface`` ``"position"`` or ``"velocity"``. A case the profiler cannot solve
    raises :class:`pcr.PlanningError`."""
    n = len(vmax)

    def f(v: Optional[Sequence[float]]) -> list:
        return [0.0] * n if v is None else [float(x) for x in v]

    d = _pcr.profile(
        [f(current_p), f(current_v), f(current_a)],
        [f(target_p), f(target_v), f(target_a)],
        f(vmax), f(amax), f(jmax),
        None if vmin is None else f(vmin), None if amin is None else f(amin),
        synchronization, control_interface, minimum_duration_s, float(dt_s),
    )
    return Profile(
        d["duration_s"], d["t_s"], d["p"], d["v"], d["a"],
        np.array(d["final_p"]), np.array(d["final_v"]), np.array(d["final_a"]),
    )
