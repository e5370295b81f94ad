"""Input conversion and validation for every module: convert once, check, name the argument."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import DataError, ShapeError

FloatArray = NDArray[np.float64]


def as_float_array(value: Any, name: str) -> FloatArray:
    """Convert an array-like to a float64 array, never sharing memory with a caller's array
    that we might later modify (we never modify it, but callers may modify the result)."""
    try:
        arr = np.array(value, dtype=np.float64, copy=True)
    except (TypeError, ValueError) as exc:
        raise DataError(f"{name}: cannot convert to a float array ({exc})") from exc
    return arr


def check_shape(arr: NDArray[Any], name: str, *shape: int | None) -> None:
    """Raise ShapeError unless ``arr.shape`` matches ``shape`` (``None`` matches any length)."""
    ok = arr.ndim == len(shape) and all(
        s is None or s == a for s, a in zip(shape, arr.shape, strict=True)
    )
    if not ok:
        expected = "(" + ", ".join("N" if s is None else str(s) for s in shape)
        expected += ",)" if len(shape) == 1 else ")"
        raise ShapeError(f"{name}: expected shape {expected}, got {arr.shape}")


def as_vectors(value: Any, name: str, width: int) -> FloatArray:
    """Array-like of shape (width,) or (N, width) -> float array of shape (N, width)."""
    arr = as_float_array(value, name)
    if arr.ndim == 1:
        check_shape(arr, name, width)
        return arr[None, :]
    check_shape(arr, name, None, width)
    return arr


def check_finite(arr: NDArray[Any], name: str, fix: str = "") -> None:
    """Raise DataError naming the first non-finite sample (time is the first axis)."""
    bad = ~np.isfinite(arr)
    if bad.any():
        idx = np.argwhere(bad)[0]
        where = f"sample {idx[0]}" + (f", column {idx[1]}" if len(idx) > 1 else "")
        count = int(bad.reshape(len(arr), -1).any(axis=1).sum()) if arr.ndim else 1
        hint = f" {fix}" if fix else ""
        raise DataError(f"{name}: non-finite value at {where} ({count} bad samples).{hint}")
