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

from mocapkit.geometry.kernels import qmul, rotation_matrix_into
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
        angle = math.sqrt(wx * wx + wy * wy + wz * wz)
        if angle <= 1e-15:
            dw, dx, dy, dz = 1.0, 0.0, 0.0, 0.0
        else:
            sh = math.sin(0.5 * angle) / angle
            dw, dx, dy, dz = math.cos(0.5 * angle), sh * wx, sh * wy, sh * wz
        w, x, y, z = qmul(w, x, y, z, dw, dx, dy, dz)
        n = math.sqrt(w * w + x * x + y * y + z * z)
        w, x, y, z = w / n, x / n, y / n, z / n
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
