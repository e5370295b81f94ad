"""``miller``: the paper's step-correct complementary quaternion filter (seed section 3).

Miller, Jenkins, Kallmann, Mataric, "Motion capture from inertial sensing for
untethered humanoid teleoperation" (Humanoids 2004), eq. 2-14 and Fig. 3, as written;
the choices below are ours wherever the text is ambiguous or misprinted.

One step, with ``q = q_t`` the estimate ``q_world_sensor``:

1. gyroscope integration (eq. 2-4): ``omega = [0, gyr dt]``, ``dq = 1/2 q omega``;
2. reference vectors to the local frame (eq. 6-8): ``g_local = q* g_ref q``,
   ``m_local = q* m_ref q`` with ``g_ref = [0, 0, 1]`` (up) and the dip-corrected
   ``m_ref = [0, 1, 0]`` (magnetic north) in the ENU world;
3. sensed vectors: ``g_sensed = acc / |acc|``; ``m_sensed`` see choice 6;
4. error vectors (eq. 9-10): ``g_error = g_local - g_sensed``, likewise for m;
5. error angles by the law of cosines on projections onto the local coordinate planes
   chosen by the partition (Fig. 3) that ``g_sensed`` falls in;
6. error-rate quaternion and correction (eq. 11-13):
   ``eps = [0, e_x dt, e_y dt, e_z dt]``, ``q_correct = 1/2 q eps``,
   ``q_next = q + dq - alpha q_correct``;
7. normalisation (eq. 14).

Choices where the paper is ambiguous or misprinted:

1. *Eq. 5 signs.* The printed product has garbled signs (e.g. ``- x1 r2`` in the i
   term, which is not associative). Eq. 3 and 6-7 only make sense with the Hamilton
   product, so that is what is used (``mocapkit.geometry.quat_mul``): ``q* v q`` maps a
   world vector to the sensor frame, and ``1/2 q omega`` is the kinematics of
   ``q_world_sensor`` with a body-frame rate.
2. *Degrees vs radians.* Eq. 2 says the rates are in degrees/s; quaternion
   kinematics need radians, so everything is in radians (gyr rad/s, error angles
   rad). The gain ``alpha`` therefore has units 1/s: each step removes about
   ``alpha dt`` of the error, a correction time constant of ``1/alpha`` seconds (with
   error angles in degrees the same behaviour would need ``alpha`` 57.3 times smaller).
3. *Partition boundaries (Fig. 3).* The figure shows three regions "along" z, y, x
   without boundaries. ``g_sensed`` is in partition 1 (z), 2 (y) or 3 (x) when that
   axis has the largest ``|component|``: the boundaries are the planes ``|g_i| = |g_j|``
   (both signs of an axis belong to its partition); ties go to z, then y.
4. *Eq. 11 ordering.* ``eps = [0, Theta, phi, mu]`` lists roll, pitch, yaw for
   partition 1, but in partitions 2 and 3 the paper measures e.g. "pitch" in the x-y
   plane, which is a rotation about z. The consistent reading, used here: the angle
   measured in the plane normal to local axis k is the correction about axis k, and
   it goes into component k of ``eps``. Gravity gives the two axes normal to the
   partition axis; the magnetometer gives the partition axis itself (the heading,
   about the local axis nearest the vertical). For partition 1 this is exactly
   ``[0, Theta, phi, mu]``.
5. *Signs of the law-of-cosines angles.* The law of cosines
   ``cos a = (|l|^2 + |s|^2 - |e|^2) / (2 |l| |s|)`` on the projected local, sensed and
   error vectors gives an unsigned angle in [0, pi]; without a sign the correction
   cannot converge. The sign is that of ``(l x s) . axis_k`` (projections), so
   ``eps`` is the rotation taking the local (predicted) vector onto the sensed one,
   i.e. the estimate's error, which eq. 13 subtracts. Antiparallel projections
   (cross product zero, angle pi) take the positive sign so an upside-down start
   still converges. A projection shorter than 1e-9 gives no angle (0).
6. *m_sensed and the dip.* The paper removes the dip from ``m_ref`` but says nothing
   of ``m_sensed``; comparing a horizontal ``m_ref`` with the dipped raw field would
   leave a permanent error of the dip angle (about 68 deg in Berlin) that leaks into
   the yaw angle whenever the sensor is tilted. ``m_sensed`` is therefore made
   horizontal the same way: its component along the estimated vertical
   ``g_local`` is removed before normalising (using ``g_local`` rather than the
   accelerometer keeps linear accelerations out of the heading correction). If the
   field is within 1e-6 of vertical the magnetometer is skipped for that sample.
7. *Integration.* Eq. 4 is first-order (Euler) integration ``q + 1/2 q omega dt``
   followed by the normalisation of eq. 14; kept as written (exact exponential
   integration would be slightly more accurate at high rates).
8. *6D and gaps.* Without a magnetometer (or in a magnetometer gap, or with a
   rejected sample) the magnetic angle is 0: the heading is integrated from the
   gyroscope only. Without a usable accelerometer sample all error angles are 0.

9. *Time alignment.* A gyroscope sample is taken as the rate over the interval that
   ends at its time stamp (the convention of BROAD's data and of vqf's and Madgwick's
   implementations), the accelerometer and magnetometer samples as readings at that
   time. Eq. 6-7 and 12 are therefore evaluated at the gyroscope-propagated estimate
   ``q_t + dq`` (normalised), the orientation at the readings' time, and eq. 13 is
   then applied as printed. Evaluating them at ``q_t``, as the printed eq. 12 reads,
   compares the readings with the orientation one sample earlier and leaves a steady
   lag of ``|w| dt`` (0.13 deg at 0.23 rad/s and 100 Hz in the tests, several degrees
   during BROAD's fast rotations).
The gain ``alpha`` default (:data:`DEFAULT_ALPHA`) was tuned on the BROAD trials by
leave-one-out cross-validation (``python -m benchmarks.tune_gains``; see docs/imu.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_mul, quat_rotate_inv
from mocapkit.imu.filters.base import (
    Backend,
    FilterInputs,
    FilterState,
    GainParams,
    OrientationFilter,
    register_filter,
)
from mocapkit.imu.filters.miller_kernel import miller_run_kernel

DEFAULT_ALPHA = 0.11  # [1/s], see the module docstring
G_REF = np.array([0.0, 0.0, 1.0])  # up, ENU world
M_REF = np.array([0.0, 1.0, 0.0])  # dip-corrected magnetic north, ENU world
_MIN_PROJECTION = 1e-9


@dataclass(frozen=True)
class MillerParams(GainParams):
    """``alpha``: correction gain [1/s] of eq. 13 (time constant ``1/alpha``);
    ``0 <= alpha dt < 1``."""

    alpha: float = DEFAULT_ALPHA


@dataclass
class MillerState(FilterState):
    """The paper's filter carries only the orientation (and the dip, unused)."""


