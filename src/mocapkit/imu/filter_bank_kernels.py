"""Numba kernels of :class:`mocapkit.imu.filter_bank.FilterBank`: one call advances many
sensors by one sample each (or a few), with the filters' own per-sample kernels.

Each bank kernel takes the bank's state ``X`` (S, L) (row s: sensor s's filter state, updated
in place: ``q_world_sensor`` for miller and bachmann, polaris's flat state), per-sensor
parameters ``P`` (S, k) and gyroscope biases ``bias`` (S, 3),
and a batch of M samples: ``slots`` (M,) (the sensor of each), ``take`` (M,) (which
samples are the bank's), ``gyr``, ``acc`` (M, 3), ``mag`` (M, 3) (all-NaN rows: gaps),
``has_mag`` (9D), ``dt`` [s] and ``acc_range`` [m/s^2] (inf: unknown). It writes ``out``
(M, 4) and ``status`` (M,) (:data:`OK`, :data:`BAD_GYR`, :data:`BAD_ACC`, :data:`BAD_MAG`,
:data:`BAD_OUTPUT`), checking each sample as :func:`mocapkit.imu.filters.inputs.prepare_inputs`
does (non-finite gyroscope or accelerometer: an error; an all-NaN magnetometer row: a gap,
processed as 6D; zero-norm or saturated vectors: their correction skipped).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from mocapkit.imu.filters.bachmann_kernel import bachmann_run_kernel
from mocapkit.imu.filters.inputs import MIN_VECTOR_NORM
from mocapkit.imu.filters.miller_kernel import miller_run_kernel
from mocapkit.imu.filters.polaris_kernels import polaris_kernel

OK, BAD_GYR, BAD_ACC, BAD_MAG, BAD_OUTPUT = 0, 1, 2, 3, 4
_SATURATION_FRACTION = 0.999  # as in mocapkit.imu.filters.inputs


@njit(cache=True)
def _prepare(
    m: int,
    s: int,
    gyr: np.ndarray,
    acc: np.ndarray,
    mag: np.ndarray,
    has_mag: bool,
    bias: np.ndarray,
    acc_range: float,
    g1: np.ndarray,
    a1: np.ndarray,
    m1: np.ndarray,
    use_acc: np.ndarray,
    use_mag: np.ndarray,
) -> int:
    """Sample m into the one-row inputs; returns its status."""
    na = 0.0
    saturated = False
    for c in range(3):
        g = gyr[m, c]
        a = acc[m, c]
        if not math.isfinite(g):
            return BAD_GYR
        if not math.isfinite(a):
            return BAD_ACC
        g1[0, c] = g - bias[s, c]
        a1[0, c] = a
        na += a * a
        if abs(a) >= _SATURATION_FRACTION * acc_range:
            saturated = True
    use_acc[0] = math.sqrt(na) > MIN_VECTOR_NORM and not saturated
    use_mag[0] = False
    m1[0, 0] = m1[0, 1] = m1[0, 2] = 0.0
    if has_mag:
        n_nan = 0
        nm = 0.0
        for c in range(3):
            v = mag[m, c]
            if math.isnan(v):
                n_nan += 1
            elif not math.isfinite(v):
                return BAD_MAG
            else:
                nm += v * v
        if n_nan == 3:
            return OK  # a gap: 6D for this sample
        if n_nan:
            return BAD_MAG
        for c in range(3):
            m1[0, c] = mag[m, c]
        use_mag[0] = math.sqrt(nm) > MIN_VECTOR_NORM
    return OK


@njit(cache=True)
def _finish(r: np.ndarray, m: int, out: np.ndarray, status: np.ndarray) -> None:
    ok = True
    for c in range(4):
        out[m, c] = r[0, c]
        ok = ok and math.isfinite(r[0, c])
    if not ok:
        status[m] = BAD_OUTPUT


@njit(cache=True)
def miller_bank_kernel(
    X: np.ndarray,
    P: np.ndarray,
    bias: np.ndarray,
    slots: np.ndarray,
    take: np.ndarray,
    gyr: np.ndarray,
    acc: np.ndarray,
    mag: np.ndarray,
    has_mag: bool,
    dt: float,
    acc_range: float,
    out: np.ndarray,
    status: np.ndarray,
) -> None:
    """``miller``: ``P[s, 0]`` is alpha [1/s]."""
    g1 = np.empty((1, 3))
    a1 = np.empty((1, 3))
    m1 = np.empty((1, 3))
    dt1 = np.full(1, dt)
    use_acc = np.empty(1, dtype=np.bool_)
    use_mag = np.empty(1, dtype=np.bool_)
    for m in range(slots.shape[0]):
        if not take[m]:
            continue
        s = slots[m]
        st = _prepare(m, s, gyr, acc, mag, has_mag, bias, acc_range, g1, a1, m1, use_acc, use_mag)
        status[m] = st
        if st != OK:
            continue
        r = miller_run_kernel(X[s], g1, a1, m1, dt1, use_acc, use_mag, P[s, 0])
        _finish(r, m, out, status)


@njit(cache=True)
def bachmann_bank_kernel(
    X: np.ndarray,
    P: np.ndarray,
    bias: np.ndarray,
    slots: np.ndarray,
    take: np.ndarray,
    gyr: np.ndarray,
    acc: np.ndarray,
    mag: np.ndarray,
    has_mag: bool,
    dt: float,
    acc_range: float,
    out: np.ndarray,
    status: np.ndarray,
) -> None:
    """``bachmann``: ``P[s] = [alpha [1/s], m_ref (3,), field usable (1.0 or 0.0)]``."""
    g1 = np.empty((1, 3))
    a1 = np.empty((1, 3))
    m1 = np.empty((1, 3))
    dt1 = np.full(1, dt)
    use_acc = np.empty(1, dtype=np.bool_)
    use_mag = np.empty(1, dtype=np.bool_)
    for m in range(slots.shape[0]):
        if not take[m]:
            continue
        s = slots[m]
        st = _prepare(m, s, gyr, acc, mag, has_mag, bias, acc_range, g1, a1, m1, use_acc, use_mag)
        status[m] = st
        if st != OK:
            continue
        r = bachmann_run_kernel(
            X[s], g1, a1, m1, dt1, use_acc, use_mag, P[s, 1:4], P[s, 4] > 0.5, P[s, 0]
        )
        _finish(r, m, out, status)


@njit(cache=True)
def polaris_bank_kernel(
    X: np.ndarray,
    P: np.ndarray,
    bias: np.ndarray,
    slots: np.ndarray,
    take: np.ndarray,
    gyr: np.ndarray,
    acc: np.ndarray,
    mag: np.ndarray,
    has_mag: bool,
    dt: float,
    acc_range: float,
    out: np.ndarray,
    status: np.ndarray,
) -> None:
    """``polaris`` (started): ``X[s]`` its flat state
    (:func:`mocapkit.imu.filters.polaris_params.pack_state`), ``P[s]`` its coefficients."""
    g1 = np.empty((1, 3))
    a1 = np.empty((1, 3))
    m1 = np.empty((1, 3))
    dt1 = np.full(1, dt)
    use_acc = np.empty(1, dtype=np.bool_)
    use_mag = np.empty(1, dtype=np.bool_)
    q9 = np.empty((1, 4))
    q6 = np.empty((1, 4))
    aux = np.empty((0, 8))
    for m in range(slots.shape[0]):
        if not take[m]:
            continue
        s = slots[m]
        st = _prepare(m, s, gyr, acc, mag, has_mag, bias, acc_range, g1, a1, m1, use_acc, use_mag)
        status[m] = st
        if st != OK:
            continue
        polaris_kernel(P[s], X[s], g1, a1, m1, dt1, use_acc, use_mag, has_mag, q9, q6, aux)
        _finish(q9, m, out, status)
