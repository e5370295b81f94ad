"""Joint angles as OpenSim motion files (``.mot``, degrees), through io/opensim_table."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mocapkit.io.opensim_table import read_table, write_table
from mocapkit.series import JointAngleSeries

_TRANSLATIONS = ("_tx", "_ty", "_tz")


def _rotational(names: tuple[str, ...]) -> np.ndarray:
    return np.array([not label.endswith(_TRANSLATIONS) for label in names], dtype=bool)


def write_joint_angles_mot(path: str | Path, angles: JointAngleSeries) -> Path:
    """Write rotational coordinates [rad] as degrees (``inDegrees=yes``), OpenSim's layout;
    translations (``_tx``, ``_ty``, ``_tz``) stay metres, as OpenSim writes them.
    NaN (unknown) values are written as ``nan``, which OpenSim reads as missing."""
    values = np.array(angles.values, dtype=float)
    rot = _rotational(angles.names)
    values[:, rot] = np.rad2deg(values[:, rot])
    return write_table(path, angles.time, list(angles.names), values, name=angles.name)


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
