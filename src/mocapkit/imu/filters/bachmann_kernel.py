"""Numba fast path of the ``bachmann`` filter (same arithmetic as
:func:`mocapkit.imu.filters.bachmann.bachmann_step`; see ``bachmann.py`` for the maths)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from mocapkit.geometry.kernels import quat_mul_into

_G_REF = np.array([0.0, 0.0, 1.0])


@njit(cache=True)
def _measurement_rows(q: np.ndarray, v: np.ndarray, jac: np.ndarray, y: np.ndarray) -> None:
    """``y = q* v q`` (3,) and its Jacobian (3, 4) wrt [w, x, y, z] (see bachmann.py)."""
    w = q[0]
    u0, u1, u2 = q[1], q[2], q[3]
    uv = u0 * v[0] + u1 * v[1] + u2 * v[2]
    uu = u0 * u0 + u1 * u1 + u2 * u2
    c0 = u1 * v[2] - u2 * v[1]  # u x v
    c1 = u2 * v[0] - u0 * v[2]
    c2 = u0 * v[1] - u1 * v[0]
    y[0] = (w * w - uu) * v[0] + 2.0 * uv * u0 - 2.0 * w * c0
    y[1] = (w * w - uu) * v[1] + 2.0 * uv * u1 - 2.0 * w * c1
    y[2] = (w * w - uu) * v[2] + 2.0 * uv * u2 - 2.0 * w * c2
    jac[0, 0] = 2.0 * w * v[0] - 2.0 * c0
    jac[1, 0] = 2.0 * w * v[1] - 2.0 * c1
    jac[2, 0] = 2.0 * w * v[2] - 2.0 * c2
    u = (u0, u1, u2)
    # -2 v u^T + 2 u v^T + 2 (u.v) I + 2 w [v]x
    vx = ((0.0, -v[2], v[1]), (v[2], 0.0, -v[0]), (-v[1], v[0], 0.0))
    for r in range(3):
        for c in range(3):
            val = -2.0 * v[r] * u[c] + 2.0 * u[r] * v[c] + 2.0 * w * vx[r][c]
            if r == c:
                val += 2.0 * uv
            jac[r, 1 + c] = val


@njit(cache=True)
def _solve_spd(A: np.ndarray, b: np.ndarray, n: int) -> None:
    """Solve ``A x = b`` in place (x in b) for a symmetric positive definite n x n A
    (Cholesky; n <= 4). A is overwritten."""
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= A[j, k] * A[j, k]
        d = math.sqrt(s)
        A[j, j] = d
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= A[i, k] * A[j, k]
            A[i, j] = s / d
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= A[i, k] * b[k]
        b[i] = s / A[i, i]
    for i in range(n - 1, -1, -1):
        s = b[i]
        for k in range(i + 1, n):
            s -= A[k, i] * b[k]
        b[i] = s / A[i, i]


@njit(cache=True)
def bachmann_run_kernel(
    q: np.ndarray,
    gyr: np.ndarray,
    acc: np.ndarray,
    mag: np.ndarray,
    dt: np.ndarray,
    use_acc: np.ndarray,
    use_mag: np.ndarray,
    m_ref: np.ndarray,
    mag_ok: bool,
    alpha: float,
) -> np.ndarray:
    """Run N steps from ``q`` (4,), which holds the last estimate on return; returns
    (N, 4) estimates at the samples' times."""
    n = gyr.shape[0]
    out = np.empty((n, 4))
    omega = np.zeros(4)
    dq = np.zeros(4)
    q_pred = np.zeros(4)
    X = np.zeros((6, 4))
    eps = np.zeros(6)
    jac = np.zeros((3, 4))
    y = np.zeros(3)
    A = np.zeros((4, 4))
    rhs = np.zeros(4)
    step = np.zeros(4)
    for t in range(n):
        h = dt[t]
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
        rows = 0
        if use_acc[t]:
            na = math.sqrt(acc[t, 0] ** 2 + acc[t, 1] ** 2 + acc[t, 2] ** 2)
            _measurement_rows(q_pred, _G_REF, jac, y)
            for r in range(3):
                eps[rows + r] = acc[t, r] / na - y[r]
                for c in range(4):
                    X[rows + r, c] = jac[r, c]
            rows += 3
        if use_mag[t] and mag_ok:
            nm = math.sqrt(mag[t, 0] ** 2 + mag[t, 1] ** 2 + mag[t, 2] ** 2)
            _measurement_rows(q_pred, m_ref, jac, y)
            for r in range(3):
                eps[rows + r] = mag[t, r] / nm - y[r]
                for c in range(4):
                    X[rows + r, c] = jac[r, c]
            rows += 3
        for c in range(4):
            step[c] = 0.0
        if rows == 6:  # eq. 15: (X^T X)^-1 X^T eps
            for i in range(4):
                s = 0.0
                for r in range(6):
                    s += X[r, i] * eps[r]
                rhs[i] = s
                for j in range(4):
                    s = 0.0
                    for r in range(6):
                        s += X[r, i] * X[r, j]
                    A[i, j] = s
            _solve_spd(A, rhs, 4)
            for c in range(4):
                step[c] = rhs[c]
        elif rows == 3:  # minimum-norm: X^T (X X^T)^-1 eps
            for i in range(3):
                rhs[i] = eps[i]
                for j in range(3):
                    s = 0.0
                    for c in range(4):
                        s += X[i, c] * X[j, c]
                    A[i, j] = s
            _solve_spd(A, rhs, 3)
            for c in range(4):
                s = 0.0
                for r in range(3):
                    s += X[r, c] * rhs[r]
                step[c] = s
        for c in range(4):
            q[c] = q[c] + dq[c] + alpha * h * step[c]
        norm = math.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2 + q[3] ** 2)
        for c in range(4):
            q[c] /= norm
            out[t, c] = q[c]
    return out
