"""The demo's per-packet arm pipeline (kept for ``mocapkit.demo.suit_chain``): sensor
orientations -> robot command on the wire, without the body model.

The teleoperation package's own pipeline is :mod:`mocapkit.teleop.pipeline` (body model,
heading refinement, host fusion, numba path) run by :class:`mocapkit.teleop.live.LiveSession`;
the demo's chain predates it and should move to it.

``ArmTeleop.process(samples)`` takes the samples that arrived in one packet (each with
``sensor_id``, ``t_arrival_ns`` and ``quat`` = ``q_world_sensor`` [w, x, y, z] or None,
the fields of the suit receiver's samples), and runs: sensor watchdog -> segment
orientations in the chest frame -> retargeting (eq. 16, ``SegmentRetargeter``) ->
intermediate model FK (``T_chest_ee``) -> session -> robot link. It returns the host-side
time from the packet's arrival to the command's ``send`` [ns] (``pipeline_ms``).

Segment orientations: only rotations since the initialisation posture matter to the
retargeting (``dR = R(t) R(0)^T``), so a sensor's mounting on its segment cancels; the
chest frame is the world rotated by the operator's heading at calibration, or follows a
root (chest) sensor when one is given (the paper's third sensor, section 6).
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import DataError
from mocapkit.geometry import quat_to_matrix
from mocapkit.robot.model import ArmModel
from mocapkit.robot.segment_retarget import SegmentRetargeter
from mocapkit.teleop.link import RobotLink
from mocapkit.teleop.session import TeleopSession, TickOutput


class SampleLike(Protocol):
    sensor_id: int
    t_arrival_ns: int
    quat: Any


@dataclass
class OrientationSample:
    """Minimal sample (what the suit receiver delivers, orientation part)."""

    sensor_id: int
    t_arrival_ns: int
    quat: FloatArray | None


@dataclass
class FrameLog:
    """What happened for one packet (for evaluation and recording)."""

    t: float
    q: FloatArray | None
    T_model: FloatArray | None
    out: TickOutput
    latency_ns: int | None


@dataclass
class SensorWatchdog:
    """Marks required sensors stale after ``stale_after_s`` without a valid sample."""

    required: tuple[int, ...]
    stale_after_s: float = 0.1
    last_valid_s: dict[int, float] = field(default_factory=dict)
    bad: dict[int, str] = field(default_factory=dict)

    def update(self, sensor_id: int, t: float, quat: Any) -> None:
        if quat is None:
            return
        q = np.asarray(quat, dtype=float)
        if q.shape != (4,) or not np.isfinite(q).all() or abs(np.linalg.norm(q) - 1) > 0.05:
            self.bad[sensor_id] = f"sensor {sensor_id}: invalid orientation {q.tolist()}"
            return
        self.bad.pop(sensor_id, None)
        self.last_valid_s[sensor_id] = t

    def fault(self, now: float) -> str | None:
        """The reason the data cannot be used now, or None."""
        for sid in self.required:
            if sid in self.bad:
                return self.bad[sid]
            last = self.last_valid_s.get(sid)
            if last is None:
                return f"sensor {sid}: no data yet"
            if now - last > self.stale_after_s:
                return f"sensor {sid}: stale for {now - last:.2f} s (dropout?)"
        return None


class ArmTeleop:
    """See the module docstring.

    Args:
        model: the intermediate kinematic model (robot arm in the chest frame).
        retargeter: segment -> joint mapping for ``model``.
        sensor_segments: sensor id -> segment name (e.g. ``{1: "humerus_r", 2: "radius_r"}``).
        session: the teleoperation session.
        link: the robot link (None: compute only, e.g. in benchmarks of the host side).
        root_sensor: sensor id on the chest (heading), or None.
        R_world_chest: the chest frame in the world when there is no root sensor (3, 3).
    """

    def __init__(
        self,
        model: ArmModel,
        retargeter: SegmentRetargeter,
        sensor_segments: Mapping[int, str],
        session: TeleopSession,
        link: RobotLink | None = None,
        root_sensor: int | None = None,
        R_world_chest: Any = None,
        stale_after_s: float = 0.1,
    ) -> None:
        self.model = model
        self.retargeter = retargeter
        self.sensor_segments = dict(sensor_segments)
        missing = set(retargeter.segments) - set(self.sensor_segments.values())
        if missing:
            raise DataError(
                f"sensor_segments: no sensor for segment(s) {', '.join(sorted(missing))}"
            )
        self.session = session
        self.link = link
        self.root_sensor = root_sensor
        self.R_world_chest = np.eye(3) if R_world_chest is None else np.asarray(R_world_chest)
        required = tuple(self.sensor_segments) + ((root_sensor,) if root_sensor else ())
        self.watchdog = SensorWatchdog(required, stale_after_s)
        self.latest: dict[int, FloatArray] = {}
        self._R_chestsensor_chest: FloatArray | None = None
        self.frames: list[FrameLog] = []
        self.keep_frames = True

    def _R_world_chest_now(self) -> FloatArray:
        if self.root_sensor is None or self._R_chestsensor_chest is None:
            return self.R_world_chest
        return quat_to_matrix(self.latest[self.root_sensor]) @ self._R_chestsensor_chest

    def calibrate(self, q_world_sensor: Mapping[int, Any]) -> None:
        """The operator stands in the initialisation posture: store the reference."""
        for sid in self.watchdog.required:
            if sid not in q_world_sensor:
                raise DataError(f"calibrate: no orientation for sensor {sid}")
        self.latest = {k: np.asarray(v, dtype=float) for k, v in q_world_sensor.items()}
        if self.root_sensor is not None:
            R_ws = quat_to_matrix(self.latest[self.root_sensor])
            self._R_chestsensor_chest = R_ws.T @ self.R_world_chest
        self.retargeter.calibrate(self._segments())

    def _segments(self) -> dict[str, FloatArray]:
        Rc = self._R_world_chest_now()
        return {
            seg: Rc.T @ quat_to_matrix(self.latest[sid])
            for sid, seg in self.sensor_segments.items()
        }

    def model_pose(self) -> tuple[FloatArray | None, FloatArray | None]:
        """(q, T_chest_ee) of the intermediate model from the latest orientations."""
        res = self.retargeter.joint_angles(self._segments())
        return res.q, self.model.fk(res.q)

    def process(self, samples: Iterable[SampleLike], now: float | None = None) -> FrameLog:
        """Handle the samples of one packet; send the session's output to the robot."""
        t_arrival: int | None = None
        t = time.monotonic() if now is None else now
        for s in samples:
            t_arrival = s.t_arrival_ns if t_arrival is None else min(t_arrival, s.t_arrival_ns)
            self.watchdog.update(s.sensor_id, t, s.quat)
            valid = (
                s.sensor_id in self.watchdog.last_valid_s and s.sensor_id not in self.watchdog.bad
            )
            if valid and s.quat is not None:
                self.latest[s.sensor_id] = np.asarray(s.quat, dtype=float)
        fault = self.watchdog.fault(t)
        q = T = None
        if fault is None:
            q, T = self.model_pose()
        robot_pose = age = gate = reason = None
        if self.link is not None:
            self.link.poll()
            robot_pose = self.link.robot_pose()
            age = self.link.report_age(t)
            if self.link.latest is not None:
                gate, reason = self.link.latest.gate, self.link.latest.reason
        out = self.session.tick(
            t, T, robot_pose, np.inf if age is None else age, fault, gate, reason
        )
        latency = None
        if self.link is not None:
            if out.command is not None:
                self.link.send_command(out.command)
            elif out.hold:
                self.link.send_hold()
        if t_arrival is not None and (out.command is not None or self.link is None):
            latency = time.perf_counter_ns() - t_arrival
        frame = FrameLog(t, q, T, out, latency)
        if self.keep_frames:
            self.frames.append(frame)
        return frame
