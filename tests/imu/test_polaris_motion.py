"""``polaris`` on simulated body motion (linear accelerations of limbs, a start in motion),
and the hand-over of a bias measured at rest (issue 2's suit-simulator findings)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.imu.filters import Polaris, make_filter
from mocapkit.imu.metrics import orientation_rmse
from mocapkit.imu.simulate import ImuErrorModel, simulate_imu
from mocapkit.series import ImuRecording, PoseSeries
from mocapkit.suit.motions import suit_poses
from mocapkit.teleop.operator_cycle import arm_sensor_poses

RATE = 100.0


def _errors_deg(name: str, rec: ImuRecording, pose: PoseSeries) -> tuple[float, float]:
    """(9D total RMSE, 6D inclination RMSE) [deg] after the first second."""
    sel = pose.time >= 1.0
    q9 = make_filter(name, RATE).run(rec.gyr, rec.acc, rec.mag)
    q6 = make_filter(name, RATE).run(rec.gyr, rec.acc)
    e9 = orientation_rmse(q9, pose.quat, sel).total
    e6 = orientation_rmse(q6, pose.quat, sel, align_heading=True).inclination
    return math.degrees(e9), math.degrees(e6)


def test_a_limb_that_starts_walking_does_not_diverge() -> None:
    # The shank of the suit's walking motion, noise-free, moving from the first sample.
    # Before the linear-acceleration terms (P3a/P7a) the running mean of the warm-up was
    # trusted as if at rest: the bias ran away and we measured 64.7 deg (9D) and 18.8 deg
    # (6D inclination). Now 5.2 and 5.1 deg (most of it the first seconds); the bounds
    # leave 50 % and fail for any return of the divergence.
    pose = suit_poses("walk", 9, 12.0, RATE)[9]
    rec = simulate_imu(pose)
    total, incl = _errors_deg("polaris", rec, pose)
    assert total < 8.0
    assert incl < 7.5


#: (9D total, 6D inclination) bounds [deg]: 1.5 x the measured values below
_ARM_BOUNDS = {"upper_arm_r": (1.0, 0.3), "forearm_r": (4.8, 0.4)}


@pytest.mark.parametrize("sensor", ["upper_arm_r", "forearm_r"])
def test_arm_motion_with_consumer_noise_beats_bachmann(sensor: str) -> None:
    # The teleoperation operator (the body model, mocapkit.teleop.operator_cycle) tracing
    # the infinity (N-pose 2 s, reach, settle, shape, hold, return: 14 s) at 100 Hz with
    # consumer-grade errors (gyroscope bias left in the readings, magnetometer hard and
    # soft iron uncalibrated). Measured (9D total / 6D inclination, deg): upper arm polaris
    # 0.65 / 0.17, bachmann 2.51 / 0.43; forearm polaris 3.17 / 0.24, bachmann 3.62 / 2.20
    # (the forearm's 9D error is mostly heading, for every filter). Bounds: 1.5 x ours
    # (noise is seeded, so only a change of the filter moves them), and below bachmann.
    pose = arm_sensor_poses(("infinity",), RATE, 6.0, seed=0)[sensor]
    rec = simulate_imu(pose, ImuErrorModel.consumer_grade(), rng=np.random.default_rng(5))
    total, incl = _errors_deg("polaris", rec, pose)
    total_b, incl_b = _errors_deg("bachmann", rec, pose)
    max_total, max_incl = _ARM_BOUNDS[sensor]
    assert total < max_total
    assert incl < max_incl
    assert total < total_b
    assert incl < incl_b


def test_bias_removed_by_the_caller_shifts_the_estimate() -> None:
    # Subtracting b from the readings and telling the filter is the same run (to rounding).
    pose = arm_sensor_poses(("circle",), RATE, 6.0, seed=1)["forearm_r"]
    rec = simulate_imu(pose, ImuErrorModel.consumer_grade(), rng=np.random.default_rng(3))
    b = np.array([0.004, -0.007, 0.002])
    one = Polaris(rate_hz=RATE).run(rec.gyr, rec.acc, rec.mag)
    f = Polaris(rate_hz=RATE)
    head = f.run(rec.gyr[:300], rec.acc[:300], rec.mag[:300])
    f.gyr_bias_removed(b)
    tail = f.run(rec.gyr[300:] - b, rec.acc[300:], rec.mag[300:])
    # rounding of (g - b) - (est - b) against g - est, over 700 samples
    np.testing.assert_allclose(np.vstack([head, tail]), one, atol=1e-9)
    # with an uncertainty the measurement pulls the estimate towards what is left: 0
    g = Polaris(rate_hz=RATE)
    g.run(rec.gyr[:300], rec.acc[:300], rec.mag[:300])
    before = g.state.bias - b
    g.gyr_bias_removed(b, sigma=np.radians(0.01))
    assert np.linalg.norm(g.state.bias) < np.linalg.norm(before)
    # filters that do not estimate a bias have nothing to do
    make_filter("bachmann", RATE).gyr_bias_removed(b)


def test_bias_removed_rejects_bad_input() -> None:
    f = Polaris(rate_hz=RATE)
    f.run(np.zeros((5, 3)), np.tile([0.0, 0.0, 9.81], (5, 1)))
    with pytest.raises(ShapeError, match="bias"):
        f.gyr_bias_removed(np.zeros(2))
    with pytest.raises(ConfigError, match="sigma: expected a positive"):
        f.gyr_bias_removed(np.zeros(3), sigma=0.0)
