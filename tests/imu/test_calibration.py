"""Rest detection, gyroscope bias, start-of-recording calibration, magnetometer fit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import ConfigError, DataError
from mocapkit.imu.calibration import (
    calibrate_from_rest,
    detect_rest,
    gyro_bias,
    remove_gyro_bias,
    rest_periods,
)
from mocapkit.imu.mag_calibration import fit_mag_calibration
from mocapkit.series import ImuRecording

RATE = 100.0


def _still_move_still() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    n = 600
    bias = np.array([0.01, -0.02, 0.005])  # rad/s
    gyr = bias + rng.normal(scale=0.002, size=(n, 3))
    acc = np.tile([0.0, 0.0, 9.81], (n, 1)) + rng.normal(scale=0.01, size=(n, 3))
    gyr[200:400] += [1.0, 0.5, 0.0]  # 2 s of motion
    acc[200:400] += [2.0, 0.0, 0.0]
    return gyr, acc, bias


def test_rest_detection_finds_the_still_periods() -> None:
    gyr, acc, _ = _still_move_still()
    rest = detect_rest(gyr, acc, RATE)
    periods = rest_periods(rest)
    assert len(periods) == 2
    # a window touching a moving sample is not at rest: the borders move in by at most
    # the 0.2 s window (20 samples)
    assert periods[0].start == 0
    assert 180 <= periods[0].stop <= 200
    assert 400 <= periods[1].start <= 420
    assert periods[1].stop == 600


def test_gyro_bias_from_rest_and_its_removal() -> None:
    gyr, acc, bias = _still_move_still()
    rest = detect_rest(gyr, acc, RATE)
    # 400 samples of 0.002 rad/s noise: the mean is within 5 sigma / sqrt(400) = 5e-4
    np.testing.assert_allclose(gyro_bias(gyr, rest), bias, atol=5e-4)
    rec = ImuRecording(np.arange(600) / RATE, gyr, acc, name="s")
    cal = calibrate_from_rest(rec)
    assert cal.period.start == 0
    np.testing.assert_allclose(cal.references.g_ref, [0.0, 0.0, 1.0], atol=1e-3)
    fixed = remove_gyro_bias(rec, cal.gyr_bias)
    assert np.abs(fixed.gyr[:150].mean(axis=0)).max() < 5e-4
    assert fixed.meta["gyr_bias_removed"] == pytest.approx(cal.gyr_bias.tolist())


def test_rest_errors() -> None:
    gyr, acc, _ = _still_move_still()
    with pytest.raises(DataError, match="rest: no sample at rest, so the gyroscope bias"):
        gyro_bias(gyr, np.zeros(600, bool))
    moving = ImuRecording(np.arange(600) / RATE, gyr + 1.0, acc, name="s")
    with pytest.raises(DataError, match="s: no rest period found"):
        calibrate_from_rest(moving)
    with pytest.raises(ConfigError, match="gyr_threshold: expected a positive value"):
        detect_rest(gyr, acc, RATE, gyr_threshold=0.0)


@pytest.mark.shared_data
def test_rest_detection_on_broad_agrees_with_the_movement_mask(shared_data: Path) -> None:
    from mocapkit.io.broad import read_broad_trial

    trial = read_broad_trial(shared_data / "broad" / "02_undisturbed_slow_rotation_B.hdf5")
    rest = detect_rest(trial.imu.gyr, trial.imu.acc, trial.rate_hz)
    # BROAD marks the movement phases; hardly any sample we call rest is in one
    assert (rest & trial.movement).mean() < 0.01
    cal = calibrate_from_rest(trial.imu)
    # the initial rest lasts about 40 s; the dip of Berlin is about 68-69 deg
    assert cal.period.n_samples > 30 * trial.rate_hz
    assert np.degrees(cal.references.dip) == pytest.approx(68.8, abs=1.0)


def _distorted_sphere(n: int = 300) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(2)
    s = rng.normal(size=(n, 3))
    s = 45.0 * s / np.linalg.norm(s, axis=1, keepdims=True)
    W = np.array([[1.2, 0.1, -0.05], [0.1, 0.9, 0.08], [-0.05, 0.08, 1.05]])  # symmetric
    b = np.array([12.0, -7.0, 3.0])
    return s, s @ W.T + b, W, b


def test_ellipsoid_fit_recovers_an_exact_distortion() -> None:
    s, raw, W, b = _distorted_sphere()
    cal = fit_mag_calibration(raw, field_strength=45.0)
    # noise-free: only rounding separates the fit from the truth
    np.testing.assert_allclose(cal.hard_iron, b, atol=1e-9)
    np.testing.assert_allclose(cal.soft_iron, np.linalg.inv(W), atol=1e-12)
    np.testing.assert_allclose(cal.apply(raw), s, atol=1e-9)
    assert cal.residual_rms < 1e-9
    gap = raw.copy()
    gap[3] = np.nan
    assert np.isnan(cal.apply(gap)[3]).all()  # gaps stay gaps


def test_sphere_fit_and_coverage_errors() -> None:
    s, _, _, b = _distorted_sphere()
    cal = fit_mag_calibration(s + b, model="sphere")
    np.testing.assert_allclose(cal.hard_iron, b, atol=1e-9)
    assert cal.field_strength == pytest.approx(45.0)
    angle = np.linspace(0, 2 * np.pi, 100)
    planar = np.column_stack([np.cos(angle), np.sin(angle), 0.3 + 0.01 * np.sin(7 * angle)])
    with pytest.raises(DataError, match="mag: the rotation sequence covers too few directions"):
        fit_mag_calibration(40.0 * planar)
    with pytest.raises(DataError, match="need at least 10 for the ellipsoid fit"):
        fit_mag_calibration(s[:5])
    with pytest.raises(ConfigError, match="model: expected 'ellipsoid' or 'sphere'"):
        fit_mag_calibration(s, model="cube")  # type: ignore[arg-type]


@pytest.mark.shared_data
def test_ellipsoid_fit_on_a_real_rotation_recording(shared_data: Path) -> None:
    from mocapkit.io.broad import read_broad_trial

    trial = read_broad_trial(shared_data / "broad" / "02_undisturbed_slow_rotation_B.hdf5")
    cal = fit_mag_calibration(trial.imu.mag)
    raw = np.linalg.norm(trial.imu.mag, axis=1)
    fixed = np.linalg.norm(cal.apply(trial.imu.mag), axis=1)
    # BROAD's magnetometer is already calibrated: the fit finds a small offset (< 1 uT)
    # and still makes the field norm steadier
    assert np.linalg.norm(cal.hard_iron) < 1.0
    assert fixed.std() < raw.std()
    assert cal.field_strength == pytest.approx(raw.mean(), rel=0.05)
