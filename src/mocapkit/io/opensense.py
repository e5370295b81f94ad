"""OpenSense orientation tables (``.sto``, ``DataType=Quaternion``): one quaternion column
``w,x,y,z`` per IMU, as written by OpenSim's IMU data readers (``*_orientations.sto``)."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import FileFormatError
from mocapkit.io.opensim_table import OpenSimTable, iter_table, read_table, write_table
from mocapkit.series import OrientationSeries

# OpenSense writes quaternions with ~16 digits; anything further than this from unit norm
# is not an orientation (a wrong column or a scaled value).
_NORM_TOLERANCE = 1e-3


def read_orientations_sto(path: str | Path) -> dict[str, OrientationSeries]:
    """{column label: OrientationSeries ``q_world_sensor``} from a quaternion ``.sto``.

    Quaternions are renormalised (the file's text precision); an all-zero or NaN cell
    becomes a missing sample (NaN)."""
    p = Path(path)
    table = read_table(p)
    _check_quaternion(p, table)
    out = {}
    for i, label in enumerate(table.labels):
        q = _unit_quaternions(p, label, table.data[:, i], 0)
        out[label] = OrientationSeries(table.time, q, name=label)
    return out


def iter_orientations_sto(
    path: str | Path, rows: int = 50_000
) -> Iterator[tuple[list[str], FloatArray, FloatArray]]:
    """A quaternion ``.sto`` ``rows`` rows at a time: (labels, time (n,) [s], quaternions
    (n, k, 4) ``q_world_sensor``, renormalised, missing cells NaN), as
    :func:`read_orientations_sto` reads them, in flat memory."""
    p = Path(path)
    row0 = 0
    for table in iter_table(p, rows):
        _check_quaternion(p, table)
        q = np.empty_like(table.data)
        for i, label in enumerate(table.labels):
            q[:, i] = _unit_quaternions(p, label, table.data[:, i], row0)
        yield table.labels, table.time, q
        row0 += table.time.shape[0]


def _check_quaternion(p: Path, table: OpenSimTable) -> None:
    if not table.is_quaternion:
        raise FileFormatError(
            f"{p}: not a quaternion table (no DataType=Quaternion and no 'w,x,y,z' cells)"
        )


def _unit_quaternions(p: Path, label: str, data: FloatArray, row0: int) -> FloatArray:
    """(n, 4) cells renormalised; all-zero or NaN cells NaN; a norm far from 1 refused,
    naming the column and the row (``row0``: rows before these)."""
    q = data.copy()
    norm = np.linalg.norm(q, axis=1)
    missing = ~np.isfinite(norm) | (norm == 0.0)
    off = ~missing & (np.abs(norm - 1.0) > _NORM_TOLERANCE)
    if off.any():
        k = int(np.flatnonzero(off)[0])
        raise FileFormatError(
            f"{p}: column {label!r}, row {row0 + k}: quaternion norm {norm[k]:.6f} is not 1; "
            "expected unit quaternions w,x,y,z"
        )
    q[missing] = np.nan
    q[~missing] /= norm[~missing, None]
    return q


def write_orientations_sto(path: str | Path, series: Mapping[str, OrientationSeries]) -> Path:
    """Write orientations on one time base as an OpenSense quaternion ``.sto``."""
    names = list(series)
    if not names:
        raise FileFormatError("no orientation series to write")
    time = series[names[0]].time
    for n in names:
        if not np.array_equal(series[n].time, time):
            raise FileFormatError(f"series {n!r}: time base differs from {names[0]!r}")
    data = np.stack([series[n].quat for n in names], axis=1)
    return write_table(path, time, names, data, name="orientations")
