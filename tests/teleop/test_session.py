"""Session state machine: engage gate with hysteresis, clutch/reindex, faults, limits."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.teleop import protocol as proto
from mocapkit.teleop.session import SessionConfig, State, TeleopSession


def _T(x=0.5, y=-0.3, z=0.0):
    T = np.eye(4)
    T[:3, 3] = [x, y, z]
    return T


def test_relative_engage_reindex_and_relative_motion(caplog):
    s = TeleopSession()
    robot = _T(0.6, -0.3, -0.1)
    model = _T(0.2, -0.2, -0.4)  # operator's pose differs from the robot's: reindexing
    with caplog.at_level(logging.INFO, logger="mocapkit.teleop.session"):
        assert s.tick(0.0, model, robot, 0.0).command is None  # disabled: nothing sent
        s.engage(0.0)
        out = s.tick(0.01, model, robot, 0.0)
    assert s.state == State.ENGAGED
    np.testing.assert_allclose(out.command, robot, atol=1e-12)
    # the operator's hand moves 5 cm up: so does the command
    out = s.tick(0.2, _T(0.2, -0.2, -0.35), robot, 0.0)
    np.testing.assert_allclose(out.command[:3, 3], robot[:3, 3] + [0, 0, 0.05], atol=1e-12)
    events = [r for r in caplog.records if getattr(r, "event", None) == "transition"]
    assert [(r.__dict__["from"], r.__dict__["to"]) for r in events] == [
        ("disabled", "aligning"),
        ("aligning", "engaged"),
    ]


def test_absolute_mode_waits_until_aligned():
    s = TeleopSession(SessionConfig(mode="absolute"))
    robot = _T()
    s.engage(0.0)
    assert s.tick(0.01, _T(0.6), robot, 0.0).command is None  # 10 cm away: aligning
    assert s.state == State.ALIGNING
    assert s.tick(0.02, _T(0.51), robot, 0.0).command is not None  # within 20 mm
    assert s.state == State.ENGAGED


def test_disengage_with_hysteresis_then_recover():
    cfg = SessionConfig(mode="absolute", disengage_after_s=0.1, max_speed_m_s=100.0)
    s = TeleopSession(cfg)
    robot = _T()
    s.engage(0.0)
    s.tick(0.0, _T(), robot, 0.0)
    # 5 cm off: beyond engage (2 cm) but within disengage (8 cm): stays engaged
    assert s.tick(0.1, _T(0.55), robot, 0.0).command is not None
    # 20 cm off (unreachable target, robot stuck) for longer than 0.1 s: back to aligning
    s.tick(0.2, _T(0.7), robot, 0.0)
    out = s.tick(0.35, _T(0.7), robot, 0.0)
    assert s.state == State.ALIGNING
    assert out.hold
    assert "robot cannot follow" in s.transitions[-1].reason
    s.tick(0.4, _T(0.51), robot, 0.0)  # the operator comes back
    assert s.state == State.ENGAGED


def test_clutch_holds_and_reindexes_on_release():
    s = TeleopSession()
    robot = _T()
    s.engage(0.0)
    s.tick(0.0, _T(0.1), robot, 0.0)
    s.clutch(True, 0.1)
    assert s.state == State.CLUTCHED
    assert s.tick(0.2, _T(0.3), robot, 0.0).command is None  # operator repositions freely
    s.clutch(False, 0.3)
    out = s.tick(0.31, _T(0.3), robot, 0.0)
    assert s.state == State.ENGAGED
    np.testing.assert_allclose(out.command, robot, atol=1e-12)  # no jump


@pytest.mark.parametrize(
    ("kwargs", "reason"),
    [
        ({"model_fault": "sensor 2: stale for 0.25 s (dropout?)"}, "sensor 2: stale"),
        ({"robot_age_s": 1.0}, "robot server silent for 1.00 s"),
    ],
)
def test_faults_hold_then_recover(kwargs, reason):
    s = TeleopSession()
    robot = _T()
    s.engage(0.0)
    s.tick(0.0, _T(0.1), robot, 0.0)
    args = {"robot_age_s": 0.0} | kwargs
    out = s.tick(0.1, _T(0.1), robot, **args)
    assert s.state == State.HELD
    assert out.hold
    assert reason in s.transitions[-1].reason
    assert s.tick(0.2, _T(0.1), robot, **args).command is None  # still held, nothing sent
    out = s.tick(0.3, _T(0.4), robot, 0.0)  # cause gone; operator moved meanwhile
    assert s.state == State.ENGAGED
    np.testing.assert_allclose(out.command, robot, atol=1e-12)  # reindexed: no jump


def test_nan_model_pose_holds():
    s = TeleopSession()
    s.engage(0.0)
    s.tick(0.0, _T(), _T(), 0.0)
    bad = _T()
    bad[0, 3] = np.nan
    s.tick(0.1, bad, _T(), 0.0)
    assert s.state == State.HELD
    assert s.transitions[-1].reason == "model pose is not finite"


def test_workspace_and_speed_limits():
    cfg = SessionConfig(
        mode="absolute",
        workspace_max=(0.55, 1.0, 0.7),
        max_speed_m_s=0.5,
        max_model_speed_m_s=100.0,  # the 0.4 m step in 10 ms below is not a glitch here
    )
    s = TeleopSession(cfg)
    s.engage(0.0)
    s.tick(0.0, _T(0.5), _T(0.5), 0.0)
    out = s.tick(0.01, _T(0.9), _T(0.5), 0.0)
    assert out.command[0, 3] <= 0.505 + 1e-12  # 0.5 m/s * 10 ms
    assert "speed limit: command slowed" in out.notes
    out = s.tick(1.0, _T(0.9), _T(0.55), 0.0)
    assert out.command[0, 3] == pytest.approx(0.55)
    assert "workspace limit: command clamped to the box" in out.notes


def test_config_validation():
    with pytest.raises(ConfigError, match="hysteresis"):
        SessionConfig(engage_pos_m=0.1, disengage_pos_m=0.05)
    with pytest.raises(ConfigError, match="mode: expected 'relative' or 'absolute'"):
        SessionConfig(mode="sideways")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="each min must be below its max"):
        SessionConfig(workspace_min=(1.0, 0.0, 0.0), workspace_max=(0.0, 1.0, 1.0))


def test_unreachable_target_is_followed_as_close_as_possible():
    """The server reports the target out of reach: the session stays engaged (the robot
    holds its closest pose), says so, and the robot follows again when it comes back."""
    cfg = SessionConfig(disengage_after_s=0.1, max_speed_m_s=100.0)
    s = TeleopSession(cfg)
    stuck = _T(0.60)
    s.engage(0.0)
    s.tick(0.0, _T(0.5), _T(0.5), 0.0)
    for k in range(5):
        out = s.tick(0.1 + 0.1 * k, _T(0.75), stuck, 0.0, robot_reason=proto.Reason.UNREACHABLE)
    assert s.state == State.ENGAGED
    assert out.command is not None
    assert "target out of reach" in out.notes[-1]
    out = s.tick(1.0, _T(0.55), stuck, 0.0)  # back within reach
    assert s.state == State.ENGAGED
    assert not out.notes
    # 40 cm beyond: too far to keep following, disengage
    for k in range(3):
        s.tick(1.1 + 0.1 * k, _T(1.0), stuck, 0.0, robot_reason=proto.Reason.UNREACHABLE)
    assert s.state == State.ALIGNING
    assert s.transitions[-1].reason == (
        "robot cannot follow: 400 mm, 0 deg away (server: UNREACHABLE)"
    )


def test_a_robot_that_cannot_follow_recovers_by_reindexing_when_the_target_comes_back():
    """A robot stuck short of its target (no reason given): disengage with a HOLD; when the
    operator's target comes back within the disengage thresholds of where the robot
    stopped, the rest is taken up by a reindex, without a jump."""
    cfg = SessionConfig(disengage_after_s=0.1, max_speed_m_s=100.0)
    s = TeleopSession(cfg)
    stuck = _T(0.60)
    s.engage(0.0)
    s.tick(0.0, _T(0.5), _T(0.5), 0.0)  # reindexed at the robot's pose: offset 0
    s.tick(0.1, _T(0.75), stuck, 0.0)
    out = s.tick(0.25, _T(0.75), stuck, 0.0)
    assert s.state == State.ALIGNING
    assert out.hold
    assert s.transitions[-1].reason == "robot cannot follow: 150 mm, 0 deg away"
    assert s.tick(0.3, _T(0.70), stuck, 0.0).command is None  # still 10 cm out: waits
    out = s.tick(0.4, _T(0.65), stuck, 0.0)  # 5 cm from the robot: back
    assert s.state == State.ENGAGED
    assert s.transitions[-1].reason == "target back within 50 mm: reindexed"
    np.testing.assert_allclose(out.command, stuck, atol=1e-12)  # no jump
    out = s.tick(0.5, _T(0.60), stuck, 0.0)  # and relative motion from there
    np.testing.assert_allclose(out.command[:3, 3], stuck[:3, 3] - [0.05, 0, 0], atol=1e-12)


def test_disable_and_clutch_send_one_hold():
    s = TeleopSession()
    s.engage(0.0)
    s.tick(0.0, _T(), _T(), 0.0)
    s.clutch(True, 0.1)
    assert s.hold_pending
    assert s.tick(0.2, _T(), _T(), 0.0).hold
    assert not s.tick(0.3, _T(), _T(), 0.0).hold  # once
    s.disable(0.4)
    out = s.tick(0.5, _T(), _T(), 0.0)
    assert out.hold
    assert out.command is None
    assert s.state == State.DISABLED
