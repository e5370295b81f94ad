"""Scalar quaternion helpers for the numba fast paths (the readable versions are in
:mod:`mocapkit.geometry`; these follow the same formulas so results agree to rounding)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def quat_mul_into(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """Hamilton product ``out = a * b`` (same formula as ``geometry.quat_mul``)."""
    w1, x1, y1, z1 = a[0], a[1], a[2], a[3]
    w2, x2, y2, z2 = b[0], b[1], b[2], b[3]
    out[0] = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2
    out[1] = w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2
    out[2] = w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2
    out[3] = w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2


@njit(cache=True)
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
