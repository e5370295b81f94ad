"""C3D marker files through ezc3d: read and write.

Read: ``POINT:UNITS`` converted to metres, axes kept as in the file (C3D files from
Vicon and Qualisys are usually z-up; ``meta["up_axis"]`` is unknown until checked
against the static trial), points with a negative residual or at exactly (0, 0, 0)
become NaN, unlabelled points (labels starting with ``*``, empty, or ``uname*``) are
dropped and listed in ``meta["dropped_unlabelled"]``, and a Vicon subject prefix
common to all labels (``Male:LFHD``) is stripped (``meta["label_prefix"]``).
Write: millimetres, residual -1 for gaps.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.errors import FileFormatError, MissingDependencyError
from mocapkit.io.units import length_scale
from mocapkit.markers.trajectories import MarkerTrajectories

log = logging.getLogger(__name__)

_UNLABELLED = re.compile(r"^(\*\d*|uname\*?\d*|unlabeled.*|unlabelled.*|)$", re.IGNORECASE)


def _ezc3d() -> Any:
    try:
        import ezc3d
    except ImportError as exc:  # pragma: no cover - ezc3d is a core dependency
        raise MissingDependencyError("reading C3D needs ezc3d: pip install ezc3d") from exc
    return ezc3d


def _labels(point: dict[str, Any], used: int) -> list[str]:
    labels: list[str] = list(point["LABELS"]["value"])
    k = 2
    while len(labels) < used and f"LABELS{k}" in point:
        labels += list(point[f"LABELS{k}"]["value"])
        k += 1
    return [str(s).strip() for s in labels[:used]]


def _strip_prefix(labels: list[str]) -> tuple[list[str], str]:
    prefixes = {s.rsplit(":", 1)[0] for s in labels if ":" in s}
    if len(prefixes) == 1 and all(":" in s for s in labels):
        prefix = prefixes.pop()
        return [s.rsplit(":", 1)[1] for s in labels], prefix + ":"
    return labels, ""


def read_c3d(path: str | Path, units: str | None = None) -> MarkerTrajectories:
    """Read the labelled points of a C3D file.

    Args:
        path: the ``.c3d`` file.
        units: override ``POINT:UNITS`` (``"mm"``, ``"cm"``, ``"m"``).
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such C3D file")
    ezc3d = _ezc3d()
    try:
        c3d = ezc3d.c3d(str(p))
    except (RuntimeError, ValueError, IndexError, OSError) as exc:
        raise FileFormatError(f"{p}: not a readable C3D file ({exc})") from exc
    point = c3d["parameters"]["POINT"]
    used = int(point["USED"]["value"][0])
    if used == 0:
        raise FileFormatError(f"{p}: the file holds no 3-D points (POINT:USED = 0)")
    labels = _labels(point, used)
    if len(labels) < used:
        raise FileFormatError(f"{p}: POINT:LABELS names {len(labels)} of {used} points")
    rate = float(point["RATE"]["value"][0])
    if not rate > 0:
        raise FileFormatError(f"{p}: POINT:RATE is {rate}; pass the frame rate explicitly")
    declared = units or (point["UNITS"]["value"][0] if point["UNITS"]["value"] else "")
    if not declared:
        raise FileFormatError(f"{p}: POINT:UNITS is empty; pass units='mm' (or 'm')")
    scale = length_scale(declared, f"{p}: POINT:UNITS")
    pts = np.asarray(c3d["data"]["points"], dtype=float)[:3]  # (3, M, N)
    residuals = np.asarray(c3d["data"]["meta_points"]["residuals"], dtype=float)[0]
    pos = np.transpose(pts, (2, 1, 0)).copy()  # (N, M, 3)
    bad = (residuals.T < 0) | np.all(pos == 0.0, axis=2) | ~np.isfinite(pos).all(axis=2)
    pos[bad] = np.nan
    keep = [i for i, s in enumerate(labels) if not _UNLABELLED.match(s)]
    dropped = [labels[i] or f"<point {i}>" for i in range(used) if i not in keep]
    if dropped:
        log.warning(
            "%s: dropped %d unlabelled points (%s); label them in your capture software to "
            "use them",
            p,
            len(dropped),
            ", ".join(dropped[:10]) + (" ..." if len(dropped) > 10 else ""),
        )
    names, prefix = _strip_prefix([labels[i] for i in keep])
    first = int(c3d["header"]["points"]["first_frame"])
    n = pos.shape[0]
    meta: dict[str, Any] = {
        "source": str(p),
        "format": "c3d",
        "units": declared,
        "rate_hz": rate,
        "up_axis": None,
        "up_axis_source": "unknown (C3D does not declare it)",
        "label_prefix": prefix,
        "dropped_unlabelled": dropped,
        "first_frame": first,
    }
    time = (first + np.arange(n)) / rate
    return MarkerTrajectories(time, pos[:, keep] * scale, tuple(names), meta=meta)


def write_c3d(path: str | Path, trajectories: MarkerTrajectories) -> Path:
    """Write trajectories (metres) as a C3D file in millimetres; gaps get residual -1."""
    p = Path(path)
    ezc3d = _ezc3d()
    traj = trajectories
    c3d = ezc3d.c3d()
    point = c3d["parameters"]["POINT"]
    point["RATE"]["value"] = [traj.rate_hz]
    point["LABELS"]["value"] = tuple(traj.names)
    point["UNITS"]["value"] = ["mm"]
    pts = np.ones((4, traj.n_markers, traj.n_frames))
    mm = np.transpose(traj.positions, (2, 1, 0)) * 1000.0
    visible = np.asarray(np.isfinite(mm).all(axis=0))
    pts[:3] = np.where(visible[None], mm, 0.0)
    c3d["data"]["points"] = pts
    residuals = np.where(visible, 0.0, -1.0)[None]
    c3d["data"]["meta_points"] = {
        "residuals": residuals,
        "camera_masks": np.zeros((7, traj.n_markers, traj.n_frames), dtype=bool),
    }
    c3d.write(str(p))
    return p
