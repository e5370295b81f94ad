"""A small library of plausible synthetic body motions, to stream before a body model exists.

A motion is a kinematic tree of segments; each segment's pose origin is its proximal
joint, and its orientation is its parent's times a joint rotation that swings
sinusoidally. World: ENU, z up; the subject faces +y (north) and walks along it.
Outputs are :class:`~mocapkit.series.PoseSeries` per segment (``q_world_segment``,
``p_world_segment`` [m]); :func:`mount` turns a segment pose into a sensor pose.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_from_axis_angle, quat_identity, quat_mul, quat_rotate
from mocapkit.series import PoseSeries

# The 15 segments of a full-body suit, in sensor-ID order (IDs 1..15).
FULL_BODY_SEGMENTS: tuple[str, ...] = (
    "pelvis",
    "upper_arm_r",
    "forearm_r",
    "hand_r",
    "upper_arm_l",
    "forearm_l",
    "hand_l",
    "thigh_r",
    "shank_r",
    "foot_r",
    "thigh_l",
    "shank_l",
    "foot_l",
    "chest",
    "head",
)
MOTIONS = ("wave", "walk", "static")


@dataclass(frozen=True)
class _Joint:
    """Segment ``name`` hangs from ``parent`` at ``offset`` (parent frame, [m]) and rotates
    about ``axis`` by ``bias + amp sin(2 pi freq t + phase)`` [rad]."""

    name: str
    parent: str | None
    offset: tuple[float, float, float]
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    amp: float = 0.0
    freq: float = 0.0
    phase: float = 0.0
    bias: float = 0.0


def _skeleton(motion: str) -> list[_Joint]:
    wave = motion == "wave"
    walk = motion == "walk"
    f = 1.0 if walk else 0.5  # gait cycle / wave frequency [Hz]
    leg = 0.45 if walk else 0.0
    knee = 0.5 if walk else 0.0
    arm = 0.3 if walk else 0.0
    pi = np.pi
    return [
        _Joint("pelvis", None, (0.0, 0.0, 0.95), (0, 0, 1), 0.08 if walk else 0.0, f),
        _Joint("chest", "pelvis", (0.0, 0.0, 0.25), (0, 0, 1), -0.1 if walk else 0.0, f),
        _Joint("head", "chest", (0.0, 0.0, 0.3), (1, 0, 0), 0.1 if wave else 0.0, 0.3),
        # right arm: waving = abduction up to ~100 deg and an elbow swing
        _Joint(
            "upper_arm_r",
            "chest",
            (0.18, 0.0, 0.2),
            (0, 1, 0),
            0.4 if wave else arm,
            f,
            0.0,
            -1.3 if wave else 0.0,
        ),
        _Joint(
            "forearm_r",
            "upper_arm_r",
            (0.0, 0.0, -0.28),
            (1, 0, 0),
            0.6 if wave else 0.15,
            2 * f if wave else f,
            0.0,
            0.8 if wave else 0.2,
        ),
        _Joint("hand_r", "forearm_r", (0.0, 0.0, -0.25), (0, 1, 0), 0.3 if wave else 0.0, 2 * f),
        _Joint("upper_arm_l", "chest", (-0.18, 0.0, 0.2), (1, 0, 0), arm, f, pi),
        _Joint("forearm_l", "upper_arm_l", (0.0, 0.0, -0.28), (1, 0, 0), 0.15, f, pi, 0.2),
        _Joint("hand_l", "forearm_l", (0.0, 0.0, -0.25), (0, 1, 0), 0.0, f),
        _Joint("thigh_r", "pelvis", (0.1, 0.0, -0.05), (1, 0, 0), leg, f, pi),
        _Joint("shank_r", "thigh_r", (0.0, 0.0, -0.42), (1, 0, 0), knee, f, pi - 1.2, -knee),
        _Joint("foot_r", "shank_r", (0.0, 0.0, -0.4), (1, 0, 0), 0.2 if walk else 0.0, f, pi),
        _Joint("thigh_l", "pelvis", (-0.1, 0.0, -0.05), (1, 0, 0), leg, f),
        _Joint("shank_l", "thigh_l", (0.0, 0.0, -0.42), (1, 0, 0), knee, f, -1.2, -knee),
        _Joint("foot_l", "shank_l", (0.0, 0.0, -0.4), (1, 0, 0), 0.2 if walk else 0.0, f),
    ]


def body_motion(motion: str, duration_s: float, rate_hz: float) -> dict[str, PoseSeries]:
    """Segment poses of a named motion: ``"wave"`` (right arm waving, body still),
    ``"walk"`` (walking-like limb swings, pelvis moving forward at 1.2 m/s with a
    vertical bob) or ``"static"`` (standing still)."""
    if motion not in MOTIONS:
        raise ConfigError(f"motion: unknown {motion!r}; choose one of {', '.join(MOTIONS)}")
    if not (duration_s > 0 and rate_hz > 0):
        raise ConfigError(
            f"duration_s and rate_hz: expected > 0, got {duration_s} s at {rate_hz} Hz"
        )
    n = max(3, round(duration_s * rate_hz) + 1)
    t = np.arange(n) / rate_hz
    q_world: dict[str, FloatArray] = {}
    p_world: dict[str, FloatArray] = {}
    for j in _skeleton(motion):
        angle = j.bias + j.amp * np.sin(2 * np.pi * j.freq * t + j.phase)
        q_local = quat_from_axis_angle(np.array(j.axis, dtype=np.float64), angle)
        if j.parent is None:
            pos = np.tile(np.array(j.offset), (n, 1))
            if motion == "walk":
                pos[:, 1] += 1.2 * t
                pos[:, 2] += 0.02 * np.sin(4 * np.pi * j.freq * t)
            q_world[j.name] = quat_mul(quat_identity(n), q_local)
            p_world[j.name] = pos
        else:
            qp = q_world[j.parent]
            p_world[j.name] = p_world[j.parent] + quat_rotate(qp, np.array(j.offset))
            q_world[j.name] = quat_mul(qp, q_local)
    return {name: PoseSeries(t, q_world[name], p_world[name], name=name) for name in q_world}


def mount(
    segment: PoseSeries,
    q_segment_sensor: object = (1.0, 0.0, 0.0, 0.0),
    p_segment_sensor: object = (0.0, 0.0, 0.0),
    name: str | None = None,
) -> PoseSeries:
    """Pose of a sensor fixed on a segment.

    ``T_world_sensor = T_world_segment T_segment_sensor`` (quaternion [w, x, y, z], metres).
    """
    q_ss = np.asarray(q_segment_sensor, dtype=np.float64)
    p_ss = np.asarray(p_segment_sensor, dtype=np.float64)
    q = quat_mul(segment.quat, q_ss)
    p = segment.pos + quat_rotate(segment.quat, p_ss)
    return PoseSeries(segment.time, q, p, name=name or segment.name)


def suit_poses(
    motion: str, n_sensors: int, duration_s: float, rate_hz: float
) -> dict[int, PoseSeries]:
    """Sensor poses for IDs 1..n_sensors on the first n segments of :data:`FULL_BODY_SEGMENTS`.

    Each sensor sits 5 cm off its segment's axis, turned 90 deg about the segment's
    long axis, so mounting and segment frames differ (as on a real suit).
    """
    if not 1 <= n_sensors <= len(FULL_BODY_SEGMENTS):
        raise ConfigError(f"n_sensors: expected 1..{len(FULL_BODY_SEGMENTS)}, got {n_sensors}")
    segments = body_motion(motion, duration_s, rate_hz)
    q_mount = quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), np.pi / 2)
    out = {}
    for sid, seg in enumerate(FULL_BODY_SEGMENTS[:n_sensors], start=1):
        out[sid] = mount(segments[seg], q_mount, (0.0, 0.05, -0.1), name=f"{sid}:{seg}")
    return out
