"""A live teleoperation session: suit stream in, robot commands out, operator controls.

:class:`LiveSession` wires the suit receiver (UDP), the per-packet pipeline
(:class:`~mocapkit.teleop.pipeline.TeleopPipeline`), the robot link and an optional
recorder. The pipeline runs on the receiver's thread (its direct consumer, ``on_batch``):
a packet is read, decoded, fused, turned into a command and sent without waking another
thread, and every 5 ms at least the watchdogs run even when nothing arrives.

The operator API is thread-safe (a web viewer, a control socket or the keyboard may call
it from their own threads): :meth:`LiveSession.calibrate`, :meth:`engage`,
:meth:`disengage`, :meth:`reindex`, :meth:`clutch` queue a command that the receiver
thread applies before its next batch (within 5 ms); :meth:`snapshot` returns the status
(state, latency, packet loss, safety, joint angles, end effector commanded and actual)
published by that thread 20 times a second.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.body.calibration import BodyCalibration, CalibrationError
from mocapkit.body.segment_points import segment_points
from mocapkit.errors import ConfigError, MocapkitError
from mocapkit.robot.registry import available_robots
from mocapkit.suit.receiver import Receiver
from mocapkit.suit.receiver_state import ReceiverConfig
from mocapkit.suit.samples import SuitSample
from mocapkit.suit.transport import UdpTransport
from mocapkit.teleop import _kernels
from mocapkit.teleop import protocol as proto
from mocapkit.teleop.humanoid_session import HumanoidSession
from mocapkit.teleop.link import RobotLink
from mocapkit.teleop.pipeline import Frame, PipelineConfig, TeleopPipeline
from mocapkit.teleop.recording import TeleopRecorder
from mocapkit.teleop.session import SessionConfig, TeleopSession, Transition

log = logging.getLogger("mocapkit.teleop.live")

_SNAPSHOT_PERIOD_S = 0.05


@dataclass(frozen=True)
class LiveConfig:
    """A live session's settings.

    Attributes:
        pipeline: what runs per packet (tree, fusion, retargeting, robot).
        session: the state machine's thresholds and limits.
        suit_host, suit_port: where the suit's UDP stream arrives (port 0: any free port).
        receiver: the suit receiver's settings.
        calibrate_s: how long the operator holds the calibration pose [s].
        robot_key: shared key of a signed robot link (the server's ``--key-file``), or
            None on loopback.
    """

    pipeline: PipelineConfig = field(default_factory=PipelineConfig)
    session: SessionConfig = field(default_factory=SessionConfig)
    suit_host: str = "127.0.0.1"
    suit_port: int = 0
    receiver: ReceiverConfig = field(default_factory=ReceiverConfig)
    calibrate_s: float = 1.0
    robot_key: bytes | None = None


class _Pending:
    """A queued operator command and its outcome."""

    def __init__(self, name: str, args: tuple[Any, ...]) -> None:
        self.name = name
        self.args = args
        self.done = threading.Event()
        self.result: Any = None
        self.error: str | None = None

    def finish(self, result: Any = None, error: str | None = None) -> None:
        self.result, self.error = result, error
        self.done.set()


def _pose_lists(T: Any) -> tuple[list[float], list[float]]:
    """(position [m], quaternion [w, x, y, z]) of a 4x4 pose, as lists."""
    q = np.empty(4)
    _kernels.mat_to_quat(T, q)
    return [float(T[0, 3]), float(T[1, 3]), float(T[2, 3])], [float(v) for v in q]


def _transitions(trs: list[Transition]) -> list[dict[str, Any]]:
    return [
        {"t": tr.t, "from": tr.source.value, "to": tr.target.value, "reason": tr.reason}
        for tr in trs
    ]


def _pose_dict(T: Any) -> dict[str, list[float]] | None:
    if T is None:
        return None
    pos, quat = _pose_lists(np.asarray(T, dtype=np.float64))
    return {"pos": pos, "quat": quat}


class LiveSession:
    """See the module docstring.

    Args:
        config: :class:`LiveConfig`.
        robot_address: the robot server's ``(host, port)``.
        record: an MCAP file to record the session to (None: no recording).
        keep_frames: keep every processed frame and robot report in memory (evaluation).
        make_link: builds another robot link for the pipeline (its robot's joints, arm or
            humanoid) instead of the UDP client of ``robot_address``
            (:class:`~mocapkit.teleop.ros2_link.Ros2RobotLink`).
    """

    def __init__(
        self,
        config: LiveConfig,
        robot_address: tuple[str, int] | None,
        record: str | Path | None = None,
        keep_frames: bool = False,
        make_link: Callable[[TeleopPipeline], Any] | None = None,
    ) -> None:
        self.config = config
        humanoid = config.pipeline.robot not in available_robots()
        self.session = (
            HumanoidSession(config.session) if humanoid else TeleopSession(config.session)
        )
        self.pipeline = TeleopPipeline(config.pipeline, self.session, None)
        if make_link is not None:  # another robot link (ROS 2), made for this pipeline's robot
            self.link = make_link(self.pipeline)
            self.link.on_report = self._on_report
        elif robot_address is None:
            raise ConfigError("live session: give the robot server's address or a link")
        else:
            self.link = RobotLink(robot_address, on_report=self._on_report,
                                  key=config.robot_key)  # fmt: skip
        self.pipeline.link = self.link
        self.pipeline.keep_frames = keep_frames
        self.pipeline.on_frame = self._on_frame
        self.keep_frames = keep_frames
        self.reports: list[tuple[float, proto.Report]] = []
        self.recorder = TeleopRecorder(record, threaded=True) if record is not None else None
        self._commands: queue.SimpleQueue[_Pending] = queue.SimpleQueue()
        self._transport: UdpTransport | None = None
        self.receiver: Receiver | None = None
        self._snap: dict[str, Any] = {"state": "stopped"}
        self._snap_t = -math.inf
        self._n_transitions = 0
        self._calibration_state = "none"
        self._recent_latency: deque[float] = deque(maxlen=1000)
        self._last_command: Any = None
        self._message = ""
        self.frame_listeners: list[Callable[[Frame], None]] = []
        # called with every batch of suit samples once the pipeline has taken it (raw
        # samples to LSL: after the commands, never before them)
        self.batch_listeners: list[Callable[[list[SuitSample]], object]] = []
        """Called with every processed frame on the receiver's thread (keep them short:
        e.g. an LSL outlet's push)."""
        self.sample_filter: Callable[[list[SuitSample]], list[SuitSample]] | None = None
        """Optional hook on each batch before the pipeline (fault injection in tests and
        the evaluation: e.g. NaN orientations)."""

    # -- lifecycle ----------------------------------------------------------------------------
    def start(self) -> LiveSession:
        """Bind the suit port and start receiving (returns self)."""
        c = self.config
        self._transport = UdpTransport.bind(c.suit_host, c.suit_port)
        self.receiver = Receiver(self._transport, c.receiver, on_batch=self._on_batch)
        self.link.send_hold()  # the server reports to whoever spoke last: introduce us
        self.receiver.start()
        log.info("live session: suit on %s, robot at %s", self._transport.name, self.link.address)
        return self

    @property
    def suit_port(self) -> int:
        if self._transport is None:
            raise ConfigError("live session: not started")
        return self._transport.port

    def stop(self) -> None:
        """Stop receiving, hold the robot, close the recording and the sockets."""
        if self.receiver is not None:
            self.receiver.stop()
        try:
            self.link.send_hold()
        finally:
            self.link.close()
            if self._transport is not None:
                self._transport.close()
            if self.recorder is not None:
                self.recorder.close()
                self.recorder = None

    def __enter__(self) -> LiveSession:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- operator API (any thread) ------------------------------------------------------------
    def _submit(self, name: str, *args: Any, wait: bool = True, timeout_s: float = 2.0) -> Any:
        p = _Pending(name, args)
        self._commands.put(p)
        if not wait:
            return None
        if not p.done.wait(timeout_s):
            raise MocapkitError(
                f"{name}: the session did not answer within {timeout_s:.1f} s; is it started?"
            )
        return p

    def calibrate(
        self, duration_s: float | None = None, wait: bool = True, timeout_s: float | None = None
    ) -> BodyCalibration | None:
        """The operator holds the calibration pose (N-pose) for ``duration_s``: calibrate the
        body model. With ``wait`` it returns the calibration or raises
        :class:`~mocapkit.body.calibration.CalibrationError` saying why."""
        d = self.config.calibrate_s if duration_s is None else float(duration_s)
        if not d > 0:
            raise ConfigError(f"duration_s: expected a positive duration, got {d}")
        p = self._submit("calibrate", d, wait=wait, timeout_s=timeout_s or d + 3.0)
        if p is None:
            return None
        if not p.done.wait(timeout_s or d + 3.0):
            raise MocapkitError("calibrate: no result; is the suit streaming?")
        if p.error is not None:
            raise CalibrationError(p.error)
        result: BodyCalibration = p.result
        return result

    def _command(self, name: str, *args: Any) -> str:
        p = self._submit(name, *args)
        if p.error is not None:
            raise MocapkitError(p.error)
        result: str = p.result
        return result

    def engage(self) -> str:
        """Start following the operator (reindexing first in relative mode); returns a
        message (``engage: aligning``). Raises :class:`MocapkitError` before a calibration."""
        return self._command("engage")

    def disengage(self) -> str:
        """Stop following: the robot holds; returns a message."""
        return self._command("disengage")

    def reindex(self) -> str:
        """Take a new offset between the operator and the robot (Fig. 10), any time."""
        return self._command("reindex")

    def clutch(self, pressed: bool) -> str:
        """Pressed: the robot holds while the operator moves; released: reindex, follow."""
        return self._command("clutch", bool(pressed))

    def snapshot(self) -> dict[str, Any]:
        """The session's status (see the module docstring); plain JSON-ready values."""
        snap = dict(self._snap)
        # these change on operator commands: current values, not the last publication
        snap["state"] = self.session.state.value if self.receiver is not None else "stopped"
        snap["calibration"] = self._calibration_state
        snap["calibrated"] = self.pipeline.body is not None
        snap["message"] = self._message
        snap["transitions"] = _transitions(self.session.transitions[-10:])
        if self.receiver is not None:
            st = self.receiver.stats()
            names = {v: k for k, v in self.pipeline.sensor_ids.items()}
            quats = snap.pop("sensor_orientations", None) or {}
            seg_of = {seg.sensor: seg.name for seg in self.pipeline.tree.segments}
            sensors = {}
            for sid, s in st.sensors.items():
                name = names.get(sid, str(sid))
                sensors[name] = {
                    "id": sid,
                    "state": s.state,
                    "rate_hz": s.rate_hz,
                    "delivered": s.delivered,
                    "lost": s.lost,
                    "loss": s.loss_ratio,
                    "segment": seg_of.get(name),
                    "quat": quats.get(name),
                }
            snap["sensors"] = sensors
            total = sum(s.delivered + s.lost for s in st.sensors.values())
            snap["packet_loss"] = sum(s.lost for s in st.sensors.values()) / total if total else 0.0
            snap["dropped"] = dict(st.dropped)
        return snap

    # -- receiver thread ----------------------------------------------------------------------
    def _apply(self, p: _Pending) -> None:
        now = time.monotonic()
        s = self.session
        try:
            if p.name == "calibrate":
                self._calibration_state = "collecting"
                self._message = f"calibrate: hold the {self.config.pipeline.pose} pose"

                def done(calib: BodyCalibration | None, error: str | None) -> None:
                    self._calibration_state = "done" if error is None else f"failed: {error}"
                    self._message = (
                        f"calibrate failed: {error}"
                        if calib is None
                        else f"calibrated (heading {math.degrees(calib.heading_rad):.1f} deg)"
                    )
                    p.finish(calib, error)

                self.pipeline.start_calibration(now, p.args[0], done)
                return  # finished when the window is full
            if p.name == "engage":
                if self.pipeline.body is None:
                    raise ConfigError(
                        "engage: calibrate first (the operator holds the "
                        f"{self.config.pipeline.pose} pose, then calibrate)"
                    )
                s.engage(now)
            elif p.name == "disengage":
                s.disable(now)
            elif p.name == "reindex":
                s.reindex(now)
            elif p.name == "clutch":
                s.clutch(p.args[0], now)
            else:  # pragma: no cover (the API only queues known names)
                raise ConfigError(f"unknown command {p.name!r}")
            self._message = f"{p.name}: {s.state.value}"
            p.finish(self._message)
        except MocapkitError as exc:
            self._message = f"{p.name} failed: {exc}"
            p.finish(error=str(exc))

    def _on_batch(self, samples: list[SuitSample], now_ns: int) -> None:
        while not self._commands.empty():
            self._apply(self._commands.get_nowait())
        if self.sample_filter is not None and samples:
            samples = self.sample_filter(samples)
        self.pipeline.process(samples, now_ns)
        for listener in self.batch_listeners:
            listener(samples)
        now = time.monotonic()
        if now - self._snap_t >= _SNAPSHOT_PERIOD_S:
            self._snap_t = now
            self._publish(now)

    def _on_frame(self, frame: Frame) -> None:
        for listener in self.frame_listeners:
            listener(frame)
        if frame.latency_ns is not None:
            self._recent_latency.append(frame.latency_ns / 1e6)
        if frame.command is not None:
            self._last_command = frame.command
        rec = self.recorder
        if rec is not None and frame.command is not None:
            pos, quat = _pose_lists(frame.command)
            rec.command(frame.t, pos, quat)
        if rec is not None and frame.angles is not None and frame.q_robot is not None:
            names = [*self.pipeline.tree.coordinate_names, *self.pipeline.robot_joint_names]
            rec.joints(frame.t, names, np.concatenate([frame.angles, frame.q_robot]))
        self._record_transitions()

    def _record_transitions(self) -> None:
        trs = self.session.transitions
        if len(trs) == self._n_transitions:
            return
        new: list[Transition] = trs[self._n_transitions :]
        self._n_transitions = len(trs)
        if self.recorder is not None:
            for tr in new:
                self.recorder.transition(tr.t, tr.source.value, tr.target.value, tr.reason)

    def _on_report(self, t: float, r: proto.Report) -> None:
        if self.keep_frames:
            self.reports.append((t, r))
        if self.recorder is not None:
            self.recorder.report(t, r.pos, r.quat, r.gate.name, r.reason.name, r.q)

    def _publish(self, now: float) -> None:
        p = self.pipeline
        lat = np.fromiter(self._recent_latency, dtype=np.float64)
        latest = self.link.latest
        trs = self.session.transitions[-10:]
        angles = p.angles
        q_robot = p.q_robot
        self._snap = {
            "t": now,
            "state": self.session.state.value,
            "calibration": self._calibration_state,
            "fault": p.last_fault,
            "transitions": _transitions(trs),
            "latency_ms": {
                "p50": float(np.percentile(lat, 50)) if lat.size else None,
                "p99": float(np.percentile(lat, 99)) if lat.size else None,
                "n": int(p.n_latencies),
            },
            "safety": {
                "robot_gate": None if latest is None else latest.gate.name,
                "robot_reason": None if latest is None else latest.reason.name,
                "robot_report_age_s": float(self.link.report_age(now)),
                "clipped_joints": list(p.clipped),
                "session_fault": self.session.fault,
            },
            "joints_deg": None
            if angles is None
            else {
                n: float(np.degrees(v))
                for n, v in zip(p.tree.coordinate_names, angles, strict=True)
            },
            "robot_joints_deg": None
            if q_robot is None
            else {
                n: float(np.degrees(v)) for n, v in zip(p.robot_joint_names, q_robot, strict=True)
            },
            "ee_commanded": _pose_dict(self._last_command),
            "ee_actual": _pose_dict(self.link.robot_pose()),
            "robot_name": self.config.pipeline.robot,
            "segments": self._segments(),
            "sensor_orientations": {
                name: [float(v) for v in q] if np.isfinite(q).all() else None
                for name, q in zip(p.tree.sensor_names, p.q_sensor, strict=True)
            },
        }

    def _segments(self) -> list[dict[str, Any]]:
        """The body model's segments for drawing: joint and end points [m] and
        ``q_world_segment`` (the ground origin at the world origin); lost ones left out."""
        p = self.pipeline
        if p.body is None or p.calibration is None:
            return []
        q = p.body.q_world_segment
        start, end = segment_points(p.tree, q, p.calibration.q_world_ground)
        return [
            {"name": name, "start": start[i].tolist(), "end": end[i].tolist(),
             "quat": q[i].tolist()}
            for i, name in enumerate(p.tree.segment_names)
            if np.isfinite(start[i]).all() and np.isfinite(end[i]).all()
        ]  # fmt: skip
