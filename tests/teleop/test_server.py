"""Robot link and robot server: real processes and UDP sockets on loopback."""

from __future__ import annotations

import time

import numpy as np
import pytest

from mocapkit.robot import robonaut2_arm
from mocapkit.teleop import protocol as proto
from mocapkit.teleop.link import RobotLink
from mocapkit.teleop.server import RobotSim, ServerConfig, spawn_robot_server

# runs live processes and sockets against the clock: run serially (see Makefile)
pytestmark = pytest.mark.realtime


def test_protocol_round_trip_and_errors():
    pos, quat = np.array([0.1, -0.2, 0.3]), np.array([1.0, 0.0, 0.0, 0.0])
    msg = proto.decode(proto.encode_command(7, 123, pos, quat))
    assert isinstance(msg, proto.Command)
    assert msg.seq == 7
    np.testing.assert_array_equal(msg.pos, pos)
    rep = proto.decode(
        proto.encode_report(3, 9, pos, quat, 7, proto.Gate.SYNCED, proto.Reason.OK, np.ones(7))
    )
    assert isinstance(rep, proto.Report)
    assert rep.gate == proto.Gate.SYNCED
    assert rep.q.shape == (7,)
    with pytest.raises(proto.LinkProtocolError, match="shorter than the header"):
        proto.decode(b"MKRL")
    with pytest.raises(proto.LinkProtocolError, match="bad magic"):
        proto.decode(b"XXXX" + bytes(60))
    bad = bytearray(proto.encode_hold(1, 1))
    bad[4] = 9
    with pytest.raises(proto.LinkProtocolError, match="protocol version 9"):
        proto.decode(bytes(bad))
    with pytest.raises(proto.LinkProtocolError, match="COMMAND body of 8 bytes"):
        proto.decode(proto.encode_hold(1, 1)[:5] + b"\x01" + proto.encode_hold(1, 1)[6:] + bytes(8))


def _cmd(T, seq=1):
    from mocapkit.robot.model import pose_parts

    pos, quat = pose_parts(T)
    return proto.Command(seq, 0, pos, quat)


def test_gate_latency_and_limits_in_process():
    """The server's logic stepped by hand: gate, jump, latency, velocity limit, timeout."""
    arm = robonaut2_arm("right")
    cfg = ServerConfig(latency_s=0.05, command_timeout_s=1.0)
    sim = RobotSim(arm, cfg)
    T0 = sim.pose()
    far = T0.copy()
    far[0, 3] += 0.2
    assert not sim.on_command(_cmd(far), 0.0)  # not synchronised: rejected
    assert sim.state.reason == proto.Reason.TOO_FAR
    near = T0.copy()
    near[2, 3] += 0.01
    assert sim.on_command(_cmd(near), 0.0)
    assert sim.state.gate == proto.Gate.SYNCED
    q_before = sim.q.copy()
    sim.step(0.02, 0.005)  # before the latency has passed: no motion
    np.testing.assert_array_equal(sim.q, q_before)
    for k in range(40):
        sim.step(0.05 + 0.005 * k, 0.005)
        assert np.all(np.abs(sim.q - q_before) <= arm.velocity_limit * 0.005 * (k + 1) + 1e-12)
        assert arm.within_limits(sim.q).all()
    assert np.linalg.norm(sim.pose()[:3, 3] - near[:3, 3]) < 1e-3  # 1 mm: converged IK
    assert not sim.on_command(_cmd(far), 0.3)  # a 20 cm jump drops synchronisation
    assert sim.state.reason == proto.Reason.JUMP
    assert sim.on_command(_cmd(sim.pose()), 0.31)
    sim.step(1.5, 0.005)  # no command for 1.19 s > 1 s
    assert sim.state.gate == proto.Gate.UNSYNCED
    assert sim.state.reason == proto.Reason.TIMEOUT
    bad = _cmd(T0)
    assert not sim.on_command(proto.Command(9, 0, bad.pos, bad.quat * 2), 1.0)
    assert sim.state.reason == proto.Reason.BAD_COMMAND


