"""IMU signal synthesis from a known motion (gyroscope, accelerometer, magnetometer).

Input: a sensor's pose over time (:class:`mocapkit.series.PoseSeries`: ``q_world_sensor``
and the sensor's position [m] in an ENU world, z up). Output: an
:class:`~mocapkit.series.ImuRecording` in the sensor frame.

Noise-free signals are exact for the sampled motion (the property the tests check):

- ``gyr[k]`` (rad/s) is the constant body-frame rate that takes ``q[k-1]`` to ``q[k]``:
  ``q[k] = q[k-1] * exp(gyr[k] dt_k / 2)``, i.e. ``gyr[k] = 2 log(q[k-1]^-1 q[k]) / dt_k``
  (``gyr[0] = gyr[1]``). Integrating it recovers the orientation to rounding.
- ``acc[k]`` (m/s^2) is the specific force ``R_k^T (a_k + g e_z)``: reads +g up at rest.
  ``a_k`` is the (non-uniform) central second difference of the positions.
- ``mag[k]`` (uT) is ``R_k^T (m_world + d(t_k))`` with ``m_world = B [0, cos dip, -sin dip]``
  (ENU: y magnetic north, field pointing down in the northern hemisphere) and ``d`` the
  disturbances active at ``t_k``.

Errors, applied in a real sensor's order: scale error (per axis), bias (constant plus a
random walk: bias drift), white noise, saturation (clip at the range). White noise is given
per sample (``noise``) or, as datasheets do, as a density (``noise_density`` [unit/sqrt(Hz)]):
a sensor sampled at ``rate_hz`` whose output is band-limited to the Nyquist frequency has a
per-sample standard deviation ``density * sqrt(rate_hz / 2)``, so the same sensor is noisier
per sample at a higher rate while its angle random walk (``density`` per sqrt(s) after
integration) does not depend on the rate. Sample-time jitter
samples the motion at instants ``t_k + e_k`` (slerp / cubic spline), while the recorded
time stamps stay nominal (the true instants are in ``meta["true_time"]``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from mocapkit._validate import FloatArray, as_vectors
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_conj, quat_log, quat_mul, quat_rotate_inv, quat_slerp
from mocapkit.series import ImuRecording, PoseSeries

STANDARD_GRAVITY = 9.80665
_SQRT_50 = float(np.sqrt(50.0))  # the Nyquist bandwidth at 100 Hz: densities from 100 Hz figures


@dataclass(frozen=True)
class EarthField:
    """Gravity and the Earth's magnetic field at the site.

    Attributes:
        gravity: magnitude [m/s^2].
        mag_strength: total field [uT].
        dip: inclination [rad], positive when the field points below the horizon.
    """

    gravity: float = STANDARD_GRAVITY
    mag_strength: float = 50.0
    dip: float = np.deg2rad(60.0)

    @property
    def mag_world(self) -> FloatArray:
        """Field vector in ENU [uT]."""
        return self.mag_strength * np.array([0.0, np.cos(self.dip), -np.sin(self.dip)])


@dataclass(frozen=True)
class MagDisturbance:
    """An extra field ``field_world`` [uT] (ENU) added between ``t_start`` and ``t_stop`` [s]."""

    t_start: float
    t_stop: float
    field_world: tuple[float, float, float]


@dataclass(frozen=True)
class SensorErrors:
    """Error model of one triad (gyroscope, accelerometer or magnetometer), SI units.

    Attributes:
        noise: white-noise standard deviation per sample.
        noise_density: white-noise density [unit/sqrt(Hz)] (per sample
            ``noise_density * sqrt(rate_hz / 2)``; the two variances add).
        bias: constant bias (3,) or None to draw it from ``bias_std``.
        bias_std: standard deviation of the drawn constant bias.
        bias_drift: random-walk intensity of the bias [unit / sqrt(s)].
        scale_std: standard deviation of the per-axis scale error (1 + e).
        range: saturation: outputs are clipped to [-range, range].
    """

    noise: float = 0.0
    noise_density: float = 0.0
    bias: tuple[float, float, float] | None = None
    bias_std: float = 0.0
    bias_drift: float = 0.0
    scale_std: float = 0.0
    range: float = np.inf

    def __post_init__(self) -> None:
        for name in ("noise", "noise_density", "bias_std", "bias_drift", "scale_std"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ConfigError(f"{name}: expected a finite value >= 0, got {v}")
        if not self.range > 0:
            raise ConfigError(f"range: expected > 0, got {self.range}")

    @property
    def is_ideal(self) -> bool:
        return (
            self.noise == 0
            and self.noise_density == 0
            and self.bias is None
            and self.bias_std == 0
            and self.bias_drift == 0
            and self.scale_std == 0
        )


@dataclass(frozen=True)
class ImuErrorModel:
    """Errors of a 9-axis IMU. The defaults are ideal (no error)."""

    gyr: SensorErrors = field(default_factory=SensorErrors)
    acc: SensorErrors = field(default_factory=SensorErrors)
    mag: SensorErrors = field(default_factory=SensorErrors)
    time_jitter_s: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.time_jitter_s) and self.time_jitter_s >= 0):
            raise ConfigError(f"time_jitter_s: expected >= 0, got {self.time_jitter_s}")

    @property
    def is_random(self) -> bool:
        return self.time_jitter_s > 0 or not (
            self.gyr.is_ideal and self.acc.is_ideal and self.mag.is_ideal
        )

    @classmethod
    def consumer_grade(cls) -> ImuErrorModel:
        """Typical MEMS figures (BMI160/LSM9DS1 class), for demos and robustness tests.

        White noise as densities, chosen so that at 100 Hz the per-sample noise is
        0.005 rad/s (0.29 deg/s), 0.03 m/s^2 and 0.3 uT; bias drift (rate random walk)
        2e-4 rad/s/sqrt(s); a turn-on gyroscope bias of 0.57 deg/s (1 sigma); a
        magnetometer calibrated to 1 uT of hard iron and 1 % of soft iron.
        """
        return cls(
            gyr=SensorErrors(
                noise_density=0.005 / _SQRT_50,
                bias_std=0.01,
                bias_drift=2e-4,
                scale_std=0.005,
                range=34.9,
            ),
            acc=SensorErrors(
                noise_density=0.03 / _SQRT_50,
                bias_std=0.05,
                bias_drift=1e-3,
                scale_std=0.005,
                range=156.9,
            ),
            mag=SensorErrors(
                noise_density=0.3 / _SQRT_50, bias_std=1.0, scale_std=0.01, range=4900.0
            ),
            time_jitter_s=0.0,
        )

    @classmethod
    def tactical_grade(cls) -> ImuErrorModel:
        """A navigation-class MEMS IMU (ADIS1649x class): gyroscope 0.003 deg/s/sqrt(Hz),
        turn-on bias 0.05 deg/s, rate random walk 2e-6 rad/s/sqrt(s); accelerometer
        60 ug/sqrt(Hz), 1 mg bias; magnetometer 0.1 uT noise at 100 Hz, calibrated to
        0.2 uT hard iron and 0.2 % soft iron."""
        return cls(
            gyr=SensorErrors(
                noise_density=np.radians(0.003),
                bias_std=np.radians(0.05),
                bias_drift=2e-6,
                scale_std=5e-4,
                range=34.9,
            ),
            acc=SensorErrors(
                noise_density=60e-6 * STANDARD_GRAVITY,
                bias_std=1e-3 * STANDARD_GRAVITY,
                bias_drift=1e-5,
                scale_std=5e-4,
                range=156.9,
            ),
            mag=SensorErrors(
                noise_density=0.1 / _SQRT_50, bias_std=0.2, scale_std=0.002, range=4900.0
            ),
            time_jitter_s=0.0,
        )


def _second_derivative(t: FloatArray, p: FloatArray) -> FloatArray:
    """Central second difference on a (possibly non-uniform) grid; edges copy neighbours."""
    a = np.zeros_like(p)
    if len(t) < 3:
        return a
    hm = (t[1:-1] - t[:-2])[:, None]
    hp = (t[2:] - t[1:-1])[:, None]
    a[1:-1] = 2.0 * ((p[2:] - p[1:-1]) / hp - (p[1:-1] - p[:-2]) / hm) / (hm + hp)
    a[0] = a[1]
    a[-1] = a[-2]
    return a


def _body_rates(t: FloatArray, q: FloatArray) -> FloatArray:
    """gyr[k] = 2 log(q[k-1]^-1 q[k]) / dt_k (body frame), gyr[0] = gyr[1]."""
    w = np.zeros((len(t), 3))
    if len(t) < 2:
        return w
    dq = quat_mul(quat_conj(q[:-1]), q[1:])
    w[1:] = 2.0 * quat_log(dq) / np.diff(t)[:, None]
    w[0] = w[1]
    return w


def _resample(pose: PoseSeries, t_true: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Orientation (slerp) and position (cubic spline) at instants inside pose.time."""
    from scipy.interpolate import CubicSpline

    t = pose.time
    idx = np.clip(np.searchsorted(t, t_true, side="right") - 1, 0, len(t) - 2)
    frac = (t_true - t[idx]) / (t[idx + 1] - t[idx])
    q = quat_slerp(pose.quat[idx], pose.quat[idx + 1], frac)
    p = CubicSpline(t, pose.pos, axis=0)(t_true)
    return q, p


