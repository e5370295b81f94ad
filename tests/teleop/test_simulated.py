"""The simulated live session (the viewer's): a cyclic operator's suit streamed from a
sender process to the live session, the operator API's answers and refusals, and the
snapshot the viewer draws; the streaming sender alone."""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest

from mocapkit.body.calibration import CalibrationError
from mocapkit.errors import ConfigError, MocapkitError
from mocapkit.imu.filters import available_filters
from mocapkit.teleop.sender import TimelineSender
from mocapkit.teleop.simulated import (
    PREFERRED_FILTERS,
    SimulatedConfig,
    SimulatedSession,
    best_filter,
)
from mocapkit.viz.live_api import LiveSnapshot

# runs live processes and sockets against the clock: run serially (see Makefile)
pytestmark = pytest.mark.realtime


def test_best_filter_prefers_the_most_accurate_registered_one() -> None:
    # the order is the measured accuracy through the real chain (simulated.PREFERRED_FILTERS)
    assert best_filter() in available_filters()
    assert best_filter() == PREFERRED_FILTERS[0]
    with pytest.raises(ConfigError, match="duration_s: expected a positive duration"):
        SimulatedConfig(duration_s=0.0)


def test_the_sender_streams_chunks_fed_after_the_start() -> None:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(5.0)
    with rx, TimelineSender([(0.0, b"a0")], "127.0.0.1", rx.getsockname()[1]) as sender:
        with pytest.raises(ConfigError, match=r"feed: start the sender with go\(stream=True\)"):
            sender.feed([(0.01, b"x")])
        sender.go(stream=True)
        sender.feed([(0.01 * k, f"a{k}".encode()) for k in range(1, 20)])
        sender.feed([(0.01 * k, f"a{k}".encode()) for k in range(20, 40)])
        sender.end()
        got = [rx.recv(100) for _ in range(40)]
        result = sender.wait(10.0)
    assert got == [f"a{k}".encode() for k in range(40)]  # all of them, in order
    assert result["sent"] == 40
    with pytest.raises(MocapkitError, match="the suit sender process has stopped"):
        sender.feed([(1.0, b"late")])


def test_a_session_that_is_not_started_says_so() -> None:
    sim = SimulatedSession(SimulatedConfig(shapes=("box",), shape_s=1.0))
    with pytest.raises(MocapkitError, match="the simulated session is not started"):
        sim.engage()


@pytest.mark.slow
def test_operator_commands_answer_refuse_with_the_reason_and_recover() -> None:
    cfg = SimulatedConfig(shapes=("vertical",), shape_s=2.0, duration_s=30.0, auto_calibrate=False)
    with SimulatedSession(cfg) as sim:
        span = sim.cycle.spans[0]
        with pytest.raises(MocapkitError, match="engage: calibrate first"):
            sim.engage()

        def until(t: float) -> None:
            while sim.motion_time < t:
                time.sleep(0.01)

        # the operator stands in the N-pose for 2 s (the still start takes the first 0.8 s)
        until(0.85)
        assert sim.calibrate(0.8).startswith("calibrated (heading ")
        # in the reach the arm moves: the still check refuses, the calibration stays
        until(span.calib_window[1] + 0.4)
        with pytest.raises(CalibrationError, match="moved during the calibration pose"):
            sim.calibrate(0.5)
        until(span.engage_t)
        assert sim.engage() == "engage: aligning"
        deadline = time.monotonic() + 5.0
        # engaged, then the first command (the tick that engages may still answer the
        # robot's gate with a hold: the command comes with the next one)
        while time.monotonic() < deadline:
            raw = sim.snapshot()
            if raw["state"] == "engaged" and raw.get("ee_commanded") is not None:
                break
            time.sleep(0.02)
        raw = sim.snapshot()
        snap = LiveSnapshot.from_mapping(raw)
        assert snap.state == "engaged", raw
        assert any(t.startswith("aligning -> engaged") for t in snap.transitions)
        assert snap.calibrated
        assert snap.packets > 0
        assert snap.packet_loss == 0.0  # loopback
        assert snap.robot_q is not None
        assert snap.ee_command is not None
        assert "moved during the calibration pose" in raw["calibration"]
        # the viewer's skeleton and sensor frames: the three segments, joined at the joints
        segs = {s.name: s for s in snap.segments}
        assert set(segs) == {"torso", "humerus_r", "radius_r"}
        np.testing.assert_allclose(segs["radius_r"].start, segs["humerus_r"].end, atol=1e-9)
        assert abs(np.linalg.norm(segs["humerus_r"].end - segs["humerus_r"].start) - 0.29) < 1e-9
        assert {s.name for s in snap.sensors} == {"torso", "upper_arm_r", "forearm_r"}
        assert sim.reindex() == "reindex: engaged"
        assert sim.disengage() == "disengage: disabled"
        assert sim.snapshot()["message"] == "disengage: disabled"