def test_unreachable_target_is_reported():
    arm = robonaut2_arm("right")
    sim = RobotSim(arm, ServerConfig(latency_s=0.0, command_timeout_s=100.0))
    T = sim.pose()
    t = 0.0
    reasons = set()
    for k in range(80):  # push forward 1 cm per command, far beyond the arm's reach
        T[0, 3] += 0.01
        t += 0.05
        assert sim.on_command(_cmd(T, seq=k + 1), t)
        for _ in range(10):
            sim.step(t, 0.005)
            reasons.add(sim.state.reason)
    assert proto.Reason.UNREACHABLE in reasons
    assert sim.state.gate == proto.Gate.SYNCED
    assert arm.within_limits(sim.q).all()


def _wait(pred, timeout=5.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.01)
    return False


def test_server_process_follows_holds_and_survives_garbage():
    with (
        spawn_robot_server(ServerConfig(latency_s=0.02), max_seconds=60) as srv,
        RobotLink(srv.address) as link,
    ):
        link.send_hold()
        assert link.wait_for_report(10.0)
        T = link.robot_pose().copy()
        assert T is not None
        far = T.copy()
        far[1, 3] += 0.2
        link.send_command(far)
        assert _wait(lambda: link.poll() >= 0 and link.latest.reason == proto.Reason.TOO_FAR)
        # garbage datagrams are dropped, the server keeps answering
        link.sock.send(b"not a robot-link message")
        target = T.copy()
        for _k in range(40):  # walk 4 cm up in 1 mm steps: within the gate each time
            target[2, 3] += 0.001
            link.send_command(target)
            time.sleep(0.01)
        assert _wait(
            lambda: (
                link.poll() >= 0
                and link.latest.gate == proto.Gate.SYNCED
                and abs(link.latest.pos[2] - target[2, 3]) < 0.002
            )
        )
        link.send_hold()
        assert _wait(lambda: link.poll() >= 0 and link.latest.gate == proto.Gate.HOLDING)


def test_server_that_stops_answering_is_detected_and_recovered():
    from mocapkit.teleop.session import State, TeleopSession

    with spawn_robot_server(ServerConfig(), max_seconds=60) as srv, RobotLink(srv.address) as link:
        link.send_hold()
        assert link.wait_for_report(10.0)
        s = TeleopSession()
        s.engage(time.monotonic())
        model = link.robot_pose().copy()  # (the link reuses its pose buffer)

        def tick():
            link.poll()
            now = time.monotonic()
            out = s.tick(now, model, link.robot_pose(), link.report_age(now))
            if out.command is not None:
                link.send_command(out.command)
            elif out.hold:
                link.send_hold()

        assert _wait(lambda: tick() is None and s.state == State.ENGAGED)
        srv.pause()  # the server freezes
        try:
            assert _wait(lambda: tick() is None and s.state == State.HELD)
            assert "silent" in s.transitions[-1].reason
        finally:
            srv.resume()
        assert _wait(lambda: tick() is None and s.state == State.ENGAGED)


def test_server_cli_json_summary_on_exit() -> None:
    """``mocapkit teleop server --json``: READY on stderr, one JSON object on stdout when
    it stops, counting what it accepted, refused and dropped."""
    import json
    import socket
    import subprocess
    import sys

    proc = subprocess.Popen(
        [sys.executable, "-m", "mocapkit", "teleop", "server", "--port", "0", "--max-seconds",
         "3", "--json"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        line = ""
        while not line.startswith("READY"):
            line = proc.stderr.readline()  # type: ignore[union-attr]
            assert line, "the server exited before READY"
        port = int(line.split()[1])
        far = np.array([5.0, 5.0, 5.0])
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(proto.encode_command(1, 0, far, np.array([1.0, 0, 0, 0])), ("127.0.0.1", port))
            s.sendto(b"garbage", ("127.0.0.1", port))
            out, _ = proc.communicate(timeout=20)
    finally:
        proc.kill()
    summary = json.loads(out)
    assert summary["robot"] == "robonaut2-right"
    assert summary["commands_refused"] == 1  # 5 m away and not synchronised: the gate
    assert summary["commands_accepted"] == 0
    assert summary["datagrams_dropped"] == 1
    assert summary["reports_sent"] > 0
    assert summary["client"].startswith("127.0.0.1:")
