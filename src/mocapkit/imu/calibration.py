"""Rest detection, gyroscope bias from a rest period, and the start-of-recording
calibration the paper performs at power-up (averaged stationary samples).

Magnetometer hard- and soft-iron calibration is in :mod:`mocapkit.imu.mag_calibration`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from mocapkit._validate import FloatArray, as_float_array, check_finite, check_shape
from mocapkit.errors import ConfigError, DataError
from mocapkit.imu.initialisation import ReferenceVectors, reference_vectors
from mocapkit.series import ImuRecording

# Defaults for a body-worn MEMS IMU: rest means the rate stays below 2 deg/s (several
# times the noise and bias of such gyroscopes) and the specific force varies by less
# than 0.3 m/s^2 around its local mean, for at least half a second.
DEFAULT_GYR_THRESHOLD = np.radians(2.0)  # [rad/s]
DEFAULT_ACC_THRESHOLD = 0.3  # [m/s^2]
DEFAULT_MIN_DURATION = 0.5  # [s]
DEFAULT_WINDOW = 0.2  # [s]


@dataclass(frozen=True)
class RestPeriod:
    """Samples ``start:stop`` (stop exclusive) at rest."""

    start: int
    stop: int

    @property
    def n_samples(self) -> int:
        return self.stop - self.start


def detect_rest(
    gyr: Any,
    acc: Any,
    rate_hz: float,
    *,
    gyr_threshold: float = DEFAULT_GYR_THRESHOLD,
    acc_threshold: float = DEFAULT_ACC_THRESHOLD,
    window_s: float = DEFAULT_WINDOW,
    min_duration_s: float = DEFAULT_MIN_DURATION,
) -> np.ndarray:
    """(N,) bool: samples at rest.

    A sample is at rest when, over the centred window of ``window_s`` seconds, every
    gyroscope norm [rad/s] stays below ``gyr_threshold`` and every accelerometer sample
    stays within ``acc_threshold`` [m/s^2] of the window mean; runs of rest shorter
    than ``min_duration_s`` are dropped. The gyroscope bias (typically < 1 deg/s) is
    far below the default threshold, so no bias correction is needed first.
    """
    g = as_float_array(gyr, "gyr")
    a = as_float_array(acc, "acc")
    check_shape(g, "gyr", None, 3)
    check_shape(a, "acc", g.shape[0], 3)
    check_finite(g, "gyr")
    check_finite(a, "acc")
    for value, name in (
        (rate_hz, "rate_hz"),
        (gyr_threshold, "gyr_threshold"),
        (acc_threshold, "acc_threshold"),
        (window_s, "window_s"),
    ):
        if not (np.isfinite(value) and value > 0):
            raise ConfigError(f"{name}: expected a positive value, got {value}")
    n = g.shape[0]
    win = max(1, round(window_s * rate_hz))
    if n < win:
        return np.zeros(n, dtype=bool)
    gyr_norm = np.linalg.norm(g, axis=1)
    gyr_max = sliding_window_view(gyr_norm, win).max(axis=1)
    acc_win = sliding_window_view(a, win, axis=0)  # (n - win + 1, 3, win)
    acc_dev = np.linalg.norm(acc_win - acc_win.mean(axis=2, keepdims=True), axis=1).max(axis=1)
    quiet = (gyr_max < gyr_threshold) & (acc_dev < acc_threshold)
    # every sample of a quiet window is at rest: window k covers samples k .. k + win - 1
    rest = np.convolve(quiet.astype(np.int64), np.ones(win, dtype=np.int64)) > 0
    min_len = max(1, round(min_duration_s * rate_hz))
    for period in rest_periods(rest):
        if period.n_samples < min_len:
            rest[period.start : period.stop] = False
    return rest


def rest_periods(rest: Any) -> list[RestPeriod]:
    """Contiguous runs of True in a (N,) mask."""
    mask = np.asarray(rest, dtype=bool).reshape(-1)
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1)
    return [RestPeriod(int(a), int(b)) for a, b in zip(starts, stops, strict=True)]


def gyro_bias(gyr: Any, rest: Any) -> FloatArray:
    """Gyroscope bias [rad/s] (3,): the mean rate over the samples marked at rest."""
    g = as_float_array(gyr, "gyr")
    check_shape(g, "gyr", None, 3)
    mask = np.asarray(rest, dtype=bool).reshape(-1)
    if mask.shape[0] != g.shape[0]:
        raise DataError(f"rest: expected {g.shape[0]} samples, got {mask.shape[0]}")
    if not mask.any():
        raise DataError(
            "rest: no sample at rest, so the gyroscope bias cannot be measured; record "
            "the sensor lying still for a second or two (or relax the rest thresholds)"
        )
    return np.asarray(g[mask].mean(axis=0))


def remove_gyro_bias(rec: ImuRecording, bias: Any) -> ImuRecording:
    """A copy of ``rec`` with ``bias`` [rad/s] (3,) subtracted from the gyroscope."""
    b = as_float_array(bias, "bias")
    check_shape(b, "bias", 3)
    meta = dict(rec.meta)
    meta["gyr_bias_removed"] = b.tolist()
    return ImuRecording(rec.time, rec.gyr - b, rec.acc, rec.mag, name=rec.name, meta=meta)


@dataclass(frozen=True)
class RestCalibration:
    """What a stationary period gives: gyroscope bias and the paper's reference vectors."""

    period: RestPeriod
    gyr_bias: FloatArray  # (3,) rad/s
    references: ReferenceVectors


def calibrate_from_rest(
    rec: ImuRecording,
    *,
    use_mag: bool = True,
    first: bool = True,
    gyr_threshold: float = DEFAULT_GYR_THRESHOLD,
    min_duration_s: float = DEFAULT_MIN_DURATION,
) -> RestCalibration:
    """Find a rest period (the first one, else the longest; see :func:`detect_rest`) and
    measure the gyroscope bias, ``g_ref`` and the dip-corrected ``m_ref`` from it
    (paper, section 3)."""
    rest = detect_rest(
        rec.gyr, rec.acc, rec.rate_hz, gyr_threshold=gyr_threshold, min_duration_s=min_duration_s
    )
    periods = rest_periods(rest)
    if not periods:
        raise DataError(
            f"{rec.name}: no rest period found (gyroscope below "
            f"{np.degrees(gyr_threshold):.3g} deg/s for {min_duration_s:g} s); keep the "
            "sensor still at the start of the recording"
        )
    period = periods[0] if first else max(periods, key=lambda p: p.n_samples)
    sl = slice(period.start, period.stop)
    mask = np.zeros(rec.n_samples, dtype=bool)
    mask[sl] = True
    bias = gyro_bias(rec.gyr, mask)
    mag = None
    if use_mag and rec.mag is not None and rec.mag_valid[sl].any():
        mag = rec.mag[sl][rec.mag_valid[sl]]
    return RestCalibration(period, bias, reference_vectors(rec.acc[sl], mag))
