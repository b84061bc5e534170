"""``pcr.calibrate``: the paper's calibration (``pcr calibrate``) from a recording with static
poses, with the CLI's options, as a result object.

The result's :attr:`Calibration.json` is the JSON of ``pcr calibrate --json`` (the same
numbers: the same library call on the same data); :meth:`Calibration.to_toml` is the robot
file of ``--out``.
"""

from __future__ import annotations

import json
import os
from typing import Any, Dict, List, Optional, Union

import pandas as pd

from pcr import _pcr
from pcr.recording import recording_arg
from pcr.robot import Robot

PathLike = Union[str, "os.PathLike[str]"]


def _accuracy_frame(before: Dict[str, Any], after: Dict[str, Any]) -> pd.DataFrame:
    rows = []
    for label, acc in (("before", before), ("after", after)):
        for split in ("train", "test"):
            a = acc.get(split)
            if a is None:
                continue
            p = a["pose"]
            rows.append(
                {
                    "model": label,
                    "set": split,
                    "poses": p["n"],
                    "m_rms_mm": a["m_rms_mm"],
                    "m_max_mm": a["m_max_mm"],
                    "position_mean_mm": p["position_mean_mm"],
                    "position_max_mm": p["position_max_mm"],
                    "position_rms_mm": p["position_rms_mm"],
                    "orientation_rms_deg": p["orientation_rms_deg"],
                    "fk_failures": p["fk_failures"],
                }
            )
    return pd.DataFrame(rows).set_index(["model", "set"])


def _params_frame(params: List[Dict[str, Any]], **labels: Any) -> pd.DataFrame:
    rows = [
        {**labels, "name": p["name"], "value": p["value"], "std": p["std"], "unit": p["unit"],
         "start": p["start"], "at_bound": p["at_bound"]}
        for p in params
    ]
    return pd.DataFrame(rows)


class Calibration:
    """The result of :func:`calibrate`.

    Attributes:
        json: everything, as ``pcr calibrate --json`` writes it (a dict).
        table1: Table I, one row per regression function: train and test RMS of M_i (mm),
            converged, monotonic (selectable), error.
        selected: the Table I function used; ``selected_by`` says why.
        parameters: the calibrated parameters with their one-sigma uncertainties (the joint
            refinement's, or the two steps' with ``method="paper"``): name, value, std, unit,
            start, at_bound.
        accuracy: the starting (``before``) and the calibrated (``after``) robot on the
            training and test poses: M_i and platform errors, mm and deg.
        warnings: what the user should know (correlated parameters, bounds, moved rows).
    """

    def __init__(self, native: Any) -> None:
        self._native = native
        self.json: Dict[str, Any] = json.loads(native.json())
        j = self.json
        self.table1 = pd.DataFrame(
            [
                {k: r[k] for k in ("index", "name", "form", "train_rms_mm", "test_rms_mm", "converged", "monotonic", "error")}
                for r in j["table1"]
            ]
        ).set_index("index")
        self.selected: int = j["selected"]
        self.selected_by: str = j["selected_by"]
        if j.get("joint") is not None and j["used"] == "joint":
            self.parameters = _params_frame(j["joint"]["fit"]["params"], step="joint")
        else:
            legs = [_params_frame(f["params"], step=f"step 1 leg {f['leg']}") for f in j["step1"]]
            self.parameters = pd.concat(legs + [_params_frame(j["step2"]["params"], step="step 2")], ignore_index=True)
        self.accuracy = _accuracy_frame(j["before"], j["after"])
        self.warnings: List[str] = list(j["warnings"])

    @property
    def before(self) -> pd.DataFrame:
        """The starting robot on the training and test poses."""
        return self.accuracy.loc["before"]

    @property
    def after(self) -> pd.DataFrame:
        """The calibrated robot on the training and test poses."""
        return self.accuracy.loc["after"]

    @property
    def robot(self) -> Robot:
        """The calibrated robot."""
        return Robot(self._native.robot)

    def to_toml(self, created: Optional[str] = None) -> str:
        """The calibrated robot file (``pcr calibrate --out``), stamped ``created``
        (default: now, UTC)."""
        return self._native.to_toml(created)

    def write_report(self, directory: PathLike) -> str:
        """Writes the Markdown report and its figures (``pcr calibrate --report``)."""
        return str(self._native.write_report(os.fspath(directory)))

    def __repr__(self) -> str:
        split = "test" if "test" in self.after.index else "train"
        before = self.before.loc[split, "position_rms_mm"]
        after = self.after.loc[split, "position_rms_mm"]
        name = self.table1.loc[self.selected, "name"]
        return (
            f"pcr.Calibration(function {self.selected} ({name}); platform position RMS on the "
            f"{split} poses {before:.3f} -> {after:.3f} mm)"
        )


def calibrate(
    data: Any,
    robot: Optional[Robot] = None,
    *,
    params: str = "paper",
    method: str = "joint",
    function: Optional[int] = None,
    phi_weight_mm_per_deg: Optional[float] = None,
    seed: int = 1,
    report: Optional[PathLike] = None,
) -> Calibration:
    """Calibrates a robot from a recording with static poses, as ``pcr calibrate`` does.

    Args:
        data: the recording: a file name or a DataFrame (``pcr.read_recording``).
        robot: the robot the recording was made with, the start of the fit (default: the
            built-in nominal robot, as ``pcr calibrate`` without ``--robot``).
        params: ``"paper"`` (step 1 [l_C, psi, k], step 2 [r_p, theta_p]) or ``"extended"``
            (also the base points and the link lengths).
        method: ``"joint"`` (the two steps refined jointly) or ``"paper"`` (the two steps).
        function: force this Table I function (1..13) instead of selecting by test RMS.
        phi_weight_mm_per_deg: weight of one degree of orientation error, mm (default
            r_p pi / 180).
        seed: seed of the random train/test split (recordings without a ``set`` column).
        report: a folder for the Markdown report and its figures.

    The GIL is released while it runs.
    """
    native = _pcr.calibrate(
        recording_arg(data),
        None if robot is None else robot._native,
        params,
        method,
        function,
        phi_weight_mm_per_deg,
        seed,
        None if report is None else os.fspath(report),
    )
    return Calibration(native)
