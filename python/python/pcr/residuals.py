"""``pcr.residuals``: what the calibrated model lacks (``pcr residuals``), with the CLI's
options, as a result object.

The result's :attr:`Residuals.json` is the JSON of ``pcr residuals --json``;
:meth:`Residuals.to_toml` is the extended robot file of ``--out``.
"""

from __future__ import annotations

import json
import os
from typing import Any, Dict, Iterable, List, Optional, Sequence, Union

import pandas as pd

from pcr import _pcr
from pcr.recording import recording_arg
from pcr.robot import Robot

PathLike = Union[str, "os.PathLike[str]"]


class Residuals:
    """The result of :func:`residuals`.

    Attributes:
        json: everything, as ``pcr residuals --json`` writes it (a dict).
        verdict: ``explained``, ``partly_explained`` or ``unexplained``.
        timing_finding: a timing declaration error, if a recording declares a longer command
            delay than its data show (part of the verdict), else None.
        effects: the effects added, one row per parameter: effect, parameter, value, std,
            unit, held-out gain (mm) and p-value of the effect.
        candidates: every candidate tried in every round, with its held-out score.
        timing: per recording, the declared and the estimated command delay (s).
        before, after: held-out errors of the starting and the extended model (rows,
            position mean / max / RMS in mm, orientation RMS in deg).
        calibration: the calibration done first, as ``pcr calibrate --json`` (None if none).
    """

    def __init__(self, native: Any) -> None:
        self._native = native
        self.json: Dict[str, Any] = json.loads(native.json())
        j = self.json
        self.verdict: str = j["verdict"]
        self.timing_finding: Optional[str] = j["timing_finding"]
        rows = []
        for e in j["effects"]:
            for p in e["params"]:
                rows.append(
                    {
                        "effect": e["name"],
                        "parameter": p["name"],
                        "value": p["value"],
                        "std": p["std"],
                        "unit": p["unit"],
                        "held_out_gain_mm": e["evidence"]["effect_mm"],
                        "p_value": e["evidence"]["p_value"],
                    }
                )
        self.effects = pd.DataFrame(
            rows, columns=["effect", "parameter", "value", "std", "unit", "held_out_gain_mm", "p_value"]
        )
        self.candidates = pd.DataFrame(
            [{k: v for k, v in c.items() if k != "params"} for c in j["candidates"]]
        )
        self.timing = pd.DataFrame(j["timing"])
        self.before = pd.Series(j["before"], name="before")
        self.after = pd.Series(j["after"], name="after")
        cal = native.calibration_json()
        self.calibration: Optional[Dict[str, Any]] = None if cal is None else json.loads(cal)
        self.messages: List[str] = list(native.messages)

    @property
    def effect_names(self) -> List[str]:
        """The effects added, in order."""
        return [e["name"] for e in self.json["effects"]]

    @property
    def robot(self) -> Robot:
        """The extended robot (its ``[effects]`` are what the running chain compensates)."""
        return Robot(self._native.robot)

    def to_toml(self, created: Optional[str] = None) -> str:
        """The extended robot file (``pcr residuals --out``), stamped ``created`` (default:
        now, UTC)."""
        return self._native.to_toml(created)

    def __repr__(self) -> str:
        return (
            f"pcr.Residuals({self.verdict}: effects {', '.join(self.effect_names) or 'none'}; "
            f"held-out position RMS {self.before['position_rms_mm']:.3f} -> {self.after['position_rms_mm']:.3f} mm)"
        )


def residuals(
    data: Union[Any, Sequence[Any]],
    robot: Optional[Robot] = None,
    *,
    holdout: Iterable[Any] = (),
    no_calibrate: bool = False,
    exact: bool = False,
    block_s: float = 4.0,
    alpha: float = 1e-2,
    min_effect_mm: float = 0.01,
    candidates: Optional[Sequence[str]] = None,
    report: Optional[PathLike] = None,
) -> Residuals:
    """Finds what the calibrated model lacks, as ``pcr residuals`` does.

    Args:
        data: a recording or a list of them (file names or DataFrames). The first one with
            static poses calibrates the robot first, as ``pcr calibrate`` does.
        robot: the robot the recordings were made with (default: the built-in nominal robot).
        holdout: recordings on which the model is only scored (default: every third block of
            about ``block_s`` of ``data`` is held out).
        no_calibrate: take the robot as it is.
        exact: solve every row on its own (slow; the reference of the default path).
        block_s: length of the held-out time blocks, s.
        alpha: family-wise significance level of a round.
        min_effect_mm: smallest held-out RMS gain worth claiming, mm.
        candidates: only these effects (names of the library; default: all).
        report: a folder for ``residuals_before.csv``, the Markdown report and its figures.

    The GIL is released while it runs.
    """
    if isinstance(data, (list, tuple)):
        items = list(data)
    else:
        items = [data]
    native = _pcr.residuals(
        [recording_arg(d) for d in items],
        [recording_arg(d) for d in holdout],
        None if robot is None else robot._native,
        no_calibrate,
        exact,
        float(block_s),
        float(alpha),
        float(min_effect_mm),
        None if candidates is None else list(candidates),
        None if report is None else os.fspath(report),
    )
    return Residuals(native)
