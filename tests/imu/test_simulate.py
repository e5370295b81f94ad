"""IMU signal synthesis: exact physics for noise-free signals, then each error term."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.geometry import (
    quat_exp,
    quat_from_axis_angle,
    quat_mul,
    quat_rotate,
    quat_rotate_inv,
)
from mocapkit.imu.simulate import (
    EarthField,
    ImuErrorModel,
    MagDisturbance,
    SensorErrors,
    _resample,
    simulate_imu,
)
from mocapkit.series import PoseSeries
from mocapkit.suit.motions import suit_poses
from tests.strategies import same_rotation


def _tumbling(n: int = 400, rate_hz: float = 100.0, translate: bool = False) -> PoseSeries:
    """A sensor tumbling about a slowly turning axis; optionally on a circle of 0.5 m."""
    t = np.arange(n) / rate_hz
    axis = np.stack([np.cos(0.3 * t), np.sin(0.3 * t), 0.5 + 0 * t], axis=1)
    angle = 2.0 * np.sin(1.3 * t) + 0.5 * t
    q = quat_from_axis_angle(axis, angle)
    pos = np.zeros((n, 3))
    if translate:
        pos = 0.5 * np.stack([np.cos(2 * t), np.sin(2 * t), 0 * t], axis=1)
    return PoseSeries(t, q, pos, name="tumble")


def test_integrating_noise_free_gyro_recovers_the_orientation() -> None:
    pose = _tumbling()
    rec = simulate_imu(pose)
    q = pose.quat[0].copy()
    est = [q]
    for k in range(1, rec.n_samples):
        dt = rec.time[k] - rec.time[k - 1]
        q = quat_mul(q, quat_exp(rec.gyr[k] * dt / 2))
        est.append(q)
    # exact by construction: only rounding accumulates over 400 products
    assert same_rotation(np.array(est), pose.quat, 1e-12)


def test_acc_and_mag_are_the_rotated_references() -> None:
    earth = EarthField(gravity=9.81, mag_strength=48.0, dip=np.deg2rad(67.0))
    pose = _tumbling()
    rec = simulate_imu(pose, earth=earth)
    up = quat_rotate(pose.quat, rec.acc)
    # fixed position: the specific force is +g up, rotated (to rounding)
    np.testing.assert_allclose(up, np.tile([0, 0, 9.81], (rec.n_samples, 1)), atol=1e-12)
    m = quat_rotate(pose.quat, rec.mag)
    expected = 48.0 * np.array([0.0, np.cos(np.deg2rad(67.0)), -np.sin(np.deg2rad(67.0))])
    np.testing.assert_allclose(m, np.tile(expected, (rec.n_samples, 1)), atol=1e-12)


def test_acc_includes_linear_acceleration() -> None:
    pose = _tumbling(translate=True)
    rec = simulate_imu(pose)
    acc_world = quat_rotate(pose.quat, rec.acc)
    t = pose.time
    exact = -2.0 * np.stack([np.cos(2 * t), np.sin(2 * t), 0 * t], axis=1)  # 0.5 * 4 on the circle
    exact[:, 2] += 9.80665
    # central second difference: error (dt^2 / 12) |p''''| = 1e-4 / 12 * 8 ~ 7e-5 m/s^2
    np.testing.assert_allclose(acc_world[1:-1], exact[1:-1], atol=1e-4)


def test_white_noise_bias_scale_and_saturation() -> None:
    pose = _tumbling(n=20_000)
    ideal = simulate_imu(pose)
    errors = ImuErrorModel(
        gyr=SensorErrors(noise=0.01),
        acc=SensorErrors(bias=(0.1, -0.2, 0.3)),
        mag=SensorErrors(scale_std=0.05, range=30.0),
    )
    rec = simulate_imu(pose, errors, rng=np.random.default_rng(7))
    dg = rec.gyr - ideal.gyr
    # sample std of 20000 draws: relative standard error 0.5 %, so 5 % is > 9 sigma
    np.testing.assert_allclose(dg.std(axis=0), 0.01, rtol=0.05)
    np.testing.assert_allclose(
        rec.acc - ideal.acc, np.tile([0.1, -0.2, 0.3], (20_000, 1)), atol=1e-12
    )
    assert np.abs(rec.mag).max() <= 30.0
    unclipped = (np.abs(ideal.mag * 1.2) < 29.0) & (np.abs(ideal.mag) > 1.0)
    ratio = rec.mag[unclipped] / ideal.mag[unclipped]
    assert np.ptp(ratio) > 0.0  # per-axis scale errors differ
    assert abs(ratio.mean() - 1.0) < 0.2


def test_bias_drift_is_a_random_walk() -> None:
    pose = _tumbling(n=10_000)
    errors = ImuErrorModel(gyr=SensorErrors(bias_drift=0.01))
    ideal = simulate_imu(pose)
    finals = []
    for seed in range(40):
        rec = simulate_imu(pose, errors, rng=np.random.default_rng(seed))
        finals.append((rec.gyr - ideal.gyr)[-1])
    # after T = 99.99 s the walk has sd 0.01 sqrt(T) ~ 0.1; 120 draws: +-30 % at ~3 sigma
    sd = np.std(np.array(finals))
    assert 0.07 < sd < 0.13


def test_magnetic_disturbance_window() -> None:
    pose = _tumbling()
    d = MagDisturbance(1.0, 2.0, (30.0, 0.0, 0.0))
    rec = simulate_imu(pose, disturbances=[d])
    ideal = simulate_imu(pose)
    diff = quat_rotate(pose.quat, rec.mag - ideal.mag)
    inside = (pose.time >= 1.0) & (pose.time < 2.0)
    np.testing.assert_allclose(diff[inside], np.tile([30.0, 0, 0], (inside.sum(), 1)), atol=1e-12)
    np.testing.assert_allclose(diff[~inside], 0.0, atol=1e-12)


def test_time_jitter_keeps_nominal_stamps_and_samples_true_instants() -> None:
    pose = _tumbling()
    rec = simulate_imu(pose, ImuErrorModel(time_jitter_s=0.001), rng=np.random.default_rng(3))
    np.testing.assert_array_equal(rec.time, pose.time)
    true_t = rec.meta["true_time"]
    assert np.all(np.diff(true_t) > 0)
    assert 0.0003 < np.std(true_t - pose.time) < 0.002
    # the gyro integrates exactly over the true intervals, between the true orientations
    q_true, _ = _resample(pose, true_t)
    q = q_true[0]
    for k in range(1, rec.n_samples):
        q = quat_mul(q, quat_exp(rec.gyr[k] * (true_t[k] - true_t[k - 1]) / 2))
    assert same_rotation(q, q_true[-1], 1e-12)  # rounding over 400 products


def test_validation_messages() -> None:
    pose = _tumbling()
    with pytest.raises(ConfigError, match="rng: the error model draws noise"):
        simulate_imu(pose, ImuErrorModel(gyr=SensorErrors(noise=0.1)))
    with pytest.raises(ConfigError, match="time_jitter_s: 0.004 s is more than a quarter"):
        simulate_imu(pose, ImuErrorModel(time_jitter_s=0.004), rng=np.random.default_rng(0))
    with pytest.raises(ConfigError, match="noise: expected a finite value >= 0, got -1"):
        SensorErrors(noise=-1)
    short = PoseSeries([0.0, 0.1], [[1, 0, 0, 0]] * 2, [[0, 0, 0]] * 2)
    with pytest.raises(ConfigError, match="need at least 3 samples"):
        simulate_imu(short)


def test_suit_motion_signals_are_consistent() -> None:
    poses = suit_poses("walk", 15, 1.0, 200.0)
    for pose in poses.values():
        rec = simulate_imu(pose)
        q = pose.quat[0]
        for k in range(1, rec.n_samples):
            q = quat_mul(q, quat_exp(rec.gyr[k] / 400.0))
        assert same_rotation(q, pose.quat[-1], 1e-12)  # rounding over 200 products
        grav = quat_rotate_inv(pose.quat, np.tile([0, 0, 9.80665], (rec.n_samples, 1)))
        assert np.all(np.linalg.norm(rec.acc - grav, axis=1) < 60.0)  # limb accelerations


def test_noise_density_scales_with_the_rate() -> None:
    # A density d [unit/sqrt(Hz)] gives d sqrt(rate / 2) per sample; consumer_grade keeps
    # its 100 Hz figure (0.005 rad/s). 20000 draws: relative standard error 0.5 %, 3 % is
    # > 5 sigma.
    for rate in (100.0, 400.0):
        pose = _tumbling(n=20_000, rate_hz=rate)
        ideal = simulate_imu(pose)
        rec = simulate_imu(pose, ImuErrorModel(gyr=SensorErrors(noise_density=0.001)),
                           rng=np.random.default_rng(2))  # fmt: skip
        np.testing.assert_allclose((rec.gyr - ideal.gyr).std(axis=0), 0.001 * np.sqrt(rate / 2),
                                   rtol=0.03)  # fmt: skip
    cg = ImuErrorModel.consumer_grade().gyr
    assert cg.noise_density * np.sqrt(50.0) == pytest.approx(0.005, rel=1e-12)
    assert not ImuErrorModel.tactical_grade().gyr.is_ideal
    with pytest.raises(ConfigError, match="noise_density"):
        SensorErrors(noise_density=-1.0)
