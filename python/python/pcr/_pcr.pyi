"""Type stubs of the native module ``pcr._pcr`` (the Python layer in ``pcr`` wraps it)."""

from os import PathLike
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

_F = npt.NDArray[np.float64]
_Path = Union[str, PathLike[str]]

__version__: str
STATUSES: List[str]

class Robot:
    @staticmethod
    def load(path: _Path) -> Robot: ...
    @staticmethod
    def nominal() -> Robot: ...
    @staticmethod
    def from_toml(text: str, origin: str = "<string>") -> Robot: ...
    def to_toml(self) -> str: ...
    @property
    def name(self) -> str: ...
    @property
    def mm_per_step(self) -> Tuple[float, float, float]: ...
    @property
    def home_kappa_per_mm(self) -> Tuple[float, float, float]: ...
    @property
    def singularity_threshold(self) -> float: ...
    def ik(self, poses: _F) -> Tuple[_F, _F, _F, _F, _F, npt.NDArray[np.uint8]]: ...
    def fk(self, values: _F, steps: bool = False) -> Tuple[_F, npt.NDArray[np.uint8]]: ...
    def jacobian(self, poses: _F, wrt: str = "kappa") -> Tuple[_F, npt.NDArray[np.uint8]]: ...
    def singularity(self, poses: _F) -> Tuple[_F, _F, _F, npt.NDArray[np.uint8]]: ...
    def workspace(self, phi_deg: float = 0.0, res_mm: float = 1.0) -> Dict[str, Any]: ...

class Recording:
    @staticmethod
    def read(path: _Path) -> Recording: ...
    @staticmethod
    def from_columns(
        numeric: Sequence[Tuple[str, _F]],
        set_column: Optional[Sequence[Optional[str]]],
        extra: Sequence[Tuple[str, Sequence[Optional[str]]]],
        metadata: Sequence[Tuple[str, str]],
        comments: Sequence[str],
        origin: str = "<DataFrame>",
    ) -> Recording: ...
    def to_columns(self) -> Dict[str, Any]: ...
    def write(self, path: _Path) -> None: ...
    @property
    def metadata(self) -> List[Tuple[str, str]]: ...
    @property
    def comments(self) -> List[str]: ...
    @property
    def command_delay_s(self) -> float: ...
    @property
    def declares_command_delay(self) -> bool: ...
    @property
    def origin(self) -> str: ...
    def __len__(self) -> int: ...

class Calibration:
    def json(self) -> str: ...
    def to_toml(self, created: Optional[str] = None) -> str: ...
    @property
    def robot(self) -> Robot: ...
    @property
    def paper_robot(self) -> Robot: ...
    def write_report(self, dir: _Path) -> str: ...

class Residuals:
    def json(self) -> str: ...
    def calibration_json(self) -> Optional[str]: ...
    @property
    def messages(self) -> List[str]: ...
    def to_toml(self, created: Optional[str] = None) -> str: ...
    @property
    def robot(self) -> Robot: ...

class Plant:
    @staticmethod
    def load(path: _Path, robot: Optional[Robot] = None) -> Plant: ...
    @staticmethod
    def prototype(robot: Optional[Robot] = None) -> Plant: ...
    @staticmethod
    def ideal(robot: Optional[Robot] = None) -> Plant: ...
    seed: int
    @property
    def name(self) -> str: ...
    def to_toml(self) -> str: ...
    def pose(self, steps: _F) -> Dict[str, _F]: ...
    def run(
        self,
        t_s: _F,
        q: _F,
        columns: Sequence[Tuple[str, _F]] = ...,
        capture_frame: bool = False,
        stop_on_fault: bool = False,
    ) -> Recording: ...

def calibrate(
    data: Recording,
    robot: Optional[Robot] = None,
    params: str = "paper",
    method: str = "joint",
    function: Optional[int] = None,
    phi_weight_mm_per_deg: Optional[float] = None,
    seed: int = 1,
    report: Optional[_Path] = None,
) -> Calibration: ...
def residuals(
    data: Sequence[Recording],
    holdout: Sequence[Recording] = ...,
    robot: Optional[Robot] = None,
    no_calibrate: bool = False,
    exact: bool = False,
    block_s: float = 4.0,
    alpha: float = 0.01,
    min_effect_mm: float = 0.01,
    candidates: Optional[Sequence[str]] = None,
    report: Optional[_Path] = None,
) -> Residuals: ...
def plan(robot: Robot, kind: str, args: Dict[str, Any]) -> Dict[str, Any]: ...
def profile(
    current: Sequence[Sequence[float]],
    target: Sequence[Sequence[float]],
    vmax: Sequence[float],
    amax: Sequence[float],
    jmax: Sequence[float],
    vmin: Optional[Sequence[float]] = None,
    amin: Optional[Sequence[float]] = None,
    synchronization: str = "time",
    control_interface: str = "position",
    minimum_duration_s: Optional[float] = None,
    dt_s: float = 0.02,
) -> Dict[str, Any]: ...
def experiment_calibration(
    config: _Path,
    out: Optional[_Path] = None,
    robot: Optional[_Path] = None,
    plant: Optional[_Path] = None,
    seed: int = 1,
    plant_seed: Optional[int] = None,
    points: int = 21,
    scales: Sequence[float] = ...,
    phis_deg: Sequence[float] = ...,
    test_per_group: int = 7,
    singularity_margin: float = 2.0,
    speed_mm_s: float = 30.0,
    settle_s: float = 1.0,
    measure_s: float = 0.5,
) -> Recording: ...