def partition_axis(g_sensed: FloatArray) -> int:
    """Fig. 3: the local axis (2 = z partition 1, 1 = y partition 2, 0 = x partition 3)
    with the largest ``|component|`` of ``g_sensed``; ties go to z, then y."""
    k = 2
    if abs(g_sensed[1]) > abs(g_sensed[k]):
        k = 1
    if abs(g_sensed[0]) > abs(g_sensed[k]):
        k = 0
    return k


def law_of_cosines_angle(local: FloatArray, sensed: FloatArray, axis: int) -> float:
    """Signed error angle [rad] about local ``axis``, from the projections of ``local``,
    ``sensed`` and ``error = local - sensed`` (eq. 9-10) onto the plane normal to it.

    Positive when rotating the projected ``local`` about ``+axis`` reaches ``sensed``.
    """
    p_local = local.copy()
    p_local[axis] = 0.0
    p_sensed = sensed.copy()
    p_sensed[axis] = 0.0
    p_error = p_local - p_sensed
    a = float(np.linalg.norm(p_local))
    b = float(np.linalg.norm(p_sensed))
    c = float(np.linalg.norm(p_error))
    if a < _MIN_PROJECTION or b < _MIN_PROJECTION:
        return 0.0
    cos_angle = min(1.0, max(-1.0, (a * a + b * b - c * c) / (2.0 * a * b)))
    angle = float(np.arccos(cos_angle))
    return angle if np.cross(p_local, p_sensed)[axis] >= 0.0 else -angle


