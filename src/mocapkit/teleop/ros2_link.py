"""The robot link to a ROS 2 robot: joint targets to a ros2_control controller, the
robot's ``/joint_states`` back, over Zenoh in rmw_zenoh's format (no ROS install;
:mod:`mocapkit.io.ros2_zenoh`).

:class:`Ros2RobotLink` stands where :class:`~mocapkit.teleop.link.RobotLink` (mocapkit's
UDP robot server) stands in the live session, for robots driven joint by joint
(humanoids, ``--robot g1``):

- a command goes out as ``std_msgs/Float64MultiArray`` on ``command_topic`` (default
  ``/forward_position_controller/commands``: ros2_control's forward command controller),
  the positions in the controller's joint order (``controller_joints``, default the
  robot model's). A floating base cannot be commanded through it and is left out.
- the robot's ``sensor_msgs/JointState`` on ``state_topic`` (default ``/joint_states``)
  become the session's reports: their positions picked out by name in the robot model's
  joint order. A state that lacks one of them, or a payload that does not decode, is
  counted (``malformed``) and dropped with a warning naming the joints.
- a HOLD sends nothing: a forward controller keeps its last target.
- an arm driven through the robot's own IK (the paper's Robonaut; ``pose_topic`` given):
  end-effector targets as ``geometry_msgs/PoseStamped`` (in ``frame_id``, the arm's base)
  on ``pose_topic``, the robot's current end-effector pose (``PoseStamped``) from
  ``pose_state_topic`` as the reports; no joints.
- the synchronisation the paper's robot enforced is the session's own here: the robot
  reports itself ready (``Gate.SYNCED``) and :class:`~mocapkit.teleop.humanoid_session.
  HumanoidSession` aligns from the reported joints at its limited rate before it follows.
  A silent ``/joint_states`` (the robot gone) holds the session after its report timeout.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError
from mocapkit.teleop import protocol as proto
from mocapkit.teleop.link import ReportedRobot

log = logging.getLogger("mocapkit.teleop.ros2_link")

COMMAND_TOPIC = "/forward_position_controller/commands"
POSE_STATE_TOPIC = "/current_pose"
STATE_TOPIC = "/joint_states"


class Ros2RobotLink(ReportedRobot):
    """See the module docstring.

    Args:
        joint_names: the robot model's one-DOF joints, in the order the session's
            commands and reports use.
        connect: Zenoh endpoints (the ROS machine's ``rmw_zenohd``, ``tcp/HOST:7447``).
        controller_joints: the controller's joint order (default ``joint_names``).
        domain_id: ``ROS_DOMAIN_ID`` (default: the environment's, else 0).
    """

    def __init__(
        self,
        joint_names: Sequence[str],
        connect: Sequence[str] = (),
        *,
        command_topic: str = COMMAND_TOPIC,
        state_topic: str = STATE_TOPIC,
        controller_joints: Sequence[str] | None = None,
        on_report: Callable[[float, proto.Report], None] | None = None,
        domain_id: int | None = None,
        pose_topic: str | None = None,
        pose_state_topic: str = POSE_STATE_TOPIC,
        frame_id: str = "base",
    ) -> None:
        from mocapkit.io.ros2_zenoh import Ros2ZenohPublisher

        super().__init__()
        self.pose_topic = pose_topic
        self.reports_pose = pose_topic is not None
        self.frame_id = frame_id
        self.joint_names = [] if pose_topic is not None else list(joint_names)
        order = list(controller_joints) if controller_joints is not None else self.joint_names
        unknown = [j for j in order if j not in self.joint_names]
        if unknown:
            raise ConfigError(
                f"controller joints {', '.join(unknown)} are not joints of the robot model "
                f"(its joints: {', '.join(self.joint_names)})"
            )
        self._to_controller = np.array([self.joint_names.index(j) for j in order], dtype=int)
        self.command_topic = command_topic
        self.state_topic = state_topic
        self.address = f"ROS 2 {command_topic} / {state_topic} over Zenoh"
        self.on_report = on_report
        self.seq = 0
        self.malformed = 0
        self.send_errors = 0
        self._incoming: tuple[float, FloatArray] | None = None
        self._lock = threading.Lock()
        self._reports = 0
        self._warned = False
        self.pub = Ros2ZenohPublisher(connect=connect, domain_id=domain_id)
        self._pose_in: tuple[FloatArray, FloatArray] = (np.zeros(3), np.array([1.0, 0, 0, 0]))
        if pose_topic is not None:
            self.address = f"ROS 2 {pose_topic} / {pose_state_topic} over Zenoh"
            self.pub.subscribe(pose_state_topic, "geometry_msgs/msg/PoseStamped", self._on_pose)
        else:
            self.pub.subscribe(state_topic, "sensor_msgs/msg/JointState", self._on_state)

    # -- from Zenoh's thread ----------------------------------------------------------------
    def _on_state(self, msg: Any) -> None:
        if msg is None:
            self._malformed("a JointState that does not decode")
            return
        names = list(msg.name)
        pos = np.asarray(msg.position, dtype=np.float64)
        if len(pos) != len(names):
            self._malformed(f"{len(names)} names but {len(pos)} positions")
            return
        where = {n: i for i, n in enumerate(names)}
        missing = [j for j in self.joint_names if j not in where]
        if missing:
            self._malformed(f"no position for {', '.join(missing[:5])}")
            return
        q = pos[[where[j] for j in self.joint_names]]
        with self._lock:
            self._incoming = (time.monotonic(), q)

    def _on_pose(self, msg: Any) -> None:
        if msg is None:
            self._malformed("a PoseStamped that does not decode")
            return
        p, o = msg.pose.position, msg.pose.orientation
        pos = np.array([p.x, p.y, p.z], dtype=np.float64)
        quat = np.array([o.w, o.x, o.y, o.z], dtype=np.float64)
        norm = float(np.linalg.norm(quat))
        if not (np.isfinite(pos).all() and np.isfinite(quat).all() and norm > 0.5):
            self._malformed("a pose that is not finite or not a rotation")
            return
        with self._lock:
            self._pose_in = (pos, quat / norm)
            self._incoming = (time.monotonic(), np.zeros(0))

    def _malformed(self, what: str) -> None:
        self.malformed += 1
        if not self._warned:  # once: a robot that names its joints otherwise says so 100x/s
            self._warned = True
            log.warning("%s: dropped a joint state: %s", self.state_topic, what)

    # -- the RobotLink interface -------------------------------------------------------------
    def send_joints(self, base_pos: Any, base_quat: Any, q: Any) -> int:
        """Joint targets [rad] in the model's order to the controller (base left out)."""
        self.seq += 1
        values = np.asarray(q, dtype=np.float64)[self._to_controller]
        try:
            self.pub.float64_array(self.command_topic, values)
        except Exception as exc:  # a Zenoh peer that disappears must not stop the session
            self.send_errors += 1
            log.debug("ROS 2 command failed: %s", exc)
        return self.seq

    def send_command(self, T_base_ee: Any) -> int:
        """An end-effector target (4, 4) [m] in the arm's base frame, for the robot's IK."""
        if self.pose_topic is None:
            raise ConfigError(
                "this ROS 2 robot link takes joint targets; give it a pose topic for "
                "end-effector poses (--ros2-pose-topic)"
            )
        from mocapkit.geometry import quat_from_matrix

        self.seq += 1
        T = np.asarray(T_base_ee, dtype=np.float64)
        try:
            self.pub.pose_stamped(self.pose_topic, self.frame_id, T[:3, 3],
                                  quat_from_matrix(T[:3, :3]))  # fmt: skip
        except Exception as exc:  # a Zenoh peer that disappears must not stop the session
            self.send_errors += 1
            log.debug("ROS 2 command failed: %s", exc)
        return self.seq

    def send_hold(self) -> None:
        """Nothing to send: a forward controller keeps its last target."""

    def poll(self) -> int:
        with self._lock:
            incoming, self._incoming = self._incoming, None
            pos, quat = self._pose_in
        if incoming is None:
            return 0
        t, q = incoming
        self._reports += 1
        report = proto.Report(
            seq=self._reports, t_send_ns=time.monotonic_ns(), pos=pos, quat=quat,
            last_command_seq=self.seq, gate=proto.Gate.SYNCED, reason=proto.Reason.OK, q=q,
        )  # fmt: skip
        self.latest, self.latest_t = report, t
        if self.on_report is not None:
            self.on_report(t, report)
        return 1

    def keepalive(self, now: float | None = None) -> bool:
        return False  # the robot publishes its joint states whether we speak or not

    def close(self) -> None:
        self.pub.close()


__all__ = ["COMMAND_TOPIC", "POSE_STATE_TOPIC", "STATE_TOPIC", "Ros2RobotLink"]
