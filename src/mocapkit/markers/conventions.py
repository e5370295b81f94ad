"""Units and axis conventions of marker files: detect, check, convert to SI and z-up.

Files declare units (C3D ``POINT:UNITS``, TRC ``Units``) but not always correctly, and
they use y-up (OpenSim, Motion Analysis) or z-up (Vicon, Qualisys) axes. Both are checked
against the body itself: a person's markers span 0.3-3 m, and in a static trial the head
is above the feet.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import DataError
from mocapkit.markers.trajectories import MarkerTrajectories

log = logging.getLogger(__name__)

BODY_SIZE_RANGE_M = (0.3, 3.0)
_UNIT_FACTORS = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}

# Rotations R with x_zup = R @ x_file for each "up" axis of the file.
_TO_Z_UP: dict[str, FloatArray] = {
    "z": np.eye(3),
    "-z": np.diag([1.0, -1.0, -1.0]),
    "y": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
    "-y": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
    "x": np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
    "-x": np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]),
}
UP_AXES = tuple(_TO_Z_UP)
UPPER_SEGMENTS = ("head", "neck", "thorax", "abdomen", "clavicle_r", "clavicle_l")
LOWER_SEGMENTS = (
    "foot_r",
    "foot_l",
    "toes_r",
    "toes_l",
    "talus_r",
    "talus_l",
    "shank_r",
    "shank_l",
)


def rotation_to_z_up(up_axis: str) -> FloatArray:
    """The proper rotation taking a file whose up axis is ``up_axis`` to z-up."""
    try:
        return _TO_Z_UP[up_axis].copy()
    except KeyError:
        raise DataError(f"up_axis: expected one of {', '.join(UP_AXES)}, got {up_axis!r}") from None


def to_z_up(traj: MarkerTrajectories, up_axis: str) -> MarkerTrajectories:
    """Rotate trajectories from a file with ``up_axis`` up into the z-up world."""
    R = rotation_to_z_up(up_axis)
    return traj.with_positions(
        traj.positions @ R.T, {"up_axis": "z", "converted_from_up_axis": up_axis}
    )


def body_size_m(traj: MarkerTrajectories) -> float:
    """The body's size: median over frames of the largest extent of the visible markers."""
    pos = traj.positions
    vis = traj.visible
    sizes = []
    step = max(1, traj.n_frames // 200)
    for f in range(0, traj.n_frames, step):
        pts = pos[f, vis[f]]
        if len(pts) >= 3:
            sizes.append(float((pts.max(axis=0) - pts.min(axis=0)).max()))
    if not sizes:
        raise DataError(
            f"{traj.meta.get('source', 'trajectories')}: no frame has 3 visible markers; "
            "cannot reconstruct anything"
        )
    return float(np.median(sizes))


@dataclass(frozen=True)
class UnitCheck:
    factor: float  # multiply positions by this to get metres
    size_m: float  # body size after the correction
    message: str  # empty when nothing was corrected


def check_units(traj: MarkerTrajectories, explicit: bool = False) -> UnitCheck:
    """Check the body's size in metres; propose a factor when a unit mistake is obvious.

    Args:
        traj: trajectories as read (already in metres according to the declared units).
        explicit: the caller stated the units; a mismatch is then an error, not a fix.
    """
    size = body_size_m(traj)
    lo, hi = BODY_SIZE_RANGE_M
    src = traj.meta.get("source", "trajectories")
    declared = traj.meta.get("units", "?")
    if lo <= size <= hi:
        return UnitCheck(1.0, size, "")
    for name, factor in (("mm", 1e-3), ("cm", 1e-2), ("m", 1e3)):
        if lo <= size * factor <= hi:
            guess = {"mm": "millimetres", "cm": "centimetres", "m": "metres"}[name]
            unit = name if name != "m" else "m"
            msg = (
                f"{src}: the markers span {size:.4g} m with the declared units "
                f"{declared!r}, which is not a human body; the data look like {guess}"
            )
            if explicit:
                raise DataError(f"{msg}. Fix: pass --units {unit} (or omit --units)")
            log.warning("%s; converted (pass --units to override)", msg)
            return UnitCheck(factor, size * factor, msg)
    raise DataError(
        f"{src}: the markers span {size:.4g} m with the declared units {declared!r}; no unit "
        "(mm, cm, m) makes that a human body. Check the file's labels and units"
    )


def apply_units(traj: MarkerTrajectories, check: UnitCheck) -> MarkerTrajectories:
    if check.factor == 1.0:
        return traj
    return traj.with_positions(traj.positions * check.factor, {"unit_correction": check.factor})


@dataclass(frozen=True)
class UpAxisCheck:
    axis: str  # detected up axis of the file
    angle_deg: float  # angle between the body's up direction and that axis


def detect_up_axis(
    static: MarkerTrajectories, marker_segments: Mapping[str, str]
) -> UpAxisCheck | None:
    """The file's up axis from a static trial: upper-body markers minus foot/shank markers.

    Args:
        static: the static trial (file axes).
        marker_segments: trial marker name -> model segment (from the marker set).

    Returns:
        The nearest signed axis, or None when the trial lacks upper or lower markers.
    """
    up_idx = [i for i, n in enumerate(static.names) if marker_segments.get(n) in UPPER_SEGMENTS]
    lo_idx = [i for i, n in enumerate(static.names) if marker_segments.get(n) in LOWER_SEGMENTS]
    if not up_idx or not lo_idx:
        return None
    pos = static.positions
    with np.errstate(invalid="ignore"):
        upper = np.nanmean(pos[:, up_idx], axis=(0, 1))
        lower = np.nanmean(pos[:, lo_idx], axis=(0, 1))
    d = upper - lower
    if not np.isfinite(d).all() or np.linalg.norm(d) < 1e-9:
        return None
    d /= np.linalg.norm(d)
    k = int(np.argmax(np.abs(d)))
    axis = ("-" if d[k] < 0 else "") + "xyz"[k]
    angle = float(np.degrees(np.arccos(min(1.0, abs(d[k])))))
    return UpAxisCheck(axis, angle)


def resolve_up_axis(
    static: MarkerTrajectories,
    marker_segments: Mapping[str, str],
    requested: str = "auto",
    max_tilt_deg: float = 30.0,
) -> str:
    """Decide the file's up axis: ``requested`` if given (checked against the static trial),
    else the detected one, else the file's hint (``meta["up_axis"]``), else z."""
    src = static.meta.get("source", "static trial")
    found = detect_up_axis(static, marker_segments)
    if found is not None and found.angle_deg > max_tilt_deg:
        log.warning(
            "%s: the body's up direction is %.0f deg from the nearest axis %s; is the subject "
            "standing?",
            src,
            found.angle_deg,
            found.axis,
        )
        found = None
    if requested != "auto":
        rotation_to_z_up(requested)  # validates the name
        if found is not None and found.axis != requested:
            raise DataError(
                f"{src}: the static trial's head markers are above its foot markers along "
                f"{found.axis}, but the up axis was given as {requested}. Fix: pass "
                f"--up-axis {found.axis} (or --up-axis auto)"
            )
        return requested
    if found is not None:
        hint = static.meta.get("up_axis")
        if hint and hint != found.axis:
            log.warning(
                "%s: the file convention suggests %s-up but the body is %s-up; using %s",
                src,
                hint,
                found.axis,
                found.axis,
            )
        return found.axis
    hint = static.meta.get("up_axis")
    if hint:
        log.warning("%s: cannot see which way is up; using the file's convention (%s)", src, hint)
        return str(hint)
    log.warning("%s: cannot see which way is up; assuming z (pass --up-axis)", src)
    return "z"
