"""Orientation error metrics as defined by BROAD (Laidig et al. 2021, section 4).

The error quaternion in the world frame is ``e = q_est * conj(q_ref)``. From it:

- total error: the whole rotation angle ``2 acos|e_w|``;
- heading error: the rotation about the world vertical, ``2 atan(|e_z / e_w|)``;
- inclination error: the tilt part, ``2 acos(sqrt(e_w^2 + e_z^2))``.

RMS values are taken over the samples that are in the movement phase and have a
finite reference. In 9D no alignment is fitted: BROAD's reference is already in
the IMU's ENU frame. In 6D the heading is unobservable, so before the total error
we remove one constant heading offset (the circular mean of the heading error over
the evaluated samples); the inclination error is unaffected by that alignment.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray, as_float_array, check_shape
from mocapkit.errors import DataError
from mocapkit.geometry import quat_conj, quat_mul, quat_normalize


@dataclass(frozen=True)
class OrientationErrors:
    """RMS errors [rad] over the evaluated samples."""

    total: float
    heading: float
    inclination: float
    n_samples: int

    def as_degrees(self) -> dict[str, float]:
        return {
            "total_deg": float(np.degrees(self.total)),
            "heading_deg": float(np.degrees(self.heading)),
            "inclination_deg": float(np.degrees(self.inclination)),
        }


def error_quat_world(q_est: Any, q_ref: Any) -> FloatArray:
    """``e = q_est * conj(q_ref)`` (N, 4), normalised, in the world frame."""
    return quat_normalize(quat_mul(quat_normalize(q_est), quat_conj(quat_normalize(q_ref))))


# The atan2 forms below equal BROAD's acos forms exactly for unit quaternions but keep
# full precision for small errors, where acos(1 - eps) loses half the digits.


def total_error(e: FloatArray) -> FloatArray:
    """``2 acos|e_w|`` [rad]."""
    return 2.0 * np.arctan2(np.linalg.norm(e[..., 1:], axis=-1), np.abs(e[..., 0]))


def heading_error(e: FloatArray) -> FloatArray:
    """``2 atan(|e_z / e_w|)`` [rad]."""
    return 2.0 * np.arctan(np.abs(e[..., 3] / e[..., 0]))


def inclination_error(e: FloatArray) -> FloatArray:
    """``2 acos(sqrt(e_w^2 + e_z^2))`` [rad]."""
    return 2.0 * np.arctan2(np.hypot(e[..., 1], e[..., 2]), np.hypot(e[..., 0], e[..., 3]))


def _rms(x: FloatArray) -> float:
    return float(np.sqrt(np.mean(x * x)))


def orientation_rmse(
    q_est: Any, q_ref: Any, mask: Any | None = None, *, align_heading: bool = False
) -> OrientationErrors:
    """BROAD's total / heading / inclination RMSE [rad].

    Args:
        q_est: (N, 4) estimate ``q_world_sensor``.
        q_ref: (N, 4) reference; rows of NaN are skipped.
        mask: (N,) bool, samples to evaluate (BROAD's ``movement``); all when None.
        align_heading: remove one constant heading offset first (use in 6D).
    """
    est = as_float_array(q_est, "q_est")
    ref = as_float_array(q_ref, "q_ref")
    check_shape(est, "q_est", None, 4)
    check_shape(ref, "q_ref", est.shape[0], 4)
    sel = np.ones(est.shape[0], bool) if mask is None else np.asarray(mask, bool).reshape(-1)
    if sel.shape[0] != est.shape[0]:
        raise DataError(f"mask: expected {est.shape[0]} samples, got {sel.shape[0]}")
    sel = sel & np.isfinite(ref).all(axis=1)
    if not np.isfinite(est[sel]).all():
        bad = int(np.flatnonzero(sel & ~np.isfinite(est).all(axis=1))[0])
        raise DataError(f"q_est: non-finite estimate at sample {bad}; the filter diverged")
    if not sel.any():
        raise DataError("mask: no sample with a finite reference to evaluate")
    e = error_quat_world(est[sel], ref[sel])
    if align_heading:
        e = remove_mean_heading(e)
    return OrientationErrors(
        total=_rms(total_error(e)),
        heading=_rms(heading_error(e)),
        inclination=_rms(inclination_error(e)),
        n_samples=int(sel.sum()),
    )


def remove_mean_heading(e: FloatArray) -> FloatArray:
    """Left-multiply world-frame errors by the inverse of their circular-mean heading."""
    e = np.where(e[:, :1] < 0.0, -e, e)
    psi = 2.0 * np.arctan2(e[:, 3], e[:, 0])
    mean = float(np.arctan2(np.mean(np.sin(psi)), np.mean(np.cos(psi))))
    q_off_inv = np.array([np.cos(0.5 * mean), 0.0, 0.0, -np.sin(0.5 * mean)])
    return quat_mul(q_off_inv, e)
