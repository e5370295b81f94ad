"""Input validation for the orientation filters: one batch of samples -> the arrays the
kernels take (:class:`FilterInputs`) and what was done with doubtful samples
(:class:`RunReport`). Used by :class:`mocapkit.imu.filters.base.OrientationFilter`."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from mocapkit._validate import FloatArray, as_float_array, check_finite, check_shape
from mocapkit.errors import DataError, MocapkitError
from mocapkit.imu.filters.inputs_kernel import scan_inputs

# A sample whose norm is below this (in its own unit) has no direction.
MIN_VECTOR_NORM = 1e-6
# Saturation: a component whose magnitude reaches this fraction of the full-scale range.
_SATURATION_FRACTION = 0.999


class SensorSaturationWarning(RuntimeWarning):
    """The gyroscope reached its full-scale range: the integrated rotation is too small."""


class FilterInputs(NamedTuple):
    """Validated arrays handed to the implementations (all C-contiguous).

    ``mag`` is (N, 3) in both modes (zeros where unused); ``use_acc``/``use_mag`` say per
    sample whether the accelerometer / magnetometer correction applies.
    """

    gyr: FloatArray
    acc: FloatArray
    mag: FloatArray
    dt: FloatArray
    use_acc: np.ndarray
    use_mag: np.ndarray


@dataclass(frozen=True)
class RunReport:
    """What the last ``run`` did with doubtful samples (counts of samples)."""

    n_samples: int
    acc_rejected: int = 0  # zero-norm or saturated accelerometer: correction skipped
    mag_gaps: int = 0  # all-NaN magnetometer rows: processed as 6D
    mag_rejected: int = 0  # zero-norm magnetometer: processed as 6D
    gyr_saturated: int = 0  # integrated as clipped (warned)
    initialised_here: bool = False  # the run started by initialising from its first samples


def _check_mag_rows(mag: FloatArray) -> np.ndarray:
    """Return the (N,) gap mask (all-NaN rows); raise on partly NaN rows or inf."""
    gap: np.ndarray = np.asarray(np.isnan(mag).all(axis=1))
    bad = ~np.isfinite(mag) & ~gap[:, None]
    if bad.any():
        i, c = (int(v) for v in np.argwhere(bad)[0])
        raise DataError(
            f"mag: non-finite value at sample {i}, column {c} ({int(bad.any(axis=1).sum())} "
            "bad samples); mark a magnetometer gap with all three components NaN"
        )
    return gap


def _dt_array(dt: Any, n: int, default: float) -> FloatArray:
    if dt is None:
        return np.full(n, default)
    arr = as_float_array(dt, "dt")
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    check_shape(arr, "dt", n)
    bad = np.flatnonzero(~(np.isfinite(arr) & (arr > 0.0)))
    if bad.size:
        i = int(bad[0])
        raise DataError(
            f"dt: sample {i} has time step {float(arr[i])!r} s; time steps must be positive and "
            "finite (sort the samples and drop duplicated time stamps)"
        )
    return arr


def prepare_inputs(
    gyr: Any,
    acc: Any,
    mag: Any,
    dt: Any,
    default_dt: float,
    acc_range: float | None = None,
    gyr_range: float | None = None,
) -> tuple[FilterInputs, RunReport]:
    """Validate a batch and build the kernels' inputs and the report (see base.py's
    module docstring for every case). ``default_dt`` [s] is used when ``dt`` is None;
    ``acc_range`` [m/s^2] and ``gyr_range`` [rad/s] are the full-scale ranges or None.

    A clean batch takes one numba pass (:mod:`mocapkit.imu.filters.inputs_kernel`);
    anything doubtful takes the numpy checks below, which raise or warn naming the sample.
    """
    fast = _prepare_clean(gyr, acc, mag, dt, default_dt, acc_range, gyr_range)
    if fast is not None:
        return fast
    return _prepare_checked(gyr, acc, mag, dt, default_dt, acc_range, gyr_range)


def _prepare_clean(
    gyr: Any,
    acc: Any,
    mag: Any,
    dt: Any,
    default_dt: float,
    acc_range: float | None,
    gyr_range: float | None,
) -> tuple[FilterInputs, RunReport] | None:
    """:func:`prepare_inputs` for a clean batch (the same arrays and report), or None when
    the batch needs the numpy checks (bad shape or value, saturated gyroscope)."""
    try:
        g = np.ascontiguousarray(as_float_array(gyr, "gyr"))
        a = np.ascontiguousarray(as_float_array(acc, "acc"))
        m = None if mag is None else np.ascontiguousarray(as_float_array(mag, "mag"))
    except MocapkitError:
        return None
    n = g.shape[0] if g.ndim == 2 else -1
    if g.shape != (n, 3) or a.shape != (n, 3) or (m is not None and m.shape != (n, 3)):
        return None
    use_acc = np.empty(n, dtype=bool)
    use_mag = np.empty(n, dtype=bool)
    clean, acc_rejected, mag_gaps, mag_rejected = scan_inputs(
        g,
        a,
        g if m is None else m,
        m is not None,
        MIN_VECTOR_NORM,
        math.inf if acc_range is None else _SATURATION_FRACTION * acc_range,
        math.inf if gyr_range is None else _SATURATION_FRACTION * gyr_range,
        use_acc,
        use_mag,
    )
    if not clean:
        return None
    steps = np.ascontiguousarray(_dt_array(dt, n, default_dt))
    inputs = FilterInputs(g, a, np.zeros((n, 3)) if m is None else m, steps, use_acc, use_mag)
    return inputs, RunReport(n, acc_rejected, mag_gaps, mag_rejected, 0)


def _prepare_checked(
    gyr: Any,
    acc: Any,
    mag: Any,
    dt: Any,
    default_dt: float,
    acc_range: float | None,
    gyr_range: float | None,
) -> tuple[FilterInputs, RunReport]:
    """:func:`prepare_inputs` with numpy checks that name the first bad sample."""
    g = as_float_array(gyr, "gyr")
    check_shape(g, "gyr", None, 3)
    a = as_float_array(acc, "acc")
    check_shape(a, "acc", g.shape[0], 3)
    fix = "Interpolate or drop the sample (ImuRecording.with_gaps_interpolated)."
    check_finite(g, "gyr", fix)
    check_finite(a, "acc", fix)
    n = g.shape[0]
    steps = _dt_array(dt, n, default_dt)
    acc_norm = np.linalg.norm(a, axis=1)
    use_acc = acc_norm > MIN_VECTOR_NORM
    if acc_range is not None:
        use_acc &= ~(np.abs(a) >= _SATURATION_FRACTION * acc_range).any(axis=1)
    gyr_saturated = 0
    if gyr_range is not None:
        sat = (np.abs(g) >= _SATURATION_FRACTION * gyr_range).any(axis=1)
        gyr_saturated = int(sat.sum())
        if gyr_saturated:
            i = int(np.flatnonzero(sat)[0])
            warnings.warn(
                f"gyr: saturated at sample {i} ({gyr_saturated} samples reach the "
                f"{gyr_range:g} rad/s range); the rotation there is "
                "underestimated and only the accelerometer/magnetometer correction "
                "recovers it. Use a larger gyroscope range if the device has one.",
                SensorSaturationWarning,
                stacklevel=5,  # the caller of OrientationFilter.run
            )
    mag_gaps = mag_rejected = 0
    if mag is None:
        m = np.zeros((n, 3))
        use_mag = np.zeros(n, dtype=bool)
    else:
        m = as_float_array(mag, "mag")
        check_shape(m, "mag", n, 3)
        gap = _check_mag_rows(m)
        m = np.where(gap[:, None], 0.0, m)
        nonzero = np.linalg.norm(m, axis=1) > MIN_VECTOR_NORM
        use_mag = ~gap & nonzero
        mag_gaps = int(gap.sum())
        mag_rejected = int((~gap & ~nonzero).sum())
    inputs = FilterInputs(
        np.ascontiguousarray(g),
        np.ascontiguousarray(a),
        np.ascontiguousarray(m),
        np.ascontiguousarray(steps),
        np.ascontiguousarray(use_acc),
        np.ascontiguousarray(use_mag),
    )
    report = RunReport(n, int((~use_acc).sum()), mag_gaps, mag_rejected, gyr_saturated)
    return inputs, report
