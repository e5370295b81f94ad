"""A humanoid through the live chain: a simulated suit in its own process, the session's
body model and whole-body retargeting (G1), JOINTS commands to a robot-server process
whose safety gate accepts them only once synchronised; a sensor dropout holds the robot
and the session aligns again when it ends. Loose sanity bounds."""

from __future__ import annotations

import time

import numpy as np
import pytest

from mocapkit.body.sensor_tree import SensorTree
from mocapkit.teleop import protocol as proto
from mocapkit.teleop.live import LiveConfig, LiveSession
from mocapkit.teleop.operator import operator_motion
from mocapkit.teleop.operator_suit import Dropout, SuitSetup, suit_timeline
from mocapkit.teleop.pipeline import PipelineConfig
from mocapkit.teleop.recording import read_messages
from mocapkit.teleop.sender import TimelineSender
from mocapkit.teleop.server import ServerConfig, spawn_robot_server
from tests.teleop.test_live import _sleep_until, _wait

pytestmark = pytest.mark.realtime
pytest.importorskip("pinocchio")

IDS = {"upper_arm_r": 1, "forearm_r": 2}


def test_g1_follows_the_operators_arm_through_the_gate(tmp_path):
    motion = operator_motion(
        "vertical", SensorTree.preset("right_arm_2"), calib_s=2.0, reach_s=1.2,
        settle_s=0.6, shape_s=2.5, hold_s=0.5, heading_rad=0.7,
    )  # fmt: skip
    # the forearm's node drops out for 0.3 s while engaged: held, named, aligned again
    drop = Dropout("forearm_r", motion.engage_t + 1.6, motion.engage_t + 1.9)
    items, _ = suit_timeline(motion, SuitSetup(), IDS, np.random.default_rng(0), (drop,))
    rec = tmp_path / "g1.mcap"
    cfg = LiveConfig(pipeline=PipelineConfig(robot="g1"))
    with spawn_robot_server(ServerConfig(robot="g1"), max_seconds=60) as srv:
        live = LiveSession(cfg, srv.address, record=rec)
        with live, TimelineSender(items, "127.0.0.1", live.suit_port) as sender:
            assert _wait(lambda: live.link.latest is not None, 20.0)
            n_joints = len(live.pipeline.robot_joint_names)
            assert live.link.latest.q.shape == (n_joints,)
            q_start = live.link.latest.q.copy()
            t_go = sender.go()
            _sleep_until(t_go + motion.calib_window[0])
            assert live.calibrate(motion.calib_window[1] - motion.calib_window[0]) is not None
            _sleep_until(t_go + motion.engage_t)
            live.engage()
            assert _wait(lambda: live.snapshot()["state"] == "engaged", 5.0)
            time.sleep(0.5)
            snap = live.snapshot()
            assert snap["safety"]["robot_gate"] == "SYNCED"
            assert len(snap["robot_joints_deg"]) == n_joints
            moved = np.abs(live.link.latest.q - q_start)
            names = live.pipeline.robot_joint_names
            assert (
                max(moved[i] for i, n in enumerate(names) if n.startswith("right_shoulder")) > 0.2
            )
            # only the operator's right arm moves (the suit has no other sensors)
            assert max(moved[i] for i, n in enumerate(names) if n.startswith("left_")) < 0.05
            _sleep_until(t_go + drop.t_stop + 0.8)
            assert live.snapshot()["state"] == "engaged"  # back after the dropout
            live.disengage()
            assert _wait(lambda: live.link.latest.gate == proto.Gate.HOLDING, 2.0)
            sender.wait(20.0)
    reasons = [m["reason"] for m in read_messages(rec, "/teleop/transition")]
    assert reasons[:2] == ["operator engaged", "aligned with the robot"]
    i = next(k for k, r in enumerate(reasons) if r.startswith("sensor forearm_r (id 2): no data"))
    assert reasons[i + 1 : i + 3] == ["fault cleared: aligning", "aligned with the robot"]
    assert "operator disabled" in reasons
    joints = read_messages(rec, "/teleop/joints")
    assert len(joints) > 50
    assert any(n == "right_shoulder_pitch_joint" for n in joints[-1]["names"])