def ideal_signals(
    time: FloatArray,
    q_world_sensor: FloatArray,
    p_world_sensor: FloatArray,
    earth: EarthField = EarthField(),
    disturbances: Sequence[MagDisturbance] = (),
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Noise-free (gyr, acc, mag), each (N, 3), in the sensor frame (see module docstring)."""
    gyr = _body_rates(time, q_world_sensor)
    acc_world = _second_derivative(time, p_world_sensor)
    acc_world[:, 2] += earth.gravity
    acc = quat_rotate_inv(q_world_sensor, acc_world)
    m_world = np.broadcast_to(earth.mag_world, (len(time), 3)).copy()
    for d in disturbances:
        on = (time >= d.t_start) & (time < d.t_stop)
        m_world[on] += np.asarray(d.field_world, dtype=np.float64)
    mag = quat_rotate_inv(q_world_sensor, m_world)
    return gyr, acc, mag


def _corrupt(
    x: FloatArray, err: SensorErrors, dt: FloatArray, rng: np.random.Generator | None
) -> FloatArray:
    if err.is_ideal and not np.isfinite(err.range):
        return x
    out = x.copy()
    if not err.is_ideal:
        assert rng is not None  # checked by simulate_imu
        if err.scale_std:
            out *= 1.0 + rng.normal(0.0, err.scale_std, 3)
        bias = np.asarray(err.bias, dtype=np.float64) if err.bias is not None else np.zeros(3)
        if err.bias_std:
            bias = bias + rng.normal(0.0, err.bias_std, 3)
        out += bias
        if err.bias_drift:
            steps = rng.normal(0.0, 1.0, x.shape) * err.bias_drift * np.sqrt(dt)[:, None]
            steps[0] = 0.0
            out += np.cumsum(steps, axis=0)
        noise = _noise_std(err, dt)
        if noise:
            out += rng.normal(0.0, noise, x.shape)
    return np.clip(out, -err.range, err.range)


def _noise_std(err: SensorErrors, dt: FloatArray) -> float:
    """Per-sample white-noise standard deviation: ``noise`` and ``noise_density`` at the
    recording's rate (from its median time step), variances added."""
    if not err.noise_density:
        return err.noise
    steps = dt[1:]
    rate_hz = 1.0 / float(np.median(steps)) if steps.size else 1.0
    return float(np.hypot(err.noise, err.noise_density * np.sqrt(rate_hz / 2.0)))


def simulate_imu(
    pose: PoseSeries,
    errors: ImuErrorModel | None = None,
    earth: EarthField | None = None,
    disturbances: Sequence[MagDisturbance] = (),
    rng: np.random.Generator | None = None,
    name: str | None = None,
) -> ImuRecording:
    """Synthesise a 9-axis IMU recording from a sensor pose (see the module docstring).

    Args:
        pose: ``q_world_sensor`` and sensor position [m] over time (ENU world).
        errors: error model (None: ideal sensor).
        earth: gravity and magnetic field (None: defaults, 60 deg dip, 50 uT).
        disturbances: magnetic disturbances (world frame) added over time windows.
        rng: random generator; required when the error model draws anything.
        name: recording name (defaults to ``pose.name``).
    """
    errors = errors or ImuErrorModel()
    earth = earth or EarthField()
    if errors.is_random and rng is None:
        raise ConfigError("rng: the error model draws noise; pass rng=np.random.default_rng(seed)")
    t = pose.time
    if len(t) < 3:
        raise ConfigError(f"pose: need at least 3 samples to differentiate, got {len(t)}")
    t_true = t
    q, p = pose.quat, pose.pos
    if errors.time_jitter_s > 0:
        assert rng is not None
        dt_min = float(np.min(np.diff(t)))
        if errors.time_jitter_s > dt_min / 4:
            raise ConfigError(
                f"time_jitter_s: {errors.time_jitter_s} s is more than a quarter of the "
                f"sample interval ({dt_min} s); samples would swap order"
            )
        jitter = np.clip(rng.normal(0.0, errors.time_jitter_s, len(t)), -dt_min / 3, dt_min / 3)
        t_true = np.clip(t + jitter, t[0], t[-1])
        t_true = np.maximum.accumulate(t_true)
        t_true[1:] = np.maximum(t_true[1:], t_true[:-1] + 1e-9)
        q, p = _resample(pose, t_true)
    gyr, acc, mag = ideal_signals(t_true, q, as_vectors(p, "pos", 3), earth, disturbances)
    dt = np.diff(t, prepend=t[0])
    gyr = _corrupt(gyr, errors.gyr, dt, rng)
    acc = _corrupt(acc, errors.acc, dt, rng)
    mag = _corrupt(mag, errors.mag, dt, rng)
    meta = {"true_time": t_true, "earth": earth, "errors": errors}
    return ImuRecording(t, gyr, acc, mag, name=name or pose.name, meta=meta)
