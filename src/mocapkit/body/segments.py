"""Calibrated segment orientations ``q_world_segment`` from sensor orientations, and the
documented fallbacks for sensors that drop out (NaN samples)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.calibration import BodyCalibration
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_mul
from mocapkit.series import OrientationSeries

DROPOUT_POLICIES = ("nan", "hold")


def hold_last_valid(
    quat: FloatArray, time: FloatArray, max_hold_s: float
) -> tuple[FloatArray, np.ndarray]:
    """Fill NaN rows of (N, 4) with the last valid row while the gap is at most
    ``max_hold_s`` old; returns the filled copy and the (N,) mask of held rows."""
    out = quat.copy()
    valid = np.isfinite(quat).all(axis=1)
    held = np.zeros(len(quat), dtype=bool)
    if valid.all() or not valid.any():
        return out, held
    last = np.where(valid, np.arange(len(quat)), -1)
    last = np.maximum.accumulate(last)
    can = (~valid) & (last >= 0)
    age = np.where(can, time - time[np.maximum(last, 0)], np.inf)
    fill = can & (age <= max_hold_s + 1e-12)
    out[fill] = quat[last[fill]]
    held[fill] = True
    return out, held


def sensor_array(
    tree: SensorTree,
    orientations: Mapping[str, OrientationSeries],
    *,
    dropout: str = "nan",
    max_hold_s: float = 0.5,
) -> tuple[FloatArray, FloatArray, dict[str, int]]:
    """(N,) time, (N, S, 4) sensor orientations in tree order, and {sensor: held samples}.

    All series must share one time base. With ``dropout="hold"`` a missing (NaN)
    orientation is replaced by the sensor's last valid one for up to ``max_hold_s``;
    longer gaps stay NaN. With ``"nan"`` nothing is filled.
    """
    if dropout not in DROPOUT_POLICIES:
        raise ConfigError(f"dropout: expected one of {DROPOUT_POLICIES}, got {dropout!r}")
    if not (np.isfinite(max_hold_s) and max_hold_s >= 0):
        raise ConfigError(f"max_hold_s: expected a non-negative time in seconds, got {max_hold_s}")
    tree.check_sensors(list(orientations))
    time = orientations[tree.segments[0].sensor].time
    q = np.empty((len(time), len(tree.segments), 4))
    held: dict[str, int] = {}
    for i, seg in enumerate(tree.segments):
        s = orientations[seg.sensor]
        if s.time.shape != time.shape or not np.array_equal(s.time, time):
            raise ConfigError(
                f"sensor {seg.sensor!r}: its time base differs from {tree.segments[0].sensor!r}; "
                "resample first (mocapkit.body.timebase.align_orientations)"
            )
        if dropout == "hold":
            q[:, i], mask = hold_last_valid(s.quat, time, max_hold_s)
            if mask.any():
                held[seg.sensor] = int(mask.sum())
        else:
            q[:, i] = s.quat
    return time, q, held


def apply_calibration(
    tree: SensorTree, calib: BodyCalibration, q_world_sensor: FloatArray
) -> FloatArray:
    """(N, S, 4) ``q_world_segment = q_heading * q_world_sensor * q_sensor_segment``."""
    calib.check_tree(tree)
    mount = np.stack([calib.segments[s.name].q_sensor_segment for s in tree.segments])
    heading = np.stack([calib.segments[s.name].q_heading for s in tree.segments])
    return quat_mul(quat_mul(heading[None], q_world_sensor), mount[None])


def segment_orientations(
    tree: SensorTree,
    calib: BodyCalibration,
    orientations: Mapping[str, OrientationSeries],
    *,
    dropout: str = "nan",
    max_hold_s: float = 0.5,
) -> dict[str, OrientationSeries]:
    """{segment: OrientationSeries ``q_world_segment``} (NaN where the sensor is missing)."""
    time, q, _ = sensor_array(tree, orientations, dropout=dropout, max_hold_s=max_hold_s)
    seg = apply_calibration(tree, calib, q)
    return {
        s.name: OrientationSeries(time, seg[:, i], name=s.name) for i, s in enumerate(tree.segments)
    }
