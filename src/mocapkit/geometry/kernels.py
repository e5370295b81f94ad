"""Scalar quaternion helpers for every numba fast path (filters, body kinematics, polaris).

The readable, vectorised versions are :mod:`mocapkit.geometry.quaternion`; these follow the
same formulas so a fast path and its reference agree to rounding. One module for all of
them: a kernel that needs a product imports it from here rather than writing its own.

numba's on-disk cache (``cache=True``) keys a kernel on its own file, not on the files of
the functions it calls: after editing this module, delete the ``__pycache__`` folders of
its callers (``make clean`` does), or they may keep the old code (docs/architecture.md).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def quat_mul_into(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """Hamilton product ``out = a * b`` (same formula as ``geometry.quat_mul``)."""
    w1, x1, y1, z1 = a[0], a[1], a[2], a[3]
    w2, x2, y2, z2 = b[0], b[1], b[2], b[3]
    out[0] = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2
    out[1] = w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2
    out[2] = w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2
    out[3] = w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2


@njit(cache=True, inline="always")
def conj_mul_into(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """``out = conj(a) * b`` (the rotation from a's frame to b's); out may not alias."""
    w1, x1, y1, z1 = a[0], -a[1], -a[2], -a[3]
    w2, x2, y2, z2 = b[0], b[1], b[2], b[3]
    out[0] = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2
    out[1] = w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2
    out[2] = w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2
    out[3] = w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2


@njit(cache=True, inline="always")
def rotate_inv_into(q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
    """``out = q* v q`` (world -> sensor for ``q_world_sensor``), as ``geometry.quat_rotate_inv``:
    ``v + w t + u x t`` with ``u = -q_xyz`` and ``t = 2 u x v``."""
    w = q[0]
    ux, uy, uz = -q[1], -q[2], -q[3]
    tx = 2.0 * (uy * v[2] - uz * v[1])
    ty = 2.0 * (uz * v[0] - ux * v[2])
    tz = 2.0 * (ux * v[1] - uy * v[0])
    out[0] = v[0] + w * tx + (uy * tz - uz * ty)
    out[1] = v[1] + w * ty + (uz * tx - ux * tz)
    out[2] = v[2] + w * tz + (ux * ty - uy * tx)


@njit(cache=True, inline="always")
def qmul(
    a0: float, a1: float, a2: float, a3: float, b0: float, b1: float, b2: float, b3: float
) -> tuple[float, float, float, float]:
    """Hamilton product on scalars (for kernels that keep quaternions in locals)."""
    return (
        a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
        a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
        a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
        a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
    )


@njit(cache=True, inline="always")
def rotation_matrix(
    w: float, x: float, y: float, z: float
) -> tuple[float, float, float, float, float, float, float, float, float]:
    """``quat_to_matrix([w, x, y, z])`` row by row as nine scalars (same formula as
    ``geometry``), for kernels that keep the matrix in locals."""
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return (
        1 - 2 * (yy + zz),
        2 * (xy - wz),
        2 * (xz + wy),
        2 * (xy + wz),
        1 - 2 * (xx + zz),
        2 * (yz - wx),
        2 * (xz - wy),
        2 * (yz + wx),
        1 - 2 * (xx + yy),
    )


@njit(cache=True, inline="always")
def rotation_matrix_into(w: float, x: float, y: float, z: float, R: np.ndarray) -> None:
    """``R = quat_to_matrix([w, x, y, z])`` (same formula as ``geometry``)."""
    r = rotation_matrix(w, x, y, z)
    R[0, 0], R[0, 1], R[0, 2] = r[0], r[1], r[2]
    R[1, 0], R[1, 1], R[1, 2] = r[3], r[4], r[5]
    R[2, 0], R[2, 1], R[2, 2] = r[6], r[7], r[8]


@njit(cache=True, inline="always")
def strapdown_step(
    w: float, x: float, y: float, z: float, wx: float, wy: float, wz: float
) -> tuple[float, float, float, float]:
    """``normalise(q * exp(r / 2))`` for the rotation vector ``r = (wx, wy, wz)`` [rad]
    (one gyroscope step ``omega dt`` in the sensor frame), ``q = (w, x, y, z)``."""
    angle = math.sqrt(wx * wx + wy * wy + wz * wz)
    if angle <= 1e-15:
        dw, dx, dy, dz = 1.0, 0.0, 0.0, 0.0
    else:
        sh = math.sin(0.5 * angle) / angle
        dw, dx, dy, dz = math.cos(0.5 * angle), sh * wx, sh * wy, sh * wz
    w, x, y, z = qmul(w, x, y, z, dw, dx, dy, dz)
    n = math.sqrt(w * w + x * x + y * y + z * z)
    return w / n, x / n, y / n, z / n
