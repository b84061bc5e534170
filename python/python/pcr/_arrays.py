"""Input arrays checked for shape and converted once, so that the native calls get what they
need (C-contiguous float64) and a wrong shape is refused with a message."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
import pandas as pd

from pcr.errors import InvalidArgument


def rows3(values: Any, what: str, columns: Sequence[str]) -> np.ndarray:
    """An (N, 3) float64 array of ``values`` (array-like, or a DataFrame with ``columns``)."""
    if isinstance(values, pd.DataFrame):
        missing = [c for c in columns if c not in values.columns]
        if missing:
            raise InvalidArgument(
                f"{what}: the DataFrame has no column {', '.join(missing)} "
                f"(has: {', '.join(map(str, values.columns))})"
            )
        values = values[list(columns)].to_numpy(dtype=np.float64)
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InvalidArgument(f"{what} must be numbers ({', '.join(columns)} per row): {e}") from None
    if a.ndim != 2 or a.shape[1] != 3:
        hint = " (one row: write [[...]])" if a.shape == (3,) else ""
        raise InvalidArgument(
            f"{what} must have shape (N, 3), one row of {', '.join(columns)} each; "
            f"got shape {a.shape}{hint}"
        )
    return np.ascontiguousarray(a)


def rows1(values: Any, what: str) -> np.ndarray:
    """A (N,) float64 array."""
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InvalidArgument(f"{what} must be numbers: {e}") from None
    if a.ndim != 1:
        raise InvalidArgument(f"{what} must have shape (N,), got shape {a.shape}")
    return np.ascontiguousarray(a)
