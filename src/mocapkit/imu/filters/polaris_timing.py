"""Magnetometer latency from the IMU's own data (no reference needed).

Many IMUs sample the magnetometer slower than the gyroscope and deliver it later (BROAD's
sensor: about 14 ms, 4 samples at 286 Hz). A filter that compares the field with the
current orientation then sees, during fast rotations, a field turned by ``rate * delay``
(several degrees at 500 deg/s), which looks like a disturbance. Since a constant field
only rotates in the sensor frame the way the gyroscope says, the delay is the shift that
best predicts the field ``W`` samples later from the field now and the gyroscope:

    ``m[i + W] ~ R(i + W - d)^T R(i - d) m[i]``

(``R(k)`` the strapdown orientation after sample ``k``), minimised over integer ``d`` on
samples that rotate faster than ``min_rate``. It assumes a calibrated magnetometer
(no large hard iron) in a homogeneous field; a disturbance only adds noise to the cost.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mocapkit._validate import as_float_array, check_finite, check_shape
from mocapkit.errors import ConfigError, DataError
from mocapkit.geometry import quat_rotate, quat_rotate_inv
from mocapkit.imu.filters.polaris_engine import strapdown

_WINDOW = 20  # samples between the two fields compared (~70 ms at 286 Hz)


def estimate_mag_delay(
    gyr: Any,
    mag: Any,
    rate_hz: float,
    max_delay_s: float = 0.05,
    min_rate: float = np.radians(30.0),
) -> float:
    """Magnetometer latency [s] behind the gyroscope, a whole number of samples.

    Args:
        gyr: (N, 3) angular rate [rad/s].
        mag: (N, 3) magnetic field (any unit).
        rate_hz: sampling rate [Hz].
        max_delay_s: largest delay tried [s].
        min_rate: only samples rotating faster than this [rad/s] are used.

    Raises:
        DataError: when fewer than 100 samples rotate fast enough to tell.
    """
    g = as_float_array(gyr, "gyr")
    check_shape(g, "gyr", None, 3)
    m = as_float_array(mag, "mag")
    check_shape(m, "mag", g.shape[0], 3)
    check_finite(g, "gyr")
    check_finite(m, "mag")
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ConfigError(f"rate_hz: expected a positive sampling rate in Hz, got {rate_hz}")
    max_d = max(0, round(max_delay_s * rate_hz))
    n = g.shape[0]
    dt = np.full(n, 1.0 / rate_hz)
    q = strapdown("fast", np.ascontiguousarray(g), np.zeros((n, 3)), dt)
    fast = np.linalg.norm(g, axis=1) > min_rate
    base = np.arange(max_d, n - _WINDOW)
    base = base[fast[base]]
    if base.size < 100:
        raise DataError(
            f"gyr: only {base.size} samples rotate faster than {np.degrees(min_rate):.0f} "
            "deg/s; rotate the sensor for a few seconds to estimate the magnetometer delay"
        )
    costs = []
    for d in range(max_d + 1):
        m_inertial = quat_rotate(q[base - d], m[base])
        predicted = quat_rotate_inv(q[base + _WINDOW - d], m_inertial)
        err = m[base + _WINDOW] - predicted
        costs.append(float(np.mean(np.sum(err * err, axis=1))))
    return float(np.argmin(costs)) / rate_hz
