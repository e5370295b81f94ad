"""Euler and Tait-Bryan angles for all 12 sequences, intrinsic and extrinsic.

Sequence strings follow SciPy's convention: three axis letters, upper case for
intrinsic rotations (about the moving axes, ``"ZYX"`` = yaw, pitch, roll), lower
case for extrinsic (about the fixed axes). For intrinsic ``"IJK"`` with angles
``(a, b, c)``: ``q = q_I(a) * q_J(b) * q_K(c)``; for extrinsic ``"ijk"``:
``q = q_k(c) * q_j(b) * q_i(a)``.

Decomposition uses the direct quaternion method of Bernardes and Viollet (2022,
"Quaternion to Euler angles conversion: a direct, general and computationally
efficient method", PLoS ONE), written here for numpy stacks.

Ranges: first and third angles in (-pi, pi]; the middle angle in [0, pi] for
proper Euler sequences (first axis == last axis) and [-pi/2, pi/2] for
Tait-Bryan sequences.

Gimbal lock (middle angle at 0 or pi for proper sequences, +-pi/2 for
Tait-Bryan): only the sum or the difference of the outer angles is defined.
We then set the *third* angle of the user's sequence to zero and put the whole
rotation in the first; :func:`euler_from_quat` reports this through its
``return_gimbal`` flag so callers (joint retargeting) can hold the previous value.
"""

from __future__ import annotations

from typing import Any, Literal, overload

import numpy as np

from mocapkit._validate import FloatArray, as_float_array
from mocapkit.errors import ConfigError, ShapeError
from mocapkit.geometry.quaternion import _quat, quat_mul, quat_normalize

# Middle angles within this distance [rad] of a singular value are treated as gimbal lock.
# 1e-7 rad keeps the decomposition well conditioned: at this distance the outer angles'
# sensitivity to quaternion noise (~1/sin(distance)) would exceed 1e7.
GIMBAL_TOLERANCE = 1e-7

_AXES = {"x": 0, "y": 1, "z": 2}

ALL_SEQUENCES: tuple[str, ...] = tuple(
    s
    for base in (
        "xyz", "xzy", "yxz", "yzx", "zxy", "zyx",
        "xyx", "xzx", "yxy", "yzy", "zxz", "zyz",
    )
    for s in (base, base.upper())
)  # fmt: skip


def _parse(seq: str) -> tuple[tuple[int, int, int], bool]:
    if not isinstance(seq, str) or len(seq) != 3 or not (seq.isupper() or seq.islower()):
        raise ConfigError(
            f"seq: expected three axis letters, all upper case (intrinsic) or all lower case "
            f"(extrinsic), e.g. 'ZYX' or 'xyz'; got {seq!r}"
        )
    try:
        axes = tuple(_AXES[c] for c in seq.lower())
    except KeyError as exc:
        raise ConfigError(f"seq: axis letters must be x, y or z; got {seq!r}") from exc
    if axes[0] == axes[1] or axes[1] == axes[2]:
        raise ConfigError(f"seq: consecutive axes must differ; got {seq!r}")
    return (axes[0], axes[1], axes[2]), seq.isupper()


def _elementary(axis: int, angle: FloatArray) -> FloatArray:
    half = 0.5 * angle
    out = np.zeros((*angle.shape, 4))
    out[..., 0] = np.cos(half)
    out[..., 1 + axis] = np.sin(half)
    return out


def quat_from_euler(angles: Any, seq: str) -> FloatArray:
    """Quaternion (..., 4) from Euler angles (..., 3) [rad] in sequence ``seq``."""
    axes, intrinsic = _parse(seq)
    ang = as_float_array(angles, "angles")
    if ang.ndim == 0 or ang.shape[-1] != 3:
        raise ShapeError(f"angles: expected shape (3,) or (N, 3), got {ang.shape}")
    q1 = _elementary(axes[0], ang[..., 0])
    q2 = _elementary(axes[1], ang[..., 1])
    q3 = _elementary(axes[2], ang[..., 2])
    if intrinsic:
        return quat_mul(quat_mul(q1, q2), q3)
    return quat_mul(q3, quat_mul(q2, q1))


def _wrap(a: FloatArray) -> FloatArray:
    """Wrap to (-pi, pi]."""
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


@overload
def euler_from_quat(q: Any, seq: str, *, return_gimbal: Literal[False] = ...) -> FloatArray: ...
@overload
def euler_from_quat(
    q: Any, seq: str, *, return_gimbal: Literal[True]
) -> tuple[FloatArray, np.ndarray]: ...


def euler_from_quat(
    q: Any, seq: str, *, return_gimbal: bool = False
) -> FloatArray | tuple[FloatArray, np.ndarray]:
    """Euler angles (..., 3) [rad] of unit quaternions ``q`` in sequence ``seq``.

    With ``return_gimbal=True`` also returns a boolean array (...,) marking samples
    in gimbal lock, where the third angle was set to zero (see module docstring).
    """
    axes, intrinsic = _parse(seq)
    qa = quat_normalize(_quat(q))
    # the direct method is written for extrinsic sequences; an intrinsic sequence
    # equals the reversed extrinsic one with its angles reversed
    i, j, k = axes[::-1] if intrinsic else axes
    proper = i == k
    if proper:
        k = 3 - i - j
    # parity of the permutation (i, j, k) of (0, 1, 2): +1 even, -1 odd
    parity = float((i - j) * (j - k) * (k - i) // 2)
    w = qa[..., 0]
    qi, qj, qk = qa[..., 1 + i], qa[..., 1 + j], qa[..., 1 + k] * parity
    if proper:
        a, b, c, d = w, qi, qj, qk
    else:
        # rotate the quaternion by pi/2 about axis j so the Tait-Bryan case maps to a proper one
        a, b, c, d = w - qj, qi + qk, qj + w, qk - qi
    middle = 2.0 * np.arctan2(np.hypot(c, d), np.hypot(a, b))
    half_sum = np.arctan2(b, a)
    half_diff = np.arctan2(d, c)
    at_zero = np.abs(middle) <= GIMBAL_TOLERANCE
    at_pi = np.abs(middle - np.pi) <= GIMBAL_TOLERANCE
    gimbal = at_zero | at_pi

    first = half_sum - half_diff
    third = half_sum + half_diff
    # gimbal lock: the user's third angle is zero. For intrinsic sequences the
    # user's third angle is the extrinsic first one.
    if intrinsic:
        first = np.where(gimbal, 0.0, first)
        third = np.where(at_zero, 2.0 * half_sum, np.where(at_pi, 2.0 * half_diff, third))
    else:
        third = np.where(gimbal, 0.0, third)
        first = np.where(at_zero, 2.0 * half_sum, np.where(at_pi, -2.0 * half_diff, first))
    if not proper:
        third = third * parity
        middle = middle - 0.5 * np.pi
    out = np.stack([_wrap(first), middle, _wrap(third)], axis=-1)
    if intrinsic:
        out = out[..., ::-1].copy()
    if return_gimbal:
        return out, gimbal
    return out
