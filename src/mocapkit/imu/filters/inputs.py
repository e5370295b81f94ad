"""Input validation for the orientation filters: one batch of samples -> the arrays the
kernels take (:class:`FilterInputs`) and what was done with doubtful samples
(:class:`RunReport`). Used by :class:`mocapkit.imu.filters.base.OrientationFilter`."""

from __future__ import annotations

import dataclasses
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


# A gyroscope axis that sits at its extreme reading of the batch, at least CLIP_MIN_RATE
# [rad/s], for CLIP_RUN samples in a row is clipped (flat-topped at a range nobody gave):
# a smooth peak read by a 16-bit converter repeats its top value 2-3 times at most.
CLIP_MIN_RATE = 4.0
CLIP_RUN = 5


class SensorSaturationWarning(RuntimeWarning):
    """The gyroscope reached its full-scale range: the integrated rotation is too small."""


class TimeGapWarning(RuntimeWarning):
    """A time step far longer than the nominal one: the gap is held, never integrated."""


class FilterInputs(NamedTuple):
    """Validated arrays handed to the implementations (all C-contiguous).

    ``mag`` is (N, 3) in both modes (zeros where unused); ``use_acc``/``use_mag`` say per
    sample whether the accelerometer / magnetometer correction applies; ``gap`` marks the
    samples that follow a time gap (their ``dt`` is already the nominal step) and
    ``saturated`` the gyroscope samples at the range or clipped: a filter that can
    restart after a fault (``polaris``) does so at those samples.
    """

    gyr: FloatArray
    acc: FloatArray
    mag: FloatArray
    dt: FloatArray
    use_acc: np.ndarray
    use_mag: np.ndarray
    gap: np.ndarray
    saturated: np.ndarray


@dataclass(frozen=True)
class RunReport:
    """What the last ``run`` did with doubtful samples (counts of samples)."""

    n_samples: int
    acc_rejected: int = 0  # zero-norm or saturated accelerometer: correction skipped
    mag_gaps: int = 0  # all-NaN magnetometer rows: processed as 6D
    mag_rejected: int = 0  # zero-norm magnetometer: processed as 6D
    gyr_saturated: int = 0  # integrated as clipped (warned)
    initialised_here: bool = False  # the run started by initialising from its first samples
    gaps: tuple[tuple[int, float], ...] = ()  # (sample, seconds) of each time gap held (warned)


# A time step this many nominal steps long has lost samples in it (a jittery clock stays
# well below 1.5).
LOST_STEP_FACTOR = 1.5


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


def hold_time_gaps(
    steps: FloatArray, default_dt: float, gap_factor: float, integrate_s: float = 0.0
) -> tuple[FloatArray, np.ndarray, tuple[tuple[int, float], ...]]:
    """Time steps longer than ``gap_factor`` nominal steps and than ``integrate_s`` are
    gaps (missing samples, a clock that jumped): what the sensor turned through in them is
    unknown, so integrating the next reading over the whole gap would be wrong by an
    arbitrary rotation. Such a step is replaced by the nominal one (the gap is held) and
    warned about, naming the sample and the length. Shorter steps (a few lost packets: a
    limb's rate hardly changes in a quarter second) are integrated over their true length:
    holding them would lose the rotation, for good in 6D. Returns ``(steps, gap_mask,
    ((sample, seconds), ...))``."""
    mask = steps > max(gap_factor * default_dt, integrate_s)
    if not mask.any():
        return steps, mask, ()
    where = np.flatnonzero(mask)
    gaps = tuple((int(i), float(steps[i])) for i in where)
    first, length = gaps[0]
    warnings.warn(
        f"dt: time gap of {length:.3g} s before sample {first} ({len(gaps)} gap(s) longer than "
        f"{max(gap_factor * default_dt, integrate_s):.3g} s); held, not integrated: the "
        "filter re-acquires its orientation after it (polaris) or carries it across. "
        "Check the recording's clock or fill the gap if the samples exist.",
        TimeGapWarning,
        stacklevel=5,  # the caller of OrientationFilter.run
    )
    held = steps.copy()
    held[where] = default_dt
    return held, mask, gaps


def clipped_gyr(g: FloatArray) -> np.ndarray:
    """(N,) samples where a gyroscope axis is flat-topped: its largest magnitude in the
    batch, at least ``CLIP_MIN_RATE``, for ``CLIP_RUN`` samples in a row (a range the
    caller did not give; with ``gyr_range`` any sample at the range counts)."""
    n = g.shape[0]
    out = np.zeros(n, dtype=bool)
    if n < CLIP_RUN:
        return out
    mag = np.abs(g)
    top = mag.max(axis=0)
    at_top = (mag == top) & (top >= CLIP_MIN_RATE)  # (N, 3)
    if at_top.sum(axis=0).max() < CLIP_RUN:
        return out
    run = at_top[: n - CLIP_RUN + 1].copy()
    for shift in range(1, CLIP_RUN):
        run &= at_top[shift : n - CLIP_RUN + 1 + shift]
    hit = run.any(axis=1)
    for shift in range(CLIP_RUN):
        out[shift : shift + hit.size] |= hit
    return out


