"""``pcr.read_recording`` / ``pcr.write_recording``: the recording format
(``shared/spec/recording.md``) as a pandas DataFrame, read and written by the stack's own reader
and writer, exactly as the tools read them.

The DataFrame has the recording's columns (the format's known columns, then the unknown ones);
``df.attrs`` holds ``metadata`` (the ``# key = value`` lines, a dict in file order),
``comments`` (other leading comment lines), ``command_delay_s`` (the timing declaration: the
pose measured at t answers the command of row time t - D; 0 when the file does not declare
it), ``declares_command_delay`` and ``origin``.
"""

from __future__ import annotations

import math
import os
from typing import Any, Dict, Iterable, List, Optional, Tuple, Union

import numpy as np
import pandas as pd

from pcr import _pcr
from pcr.errors import InvalidArgument

PathLike = Union[str, "os.PathLike[str]"]

#: The columns the format defines, in the recommended order.
KNOWN_COLUMNS: Tuple[str, ...] = (
    "t_s", "q1", "q2", "q3", "x_mm", "y_mm", "phi_deg", "m1x_mm", "m1y_mm", "m2x_mm",
    "m2y_mm", "m3x_mm", "m3y_mm", "xp_mm", "yp_mm", "phip_deg", "pose_id", "rep",
    "settled", "set",
)
_INT = ("q1", "q2", "q3")
_NULLABLE_INT = ("pose_id", "rep", "settled")


def _text_column(cells: List[Optional[str]]) -> Any:
    """An unknown column: numbers when every cell is one, else text (None = empty)."""
    try:
        return np.array([np.nan if c is None else float(c) for c in cells], dtype=np.float64)
    except ValueError:
        return pd.array(cells, dtype="string")


def frame_of(native: Any) -> pd.DataFrame:
    """The DataFrame of a native recording."""
    c = native.to_columns()
    cols: Dict[str, Any] = {}
    for name in c["columns"]:
        if name in c["numeric"]:
            a = c["numeric"][name]
            if name in _INT:
                a = a.astype(np.int64)
            elif name in _NULLABLE_INT:
                a = pd.Series(a).astype("Int64").array
            cols[name] = a
        elif name == "set":
            cols[name] = pd.array(c["set"], dtype="string")
        else:
            cols[name] = _text_column(c["extra"][name])
    df = pd.DataFrame(cols, columns=c["columns"])
    df.attrs["metadata"] = dict(native.metadata)
    df.attrs["comments"] = list(native.comments)
    df.attrs["command_delay_s"] = native.command_delay_s
    df.attrs["declares_command_delay"] = native.declares_command_delay
    df.attrs["origin"] = native.origin
    return df


def read_recording(path: PathLike) -> pd.DataFrame:
    """Reads a recording file as the tools read it; errors (:class:`pcr.RecordingError`) name
    the file, line and column. See the module documentation for ``df.attrs``."""
    return frame_of(_pcr.Recording.read(os.fspath(path)))


def _cell_text(v: Any) -> Optional[str]:
    if v is None or v is pd.NA:
        return None
    if isinstance(v, float):
        if math.isnan(v):
            return None
        return repr(v)
    if isinstance(v, (np.floating,)):
        return None if np.isnan(v) else repr(float(v))
    if isinstance(v, (np.integer,)):
        return str(int(v))
    s = str(v)
    return s if s != "" else None


def native_of(
    df: pd.DataFrame,
    metadata: Optional[Dict[str, Any]] = None,
    comments: Optional[Iterable[str]] = None,
    origin: str = "<DataFrame>",
) -> Any:
    """The native recording of a DataFrame (known columns by name; the others kept as text)."""
    if not isinstance(df, pd.DataFrame):
        raise InvalidArgument(f"a recording must be a pandas DataFrame or a file, got {type(df).__name__}")
    meta = dict(df.attrs.get("metadata", {}) if metadata is None else metadata)
    comm = list(df.attrs.get("comments", []) if comments is None else comments)
    numeric: List[Tuple[str, np.ndarray]] = []
    set_col = None
    extra: List[Tuple[str, List[Optional[str]]]] = []
    for name in df.columns:
        if not isinstance(name, str):
            raise InvalidArgument(f"column names must be text, got {name!r}")
        s = df[name]
        if name == "set":
            set_col = [_cell_text(v) for v in s.tolist()]
        elif name in KNOWN_COLUMNS:
            try:
                a = s.astype("Float64").to_numpy(dtype=np.float64, na_value=np.nan)
            except (TypeError, ValueError) as e:
                raise InvalidArgument(f"column `{name}` must be numbers: {e}") from None
            numeric.append((name, np.ascontiguousarray(a)))
        else:
            extra.append((name, [_cell_text(v) for v in s.tolist()]))
    return _pcr.Recording.from_columns(
        numeric, set_col, extra, [(str(k), str(v)) for k, v in meta.items()], comm, origin
    )


def recording_arg(data: Any) -> Any:
    """A native recording of a path or a DataFrame (the tools' input)."""
    if isinstance(data, pd.DataFrame):
        return native_of(data, origin=str(data.attrs.get("origin", "<DataFrame>")))
    if isinstance(data, (str, os.PathLike)):
        return _pcr.Recording.read(os.fspath(data))
    if isinstance(data, _pcr.Recording):
        return data
    raise InvalidArgument(f"a recording must be a file name or a DataFrame, got {type(data).__name__}")


def write_recording(
    path: PathLike,
    df: pd.DataFrame,
    metadata: Optional[Dict[str, Any]] = None,
    comments: Optional[Iterable[str]] = None,
) -> None:
    """Writes a DataFrame as a recording file: the known columns by name (t_s, q1..q3
    required; NaN or NA = empty cell), the others as text; ``metadata`` (default
    ``df.attrs["metadata"]``) as ``# key = value`` lines (``command_delay_s`` is checked)."""
    native_of(df, metadata, comments).write(os.fspath(path))
