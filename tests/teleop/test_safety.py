"""A robot that only moves when it should (issue 12): sensor clocks that stand still or
run backwards, impossible orientations and jumps faster than a human hold the session
with the reason, and it re-engages only after reindexing (no jump reaches the robot);
the control socket refuses empty, foreign, forged and replayed datagrams."""

from __future__ import annotations

import json
import socket
import time

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_from_axis_angle, quat_mul
from mocapkit.teleop.control import Controls, ControlSocket, sign
from mocapkit.teleop.pipeline import PipelineConfig
from mocapkit.teleop.session import State, TeleopSession
from tests.teleop.test_pipeline import _calibrated, _FakeLink, _samples


def _engaged():  # type: ignore[no-untyped-def]
    pipe, q = _calibrated(PipelineConfig(stale_after_s=0.1))
    robot = pipe.arm.fk(pipe.arm.q_ref)
    pipe.link = _FakeLink(robot)
    pipe.session.engage(1.0)
    pipe.process(_samples(q, 1.0), now=1.0)
    assert pipe.session.state == State.ENGAGED
    return pipe, q, robot


def test_a_sensor_clock_that_stands_still_holds_the_session() -> None:
    pipe, q, _ = _engaged()
    for k in range(1, 20):  # the samples keep coming, their time stamp does not move
        now = 1.0 + 0.01 * k
        pipe.process(_samples(q, 1.0), now=now)
    assert pipe.session.state == State.HELD
    reason = pipe.session.transitions[-1].reason
    assert "sensor clock stands still or runs backwards (at 1.000 s after 1.000 s)" in reason
    assert "no fresh sample" in reason


def test_a_sensor_clock_that_runs_backwards_holds_then_reindexes(caplog) -> None:  # type: ignore[no-untyped-def]
    pipe, q, robot = _engaged()
    pipe.process(_samples(q, 0.995), now=1.005)  # a late sample: ignored, not fresh
    assert pipe.session.state == State.ENGAGED
    pipe.process(_samples(q, 0.2), now=1.01)  # a reset
    assert pipe.session.state == State.HELD
    assert "sensor clock ran backwards (1.000 -> 0.200 s)" in pipe.session.transitions[-1].reason
    f = pipe.process(_samples(q, 0.21), now=1.02)  # the new clock goes on
    assert pipe.session.state == State.ENGAGED
    np.testing.assert_allclose(f.command, robot, atol=1e-9)


def test_an_orientation_no_unit_quaternion_encodes_holds() -> None:
    pipe, q, _ = _engaged()
    bad = q.copy()
    bad[0] = bad[0] * np.sqrt(1.05)  # |q|^2 = 1.05: a decoded smallest-three with s > 1
    pipe.process(_samples(bad, 1.01), now=1.01)
    assert pipe.session.state == State.HELD
    assert "invalid orientation" in pipe.session.transitions[-1].reason


def test_an_arm_jump_of_60_deg_in_10_ms_is_held_not_followed() -> None:
    pipe, q, robot = _engaged()
    pipe.process(_samples(q, 1.01), now=1.01)
    jumped = q.copy()
    jumped[0] = quat_mul(quat_from_axis_angle([0.0, 1.0, 0.0], np.radians(60.0)), q[0])
    sent_before = len(pipe.link.commands)
    pipe.process(_samples(jumped, 1.02), now=1.02)
    assert pipe.session.state == State.HELD
    assert (
        "sensor upper_arm_r (id 1): turned 60 deg in 10 ms" in pipe.session.transitions[-1].reason
    )
    assert len(pipe.link.commands) == sent_before  # nothing towards the jump was sent
    f = pipe.process(_samples(jumped, 1.03), now=1.03)  # the arm stays there: re-synchronise
    assert pipe.session.state == State.ENGAGED
    np.testing.assert_allclose(f.command, robot, atol=1e-9)  # reindexed: the robot stays
    assert pipe.sensor_jumps == 1


def test_the_session_holds_a_model_pose_that_jumps() -> None:
    s = TeleopSession()
    s.engage(0.0)
    T0 = np.eye(4)
    s.tick(0.0, T0, T0, 0.0)
    T1 = np.eye(4)
    T1[0, 3] = 0.3  # 30 cm in 10 ms
    out = s.tick(0.01, T1, T0, 0.0)
    assert s.state == State.HELD
    assert out.command is None
    assert "model pose jumped 0 deg / 300 mm in 10 ms" in s.transitions[-1].reason
    out = s.tick(0.02, T1, T0, 0.0)  # re-synchronised: reindexed, the robot stays
    assert s.state == State.ENGAGED
    np.testing.assert_allclose(out.command, T0, atol=1e-12)


