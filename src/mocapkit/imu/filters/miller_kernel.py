"""Numba fast path of the ``miller`` filter: the same arithmetic as
:func:`mocapkit.imu.filters.miller.miller_step`, written out on scalars.

Kept in the same order of operations as the reference so the two agree to rounding
(tests: 1e-9 on real BROAD data). See ``miller.py`` for the equations and choices.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from mocapkit.geometry.kernels import quat_mul_into, rotate_inv_into

_MIN_PROJECTION = 1e-9
_G_REF = np.array([0.0, 0.0, 1.0])
_M_REF = np.array([0.0, 1.0, 0.0])


@njit(cache=True)
def _law_of_cosines_angle(local: np.ndarray, sensed: np.ndarray, axis: int) -> float:
    """Scalar form of ``miller.law_of_cosines_angle``: the projections onto the plane
    normal to ``axis`` are the components ``i, j`` (cyclic order)."""
    i = (axis + 1) % 3
    j = (axis + 2) % 3
    li, lj = local[i], local[j]
    si, sj = sensed[i], sensed[j]
    ei = li - si
    ej = lj - sj
    a = math.sqrt(li * li + lj * lj)
    b = math.sqrt(si * si + sj * sj)
    c = math.sqrt(ei * ei + ej * ej)
    if a < _MIN_PROJECTION or b < _MIN_PROJECTION:
        return 0.0
    cos_angle = min(1.0, max(-1.0, (a * a + b * b - c * c) / (2.0 * a * b)))
    angle = math.acos(cos_angle)
    return angle if li * sj - lj * si >= 0.0 else -angle


@njit(cache=True)
def miller_run_kernel(
    q: np.ndarray,
    gyr: np.ndarray,
    acc: np.ndarray,
    mag: np.ndarray,
    dt: np.ndarray,
    use_acc: np.ndarray,
    use_mag: np.ndarray,
    alpha: float,
) -> np.ndarray:
    """Run eq. 2-14 over N samples from ``q`` (4,), which holds the last estimate on
    return. Returns (N, 4) estimates ``q_world_sensor`` at the samples' times."""
    n = gyr.shape[0]
    out = np.empty((n, 4))
    omega = np.zeros(4)
    eps = np.zeros(4)
    dq = np.zeros(4)
    q_pred = np.zeros(4)
    q_correct = np.zeros(4)
    g_local = np.zeros(3)
    m_local = np.zeros(3)
    g_sensed = np.zeros(3)
    m_h = np.zeros(3)
    angles = np.zeros(3)
    for t in range(n):
        h = dt[t]
        omega[0] = 0.0
        omega[1] = gyr[t, 0] * h
        omega[2] = gyr[t, 1] * h
        omega[3] = gyr[t, 2] * h
        quat_mul_into(q, omega, dq)
        for c in range(4):
            dq[c] *= 0.5
            q_pred[c] = q[c] + dq[c]
        norm = math.sqrt(q_pred[0] ** 2 + q_pred[1] ** 2 + q_pred[2] ** 2 + q_pred[3] ** 2)
        for c in range(4):
            q_pred[c] /= norm
        angles[0] = 0.0
        angles[1] = 0.0
        angles[2] = 0.0
        if use_acc[t]:
            na = math.sqrt(acc[t, 0] ** 2 + acc[t, 1] ** 2 + acc[t, 2] ** 2)
            for c in range(3):
                g_sensed[c] = acc[t, c] / na
            rotate_inv_into(q_pred, _G_REF, g_local)
            k = 2
            if abs(g_sensed[1]) > abs(g_sensed[k]):
                k = 1
            if abs(g_sensed[0]) > abs(g_sensed[k]):
                k = 0
            for axis in range(3):
                if axis != k:
                    angles[axis] = _law_of_cosines_angle(g_local, g_sensed, axis)
            if use_mag[t]:
                rotate_inv_into(q_pred, _M_REF, m_local)
                d = mag[t, 0] * g_local[0] + mag[t, 1] * g_local[1] + mag[t, 2] * g_local[2]
                for c in range(3):
                    m_h[c] = mag[t, c] - d * g_local[c]
                nh = math.sqrt(m_h[0] ** 2 + m_h[1] ** 2 + m_h[2] ** 2)
                nm = math.sqrt(mag[t, 0] ** 2 + mag[t, 1] ** 2 + mag[t, 2] ** 2)
                if nh > 1e-6 * nm:
                    for c in range(3):
                        m_h[c] /= nh
                    angles[k] = _law_of_cosines_angle(m_local, m_h, k)
        eps[0] = 0.0
        eps[1] = angles[0] * h
        eps[2] = angles[1] * h
        eps[3] = angles[2] * h
        quat_mul_into(q_pred, eps, q_correct)
        for c in range(4):
            q_correct[c] *= 0.5
        for c in range(4):
            q[c] = q[c] + dq[c] - alpha * q_correct[c]
        norm = math.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2 + q[3] ** 2)
        for c in range(4):
            q[c] /= norm
            out[t, c] = q[c]
    return out
