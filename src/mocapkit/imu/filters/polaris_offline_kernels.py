"""``polaris`` offline: the numba kernels of the smoother's sequential steps.

The strapdown integration with a per-sample bias (O4) and the heading filter alone over a
given 6D orientation (O5), with the arithmetic of
:func:`mocapkit.imu.filters.polaris_reference.strapdown_reference` and
:func:`~mocapkit.imu.filters.polaris_reference.heading_pass_reference`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from mocapkit.geometry.kernels import qmul, rotation_matrix_into, strapdown_step
from mocapkit.imu.filters.polaris_heading_kernels import heading_update, start_heading
from mocapkit.imu.filters.polaris_params import (
    C_BLOCK,
    S_BLOCK_COUNT,
    S_BLOCK_TIME,
    S_MAG_COUNT,
    S_MAG_P,
    S_MAG_R_SUM,
    S_MAG_RATE2_SUM,
    S_MAG_READY,
    S_MAG_SCALE,
    S_MAG_X,
    S_MAG_Y_SUM,
)


@njit(cache=True)
def strapdown_kernel(gyr: np.ndarray, bias: np.ndarray, dt: np.ndarray, out: np.ndarray) -> None:
    """``out[k] = q_I_S`` after integrating ``(gyr - bias) dt`` up to sample k from identity
    (as (P1); used by the offline smoother with the smoothed bias (N, 3))."""
    w, x, y, z = 1.0, 0.0, 0.0, 0.0
    for k in range(gyr.shape[0]):
        wx = (gyr[k, 0] - bias[k, 0]) * dt[k]
        wy = (gyr[k, 1] - bias[k, 1]) * dt[k]
        wz = (gyr[k, 2] - bias[k, 2]) * dt[k]
        w, x, y, z = strapdown_step(w, x, y, z, wx, wy, wz)
        out[k, 0], out[k, 1], out[k, 2], out[k, 3] = w, x, y, z


@njit(cache=True)
def heading_kernel(
    c: np.ndarray,
    s: np.ndarray,
    q6: np.ndarray,
    mag: np.ndarray,
    rate2: np.ndarray,
    dt: np.ndarray,
    use_mag: np.ndarray,
    out: np.ndarray,
) -> None:
    """The heading filter (P5, P11-P13) alone, on a given 6D orientation ``q6`` (N, 4) and
    squared angular rates ``rate2`` (N,) [rad^2/s^2] (no delay, no bias term: the offline
    smoother's use); ``out`` (N, 2) receives ``[delta, var(delta)]``. Uses only the
    heading fields of the flat state ``s``."""
    block = c[C_BLOCK]
    R = np.empty((3, 3))
    Pm = np.empty((6, 6))
    Hm = np.empty((3, 6))
    PHm = np.empty((6, 3))
    Sm = np.empty((3, 3))
    Sim = np.empty((3, 3))
    nu = np.empty(3)
    for k in range(q6.shape[0]):
        if use_mag[k]:
            rotation_matrix_into(q6[k, 0], q6[k, 1], q6[k, 2], q6[k, 3], R)
            mx, my, mz = mag[k, 0], mag[k, 1], mag[k, 2]
            if s[S_MAG_READY] == 0.0:
                start_heading(c, s, R, mx, my, mz)
            scale = s[S_MAG_SCALE]
            ux, uy, uz = mx / scale, my / scale, mz / scale
            for i in range(3):
                s[S_MAG_Y_SUM + i] += R[i, 0] * ux + R[i, 1] * uy + R[i, 2] * uz
                for jj in range(3):
                    s[S_MAG_R_SUM + 3 * i + jj] += R[i, jj]
            s[S_MAG_COUNT] += 1.0
            s[S_MAG_RATE2_SUM] += rate2[k]
        s[S_BLOCK_COUNT] += 1.0
        s[S_BLOCK_TIME] += dt[k]
        if s[S_BLOCK_COUNT] >= block:
            if s[S_MAG_READY] != 0.0:
                heading_update(c, s, Pm, Hm, PHm, Sm, Sim, nu)
            s[S_BLOCK_COUNT] = 0.0
            s[S_BLOCK_TIME] = 0.0
        out[k, 0] = s[S_MAG_X]
        out[k, 1] = s[S_MAG_P] if s[S_MAG_READY] != 0.0 else 0.0


@njit(cache=True)
def smoothed_strapdown_kernel(
    gyr: np.ndarray,
    acc: np.ndarray,
    dt: np.ndarray,
    aux_f: np.ndarray,
    aux_b: np.ndarray,
    q: np.ndarray,
    bias: np.ndarray,
    q_IS: np.ndarray,
    acc_I: np.ndarray,
) -> None:
    """(O3) and (O4) in one pass over a piece of the recording: the smoothed bias ``bias``
    (N, 3) from the forward aux ``aux_f`` and the backward aux ``aux_b`` (N, 8, both in
    time order), the strapdown ``q_IS`` (N, 4) with it (:func:`strapdown_kernel`'s
    arithmetic) from ``q`` (4,), the orientation before the piece (updated: the next
    piece goes on from it), and the accelerometer in I, ``acc_I`` (N, 3)
    (``geometry.quat_rotate``'s arithmetic)."""
    n = gyr.shape[0]
    w, x, y, z = q[0], q[1], q[2], q[3]
    for k in range(n):
        var_f = aux_f[k, 7]
        var_b = aux_b[k, 7]
        for i in range(3):
            bias[k, i] = (aux_f[k, 4 + i] * var_b - aux_b[k, 4 + i] * var_f) / (var_f + var_b)
        wx = (gyr[k, 0] - bias[k, 0]) * dt[k]
        wy = (gyr[k, 1] - bias[k, 1]) * dt[k]
        wz = (gyr[k, 2] - bias[k, 2]) * dt[k]
        w, x, y, z = strapdown_step(w, x, y, z, wx, wy, wz)
        q_IS[k, 0], q_IS[k, 1], q_IS[k, 2], q_IS[k, 3] = w, x, y, z
        # v + w t + u x t with t = 2 u x v
        v0, v1, v2 = acc[k, 0], acc[k, 1], acc[k, 2]
        t0 = 2.0 * (y * v2 - z * v1)
        t1 = 2.0 * (z * v0 - x * v2)
        t2 = 2.0 * (x * v1 - y * v0)
        acc_I[k, 0] = v0 + w * t0 + (y * t2 - z * t1)
        acc_I[k, 1] = v1 + w * t1 + (z * t0 - x * t2)
        acc_I[k, 2] = v2 + w * t2 + (x * t1 - y * t0)
    q[0], q[1], q[2], q[3] = w, x, y, z


@njit(cache=True)
def iir_kernel(
    x: np.ndarray,
    b0: float,
    b1: float,
    b2: float,
    a1: float,
    a2: float,
    zi: np.ndarray,
    backward: bool,
    out: np.ndarray,
) -> None:
    """The Butterworth ``(b0, b1, b2, 1, a1, a2)`` over each column of a piece ``x``
    (N, 3) into ``out``, forward or ``backward`` (last row first), with the arithmetic of
    ``scipy.signal.lfilter`` (transposed direct form II); ``zi`` (3, 2) is each column's
    filter memory before the piece and is updated (the next piece goes on from it). The
    zero-phase low-pass (O4) is a forward run then a backward run over its output, each
    started at steady state: ``zi = [b1 - a1 + b2 - a2, b2 - a2] * first value``."""
    n = x.shape[0]
    for j in range(x.shape[1]):
        z0, z1 = zi[j, 0], zi[j, 1]
        for i in range(n):
            k = n - 1 - i if backward else i
            v = x[k, j]
            yk = z0 + b0 * v
            z0 = z1 + v * b1 - yk * a1
            z1 = v * b2 - yk * a2
            out[k, j] = yk
        zi[j, 0], zi[j, 1] = z0, z1


@njit(cache=True)
def inclination_kernel(acc_lp: np.ndarray, q_IS: np.ndarray, q6: np.ndarray) -> bool:
    """``q6 = q_from_two_vectors(acc_lp, up) * q_IS`` (N, 4) with the arithmetic of
    ``geometry.quat_from_two_vectors`` and ``quat_mul``; False (``q6`` incomplete) when a
    vector is zero, points down (the antiparallel case) or the result is not finite, for
    the numpy path to handle."""
    v0, v1, v2 = 0.0, 0.0, 1.0  # up
    for k in range(acc_lp.shape[0]):
        a0, a1, a2 = acc_lp[k, 0], acc_lp[k, 1], acc_lp[k, 2]
        na = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        if not na > 0.0:
            return False
        a0, a1, a2 = a0 / na, a1 / na, a2 / na
        d = a0 * v0 + a1 * v1 + a2 * v2
        w = 1.0 + d
        if w < 1e-12:
            return False
        x = a1 * v2 - a2 * v1
        y = a2 * v0 - a0 * v2
        z = a0 * v1 - a1 * v0
        nq = math.sqrt(w * w + x * x + y * y + z * z)
        if not (nq > 0.0 and math.isfinite(nq)):
            return False
        w, x, y, z = w / nq, x / nq, y / nq, z / nq
        q0, q1, q2, q3 = qmul(w, x, y, z, q_IS[k, 0], q_IS[k, 1], q_IS[k, 2], q_IS[k, 3])
        q6[k, 0], q6[k, 1], q6[k, 2], q6[k, 3] = q0, q1, q2, q3
    return True


@njit(cache=True)
def heading_fusion_kernel(
    q6: np.ndarray, fwd: np.ndarray, bwd: np.ndarray, diff: np.ndarray, q9: np.ndarray
) -> None:
    """(O5) ``q9 = Rz(psi) * q6`` (N, 4), ``psi`` the forward heading offset ``fwd``
    (N, 2) and the backward one ``bwd`` (N, 2, in time order) fused by their variances (a
    direction whose filter has not started yet, variance 0, gets no weight); ``diff`` (N,)
    is backward minus forward wrapped to [-pi, pi] (numpy's ``arctan2``, which differs
    from the C library's in the last bit for some arguments)."""
    for k in range(q6.shape[0]):
        f, var_f = fwd[k, 0], fwd[k, 1]
        var_b = bwd[k, 1]
        weight = 0.0
        if var_f > 0.0 and var_b > 0.0:
            weight = var_f / (var_f + var_b)
        elif var_b > 0.0:
            weight = 1.0
        half = 0.5 * (f + weight * diff[k])
        h0, h1, h2, h3 = qmul(
            math.cos(half), 0.0, 0.0, math.sin(half), q6[k, 0], q6[k, 1], q6[k, 2], q6[k, 3]
        )
        q9[k, 0], q9[k, 1], q9[k, 2], q9[k, 3] = h0, h1, h2, h3
