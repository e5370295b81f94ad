"""A live session in Foxglove: a Foxglove WebSocket server (the maintained ``foxglove-sdk``)
that publishes the session's snapshot 20 times a second.

Channels:

- ``/body/tf`` (``foxglove.FrameTransforms``): ``world`` -> every body segment, at the
  segment's joint point with its orientation (real translations: Foxglove's 3-D panel
  draws the body without set-up);
- ``/robot/joints`` (JSON: ``names``, ``positions_rad``): the robot's reported joints;
- ``/session/state`` (JSON): state, safety, latency p50/p99 [ms], packet loss, message;
- with a humanoid (``robot``): ``/robot/tf`` (``foxglove.FrameTransforms``): ``world`` ->
  every link of the URDF at the reported joints (Pinocchio's forward kinematics; the base
  at the robot's reference stance), and ``/robot_description`` (the URDF's text as
  ``std_msgs/String``-shaped JSON ``{"data": ...}``, once a second so a late client gets
  it): Foxglove's 3-D panel draws the robot from its URDF (a URDF layer on that topic, or
  on the file) on those frames.

Timestamps are wall-clock nanoseconds. Open Foxglove and connect to
``ws://HOST:PORT`` (Foxglove WebSocket). The SDK serves any number of clients and drops
a client that misbehaves; the session never waits for a client.
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any

from mocapkit.errors import MissingDependencyError

log = logging.getLogger("mocapkit.teleop.foxglove_live")

PERIOD_S = 0.05
JOINTS_SCHEMA = {
    "type": "object",
    "properties": {
        "names": {"type": "array", "items": {"type": "string"}},
        "positions_rad": {"type": "array", "items": {"type": "number"}},
    },
}
STATE_SCHEMA = {
    "type": "object",
    "properties": {
        "state": {"type": "string"},
        "safety": {"type": "object"},
        "latency_ms": {"type": "object"},
        "packet_loss": {"type": "number"},
        "message": {"type": "string"},
    },
}


def _foxglove() -> Any:
    try:
        import foxglove
    except ImportError as exc:
        raise MissingDependencyError(
            "the live Foxglove server needs foxglove-sdk: pip install 'mocapkit[viz]'"
        ) from exc
    return foxglove


DESCRIPTION_SCHEMA = {"type": "object", "properties": {"data": {"type": "string"}}}


class RobotFrames:
    """A humanoid's URDF links placed by forward kinematics (Pinocchio) from reported
    joints (``{name: deg}``, the names of ``robot.iq_names``), the base at its reference
    stance."""

    def __init__(self, robot: Any) -> None:
        import pinocchio as pin

        self.robot = robot
        self.data = robot.model.createData()
        self.frames = [
            (i, f.name) for i, f in enumerate(robot.model.frames) if f.type == pin.FrameType.BODY
        ]
        self.urdf = robot.spec.urdf.read_text()
        self._names = list(robot.iq_names)

    def links(self, joints_deg: Mapping[str, float]) -> list[tuple[str, Any, Any]]:
        """[(link, position (3,), [w, x, y, z])] in the world."""
        import numpy as np
        import pinocchio as pin

        from mocapkit.geometry import quat_from_matrix

        q = self.robot.q_ref.copy()
        q[self.robot.iq] = [math.radians(float(joints_deg.get(n, 0.0))) for n in self._names]
        pin.framesForwardKinematics(self.robot.model, self.data, q)
        out = []
        for i, name in self.frames:
            m = self.data.oMf[i]
            out.append((name, np.array(m.translation),  # a copy: oMf is reused
                        quat_from_matrix(np.asarray(m.rotation))))  # fmt: skip
        return out


class FoxgloveLive:
    """Publishes ``snapshot()`` (a live session's, :class:`~mocapkit.teleop.live.LiveSession`)
    on a Foxglove WebSocket server at ``host:port`` (0: any free port)."""

    def __init__(
        self,
        snapshot: Callable[[], Mapping[str, Any]],
        host: str = "127.0.0.1",
        port: int = 8765,
        robot: Any = None,
    ) -> None:
        fg = _foxglove()
        from foxglove.channels import FrameTransformsChannel

        self.snapshot = snapshot
        self.context = fg.Context()
        self.server = fg.start_server(name="mocapkit", host=host, port=port, context=self.context)
        self.port = int(self.server.port)
        self.url = f"ws://{host}:{self.port}"
        self.tf = FrameTransformsChannel("/body/tf", context=self.context)
        self.joints = fg.Channel(
            "/robot/joints", schema=JOINTS_SCHEMA, message_encoding="json", context=self.context
        )
        self.state = fg.Channel(
            "/session/state", schema=STATE_SCHEMA, message_encoding="json", context=self.context
        )
        self.robot = RobotFrames(robot) if robot is not None else None
        if self.robot is not None:
            self.robot_tf = FrameTransformsChannel("/robot/tf", context=self.context)
            schema = fg.Schema(name="std_msgs/String", encoding="jsonschema",
                               data=json.dumps(DESCRIPTION_SCHEMA).encode())  # fmt: skip
            self.description = fg.Channel(
                "/robot_description", schema=schema, message_encoding="json", context=self.context
            )
            self._described = -math.inf
        self.published = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="mocapkit-foxglove", daemon=True)

    def start(self) -> FoxgloveLive:
        self._thread.start()
        return self

    def publish(self) -> None:
        """One snapshot out on every channel."""
        from foxglove.messages import (
            FrameTransform,
            FrameTransforms,
            Quaternion,
            Timestamp,
            Vector3,
        )

        snap = self.snapshot()
        t_ns = time.time_ns()
        stamp = Timestamp(sec=t_ns // 1_000_000_000, nsec=t_ns % 1_000_000_000)
        tfs = []
        for seg in snap.get("segments") or []:
            w, x, y, z = seg["quat"]
            px, py, pz = seg["start"]
            tfs.append(FrameTransform(
                timestamp=stamp, parent_frame_id="world", child_frame_id=seg["name"],
                translation=Vector3(x=px, y=py, z=pz), rotation=Quaternion(x=x, y=y, z=z, w=w),
            ))  # fmt: skip
        if tfs:
            self.tf.log(FrameTransforms(transforms=tfs), log_time=t_ns)
        joints = snap.get("robot_joints_deg")
        if joints:
            rad = [math.radians(float(v)) for v in joints.values()]
            self.joints.log({"names": list(joints), "positions_rad": rad}, log_time=t_ns)
        if self.robot is not None:
            self._publish_robot(snap, stamp, t_ns)
        state = {k: snap.get(k) for k in ("state", "safety", "latency_ms", "packet_loss",
                                          "message")}  # fmt: skip
        self.state.log(json.loads(json.dumps(state, default=str)), log_time=t_ns)
        self.published += 1

    def _publish_robot(self, snap: Mapping[str, Any], stamp: Any, t_ns: int) -> None:
        from foxglove.messages import FrameTransform, FrameTransforms, Quaternion, Vector3

        assert self.robot is not None
        joints = snap.get("robot_joints_deg")
        if joints:
            tfs = []
            for name, pos, (w, x, y, z) in self.robot.links(joints):
                tfs.append(FrameTransform(
                    timestamp=stamp, parent_frame_id="world", child_frame_id=name,
                    translation=Vector3(x=pos[0], y=pos[1], z=pos[2]),
                    rotation=Quaternion(x=x, y=y, z=z, w=w),
                ))  # fmt: skip
            self.robot_tf.log(FrameTransforms(transforms=tfs), log_time=t_ns)
        now = time.monotonic()
        if now - self._described >= 1.0:
            self.description.log({"data": self.robot.urdf}, log_time=t_ns)
            self._described = now

    def _loop(self) -> None:
        while not self._stop.wait(PERIOD_S):
            try:
                self.publish()
            except Exception as exc:  # the session must go on whatever a publish does
                log.warning("foxglove: publish failed: %s", exc)

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        self.server.stop()

    def __enter__(self) -> FoxgloveLive:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
