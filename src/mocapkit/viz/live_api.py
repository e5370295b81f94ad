"""What the live viewer needs from a teleoperation session: a small protocol and a snapshot.

Any object with these methods can be shown by :class:`mocapkit.viz.viewer.TeleopViewer`:

``calibrate()``, ``engage()``, ``disengage()``, ``reindex()``
    operator commands; each may return a short human-readable message (anything else is
    shown as "done") and raises a :class:`~mocapkit.errors.MocapkitError` when it cannot
    be done (the viewer shows the message);
``snapshot() -> LiveSnapshot`` (or a mapping, see :meth:`LiveSnapshot.from_mapping`)
    a consistent copy of the session's latest state, cheap enough to call at 30 Hz.

Frames: positions in metres in the viewer's world (z up); the human skeleton and the
sensor frames in the body's world, the robot in its own chest frame (the viewer places
the chest frame with ``robot_origin``). Quaternions ``[w, x, y, z]``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from mocapkit._validate import FloatArray


@dataclass(frozen=True)
class SegmentPose:
    """One body segment for drawing: the proximal joint, the far end, the orientation."""

    name: str
    start: FloatArray  # (3,) [m] world
    end: FloatArray  # (3,) [m] world
    q_world_segment: FloatArray  # (4,)


@dataclass(frozen=True)
class SensorPose:
    """One sensor for drawing: where it is drawn and its estimated ``q_world_sensor``."""

    name: str
    position: FloatArray  # (3,) [m] world (on its segment)
    q_world_sensor: FloatArray  # (4,)


@dataclass(frozen=True)
class LiveSnapshot:
    """The session's state at one instant (see the module docstring).

    Attributes:
        t_s: session time since start [s].
        state: teleoperation state (``disabled``, ``aligning``, ``engaged``, ``clutched``,
            ``held``).
        safety: one line on the safety state (the session's fault, or the robot server's
            gate and reason).
        calibrated: whether the body calibration has been taken.
        latency_ms_p50, latency_ms_p99: host-side pipeline latency over the recent
            window (packet arrival to robot command sent) [ms]; NaN before any command.
        packet_loss: lost / (delivered + lost) packets over the session, 0..1.
        packets: packets delivered by the receiver.
        segments, sensors: the human skeleton and the sensor frames.
        robot_name: registry name of the robot arm (``mocapkit.robot.robot_arm``).
        robot_q: the robot's reported joint angles (n,) [rad], or None before a report.
        ee_command, ee_actual: commanded and reported end-effector poses (4, 4) in the
            robot's chest frame, or None.
        message: the latest operator-facing message (a failed calibration, a transition).
        transitions: the last few state transitions, oldest first.
    """

    t_s: float
    state: str
    safety: str
    calibrated: bool
    latency_ms_p50: float
    latency_ms_p99: float
    packet_loss: float
    packets: int
    segments: tuple[SegmentPose, ...] = ()
    sensors: tuple[SensorPose, ...] = ()
    robot_name: str = "robonaut2-right"
    robot_q: FloatArray | None = None
    ee_command: FloatArray | None = None
    ee_actual: FloatArray | None = None
    message: str = ""
    transitions: tuple[str, ...] = field(default_factory=tuple)

    @staticmethod
    def empty(robot_name: str = "robonaut2-right") -> LiveSnapshot:
        """The snapshot of a session that has not produced anything yet."""
        return LiveSnapshot(
            0.0,
            "disabled",
            "starting",
            False,
            float("nan"),
            float("nan"),
            0.0,
            0,
            robot_name=robot_name,
        )

    @staticmethod
    def from_mapping(d: Mapping[str, Any], robot_name: str = "robonaut2-right") -> LiveSnapshot:
        """A snapshot from a JSON-ready status mapping (the teleoperation package's live
        session publishes one): ``state``, ``fault``, ``safety`` (str or mapping),
        ``latency_ms`` ``{p50, p99}``, ``packet_loss``, ``sensors`` ``{name: {delivered}}``,
        ``robot_joints_deg`` ``{joint: deg}`` (in the arm's order), ``ee_commanded`` /
        ``ee_actual`` ``{pos, quat}``, ``transitions`` (str or ``{from, to, reason}``),
        optional ``segments`` ``[{name, start, end, quat}]``, ``calibrated``, ``message``,
        ``robot_name``; a sensor with ``quat`` and ``segment`` (a drawn one) is drawn at the
        middle of its segment."""
        from mocapkit.robot.model import pose_matrix

        safety = d.get("safety", "")
        if isinstance(safety, Mapping):
            parts = [str(safety["session_fault"])] if safety.get("session_fault") else []
            if safety.get("robot_gate"):
                reason = str(safety.get("robot_reason", "")).lower()
                parts.append(f"robot gate {str(safety['robot_gate']).lower()} ({reason})")
            safety = "; ".join(parts) or "ok"
        lat = d.get("latency_ms") or {}
        nan = float("nan")

        def num(v: Any) -> float:
            return nan if v is None else float(v)

        def pose(p: Any) -> FloatArray | None:
            return None if not p else pose_matrix(p["pos"], p["quat"])

        joints = d.get("robot_joints_deg")
        transitions = tuple(
            t if isinstance(t, str) else f"{t['from']} -> {t['to']}: {t['reason']}"
            for t in d.get("transitions", ())
        )
        segments = tuple(
            SegmentPose(s["name"], np.asarray(s["start"], float), np.asarray(s["end"], float),
                        np.asarray(s["quat"], float))
            for s in d.get("segments", ())
        )  # fmt: skip
        sensors = d.get("sensors") or {}
        middle = {s.name: 0.5 * (s.start + s.end) for s in segments}
        sensor_poses = tuple(
            SensorPose(name, middle[v["segment"]], np.asarray(v["quat"], float))
            for name, v in sensors.items()
            if v.get("quat") is not None and v.get("segment") in middle
        )
        calib = d.get("calibration")
        return LiveSnapshot(
            t_s=float(d.get("t", 0.0)),
            state=str(d.get("state", "unknown")),
            safety=str(safety),
            calibrated=bool(d.get("calibrated", calib == "done")),
            latency_ms_p50=num(lat.get("p50") if isinstance(lat, Mapping) else None),
            latency_ms_p99=num(lat.get("p99") if isinstance(lat, Mapping) else None),
            packet_loss=float(d.get("packet_loss", 0.0) or 0.0),
            packets=int(sum(int(v.get("delivered", 0)) for v in sensors.values())),
            segments=segments,
            sensors=sensor_poses,
            robot_name=str(d.get("robot_name", robot_name)),
            robot_q=None if joints is None else np.radians(np.array(list(joints.values()))),
            ee_command=pose(d.get("ee_commanded")),
            ee_actual=pose(d.get("ee_actual")),
            message=str(d.get("message") or d.get("fault") or ""),
            transitions=transitions,
        )

    def gauges(self) -> dict[str, float | str]:
        """The figures the viewer shows as gauges (units in the keys)."""
        return {
            "state": self.state,
            "safety": self.safety,
            "latency_ms_p50": float(self.latency_ms_p50),
            "latency_ms_p99": float(self.latency_ms_p99),
            "packet_loss_percent": float(100.0 * self.packet_loss),
            "packets": float(self.packets),
        }


@runtime_checkable
class LiveSession(Protocol):
    """A live teleoperation session the viewer can drive (see the module docstring)."""

    def calibrate(self) -> object: ...

    def engage(self) -> object: ...

    def disengage(self) -> object: ...

    def reindex(self) -> object: ...

    def snapshot(self) -> LiveSnapshot | Mapping[str, Any]: ...


def percentile_or_nan(values: FloatArray, q: float) -> float:
    """``np.percentile`` that returns NaN for an empty array."""
    return float(np.percentile(values, q)) if len(values) else float("nan")
