"""Joint angles as OpenSim motion files (``.mot``, degrees), through io/opensim_table."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from mocapkit.errors import DataError
from mocapkit.io.opensim_table import TableWriter, iter_table, read_table
from mocapkit.series import JointAngleSeries

_TRANSLATIONS = ("_tx", "_ty", "_tz")
_BLOCK_ROWS = 50_000


def _rotational(names: tuple[str, ...]) -> np.ndarray:
    return np.array([not label.endswith(_TRANSLATIONS) for label in names], dtype=bool)


def write_joint_angles_mot(path: str | Path, angles: JointAngleSeries) -> Path:
    """Write rotational coordinates [rad] as degrees (``inDegrees=yes``), OpenSim's layout;
    translations (``_tx``, ``_ty``, ``_tz``) stay metres, as OpenSim writes them.
    NaN (unknown) values are written as ``nan``, which OpenSim reads as missing."""
    with JointAnglesMotWriter(path, angles.names, name=angles.name) as w:
        for a in range(0, angles.n_samples, _BLOCK_ROWS):
            w.write(angles.time[a : a + _BLOCK_ROWS], angles.values[a : a + _BLOCK_ROWS])
    return Path(path)


class JointAnglesMotWriter:
    """:func:`write_joint_angles_mot` as the angles come, row block by row block
    (the streamed body pipeline writes an hour this way in flat memory)."""

    def __init__(
        self, path: str | Path, names: tuple[str, ...], *, name: str = "joint_angles"
    ) -> None:
        self._rot = _rotational(tuple(names))
        self._w = TableWriter(path, list(names), name=name, in_degrees=True)

    def write(self, time: np.ndarray, values_rad: np.ndarray) -> None:
        """Append rows: ``time`` (N,) [s], coordinates (N, K) [rad; translations m]."""
        values = np.array(values_rad, dtype=float)
        values[:, self._rot] = np.rad2deg(values[:, self._rot])
        self._w.write(time, values)

    def close(self) -> None:
        self._w.close()

    def __enter__(self) -> JointAnglesMotWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_joint_angles_mot(path: str | Path) -> JointAngleSeries:
    """Read a ``.mot``/``.sto`` of coordinates; with ``inDegrees=yes`` the rotational ones
    are converted to radians. Translations (names ending ``_tx``, ``_ty``, ``_tz``, as
    OpenSim's ``pelvis_tx``) are metres in either case and are left as they are."""
    table = read_table(path)
    values = table.data.copy()
    if table.in_degrees:
        rot = _rotational(tuple(table.labels))
        values[:, rot] = np.deg2rad(values[:, rot])
    return JointAngleSeries(table.time, tuple(table.labels), values, name=Path(path).stem)


def iter_joint_angles_mot(path: str | Path, rows: int = _BLOCK_ROWS) -> Iterator[JointAngleSeries]:
    """:func:`read_joint_angles_mot` ``rows`` rows at a time (flat memory on an hour): the
    same checks, and time increasing across the pieces too."""
    t_last: float | None = None
    row0 = 0
    for table in iter_table(path, rows):
        values = table.data.copy()
        if table.in_degrees:
            rot = _rotational(tuple(table.labels))
            values[:, rot] = np.deg2rad(values[:, rot])
        _check_rows(path, table.time, values, t_last, row0)
        yield JointAngleSeries(table.time, tuple(table.labels), values, name=Path(path).stem)
        if table.time.size:
            t_last = float(table.time[-1])
        row0 += table.time.size


def _check_rows(
    path: str | Path, time: np.ndarray, values: np.ndarray, t_last: float | None, row0: int
) -> None:
    """A piece's rows checked as :class:`JointAngleSeries` checks a whole file, the bad row
    named by its number in the file (``row0``: rows before the piece)."""
    bad_t = np.flatnonzero(~np.isfinite(time))
    if bad_t.size:
        raise DataError(f"{path}: time is not a number at row {row0 + int(bad_t[0])}")
    before = np.concatenate([[t_last], time[:-1]]) if t_last is not None else time[:-1]
    after = time if t_last is not None else time[1:]
    back = np.flatnonzero(after <= before)
    if back.size:
        i = int(back[0]) + (0 if t_last is not None else 1)
        raise DataError(
            f"{path}: time not strictly increasing at row {row0 + i} ({before[back[0]]:.6f} s "
            f"then {after[back[0]]:.6f} s). Sort the rows and drop duplicates."
        )
    inf = np.argwhere(np.isinf(values))
    if inf.size:
        raise DataError(f"{path}: infinite value at row {row0 + int(inf[0][0])}")
