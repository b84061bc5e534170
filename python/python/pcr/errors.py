"""The exceptions of ``pcr``: one class per kind of input that can be wrong.

Their text is what the ``pcr`` command-line tool prints for the same error (a bad robot file
names its key, a bad recording its file, line and column).
"""


class PcrError(Exception):
    """Base class of every error the stack reports."""


class ConfigError(PcrError):
    """A robot, plant, program or supervisor configuration file is wrong (the key is named)."""


class RecordingError(PcrError):
    """A recording cannot be read or written (file, line and column are named)."""


class CalibrationError(PcrError):
    """The calibration cannot be done on the data."""


class ResidualsError(PcrError):
    """The residual analysis cannot be done on the data."""


class PlanningError(PcrError):
    """A plan or a profiling case was refused (the move and the time are named)."""


class KinematicsError(PcrError):
    """The kinematic model has no answer (no home pose, no IK solution where one is needed)."""


class PlantError(PcrError):
    """The simulated plant failed (no equilibrium, a setpoint it cannot follow)."""


class InvalidArgument(PcrError, ValueError):
    """An argument is out of its range or an array has the wrong shape."""


__all__ = [
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