def error_angles(
    q: FloatArray, acc: FloatArray, mag: FloatArray, use_acc: bool, use_mag: bool
) -> FloatArray:
    """``[e_x, e_y, e_z]`` [rad]: the angles of eq. 11 (choices 3-6 of the module doc)."""
    angles = np.zeros(3)
    if not use_acc:
        return angles
    g_sensed = acc / np.linalg.norm(acc)
    g_local = quat_rotate_inv(q, G_REF)  # eq. 6
    k = partition_axis(g_sensed)
    for axis in range(3):
        if axis != k:
            angles[axis] = law_of_cosines_angle(g_local, g_sensed, axis)
    if use_mag:
        m_local = quat_rotate_inv(q, M_REF)  # eq. 7
        m_horizontal = mag - float(mag @ g_local) * g_local
        norm = float(np.linalg.norm(m_horizontal))
        if norm > 1e-6 * float(np.linalg.norm(mag)):
            angles[k] = law_of_cosines_angle(m_local, m_horizontal / norm, k)
    return angles


def miller_step(
    q: FloatArray,
    gyr: FloatArray,
    acc: FloatArray,
    mag: FloatArray,
    dt: float,
    use_acc: bool,
    use_mag: bool,
    alpha: float,
) -> FloatArray:
    """One step of eq. 2-14 from ``q`` (4,), the estimate at the previous sample's time;
    returns the normalised estimate at this sample's time (choice 9)."""
    omega = np.concatenate([[0.0], gyr * dt])  # eq. 2
    dq = 0.5 * quat_mul(q, omega)  # eq. 3
    q_pred = (q + dq) / np.linalg.norm(q + dq)  # eq. 4, 14: the orientation at the readings' time
    angles = error_angles(q_pred, acc, mag, use_acc, use_mag)  # eq. 6-10 and Fig. 3
    eps = np.concatenate([[0.0], angles * dt])  # eq. 11
    q_correct = 0.5 * quat_mul(q_pred, eps)  # eq. 12
    q_next = q + dq - alpha * q_correct  # eq. 13
    return q_next / np.linalg.norm(q_next)  # eq. 14


class MillerFilter(OrientationFilter):
    """The paper's filter; see the module docstring for the equations and choices."""

    name = "miller"
    state_type = MillerState
    params: MillerParams

    def __init__(self, params: MillerParams, backend: Backend = "fast") -> None:
        if not isinstance(params, MillerParams):
            raise ConfigError(f"params: expected MillerParams, got {type(params).__name__}")
        super().__init__(params, backend)

    def _run_reference(self, inputs: FilterInputs) -> FloatArray:
        q = np.array(self.state.quat, dtype=np.float64)
        out = np.empty((inputs.gyr.shape[0], 4))
        for i in range(out.shape[0]):
            q = miller_step(
                q,
                inputs.gyr[i],
                inputs.acc[i],
                inputs.mag[i],
                float(inputs.dt[i]),
                bool(inputs.use_acc[i]),
                bool(inputs.use_mag[i]),
                self.params.alpha,
            )
            out[i] = q
        self.state.quat = q.copy()
        return out

    def _run_fast(self, inputs: FilterInputs) -> FloatArray:
        q = np.array(self.state.quat, dtype=np.float64)
        out = miller_run_kernel(q, *inputs[:6], self.params.alpha)
        self.state.quat = q  # the kernel leaves the final estimate in q
        return out


@register_filter("miller")
def make_miller(rate_hz: float, backend: Backend = "fast", **params: Any) -> MillerFilter:
    """Registry factory: ``make_filter("miller", rate_hz, alpha=...)``."""
    return MillerFilter(MillerParams(rate_hz=rate_hz, **params), backend)