def prepare_inputs(
    gyr: Any,
    acc: Any,
    mag: Any,
    dt: Any,
    default_dt: float,
    acc_range: float | None = None,
    gyr_range: float | None = None,
    gap_factor: float = math.inf,
    integrate_s: float = 0.0,
    last_gyr: FloatArray | None = None,
) -> tuple[FilterInputs, RunReport]:
    """Validate a batch and build the kernels' inputs and the report (see base.py's
    module docstring for every case). ``default_dt`` [s] is used when ``dt`` is None;
    ``acc_range`` [m/s^2] and ``gyr_range`` [rad/s] are the full-scale ranges or None;
    a step longer than ``gap_factor`` nominal steps is a gap (:func:`hold_time_gaps`);
    ``last_gyr`` (3,) is the reading before the batch (a previous batch's last), if any.

    A clean batch takes one numba pass (:mod:`mocapkit.imu.filters.inputs_kernel`);
    anything doubtful takes the numpy checks below, which raise or warn naming the sample.
    """
    fast = _prepare_clean(gyr, acc, mag, dt, default_dt, acc_range, gyr_range)
    if fast is None:
        fast = _prepare_checked(gyr, acc, mag, dt, default_dt, acc_range, gyr_range)
    inputs, report = fast
    if not math.isfinite(gap_factor) or inputs.dt.size == 0:
        return fast
    steps, gap, gaps = hold_time_gaps(inputs.dt, default_dt, gap_factor, integrate_s)
    inputs = _trapezoid_over_lost_samples(inputs, default_dt, gap, last_gyr)
    if not gaps:
        return inputs, report
    inputs = inputs._replace(dt=np.ascontiguousarray(steps), gap=gap)
    return inputs, dataclasses.replace(report, gaps=gaps)


def _trapezoid_over_lost_samples(
    inputs: FilterInputs, default_dt: float, held: np.ndarray, last_gyr: FloatArray | None
) -> FilterInputs:
    """A step over lost samples (longer than ``LOST_STEP_FACTOR`` nominal ones, integrated,
    not held) turns the sensor at the mean of the readings either side of it instead of
    the later one alone: the trapezoidal rule, causal (both are known once the later one
    arrives). A foot swinging at 7 rad/s through 80 ms of lost packets turns ~30 deg; the
    later reading alone gets that wrong by as much as the rate changed. The first sample
    takes ``last_gyr`` (the previous batch's last reading) as the one before it: a live
    session fed sample by sample integrates lost packets as one run over the recording."""
    long = inputs.dt > LOST_STEP_FACTOR * default_dt
    before = None if last_gyr is None else np.asarray(last_gyr, dtype=float).reshape(3)
    if before is None or not np.isfinite(before).all():
        long[0] = False
    long &= ~held
    if not long.any():
        return inputs
    idx = np.flatnonzero(long)
    gyr = inputs.gyr.copy()
    prev = np.empty((idx.size, 3))
    inner = idx > 0
    prev[inner] = inputs.gyr[idx[inner] - 1]
    prev[~inner] = before
    gyr[idx] = 0.5 * (prev + inputs.gyr[idx])
    return inputs._replace(gyr=np.ascontiguousarray(gyr))


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
    if not clean or (n >= CLIP_RUN and clipped_gyr(g).any()):
        return None
    steps = np.ascontiguousarray(_dt_array(dt, n, default_dt))
    no = np.zeros(n, dtype=bool)
    mm = np.zeros((n, 3)) if m is None else m
    inputs = FilterInputs(g, a, mm, steps, use_acc, use_mag, no, no)
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
    sat = clipped_gyr(g)
    if gyr_range is not None:
        sat |= (np.abs(g) >= _SATURATION_FRACTION * gyr_range).any(axis=1)
    gyr_saturated = int(sat.sum())
    if gyr_saturated:
        i = int(np.flatnonzero(sat)[0])
        what = f"the {gyr_range:g} rad/s range" if gyr_range is not None else "a flat top"
        warnings.warn(
            f"gyr: saturated at sample {i} ({gyr_saturated} samples reach {what}, "
            f"{float(np.abs(g[i]).max()):.4g} rad/s); the rotation there is underestimated "
            "and the filter re-acquires its orientation after it (polaris) or only the "
            "accelerometer/magnetometer correction recovers it. Use a larger gyroscope "
            "range if the device has one.",
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
        np.zeros(n, dtype=bool),
        np.ascontiguousarray(sat),
    )
    report = RunReport(n, int((~use_acc).sum()), mag_gaps, mag_rejected, gyr_saturated)
    return inputs, report
