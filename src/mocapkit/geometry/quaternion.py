"""Hamilton unit quaternions ``[w, x, y, z]``, vectorised over leading axes.

Every function accepts a single quaternion ``(4,)`` or a stack ``(..., 4)`` and
broadcasts like numpy. Frames follow ``q_a_b``: the orientation of frame b in
frame a, so ``v_a = quat_rotate(q_a_b, v_b)`` and ``q_a_c = q_a_b * q_b_c``.

Conversions to the ``[x, y, z, w]`` order used by SciPy, ROS and Pinocchio live
only in :func:`quat_to_xyzw` / :func:`quat_from_xyzw`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mocapkit._validate import FloatArray, as_float_array
from mocapkit.errors import DataError, ShapeError

# Below this rotation-vector norm [rad] the Taylor series replace sin(x)/x, keeping
# full double precision near identity.
_SMALL_ANGLE = 1e-6


def _quat(q: Any, name: str = "q") -> FloatArray:
    arr = as_float_array(q, name)
    if arr.ndim == 0 or arr.shape[-1] != 4:
        raise ShapeError(f"{name}: expected shape (4,) or (N, 4), got {arr.shape}")
    return arr


def _vec3(v: Any, name: str = "v") -> FloatArray:
    arr = as_float_array(v, name)
    if arr.ndim == 0 or arr.shape[-1] != 3:
        raise ShapeError(f"{name}: expected shape (3,) or (N, 3), got {arr.shape}")
    return arr


def quat_identity(n: int | None = None) -> FloatArray:
    """Identity quaternion, shape (4,) or (n, 4)."""
    if n is None:
        return np.array([1.0, 0.0, 0.0, 0.0])
    out = np.zeros((n, 4))
    out[:, 0] = 1.0
    return out


def quat_mul(q1: Any, q2: Any) -> FloatArray:
    """Hamilton product ``q1 * q2`` (apply q2 first, then q1 when rotating vectors)."""
    a = _quat(q1, "q1")
    b = _quat(q2, "q2")
    w1, x1, y1, z1 = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    w2, x2, y2, z2 = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))  # no stack: small inputs are many
    out[..., 0] = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2
    out[..., 1] = w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2
    out[..., 2] = w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2
    out[..., 3] = w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2
    return out


def quat_conj(q: Any) -> FloatArray:
    """Conjugate ``[w, -x, -y, -z]``; the inverse of a unit quaternion."""
    out = _quat(q)
    out[..., 1:] *= -1.0
    return out


def quat_inv(q: Any) -> FloatArray:
    """Inverse ``conj(q) / |q|^2`` (valid for non-unit quaternions)."""
    arr = _quat(q)
    norm2 = np.sum(arr * arr, axis=-1, keepdims=True)
    if np.any(norm2 == 0.0):
        raise DataError("q: cannot invert a zero quaternion")
    return quat_conj(arr) / norm2


def quat_normalize(q: Any) -> FloatArray:
    """Scale to unit norm. Raises DataError on a zero or non-finite quaternion."""
    arr = _quat(q)
    norm = np.linalg.norm(arr, axis=-1, keepdims=True)
    bad = ~(np.isfinite(norm) & (norm > 0.0))
    if np.any(bad):
        idx = np.argwhere(bad[..., 0])
        where = f" at index {tuple(idx[0])}" if idx.size else ""
        raise DataError(f"q: zero or non-finite quaternion{where}; cannot normalise")
    return arr / norm


def quat_canonical(q: Any) -> FloatArray:
    """Return the representative with ``w >= 0`` (q and -q are the same rotation)."""
    arr = _quat(q)
    return np.where(arr[..., :1] < 0.0, -arr, arr)


def quat_rotate(q: Any, v: Any) -> FloatArray:
    """Rotate vectors: ``v' = q v q*``. With ``q_world_sensor``: sensor -> world."""
    qa = _quat(q)
    va = _vec3(v)
    w = qa[..., :1]
    u = qa[..., 1:]
    # v' = v + 2 w (u x v) + 2 u x (u x v), valid for unit q
    t = 2.0 * _cross(u, va)
    return va + w * t + _cross(u, t)


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """``np.cross`` on the last axis with its arithmetic (the same bits), without its
    axis bookkeeping (which dominates on small inputs)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def quat_rotate_inv(q: Any, v: Any) -> FloatArray:
    """Rotate by the inverse: ``v' = q* v q``. With ``q_world_sensor``: world -> sensor."""
    return quat_rotate(quat_conj(q), v)