def test_a_fast_but_human_motion_is_followed() -> None:
    s = TeleopSession()
    s.engage(0.0)
    T0 = np.eye(4)
    s.tick(0.0, T0, T0, 0.0)
    T1 = np.eye(4)
    T1[:3, :3] = [[np.cos(0.1), -np.sin(0.1), 0], [np.sin(0.1), np.cos(0.1), 0], [0, 0, 1]]
    out = s.tick(0.01, T1, T0, 0.0)  # 0.1 rad in 10 ms = 573 deg/s: a quick human turn
    assert s.state == State.ENGAGED
    assert out.command is not None


def _reply(sock: socket.socket) -> dict:  # type: ignore[type-arg]
    data, _ = sock.recvfrom(65536)
    return json.loads(data)


class _Live:
    def __init__(self) -> None:
        self.clutched: list[bool] = []

    def clutch(self, pressed: bool) -> str:
        self.clutched.append(pressed)
        return "ok"


def test_control_socket_refuses_empty_and_foreign_datagrams() -> None:
    live = _Live()
    with ControlSocket(Controls(live, lambda: None)) as ctl:  # type: ignore[arg-type]
        a = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        b = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        a.settimeout(5.0)
        b.settimeout(5.0)
        with a, b:
            a.sendto(b"", ("127.0.0.1", ctl.port))
            assert "empty command" in _reply(a)["error"]
            a.sendto(b"clutch on", ("127.0.0.1", ctl.port))
            assert _reply(a)["ok"]
            b.sendto(b"clutch off", ("127.0.0.1", ctl.port))
            assert "not the paired controller" in _reply(b)["error"]
    assert live.clutched == [True]
    assert ctl.refused == 2


def test_control_socket_off_loopback_needs_a_key_and_checks_it() -> None:
    with pytest.raises(ConfigError, match="needs a shared key"):
        ControlSocket(Controls(_Live(), lambda: None), host="0.0.0.0")  # type: ignore[arg-type]
    live = _Live()
    key = b"shared secret"
    controls = Controls(live, lambda: None)  # type: ignore[arg-type]
    with (
        ControlSocket(controls, key=key) as ctl,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as a,
    ):
        a.settimeout(5.0)
        addr = ("127.0.0.1", ctl.port)
        a.sendto(b"clutch on", addr)
        assert "bad signature" in _reply(a)["error"]
        a.sendto(sign(b"wrong key", 1, "clutch on"), addr)
        assert "bad signature" in _reply(a)["error"]
        a.sendto(sign(key, 1, "clutch on"), addr)
        assert _reply(a)["ok"]
        a.sendto(sign(key, 1, "clutch off"), addr)  # replayed sequence number
        assert "a replay" in _reply(a)["error"]
        a.sendto(sign(key, 2, "clutch off"), addr)
        assert _reply(a)["ok"]
    assert live.clutched == [True, False]


def test_the_robot_link_signed_end_to_end(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """A server started with a key answers only signed datagrams and signs its reports;
    an unsigned client, a client with the wrong key and a replayed datagram get nothing."""
    from mocapkit.teleop import protocol as proto
    from mocapkit.teleop.link import RobotLink
    from mocapkit.teleop.server import spawn_robot_server

    key_file = tmp_path / "robot.key"
    key_file.write_bytes(b"0123456789abcdef-shared")
    key = b"0123456789abcdef-shared"
    with spawn_robot_server(max_seconds=60.0, key_file=str(key_file)) as srv:
        for wrong in (None, b"another key of sixteen+"):
            with RobotLink(srv.address, key=wrong) as link:
                link.send_hold()
                assert not link.wait_for_report(0.5)
        with RobotLink(srv.address, key=key) as link:
            link.send_hold()
            assert link.wait_for_report(5.0)
            assert link.latest is not None
            assert link.malformed == 0
        # another address is refused while the paired client is active, accepted (paired
        # anew) after it has been silent for PAIR_TIMEOUT_S
        time.sleep(1.2)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
            raw.settimeout(2.0)
            raw.sendto(proto.sign(proto.encode_hold(5, 0), key), srv.address)
            data, _ = raw.recvfrom(4096)
            assert isinstance(proto.decode(proto.open_signed(data, key)), proto.Report)


def test_a_robot_server_off_loopback_needs_a_key() -> None:
    from mocapkit.teleop.server import main as server_main

    assert server_main(["--host", "0.0.0.0", "--port", "0", "--max-seconds", "1"]) == 1
