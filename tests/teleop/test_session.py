"""Session state machine: engage gate with hysteresis, clutch/reindex, faults, limits."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from mocapkit.errors import ConfigError
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
    cfg = SessionConfig(mode="absolute", workspace_max=(0.55, 1.0, 0.7), max_speed_m_s=0.5)
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
