"""The simulated live session: real suit stream, receiver, filters, body, robot server."""

from __future__ import annotations

import time

import numpy as np
import pytest

from mocapkit.body.calibration import CalibrationError
from mocapkit.demo.operator_cycle import SENSORS, operator_cycle
from mocapkit.demo.suit_chain import PREFERRED_FILTERS, ChainConfig, SuitTeleopChain, best_filter
from mocapkit.errors import ConfigError, DataError
from mocapkit.geometry import quat_angle_between
from mocapkit.imu.filters import available_filters

# runs live processes and sockets against the clock: run serially (see Makefile)
pytestmark = pytest.mark.realtime


def test_operator_cycle_repeats_and_the_sensors_ride_their_segments() -> None:
    c = operator_cycle(("vertical", "circle"), shape_s=2.0, repeat_until_s=30.0)
    n = round(c.period_s * c.rate_hz)
    assert len(c.time) >= 30.0 * c.rate_hz
    np.testing.assert_array_equal(c.q_human[:n], c.q_human[n : 2 * n])
    # the cycle starts and ends in the initialisation posture: no jump when it repeats
    np.testing.assert_allclose(c.q_human[n - 1], c.q_human[0], atol=1e-9)
    assert [s.shape for s in c.spans[:4]] == ["vertical", "circle", "vertical", "circle"]
    # each sensor keeps a constant mounting on its segment
    for sid, (_name, seg, _frame) in SENSORS.items():
        q_s = c.sensor_poses[sid].quat
        from mocapkit.geometry import quat_conj, quat_mul

        mount = quat_mul(quat_conj(c.q_segments[seg]), q_s)
        assert np.max(quat_angle_between(mount, mount[0])) < 1e-9  # rounding only
    with pytest.raises(ConfigError, match="shapes: expected some of"):
        operator_cycle(("spiral",))


def test_best_filter_prefers_the_most_accurate_registered_one() -> None:
    # the order is the measured accuracy on the simulated chain (suit_chain.PREFERRED_FILTERS)
    assert best_filter() in available_filters()
    assert best_filter() == PREFERRED_FILTERS[0]


@pytest.mark.slow
def test_operator_commands_fail_with_the_reason_and_recover() -> None:
    cfg = ChainConfig(shapes=("vertical",), shape_s=2.0, duration_s=20.0, auto_calibrate_at_s=None)
    with SuitTeleopChain(cfg) as chain:
        with pytest.raises(DataError, match="engage: calibrate first"):
            chain.engage()
        # the operator is still at rest for the first second: calibration works then
        assert chain.wait_motion_time(0.7, 15.0)
        assert chain.calibrate().startswith("calibrated at t = ")
        assert chain.engage() == "engage: aligning"
        # in the middle of the reach the arm moves: the still check refuses
        assert chain.wait_motion_time(2.0, 15.0)
        with pytest.raises(CalibrationError, match="moved during the calibration pose"):
            chain.calibrate()
        deadline = time.monotonic() + 5.0
        while chain.snapshot().ee_command is None and time.monotonic() < deadline:
            time.sleep(0.02)
        snap = chain.snapshot()
        # engaged at rest, the robot follows the hand (relative control) until the reach
        # takes it out of the robot's workspace, when the session says so and realigns
        assert any(t.startswith("aligning -> engaged") for t in snap.transitions), snap
        assert snap.state in ("engaged", "aligning")
        assert snap.calibrated
        assert snap.packets > 0
        assert snap.robot_q is not None
        assert "moved during the calibration pose" in snap.message
        assert chain.disengage() == "disable: disabled"
