"""Exact synthetic IMU signals for filter tests: a sensor turning at a constant body rate.

With ``q(t) = q0 * exp(w t / 2)`` the gyroscope reads exactly ``w`` and the
accelerometer / magnetometer read the world vectors rotated into the sensor frame,
so a filter's only error is its own (integration, gains).
"""

from __future__ import annotations

import numpy as np

from mocapkit.geometry import quat_exp, quat_mul, quat_rotate_inv

GRAVITY = 9.81
DIP = np.radians(65.0)
FIELD_WORLD = 48.0 * np.array([0.0, np.cos(DIP), -np.sin(DIP)])  # uT, ENU


def constant_rotation(
    q0: np.ndarray, rate: np.ndarray, n: int, rate_hz: float = 100.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(q_true (n, 4), gyr (n, 3), acc (n, 3), mag (n, 3)) at sample times k / rate_hz,
    k = 1..n: a filter started from ``q0`` (time 0) outputs row k - 1 at time k / rate_hz."""
    t = np.arange(1, n + 1) / rate_hz
    q = quat_mul(np.asarray(q0, float), quat_exp(0.5 * t[:, None] * np.asarray(rate, float)))
    gyr = np.tile(np.asarray(rate, float), (n, 1))
    acc = quat_rotate_inv(q, np.array([0.0, 0.0, GRAVITY]))
    mag = quat_rotate_inv(q, FIELD_WORLD)
    return q, gyr, acc, mag
