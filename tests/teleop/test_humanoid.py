"""Humanoid teleoperation pieces with exact answers: the JOINTS message, the server's
safety gate in joint space, the session's aligning and glitch rules."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.teleop import protocol as proto
from mocapkit.teleop.humanoid_session import HumanoidSession, JointsTarget
from mocapkit.teleop.session import State

pytest.importorskip("pinocchio")


@pytest.fixture(scope="module")
def sim_factory():
    from mocapkit.teleop.server import ServerConfig, build_sim

    return lambda **kw: build_sim(ServerConfig(robot="g1", latency_s=0.0, **kw))


def test_joints_message_round_trip_and_damage():
    q = np.linspace(-1, 1, 29)
    data = proto.encode_joints(7, 123, np.array([0.1, 0.2, 0.8]), np.array([1.0, 0, 0, 0]), q)
    msg = proto.decode(data)
    assert isinstance(msg, proto.JointsCommand)
    assert msg.seq == 7
    np.testing.assert_array_equal(msg.q, q)
    np.testing.assert_array_equal(msg.base_pos, [0.1, 0.2, 0.8])
    with pytest.raises(proto.LinkProtocolError, match="announces 29 joints"):
        proto.decode(data[:-8])
    with pytest.raises(proto.LinkProtocolError, match="at most"):
        proto.encode_joints(1, 1, np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(65))


def _cmd(sim, q, seq=1):
    return proto.JointsCommand(seq, 0, sim.base_pos, sim.base_quat, q)


def test_the_gate_accepts_only_near_the_robot_then_refuses_jumps(sim_factory):
    sim = sim_factory()
    q0 = sim.joints.copy()
    far = q0.copy()
    far[0] += 0.3  # 17 deg from the robot's joint: refused until aligned
    assert not sim.on_joints(_cmd(sim, far), 0.0)
    assert sim.state.reason == proto.Reason.TOO_FAR
    near = q0.copy()
    near[0] += 0.05
    assert sim.on_joints(_cmd(sim, near, 2), 0.01)
    assert sim.state.gate == proto.Gate.SYNCED
    sim.step(0.02, 0.01)
    assert 0.0 < sim.joints[0] - q0[0] <= sim.v_max[0] * 0.01 + 1e-12  # at its speed limit
    jump = near.copy()
    jump[3] += 0.3
    assert not sim.on_joints(_cmd(sim, jump, 3), 0.03)
    assert (sim.state.gate, sim.state.reason) == (proto.Gate.UNSYNCED, proto.Reason.JUMP)


def test_bad_joint_commands_are_refused_and_an_arm_command_too(sim_factory):
    sim = sim_factory()
    q = sim.joints.copy()
    q[2] = np.nan
    assert not sim.on_joints(_cmd(sim, q), 0.0)
    assert sim.state.reason == proto.Reason.BAD_COMMAND
    beyond = sim.joints.copy()
    beyond[0] = sim.hi[0] + 0.01
    assert not sim.on_joints(_cmd(sim, beyond), 0.0)
    assert not sim.on_joints(_cmd(sim, sim.joints[:-1]), 0.0)  # one joint short
    assert not sim.on_command(proto.Command(1, 0, np.zeros(3), np.array([1.0, 0, 0, 0])), 0.0)
    assert sim.state.gate == proto.Gate.UNSYNCED


def test_the_gate_times_out(sim_factory):
    sim = sim_factory(command_timeout_s=0.2)
    assert sim.on_joints(_cmd(sim, sim.joints.copy()), 0.0)
    sim.step(0.1, 0.01)
    assert sim.state.gate == proto.Gate.SYNCED
    sim.step(0.31, 0.01)
    assert (sim.state.gate, sim.state.reason) == (proto.Gate.UNSYNCED, proto.Reason.TIMEOUT)


def _target(q):
    return JointsTarget(np.zeros(3), np.array([1.0, 0, 0, 0]), np.asarray(q, dtype=float))


def test_session_aligns_step_by_step_then_follows_and_holds_on_a_glitch():
    s = HumanoidSession()
    s.v_max = np.full(3, 2.0)
    robot = np.zeros(3)
    goal = np.array([0.2, -0.1, 0.0])
    s.engage(0.0)
    t, sent = 0.0, []
    for _ in range(200):
        t += 0.01
        out = s.tick_joints(t, _target(goal), robot, 0.0, None, proto.Gate.SYNCED)
        if out.joints is not None:
            step = out.joints[2] - (sent[-1] if sent else robot)
            assert np.abs(step).max() <= s.align_speed_rad_s * 0.01 + 1e-12
            sent.append(out.joints[2])
        if s.state == State.ENGAGED:
            break
    assert s.state == State.ENGAGED
    np.testing.assert_allclose(sent[-1], goal, atol=1e-3)
    out = s.tick_joints(t + 0.01, _target(goal + 0.01), goal, 0.0, None, proto.Gate.SYNCED)
    np.testing.assert_allclose(out.joints[2], goal + 0.01)  # engaged: the target itself
    out = s.tick_joints(t + 0.02, _target(goal + 1.0), goal, 0.0, None, proto.Gate.SYNCED)
    assert out.hold
    assert out.joints is None
    assert s.state == State.HELD
    assert "glitch" in s.transitions[-1].reason
    out = s.tick_joints(t + 0.03, _target(goal), goal, 0.0, None, proto.Gate.SYNCED)
    assert s.state == State.HELD  # a glitch waits for the operator
    s.engage(t + 0.04)  # ... who engages again: aligned from the robot's joints first
    assert s.state == State.ALIGNING
    out = s.tick_joints(t + 0.05, _target(goal + 0.5), goal, 0.0, None, proto.Gate.SYNCED)
    assert np.abs(out.joints[2] - goal).max() <= s.align_speed_rad_s * 0.02 + 1e-12  # 20 ms


def test_session_holds_on_a_fault_and_realigns_when_it_clears():
    s = HumanoidSession()
    s.v_max = np.full(2, 2.0)
    s.engage(0.0)
    q = np.zeros(2)
    s.tick_joints(0.01, _target(q), q, 0.0, None, proto.Gate.SYNCED)
    assert s.state == State.ENGAGED
    out = s.tick_joints(0.02, None, q, 0.0, "sensor forearm_r: no data for 0.20 s")
    assert out.hold
    assert s.state == State.HELD
    out = s.tick_joints(0.03, _target(q), q, 0.0, None, proto.Gate.SYNCED)
    assert [tr.reason for tr in s.transitions[-2:]] == [
        "fault cleared: aligning",
        "aligned with the robot",
    ]
    out = s.tick_joints(0.04, _target(q), q, 5.0, None, proto.Gate.SYNCED)  # link silent
    assert out.hold
    assert "no report" in s.transitions[-1].reason
