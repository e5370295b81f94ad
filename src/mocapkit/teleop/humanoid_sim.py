"""A humanoid behind the robot server: joint commands in, joint reports out, with the same
safety gate as the arms (commands accepted only once synchronised with the robot).

:class:`HumanoidSim` stands for a whole-body robot (any packaged humanoid or robot YAML,
``mocapkit.retarget``) whose own controller takes joint position targets: the JOINTS
message carries the floating base's pose and every one-DOF joint's position, in the
model's order (``Humanoid.joint_names`` restricted to ``iq``). The gate:

- a command is refused when a joint is non-finite, the base quaternion is not a unit
  one, the joint count is not the robot's, or a joint lies beyond its limits by more than
  ``LIMIT_SLACK_RAD`` (``BAD_COMMAND``);
- unsynchronised (at start, after a hold, a jump or a timeout), a command is accepted
  only when every joint is within ``gate_joint_rad`` of the robot's actual position
  (``TOO_FAR`` otherwise): the host aligns the robot to the operator in small steps;
- synchronised, a command that moves a joint more than ``gate_joint_rad`` from the last
  accepted one is a jump: refused and the gate drops (``JUMP``);
- no command for ``command_timeout_s``: the gate drops and the robot holds (``TIMEOUT``).

Accepted targets act after ``latency_s``; the joints move towards them at most at their
velocity limits (times ``velocity_scale``); the base follows its commanded pose (a real
humanoid's balance controller does that part).
"""

from __future__ import annotations

import logging

import numpy as np

from mocapkit.retarget.robot_model import Humanoid
from mocapkit.teleop import protocol as proto
from mocapkit.teleop.server import GatedSim, ServerConfig, SimState

log = logging.getLogger("mocapkit.teleop.server")

LIMIT_SLACK_RAD = 1e-3  # a command may touch a limit, not pass it


class HumanoidSim(GatedSim):
    """See the module docstring; stepped by the caller with explicit times [s]."""

    def __init__(self, robot: Humanoid, config: ServerConfig) -> None:
        self.robot = robot
        self.config = config
        self.joints = robot.q_ref[robot.iq].copy()  # (n,) actual one-DOF joints
        self.lo = robot.q_min[robot.iq]
        self.hi = robot.q_max[robot.iq]
        self.v_max = robot.v_max[robot.iv]
        base = robot.q_ref[:7] if robot.spec.floating_base else np.array([0, 0, 0, 0, 0, 0, 1.0])
        self.base_pos = np.array(base[:3], dtype=float)
        self.base_quat = np.array([base[6], base[3], base[4], base[5]], dtype=float)  # wxyz
        self.state = SimState()
        self.gate_joint_rad = config.gate_joint_rad

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.robot.iq_names

    def on_command(self, cmd: proto.Command, now: float) -> bool:
        """An end-effector command: a humanoid takes joints (refused, counted)."""
        self.state.rejected += 1
        self._set(self.state.gate, proto.Reason.BAD_COMMAND)
        log.warning("end-effector command to a humanoid: send JOINTS messages")
        return False

    def on_joints(self, cmd: proto.JointsCommand, now: float) -> bool:
        """Gate a joint command; returns True when accepted."""
        s = self.state
        q = np.asarray(cmd.q, dtype=float)
        quat = np.asarray(cmd.base_quat, dtype=float)
        bad = (
            q.shape != self.joints.shape
            or not (np.isfinite(q).all() and np.isfinite(cmd.base_pos).all())
            or not np.isfinite(quat).all()
            or abs(float(np.linalg.norm(quat)) - 1.0) > 1e-3
            or bool(np.any(q < self.lo - LIMIT_SLACK_RAD) or np.any(q > self.hi + LIMIT_SLACK_RAD))
        )
        if bad:
            s.rejected += 1
            self._set(s.gate, proto.Reason.BAD_COMMAND)
            return False
        if s.gate == proto.Gate.SYNCED:
            assert s.last_accepted is not None
            if float(np.max(np.abs(q - s.last_accepted))) > self.gate_joint_rad:
                return self._jumped()
        else:
            if float(np.max(np.abs(q - self.joints))) > self.gate_joint_rad:
                return self._too_far()
            self._set(proto.Gate.SYNCED, proto.Reason.OK)
        target = (np.asarray(cmd.base_pos, dtype=float), quat / np.linalg.norm(quat), q)
        return self._accept(cmd.seq, now, q, target)

    def step(self, now: float, dt: float) -> None:
        """Advance the joints by one control tick of dt [s]."""
        s, c = self.state, self.config
        self._due(now)
        if s.target is None:
            return
        pos, quat, q = s.target
        step = self.v_max * c.velocity_scale * dt
        self.joints = self.joints + np.clip(q - self.joints, -step, step)
        self.base_pos, self.base_quat = pos, quat

    def report(self, seq: int, t_ns: int) -> bytes:
        s = self.state
        return proto.encode_report(
            seq, t_ns, self.base_pos, self.base_quat, s.last_command_seq, s.gate, s.reason,
            self.joints,
        )  # fmt: skip
