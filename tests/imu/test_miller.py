"""The paper's filter: the pieces of eq. 2-14, convergence from a wrong start, the
magnetometer-gap fallback, and fast-versus-reference on real BROAD data."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.geometry import (
    quat_angle_between,
    quat_from_axis_angle,
    quat_mul,
    quat_rotate,
    quat_rotate_inv,
)
from mocapkit.imu.filters import make_filter
from mocapkit.imu.filters.miller import (
    G_REF,
    M_REF,
    MillerFilter,
    MillerParams,
    error_angles,
    law_of_cosines_angle,
    partition_axis,
)
from tests.imu.synthetic import constant_rotation


def test_partition_is_the_dominant_axis_with_ties_to_z_then_y() -> None:
    assert partition_axis(np.array([0.1, 0.2, -0.9])) == 2
    assert partition_axis(np.array([0.1, -0.9, 0.2])) == 1
    assert partition_axis(np.array([-0.9, 0.1, 0.2])) == 0
    assert partition_axis(np.array([0.6, 0.6, 0.6])) == 2
    assert partition_axis(np.array([0.7, 0.7, 0.1])) == 1


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("angle", [0.3, -1.2, 3.0])
def test_law_of_cosines_angle_is_signed_about_the_axis(axis: int, angle: float) -> None:
    e = np.zeros(3)
    e[axis] = 1.0
    v = np.array([0.3, -0.5, 0.8])
    rotated = quat_rotate(quat_from_axis_angle(e, angle), v)
    # acos of a cosine near +-1 costs half the digits: 1e-7 rad
    assert law_of_cosines_angle(v, rotated, axis) == pytest.approx(angle, abs=1e-7)


def test_antiparallel_projections_give_plus_pi_and_degenerate_ones_zero() -> None:
    v = np.array([0.0, 1.0, 0.0])
    assert law_of_cosines_angle(v, -v, 2) == pytest.approx(np.pi)
    assert law_of_cosines_angle(np.array([0.0, 0.0, 1.0]), v, 2) == 0.0


def _level_readings(q_true: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    acc = quat_rotate_inv(q_true, G_REF) * 9.81
    # a dipped field (65 deg): the filter removes the dip itself
    mag = quat_rotate_inv(q_true, M_REF * np.cos(1.13) - G_REF * np.sin(1.13)) * 50.0
    return acc, mag


def test_error_angles_are_the_estimate_error_in_the_body_frame() -> None:
    """The convention that makes eq. 13 converge: eps is the rotation taking the
    predicted vectors onto the sensed ones, i.e. q_est = q_true * exp(eps / 2)."""
    q_true = quat_from_axis_angle([0.0, 0.0, 1.0], 0.7)  # level: partition 1 (z)
    acc, mag = _level_readings(q_true)
    # a tilt error: the gravity angles (about x and y) measure it
    tilt = np.array([0.004, -0.006, 0.0])
    q_est = quat_mul(q_true, quat_from_axis_angle(tilt, np.linalg.norm(tilt)))
    angles = error_angles(q_est, acc, mag, True, False)
    # first order in the error: the residual is of order |e|^2 = 5e-5
    np.testing.assert_allclose(angles, tilt, atol=1e-4)
    # a heading error: the magnetometer angle (about z) measures it, gravity sees nothing
    heading = np.array([0.0, 0.0, 0.005])
    q_est = quat_mul(q_true, quat_from_axis_angle(heading, 0.005))
    np.testing.assert_allclose(error_angles(q_est, acc, mag, True, True), heading, atol=1e-9)
    # with the sensor on its side (partition 3, x up) the heading is about x
    q_side = quat_from_axis_angle([0.0, 1.0, 0.0], -np.pi / 2)
    acc, mag = _level_readings(q_side)
    q_est = quat_mul(q_side, quat_from_axis_angle([1.0, 0.0, 0.0], 0.005))
    np.testing.assert_allclose(error_angles(q_est, acc, mag, True, True), [0.005, 0, 0], atol=1e-9)


@pytest.mark.parametrize("backend", ["fast", "reference"])
def test_converges_from_a_wrong_start_in_9d(backend: str) -> None:
    q0 = quat_from_axis_angle([0.5, -0.3, 0.8], 1.3)
    q_true, gyr, acc, mag = constant_rotation(q0, [0.05, -0.1, 0.2], 3000, 100.0)
    f = make_filter("miller", 100.0, backend, alpha=2.0)
    # 100 deg of inclination error and 120 deg of heading error at time 0
    wrong = quat_mul(
        quat_from_axis_angle([0.0, 0.0, 1.0], np.radians(120.0)),
        quat_mul(quat_from_axis_angle([1.0, 0.0, 0.0], np.radians(100.0)), q0),
    )
    f.reset(wrong)
    n = 3000 if backend == "fast" else 1500
    out = f.run(gyr[:n], acc[:n], mag[:n])
    err = np.degrees(quat_angle_between(out, q_true[:n]))
    assert err[0] > 100.0
    # exact signals: what remains is the first-order integration error (~1e-9 rad a step)
    assert err[-1] < 1e-4


def test_converges_from_upside_down_in_6d() -> None:
    q0 = quat_from_axis_angle([0.0, 1.0, 0.0], 0.4)
    _, gyr, acc, _ = constant_rotation(q0, [0.0, 0.0, 0.3], 3000, 100.0)
    f = make_filter("miller", 100.0, alpha=2.0)
    f.reset(quat_mul(quat_from_axis_angle([1.0, 0.0, 0.0], np.pi), q0))
    out = f.run(gyr, acc)
    up_est = quat_rotate(out, acc / np.linalg.norm(acc, axis=1, keepdims=True))
    tilt = np.degrees(np.arccos(np.clip(up_est[:, 2], -1.0, 1.0)))
    assert tilt[0] > 170.0
    assert tilt[-1] < 1e-4  # exact signals, as above


def test_alpha_zero_is_the_papers_gyroscope_integration() -> None:
    _, gyr, acc, mag = constant_rotation(
        quat_from_axis_angle([1.0, 0.0, 0.0], 0.2), [0.1, 0.2, -0.3], 50
    )
    f = make_filter("miller", 100.0, alpha=0.0)
    f.reset([1.0, 0.0, 0.0, 0.0])
    q = np.array([1.0, 0.0, 0.0, 0.0])
    expected = []
    for w in gyr:  # eq. 2-4 and 14 by hand
        q = q + 0.5 * quat_mul(q, np.concatenate([[0.0], w * 0.01]))
        q = q / np.linalg.norm(q)
        expected.append(q)
    np.testing.assert_allclose(f.run(gyr, acc, mag), expected, atol=1e-15)


@pytest.mark.parametrize("name", ["miller", "bachmann"])
def test_magnetometer_gap_is_processed_as_6d(name: str) -> None:
    _q_true, gyr, acc, mag = constant_rotation(
        quat_from_axis_angle([0.5, -0.3, 0.8], 1.3), [0.05, -0.1, 0.2], 300, 100.0
    )
    gapped = mag.copy()
    gapped[100:200] = np.nan
    f = make_filter(name, 100.0)
    out = f.run(gyr, acc, gapped)
    assert f.last_report.mag_gaps == 100
    g = make_filter(name, 100.0)
    expected = np.vstack(
        [
            g.run(gyr[:100], acc[:100], mag[:100]),
            g.run(gyr[100:200], acc[100:200]),
            g.run(gyr[200:], acc[200:], mag[200:]),
        ]
    )
    np.testing.assert_array_equal(out, expected)


def test_params_validation() -> None:
    with pytest.raises(ConfigError, match=r"alpha: expected 0 <= alpha < rate_hz \(100\)"):
        MillerParams(rate_hz=100.0, alpha=150.0)
    with pytest.raises(ConfigError, match="alpha: expected"):
        MillerParams(rate_hz=100.0, alpha=-1.0)
    with pytest.raises(ConfigError, match="params: expected MillerParams"):
        MillerFilter(object())  # type: ignore[arg-type]


@pytest.mark.shared_data
@pytest.mark.parametrize("name", ["miller", "bachmann"])
@pytest.mark.parametrize("use_mag", [True, False])
def test_fast_path_matches_reference_on_broad(shared_data, name: str, use_mag: bool) -> None:  # type: ignore[no-untyped-def]
    from mocapkit.io.broad import read_broad_trial

    trial = read_broad_trial(shared_data / "broad" / "07_undisturbed_fast_rotation_B.hdf5")
    start = int(np.flatnonzero(trial.movement)[0]) - 500  # rest, then fast rotation
    sl = slice(start, start + 4000)
    gyr, acc = trial.imu.gyr[sl], trial.imu.acc[sl].copy()
    mag = trial.imu.mag[sl].copy() if use_mag else None
    acc[1000] = 0.0  # and the fallbacks: a dead accelerometer sample, a magnetometer gap
    if mag is not None:
        mag[2000:2100] = np.nan
    fast = make_filter(name, trial.rate_hz, "fast").run(gyr, acc, mag)
    ref = make_filter(name, trial.rate_hz, "reference").run(gyr, acc, mag)
    # the bound; the arithmetic is the same, so rounding (1e-16) accumulates only
    np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-9)