def quat_to_matrix(q: Any) -> FloatArray:
    """Rotation matrix (..., 3, 3) of a unit quaternion; ``R @ v == quat_rotate(q, v)``."""
    qa = _quat(q)
    w, x, y, z = qa[..., 0], qa[..., 1], qa[..., 2], qa[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    out = np.empty((*qa.shape[:-1], 3, 3))
    out[..., 0, 0] = 1 - 2 * (yy + zz)
    out[..., 0, 1] = 2 * (xy - wz)
    out[..., 0, 2] = 2 * (xz + wy)
    out[..., 1, 0] = 2 * (xy + wz)
    out[..., 1, 1] = 1 - 2 * (xx + zz)
    out[..., 1, 2] = 2 * (yz - wx)
    out[..., 2, 0] = 2 * (xz - wy)
    out[..., 2, 1] = 2 * (yz + wx)
    out[..., 2, 2] = 1 - 2 * (xx + yy)
    return out


def quat_from_matrix(R: Any) -> FloatArray:
    """Unit quaternion (w >= 0) of a rotation matrix (..., 3, 3).

    Uses the numerically stable branch on the largest of the four squared
    components (Shepperd's method), so it is exact near rotations of pi too.
    """
    m = as_float_array(R, "R")
    if m.ndim < 2 or m.shape[-2:] != (3, 3):
        raise ShapeError(f"R: expected shape (3, 3) or (N, 3, 3), got {m.shape}")
    m00, m01, m02 = m[..., 0, 0], m[..., 0, 1], m[..., 0, 2]
    m10, m11, m12 = m[..., 1, 0], m[..., 1, 1], m[..., 1, 2]
    m20, m21, m22 = m[..., 2, 0], m[..., 2, 1], m[..., 2, 2]
    trace = m00 + m11 + m22
    cand = np.stack([trace, m00, m11, m22], axis=-1)
    choice = np.argmax(cand, axis=-1)
    out = np.empty((*m.shape[:-2], 4))
    # each branch computes the largest component from the diagonal, others from off-diagonals
    with np.errstate(invalid="ignore", divide="ignore"):
        s0 = np.sqrt(np.maximum(1.0 + trace, 0.0)) * 2.0
        b0 = np.stack([0.25 * s0, (m21 - m12) / s0, (m02 - m20) / s0, (m10 - m01) / s0], -1)
        s1 = np.sqrt(np.maximum(1.0 + m00 - m11 - m22, 0.0)) * 2.0
        b1 = np.stack([(m21 - m12) / s1, 0.25 * s1, (m01 + m10) / s1, (m02 + m20) / s1], -1)
        s2 = np.sqrt(np.maximum(1.0 - m00 + m11 - m22, 0.0)) * 2.0
        b2 = np.stack([(m02 - m20) / s2, (m01 + m10) / s2, 0.25 * s2, (m12 + m21) / s2], -1)
        s3 = np.sqrt(np.maximum(1.0 - m00 - m11 + m22, 0.0)) * 2.0
        b3 = np.stack([(m10 - m01) / s3, (m02 + m20) / s3, (m12 + m21) / s3, 0.25 * s3], -1)
    for k, b in enumerate((b0, b1, b2, b3)):
        sel = choice == k
        out[sel] = b[sel]
    return quat_canonical(quat_normalize(out))


def quat_exp(v: Any) -> FloatArray:
    """Exponential of the pure quaternion ``[0, v]``: ``[cos|v|, sin|v| v/|v|]``.

    Note the factor: a rotation by angle ``a`` about unit axis ``n`` is ``quat_exp(a n / 2)``.
    """
    va = _vec3(v)
    theta = np.linalg.norm(va, axis=-1, keepdims=True)
    small = theta < _SMALL_ANGLE
    safe = np.where(small, 1.0, theta)
    # sin(t)/t ~ 1 - t^2/6 near zero
    sinc = np.where(small, 1.0 - theta * theta / 6.0, np.sin(safe) / safe)
    return np.concatenate([np.cos(theta), sinc * va], axis=-1)


def quat_log(q: Any) -> FloatArray:
    """Logarithm of a unit quaternion: the vector ``v`` with ``quat_exp(v) == q``.

    The result is for the representative with ``w >= 0``, so ``|v| <= pi/2``.
    """
    qa = quat_canonical(_quat(q))
    w = qa[..., :1]
    u = qa[..., 1:]
    s = np.linalg.norm(u, axis=-1, keepdims=True)
    theta = np.arctan2(s, w)
    small = s < _SMALL_ANGLE
    safe = np.where(small, 1.0, s)
    # theta / s ~ 1/w (1 - s^2/(3 w^2)) near zero
    factor = np.where(small, (1.0 - s * s / (3.0 * w * w)) / w, theta / safe)
    return factor * u


def quat_from_rotvec(rotvec: Any) -> FloatArray:
    """Quaternion of a rotation vector (axis times angle, rad)."""
    return quat_exp(0.5 * _vec3(rotvec, "rotvec"))


def quat_to_rotvec(q: Any) -> FloatArray:
    """Rotation vector (axis times angle in [0, pi], rad) of a unit quaternion."""
    return 2.0 * quat_log(q)


def quat_from_axis_angle(axis: Any, angle: Any) -> FloatArray:
    """Quaternion of a rotation by ``angle`` [rad] about ``axis`` (normalised here)."""
    ax = _vec3(axis, "axis")
    norm = np.linalg.norm(ax, axis=-1, keepdims=True)
    if np.any(norm == 0.0):
        raise DataError("axis: zero-length rotation axis")
    half = 0.5 * np.asarray(angle, dtype=np.float64)[..., None]
    vec = np.sin(half) * ax / norm
    scalar = np.broadcast_to(np.cos(half), (*vec.shape[:-1], 1))
    return np.concatenate([scalar, vec], axis=-1)


def quat_to_axis_angle(q: Any) -> tuple[FloatArray, FloatArray]:
    """Unit axis (..., 3) and angle (...,) in [0, pi]. The axis is x for the identity."""
    rv = quat_to_rotvec(q)
    angle = np.linalg.norm(rv, axis=-1)
    safe = np.where(angle > 0.0, angle, 1.0)[..., None]
    axis = np.where(angle[..., None] > 0.0, rv / safe, np.array([1.0, 0.0, 0.0]))
    return axis, angle


def quat_angle(q: Any) -> FloatArray:
    """Rotation angle of q in [0, pi] (rad), robust near 0 and pi."""
    qa = _quat(q)
    return 2.0 * np.arctan2(np.linalg.norm(qa[..., 1:], axis=-1), np.abs(qa[..., 0]))


def quat_angle_between(q1: Any, q2: Any) -> FloatArray:
    """Angle (rad, in [0, pi]) of the rotation taking q1 to q2; sign-invariant."""
    return quat_angle(quat_mul(quat_conj(q1), q2))


def quat_slerp(q0: Any, q1: Any, t: Any) -> FloatArray:
    """Spherical linear interpolation along the shorter arc; ``t`` in [0, 1] broadcasts."""
    a = quat_normalize(q0)
    b = quat_normalize(q1)
    dot = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(dot < 0.0, -b, b)
    delta = quat_log(quat_mul(quat_conj(a), b))
    tt = np.asarray(t, dtype=np.float64)[..., None]
    return quat_mul(a, quat_exp(tt * delta))


def quat_from_two_vectors(a: Any, b: Any) -> FloatArray:
    """Shortest rotation taking direction ``a`` to direction ``b`` (both (..., 3))."""
    u = _vec3(a, "a")
    v = _vec3(b, "b")
    nu = np.linalg.norm(u, axis=-1, keepdims=True)
    nv = np.linalg.norm(v, axis=-1, keepdims=True)
    if np.any(nu == 0.0) or np.any(nv == 0.0):
        raise DataError("a, b: zero-length vector has no direction")
    u = u / nu
    v = v / nv
    d = np.sum(u * v, axis=-1, keepdims=True)
    c = np.cross(u, v)
    q = np.concatenate([1.0 + d, c], axis=-1)
    # antiparallel: rotate by pi about any axis orthogonal to u
    anti = (1.0 + d)[..., 0] < 1e-12
    if np.any(anti):
        ortho = np.cross(u, np.array([1.0, 0.0, 0.0]))
        weak = np.linalg.norm(ortho, axis=-1) < 1e-6
        ortho = np.where(weak[..., None], np.cross(u, np.array([0.0, 1.0, 0.0])), ortho)
        alt = np.concatenate([np.zeros_like(d), ortho], axis=-1)
        q = np.where(anti[..., None], alt, q)
    return quat_normalize(q)


def quat_to_xyzw(q: Any) -> FloatArray:
    """``[w, x, y, z]`` -> ``[x, y, z, w]`` (SciPy, ROS, Pinocchio). Edge use only."""
    qa = _quat(q)
    return np.concatenate([qa[..., 1:], qa[..., :1]], axis=-1)


def quat_from_xyzw(q_xyzw: Any) -> FloatArray:
    """``[x, y, z, w]`` -> ``[w, x, y, z]``. Edge use only."""
    qa = _quat(q_xyzw, "q_xyzw")
    return np.concatenate([qa[..., 3:], qa[..., :3]], axis=-1)
