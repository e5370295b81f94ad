"""The subject of a marker reconstruction: the static trial checked, the stature and mass
(given, or estimated and said), the model scaled (from the static trial, or from the
trial's motion)."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.anthropometry import Sex
from mocapkit.body.markersets import MarkerSet
from mocapkit.body.scaling import Subject, scale_from_static
from mocapkit.errors import ConfigError, DataError
from mocapkit.markers.trajectories import MarkerTrajectories

log = logging.getLogger(__name__)

RIGID_PAIR_TOLERANCE_M = 0.015  # above: a warning (skin motion, a marker moved)
RIGID_PAIR_REFUSE_M = 0.04  # above: another subject, or swapped labels
STATIC_SPEED_REFUSE_M_S = 0.1  # a "static" trial whose stillest 0.5 s moves this fast
DEFAULT_MASS_KG = 75.0


class Warnings(list[str]):
    """Warnings that are logged as they are added and kept for the result."""

    def add(self, msg: str) -> None:
        log.warning("%s", msg)
        self.append(msg)


ACROMION_HEIGHT_RATIO = 0.818  # acromion height / stature (Drillis & Contini; de Leva)
_FEET = ("foot_r", "foot_l", "toes_r", "toes_l")
_SHOULDERS = ("clavicle_r", "clavicle_l")


def _extent(z: FloatArray) -> float | None:
    """Median over frames of the vertical extent of the visible markers (z (N, M)), or
    None when no frame shows two of them."""
    seen = np.isfinite(z).sum(axis=1) >= 2
    if not seen.any():
        return None
    zs = z[seen]
    top = np.max(np.where(np.isfinite(zs), zs, -np.inf), axis=1)
    bottom = np.min(np.where(np.isfinite(zs), zs, np.inf), axis=1)
    return float(np.median(top - bottom))


def estimate_height(
    traj: MarkerTrajectories, ms: MarkerSet | None = None, warnings: Warnings | None = None
) -> float:
    """Stature [m] from the markers (z-up).

    With head and foot markers: the median vertical extent of the markers (the head markers
    sit about a marker radius above the vertex, the foot markers about as far above the
    floor). Without head markers but with shoulders and feet: the acromion height over
    :data:`ACROMION_HEIGHT_RATIO` (a population ratio: a few centimetres either way), with
    a loud warning. Otherwise (or without a marker set to tell): refused, pass --height-m.
    """
    from mocapkit.body.anthropometry import HEIGHT_RANGE_M

    z = traj.positions[..., 2]
    if ms is not None:
        seg = {m.name: m.segment for m in ms.markers}
        cols = {s: [i for i, n in enumerate(traj.names) if seg.get(n) in s]
                for s in (("head",), _FEET, _SHOULDERS)}  # fmt: skip
        head, feet, shoulders = (cols[("head",)], cols[_FEET], cols[_SHOULDERS])
        if not feet or not (head or shoulders):
            lacking = "foot" if not feet else "head or shoulder"
            raise DataError(
                f"cannot estimate the stature: the trial has no {lacking} markers (the "
                "markers' height range would not be the body's); pass --height-m"
            )
        if not head:
            with np.errstate(invalid="ignore"):
                floor = np.nanmin(z[:, feet], axis=1)
                acromion = np.nanmean(z[:, shoulders], axis=1) - floor
            acromion = acromion[np.isfinite(acromion)]
            if acromion.size == 0:
                raise DataError(
                    "cannot estimate the stature: no frame shows a shoulder and a foot "
                    "marker together; pass --height-m"
                )
            h = float(np.median(acromion)) / ACROMION_HEIGHT_RATIO
            if warnings is not None:
                warnings.add(
                    f"NO HEAD MARKERS: the stature ({h:.3f} m) is estimated from the "
                    f"shoulder markers' height / {ACROMION_HEIGHT_RATIO} (a population ratio, "
                    "+-4 %); segment lengths and masses scale with it. Pass --height-m"
                )
            if not (HEIGHT_RANGE_M[0] <= h <= HEIGHT_RANGE_M[1]):
                raise DataError(
                    f"cannot estimate the stature from the shoulder markers ({h:.2f} m); "
                    "pass --height-m"
                )
            return h
    extent = _extent(z)
    if extent is None:
        raise DataError(
            "cannot estimate the stature: no frame shows two markers at once; pass --height-m"
        )
    h = extent
    if not (HEIGHT_RANGE_M[0] <= h <= HEIGHT_RANGE_M[1]):
        raise DataError(
            f"cannot estimate the stature from the markers (vertical extent {h:.2f} m); "
            "pass --height-m"
        )
    return h


def check_static_matches(
    static: MarkerTrajectories, trial: MarkerTrajectories, ms: MarkerSet, warnings: Warnings
) -> None:
    """Markers on one rigid segment keep their distance: compare the static trial with the
    trial (median over frames); a mismatch means another subject or relabelled markers."""
    index_s = {n: i for i, n in enumerate(static.names)}
    index_t = {n: i for i, n in enumerate(trial.names)}
    by_seg: dict[str, list[str]] = {}
    for m in ms.markers:
        if m.name in index_s and m.name in index_t:
            by_seg.setdefault(m.segment, []).append(m.name)
    worst: tuple[float, str, str, float, float] | None = None
    for names in by_seg.values():
        for i, a in enumerate(names):
            for b in names[i + 1 :]:
                d_s = np.linalg.norm(static.marker(a) - static.marker(b), axis=1)
                d_t = np.linalg.norm(trial.marker(a) - trial.marker(b), axis=1)
                d_s, d_t = d_s[np.isfinite(d_s)], d_t[np.isfinite(d_t)]
                if d_s.size == 0 or d_t.size == 0:
                    continue
                ds, dt = float(np.median(d_s)), float(np.median(d_t))
                if worst is None or abs(ds - dt) > worst[0]:
                    worst = (abs(ds - dt), a, b, float(ds), float(dt))
    if worst is None or worst[0] <= RIGID_PAIR_TOLERANCE_M:
        return
    _, a, b, ds, dt = worst
    what = (
        f"markers {a} and {b} sit on one segment but are {ds * 1000:.0f} mm apart in the "
        f"static trial and {dt * 1000:.0f} mm in the trial"
    )
    if worst[0] > RIGID_PAIR_REFUSE_M:
        raise DataError(
            f"the static trial does not match the trial: {what}. Use the same subject's "
            "static trial (or fix swapped labels)"
        )
    warnings.add(
        f"the static trial and the trial differ: {what} (a marker moved between them, or "
        "skin motion); its registered offset may be off by that much"
    )


def check_static_still(static: MarkerTrajectories) -> None:
    """Refuse a static trial that moves (a walking trial given as the static one): its
    stillest 0.5 s would be scaled as a standing pose."""
    from mocapkit.body.scaling import STATIC_WINDOW_S, static_speed

    speed = static_speed(static.time, static.positions)
    if speed > STATIC_SPEED_REFUSE_M_S:
        raise DataError(
            f"{static.meta.get('source', 'static trial')}: not a static trial: its stillest "
            f"{STATIC_WINDOW_S:.1f} s still moves at {speed * 1000:.0f} mm/s (mean marker "
            "speed). Pass a recording of the subject standing still, or omit --static to "
            "estimate the limb lengths from the trial"
        )


def calibrate(
    static: MarkerTrajectories | None,
    trial: MarkerTrajectories,
    ms: MarkerSet,
    height_m: float,
    mass_kg: float,
    sex: Sex = "male",
) -> Subject:
    """A scaled subject from the static trial, or from the trial itself when there is none."""
    if static is not None:
        return scale_from_static(
            static.names, static.time, static.positions, ms, height_m, mass_kg, sex
        )
    from mocapkit.body.scaling import estimate_scales_from_motion

    return estimate_scales_from_motion(trial.names, trial.positions, ms, height_m, mass_kg, sex)


def check_static_is_not_trial(trial_path: str | Path, static_path: str | Path | None) -> None:
    if static_path is not None and Path(static_path).resolve() == Path(trial_path).resolve():
        raise ConfigError(
            f"--static {static_path} is the trial itself; a static trial is a separate "
            "recording of the subject standing still. Pass it, or omit --static to estimate "
            "the limb lengths from the trial"
        )


def scaled_subject(
    trial: MarkerTrajectories,
    static: MarkerTrajectories | None,
    ms: MarkerSet,
    height_m: float | None,
    mass_kg: float | None,
    sex: Sex,
    warn: Warnings,
) -> Subject:
    """The static trial checked, the stature and mass (estimated or assumed, said), the
    subject scaled (from the static trial, or from the trial's motion)."""
    if static is not None:
        check_static_still(static)
        check_static_matches(static, trial, ms, warn)
    if height_m is None:
        n_before = len(warn)
        height_m = estimate_height(static if static is not None else trial, ms, warn)
        if len(warn) == n_before:
            warn.add(
                f"no --height-m given: {height_m:.3f} m estimated from the markers' extent "
                "(head to feet)"
            )
    if mass_kg is None:
        mass_kg = DEFAULT_MASS_KG
        warn.add(
            f"no --mass-kg given: {mass_kg:.0f} kg assumed for the segment masses (they set "
            "the simulated dynamics of direct marker control, not IK's angles)"
        )
    scale_static = static
    if static is not None and ms.description.startswith("assigned automatically"):
        warn.add(
            "the marker set was assigned automatically, so its markers have no known place "
            "on their segments to start a static registration from: the limb lengths and "
            "marker places are estimated from the trial's motion; the static trial gave the "
            "stature only"
        )
        scale_static = None
    return calibrate(scale_static, trial, ms, height_m, mass_kg, sex)
