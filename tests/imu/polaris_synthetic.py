"""Noise-free IMU signals from a known rotation trajectory, for ``polaris`` tests.

The trajectory is defined by its body rates: ``q[k] = q[k-1] * exp(w[k] dt)`` from ``q0``
(the same discrete kinematics the filters integrate, so the truth is exact), with a rest
period first. The readings are ``gyr = w + bias``, ``acc = R^T (g up + a_lin)`` and
``mag = R^T field + hard_iron`` (+ an optional world-frame disturbance).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapkit.geometry import quat_from_rotvec, quat_mul, quat_normalize, quat_rotate_inv

G = 9.81
# Berlin-like field [uT], ENU: 68.6 deg dip.
FIELD_ENU = np.array([0.0, 16.0, -41.0])


@dataclass(frozen=True)
class Synthetic:
    """Readings (N, 3), truth ``q`` (N, 4) ``q_world_sensor`` and the constants used."""

    rate_hz: float
    gyr: np.ndarray
    acc: np.ndarray
    mag: np.ndarray
    q: np.ndarray
    bias: np.ndarray
    rest_samples: int


def body_rates(n: int, rate_hz: float, rest_s: float, amplitude: float) -> np.ndarray:
    """(N, 3) smooth multi-axis rates [rad/s]: zero for ``rest_s``, then sines whose
    frequencies are not multiples of each other (every axis is excited)."""
    t = np.arange(n) / rate_hz
    freqs = np.array([0.31, 0.53, 0.71])
    phases = np.array([0.0, 1.0, 2.0])
    w = amplitude * np.sin(2 * np.pi * freqs * (t[:, None] - rest_s) + phases)
    ramp = np.clip((t - rest_s) / 2.0, 0.0, 1.0)  # start moving smoothly over 2 s
    return w * ramp[:, None]


def make_synthetic(
    duration_s: float = 60.0,
    rate_hz: float = 200.0,
    rest_s: float = 5.0,
    q0: np.ndarray | None = None,
    bias_deg_s: tuple[float, float, float] = (0.4, -0.3, 0.25),
    amplitude_deg_s: float = 60.0,
    hard_iron: np.ndarray | None = None,
    hard_iron_from_s: float = 0.0,
    world_disturbance: np.ndarray | None = None,
    disturbance_s: tuple[float, float] = (0.0, 0.0),
) -> Synthetic:
    n = round(duration_s * rate_hz)
    dt = 1.0 / rate_hz
    w = body_rates(n, rate_hz, rest_s, np.radians(amplitude_deg_s))
    steps = quat_from_rotvec(w * dt)
    q = np.empty((n, 4))
    cur = quat_normalize(np.asarray(q0 if q0 is not None else [1.0, 0.0, 0.0, 0.0], float))
    for k in range(n):
        cur = quat_normalize(quat_mul(cur, steps[k]))
        q[k] = cur
    bias = np.radians(np.asarray(bias_deg_s, float))
    acc = quat_rotate_inv(q, np.tile([0.0, 0.0, G], (n, 1)))
    field = np.tile(FIELD_ENU, (n, 1))
    if world_disturbance is not None:
        t = np.arange(n) / rate_hz
        on = (t >= disturbance_s[0]) & (t < disturbance_s[1])
        field[on] += world_disturbance
    mag = quat_rotate_inv(q, field)
    if hard_iron is not None:
        t = np.arange(n) / rate_hz
        mag[t >= hard_iron_from_s] += hard_iron
    return Synthetic(rate_hz, w + bias, acc, mag, q, bias, round(rest_s * rate_hz))
