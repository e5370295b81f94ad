"""``polaris`` offline: a forward-backward smoother for whole recordings.

Online, every estimate uses past samples only, so the low-passed accelerometer lags and
the bias estimate trails. Offline all samples are known:

1. (O1) the magnetometer is moved ``mag_delay_s`` earlier (its latency is known), so both
   passes compare it with the orientation of its own time;
2. (O2) a forward pass and a backward pass (time reversed: the gyroscope negated and
   shifted by one sample, because reading ``k`` is the rotation from sample ``k - 1`` to
   ``k``) of the online filter give two independent estimates of the bias with their
   variances, and two heading offsets with theirs;
3. (O3) smoothed bias: the inverse-variance fusion of the two (the two-filter smoother of
   Fraser and Potter for a scalar weight per sample);
4. (O4) strapdown integration with the smoothed bias gives the almost-inertial frame I;
   the accelerometer in I is low-passed *zero-phase* (the Butterworth of
   ``offline_tau_acc`` run forward then backward, no lag), and the inclination at each
   sample is the rotation that brings that low-passed vertical onto up;
5. (O5) 9D: the heading filter of the online mode (P11-P13, with the timing noise of the
   bias-corrected rates) runs forward and backward over the smoothed 6D orientation; the
   two heading offsets are fused by their variances (the direction whose magnetometer was
   rejected for a while has the larger variance there).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.signal import lfilter

from mocapkit._validate import FloatArray
from mocapkit.geometry import quat_from_two_vectors, quat_mul, quat_rotate
from mocapkit.imu.filters import polaris_params as pp
from mocapkit.imu.filters.polaris_engine import (
    heading_pass,
    initial_linear_acc,
    initial_tilt,
    run_pass,
    start,
    strapdown,
)
from mocapkit.imu.filters.polaris_offline_chunks import RamStore, smooth_pieces
from mocapkit.imu.filters.polaris_params import PolarisCore, PolarisParams, butterworth2

_UP = np.array([0.0, 0.0, 1.0])


class OfflineResult(NamedTuple):
    """Smoothed ``q6`` (N, 4), ``q9`` (N, 4) (None in 6D) and bias [rad/s] (N, 3)."""

    q6: FloatArray
    q9: FloatArray | None
    bias: FloatArray


def _heading_about_z(e: FloatArray) -> FloatArray:
    """The rotation angle [rad] about world z of ``e = Rz(psi) * tilt`` (N, 4)."""
    return 2.0 * np.arctan2(e[:, 3], e[:, 0])


def _heading_rotation(psi: FloatArray) -> FloatArray:
    out = np.zeros((psi.shape[0], 4))
    out[:, 0] = np.cos(0.5 * psi)
    out[:, 3] = np.sin(0.5 * psi)
    return out


def _zero_phase_lowpass(params: PolarisParams, x: FloatArray) -> FloatArray:
    """The offline Butterworth forward then backward, each started at steady state."""
    b0, b1, b2, a1, a2 = butterworth2(params.offline_tau_acc, params.dt)
    b = np.array([b0, b1, b2])
    a = np.array([1.0, a1, a2])
    zi_unit = np.array([b1 - a1 + b2 - a2, b2 - a2])  # steady-state memory for input 1
    forward = np.empty_like(x)
    for j in range(x.shape[1]):
        forward[:, j], _ = lfilter(b, a, x[:, j], zi=zi_unit * x[0, j])
    out = np.empty_like(x)
    for j in range(x.shape[1]):
        rev = forward[::-1, j]
        y, _ = lfilter(b, a, rev, zi=zi_unit * rev[0])
        out[:, j] = y[::-1]
    return out


def _fill_unusable(x: FloatArray, usable: np.ndarray) -> FloatArray:
    """Linear interpolation over rows that are not ``usable`` (held at the ends)."""
    if usable.all():
        return x
    idx = np.flatnonzero(usable)
    t = np.arange(x.shape[0])
    return np.stack([np.interp(t, idx, x[idx, j]) for j in range(x.shape[1])], axis=1)


def _one_pass(
    params: PolarisParams,
    c: FloatArray,
    backend: str,
    gyr: FloatArray,
    acc: FloatArray,
    mag: FloatArray,
    dt: FloatArray,
    use_acc: np.ndarray,
    use_mag: np.ndarray,
    has_mag: bool,
) -> FloatArray:
    """One online pass in 6D (the bias is all the smoother takes from it); (N, 8) aux."""
    core = PolarisCore()
    q_init = initial_tilt(acc, use_acc)
    first = int(np.flatnonzero(use_acc)[0])
    lin2 = initial_linear_acc(acc[first : first + 1], gyr[first : first + 1], float(dt[0]))
    start(c, core, q_init, gyr[0], acc[first], lin2)
    result = run_pass(c, core, backend, gyr, acc, mag, dt, use_acc, use_mag, False, True)
    return result.aux


def smooth(
    params: PolarisParams,
    backend: str,
    gyr: FloatArray,
    acc: FloatArray,
    mag: FloatArray,
    dt: FloatArray,
    use_acc: np.ndarray,
    use_mag: np.ndarray,
    has_mag: bool,
) -> OfflineResult:
    """The offline estimate (O1-O5) of validated (N, 3) arrays; see the module docstring.
    The fast backend runs the steps of :mod:`mocapkit.imu.filters.polaris_offline_chunks`
    over the arrays in memory (one piece); the reference backend the numpy steps below."""
    n = gyr.shape[0]
    if backend == "fast":
        store = RamStore(n, gyr=gyr, acc=acc, mag=mag, dt=dt)
        (piece,) = smooth_pieces(params, store, n, use_acc, use_mag, has_mag, max(n, 1))
        return OfflineResult(piece.q6, piece.q9, piece.bias)
    return smooth_steps(params, backend, gyr, acc, mag, dt, use_acc, use_mag, has_mag)


def smooth_steps(
    params: PolarisParams,
    backend: str,
    gyr: FloatArray,
    acc: FloatArray,
    mag: FloatArray,
    dt: FloatArray,
    use_acc: np.ndarray,
    use_mag: np.ndarray,
    has_mag: bool,
) -> OfflineResult:
    """:func:`smooth` as numpy steps over whole arrays (the reference backend's path; with
    ``backend="fast"`` the passes are numba's and the rest numpy: the tests' check that
    the pieces give the same numbers to the bit)."""
    n = gyr.shape[0]
    c = pp.coefficients(params)
    c[pp.C_MAG_DELAY] = 0.0
    # (O1) align the magnetometer with the gyroscope.
    delay = params.mag_delay_samples if has_mag else 0
    if delay > 0 and n > delay:
        mag = np.concatenate([mag[delay:], np.repeat(mag[-1:], delay, axis=0)])
        use_mag = np.concatenate([use_mag[delay:], np.repeat(use_mag[-1:], delay)])
    # (O2) forward and backward passes.
    aux_f = _one_pass(params, c, backend, gyr, acc, mag, dt, use_acc, use_mag, has_mag)
    gyr_b = np.zeros_like(gyr)
    gyr_b[1:] = -gyr[::-1][:-1]
    dt_b = np.empty_like(dt)
    dt_b[0] = dt[-1]
    dt_b[1:] = dt[::-1][:-1]
    aux_b = _one_pass(
        params,
        c,
        backend,
        np.ascontiguousarray(gyr_b),
        np.ascontiguousarray(acc[::-1]),
        np.ascontiguousarray(mag[::-1]),
        np.ascontiguousarray(dt_b),
        np.ascontiguousarray(use_acc[::-1]),
        np.ascontiguousarray(use_mag[::-1]),
        has_mag,
    )
    return _tail_numpy(
        params, c, backend, gyr, acc, mag, dt, dt_b, use_acc, use_mag, has_mag, aux_f, aux_b
    )


def _tail_numpy(
    params: PolarisParams,
    c: FloatArray,
    backend: str,
    gyr: FloatArray,
    acc: FloatArray,
    mag: FloatArray,
    dt: FloatArray,
    dt_b: FloatArray,
    use_acc: np.ndarray,
    use_mag: np.ndarray,
    has_mag: bool,
    aux_f: FloatArray,
    aux_b: FloatArray,
) -> OfflineResult:
    """(O3)-(O5) in numpy from the forward aux ``aux_f`` and the time-reversed backward
    aux ``aux_b`` (N, 8) (the reference backend's path)."""
    n = gyr.shape[0]
    aux_b = aux_b[::-1]
    # (O3) smoothed bias (the backward pass estimates -b).
    var_f = aux_f[:, 7:8]
    var_b = aux_b[:, 7:8]
    bias = (aux_f[:, 4:7] * var_b - aux_b[:, 4:7] * var_f) / (var_f + var_b)
    # (O4) zero-phase inclination in the smoothed strapdown frame.
    q_IS = strapdown(backend, gyr, bias, dt)
    a_I = _fill_unusable(quat_rotate(q_IS, acc), use_acc)
    q6 = _inclination(a_I, q_IS, params)
    if not has_mag:
        return OfflineResult(q6, None, bias)
    # (O5) heading: the heading filter forward and backward over the smoothed 6D
    # orientation, fused by the variances of its heading offset.
    fwd, bwd = _heading_passes(c, backend, q6, mag, _rate2(gyr, bias), dt, dt_b, use_mag)
    bwd = bwd[::-1]
    var_f, var_b = fwd[:, 1], bwd[:, 1]
    ready_f = var_f > 0.0  # the heading filter has started in that direction
    ready_b = var_b > 0.0
    weight = np.zeros(n)
    both = ready_f & ready_b
    weight[both] = var_f[both] / (var_f[both] + var_b[both])
    weight[~ready_f & ready_b] = 1.0
    diff = np.arctan2(np.sin(bwd[:, 0] - fwd[:, 0]), np.cos(bwd[:, 0] - fwd[:, 0]))
    q9 = quat_mul(_heading_rotation(fwd[:, 0] + weight * diff), q6)
    return OfflineResult(q6, q9, bias)


def _inclination(a_I: FloatArray, q_IS: FloatArray, params: PolarisParams) -> FloatArray:
    """(O4) ``q6`` (N, 4): the zero-phase low-passed ``a_I`` brought onto up, times ``q_IS``."""
    a_I_lp = _zero_phase_lowpass(params, a_I)
    q_EI = quat_from_two_vectors(a_I_lp, np.broadcast_to(_UP, a_I_lp.shape))
    return quat_mul(q_EI, q_IS)


def _rate2(gyr: FloatArray, bias: FloatArray) -> FloatArray:
    """Squared bias-corrected angular rates [rad^2/s^2] (N,)."""
    rate = gyr - bias
    return np.einsum("ij,ij->i", rate, rate)


def _heading_passes(
    c: FloatArray,
    backend: str,
    q6: FloatArray,
    mag: FloatArray,
    rate2: FloatArray,
    dt: FloatArray,
    dt_b: FloatArray,
    use_mag: np.ndarray,
) -> tuple[FloatArray, FloatArray]:
    """(O5) the heading filter forward, and backward (its output time-reversed: index 0 is
    the last sample), each (N, 2) ``[delta, var]``."""
    fwd = heading_pass(c, backend, q6, mag, rate2, dt, use_mag)
    bwd = heading_pass(
        c,
        backend,
        np.ascontiguousarray(q6[::-1]),
        np.ascontiguousarray(mag[::-1]),
        np.ascontiguousarray(rate2[::-1]),
        np.ascontiguousarray(dt_b),
        np.ascontiguousarray(use_mag[::-1]),
    )
    return fwd, bwd
