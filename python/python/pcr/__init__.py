"""``pcr``: the 3-FbRR control stack from Python.

The stack's kinematics, planning, recordings, calibration, residual analysis and simulated
plant, as thin bindings over its Rust crates (the same code as the ``pcr`` command-line tool:
the same inputs give the same numbers). Arrays in and out are numpy arrays and pandas
DataFrames; units are in the names (mm, deg, s, steps, 1/mm).

>>> import pcr
>>> robot = pcr.Robot.nominal()
>>> robot.ik([[0, 0, 0], [10, 5, 2]]).steps

Modules: :mod:`pcr.robot` (``Robot``), :mod:`pcr.recording` (``read_recording``,
``write_recording``), :mod:`pcr.plan` (paths, programs, joint moves, the profiler),
:mod:`pcr.calibration` (``calibrate``), :mod:`pcr.residuals` (``residuals``),
:mod:`pcr.plant` (``Plant``), :mod:`pcr.experiment` (the calibration set on the simulated
plant), :mod:`pcr.errors` (the exceptions).
"""

from pcr import experiment, plan
from pcr._pcr import __version__
from pcr.calibration import Calibration, calibrate
from pcr.errors import (
    CalibrationError,
    ConfigError,
    InvalidArgument,
    KinematicsError,
    PcrError,
    PlanningError,
    PlantError,
    RecordingError,
    ResidualsError,
)
from pcr.plan import Profile, profile
from pcr.plant import Plant
from pcr.recording import read_recording, write_recording
from pcr.residuals import Residuals, residuals
from pcr.robot import STATUSES, FkResult, IkResult, Robot, Singularity, Workspace

__all__ = [
    "__version__",
    "Robot",
    "IkResult",
    "FkResult",
    "Singularity",
    "Workspace",
    "STATUSES",
    "read_recording",
    "write_recording",
    "plan",
    "profile",
    "Profile",
    "calibrate",
    "Calibration",
    "residuals",
    "Residuals",
    "Plant",
    "experiment",
    "PcrError",
    "ConfigError",
    "RecordingError",
    "CalibrationError",
    "ResidualsError",
    "PlanningError",
    "KinematicsError",
    "PlantError",
    "InvalidArgument",
]
