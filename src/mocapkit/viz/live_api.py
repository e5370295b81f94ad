"""What the live viewer needs from a teleoperation session: a small protocol and a snapshot.

Any object with these methods can be shown by :class:`mocapkit.viz.viewer.TeleopViewer`:

``calibrate()``, ``engage()``, ``disengage()``, ``reindex()``
    operator commands; each returns a short human-readable message and raises a
    :class:`~mocapkit.errors.MocapkitError` when it cannot be done (the viewer shows the
    message);
``snapshot() -> LiveSnapshot``
    a consistent copy of the session's latest state, cheap enough to call at 30 Hz.

Frames: positions in metres in the viewer's world (z up); the human skeleton and the
sensor frames in the body's world, the robot in its own chest frame (the viewer places
the chest frame with ``robot_origin``). Quaternions ``[w, x, y, z]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

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

    def calibrate(self) -> str: ...

    def engage(self) -> str: ...

    def disengage(self) -> str: ...

    def reindex(self) -> str: ...

    def snapshot(self) -> LiveSnapshot: ...


def percentile_or_nan(values: FloatArray, q: float) -> float:
    """``np.percentile`` that returns NaN for an empty array."""
    return float(np.percentile(values, q)) if len(values) else float("nan")
