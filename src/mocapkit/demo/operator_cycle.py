"""A simulated operator who traces the paper's shapes one after the other, for ever.

Each shape is :func:`mocapkit.teleop.arm_operator.operator_motion` (rest in the suit's
initialisation posture, reach, trace, hold) followed by a smooth return to the
initialisation posture, so shapes chain without a jump and the whole cycle repeats.
The operator's chest frame is the simulation's world (x forward, y left, z up: ENU with
the operator facing east, magnetic north +y).

Three suit sensors (IDs as the suit numbers them): 1 on the upper arm, 2 on the
forearm, 3 on the chest (the root sensor of the paper's section 6), each with its own
mounting rotation (unknown to the pipeline: the body calibration estimates it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_from_matrix, quat_mul, quat_normalize
from mocapkit.series import PoseSeries
from mocapkit.teleop.arm_operator import INIT_POSTURE, SHAPES, human_right_arm, operator_motion

#: suit sensor ID -> (sensor name in the body tree, segment, human-arm frame or None)
SENSORS: dict[int, tuple[str, str, str | None]] = {
    1: ("upper_arm_r", "humerus_r", "arm_rot_r"),
    2: ("forearm_r", "radius_r", "pro_sup_r"),
    3: ("torso", "torso", None),
}
#: the body tree the sensors belong to (``SensorTree.preset``)
TREE = "right_arm_torso_3"
#: human coordinates of the simulated arm that the body model also reports
COMPARED_COORDS = ("arm_flex_r", "arm_add_r", "arm_rot_r", "elbow_flex_r", "pro_sup_r")


@dataclass(frozen=True)
class ShapeSpan:
    shape: str
    t_start: float  # the shape begins [s]
    t_end: float  # the shape ends [s]
    t_engage: float  # a good instant to engage (the hand at the working point) [s]


@dataclass(frozen=True)
class OperatorCycle:
    """The operator's truth: human joint angles and sensor poses on one time base."""

    time: FloatArray  # (N,) [s]
    coords: tuple[str, ...]  # human coordinate names (OpenSim)
    q_human: FloatArray  # (N, 7) [rad]
    sensor_poses: dict[int, PoseSeries]  # suit ID -> q_world_sensor, p_world_sensor
    q_segments: dict[str, FloatArray]  # segment -> (N, 4) q_world_segment (truth)
    spans: tuple[ShapeSpan, ...]
    period_s: float  # one pass over the shapes [s]

    @property
    def rate_hz(self) -> float:
        return 1.0 / float(self.time[1] - self.time[0])

    def span_at(self, t: float) -> ShapeSpan | None:
        for s in self.spans:
            if s.t_start <= t <= s.t_end:
                return s
        return None


def _smooth(u: FloatArray) -> FloatArray:
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2)


def _mountings(rng: np.random.Generator) -> dict[int, FloatArray]:
    """A random mounting rotation ``q_segment_sensor`` per sensor (within 60 deg of a
    strap-on pose: sensors sit on the segment's side, but not squarely)."""
    out = {}
    for sid in SENSORS:
        v = rng.normal(size=3)
        v *= rng.uniform(0.3, 1.0) / np.linalg.norm(v)
        out[sid] = quat_normalize(np.concatenate([[1.0], 0.5 * v]))
    return out


def operator_cycle(
    shapes: tuple[str, ...] = SHAPES,
    rate_hz: float = 100.0,
    shape_s: float = 6.0,
    return_s: float = 2.0,
    repeat_until_s: float | None = None,
    seed: int = 0,
) -> OperatorCycle:
    """The motion (see the module docstring), repeated until ``repeat_until_s`` if given.

    Raises:
        ConfigError: an unknown shape, or non-positive durations.
    """
    unknown = [s for s in shapes if s not in SHAPES]
    if unknown or not shapes:
        raise ConfigError(f"shapes: expected some of {', '.join(SHAPES)}, got {list(shapes)}")
    if not (rate_hz > 0 and shape_s > 0 and return_s > 0):
        raise ConfigError("rate_hz, shape_s and return_s must be positive")
    parts: list[FloatArray] = []
    spans: list[ShapeSpan] = []
    t0 = 0.0
    n_ret = round(return_s * rate_hz)
    coords: tuple[str, ...] = ()
    for shape in shapes:
        m = operator_motion(shape, rate_hz=rate_hz, shape_s=shape_s)
        coords = m.joints.names
        q = np.asarray(m.joints.values)
        u = _smooth(np.arange(1, n_ret + 1) / n_ret)[:, None]
        back = q[-1] + u * (INIT_POSTURE - q[-1])
        parts.append(np.vstack([q, back]))
        spans.append(
            ShapeSpan(shape, t0 + m.shape_start, t0 + m.shape_end, t0 + m.shape_start - 0.5)
        )
        t0 += (len(q) + n_ret) / rate_hz
    one = np.vstack(parts)
    period = len(one) / rate_hz
    reps = 1 if repeat_until_s is None else max(1, int(np.ceil(repeat_until_s / period)))
    q_all = np.tile(one, (reps, 1))
    spans_all = [
        ShapeSpan(s.shape, s.t_start + k * period, s.t_end + k * period, s.t_engage + k * period)
        for k in range(reps)
        for s in spans
    ]
    time = np.arange(len(q_all)) / rate_hz
    # the motion is periodic: compute one period's poses and repeat them
    poses1, segs1 = _sensor_poses(time[: len(one)], one, np.random.default_rng(seed))
    poses = {
        sid: PoseSeries(time, np.tile(p.quat, (reps, 1)), np.tile(p.pos, (reps, 1)), name=p.name)
        for sid, p in poses1.items()
    }
    segments = {s: np.tile(q, (reps, 1)) for s, q in segs1.items()}
    return OperatorCycle(time, coords, q_all, poses, segments, tuple(spans_all), period)


def _sensor_poses(
    time: FloatArray, q_human: FloatArray, rng: np.random.Generator
) -> tuple[dict[int, PoseSeries], dict[str, FloatArray]]:
    """Sensor poses in the world (the arm sensors 15 cm down their segment, the chest
    sensor fixed on the sternum; each turned by its mounting) and the segments'
    orientations (the segment frames of the human arm model; the chest = the world)."""
    arm = human_right_arm()
    mounts = _mountings(rng)
    n = len(time)
    out: dict[int, PoseSeries] = {}
    segments: dict[str, FloatArray] = {}
    for sid, (name, segment, frame) in SENSORS.items():
        if frame is None:
            R = np.tile(np.eye(3), (n, 1, 1))
            p = np.tile([0.10, 0.0, -0.10], (n, 1))
        else:
            T = np.stack([arm.frame_pose(qk, frame) for qk in q_human])
            R = T[:, :3, :3]
            p = T[:, :3, 3] + R @ np.array([0.0, 0.0, -0.15])
        segments[segment] = quat_from_matrix(R)
        out[sid] = PoseSeries(time, quat_mul(segments[segment], mounts[sid]), p, name=name)
    return out, segments
