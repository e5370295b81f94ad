"""A simulated operator who traces several of the paper's shapes one after the other, in a
loop (the live viewer's operator).

Each shape is :func:`mocapkit.teleop.operator.operator_motion` (still in the N-pose, reach
to the working point, settle, the shape, hold), followed by a smooth return to the N-pose
(``return_s``), so the shapes chain without a jump and the whole cycle repeats: its last
frame leads into its first. The truth is the body model's own coordinates, as in the
evaluation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError
from mocapkit.series import PoseSeries
from mocapkit.teleop.operator import (
    SHAPES,
    OperatorMotion,
    motion_from_coordinates,
    npose_coordinates,
    operator_motion,
)


@dataclass(frozen=True)
class ShapeSpan:
    """One shape of the cycle; times from the start of the cycle [s].

    Attributes:
        shape: the shape's name.
        calib_window: (t0, t1) still in the N-pose (a good calibration window).
        engage_t: the hand is still at the working point (a good instant to engage).
        t_start, t_end: the shape itself.
    """

    shape: str
    calib_window: tuple[float, float]
    engage_t: float
    t_start: float
    t_end: float


@dataclass(frozen=True)
class OperatorCycle:
    """One period of the operator's motion and where each shape is in it.

    Attributes:
        motion: the period (its ``calib_window``, ``engage_t`` and shape span are the
            first shape's).
        spans: the shapes, in order.
    """

    motion: OperatorMotion
    spans: tuple[ShapeSpan, ...]

    @property
    def period_s(self) -> float:
        """Duration of one cycle [s] (time of the frame after the last)."""
        t = self.motion.time
        return float(t[-1] + (t[1] - t[0]))

    def span_at(self, t: float) -> ShapeSpan | None:
        """The shape being traced at time ``t`` [s] (any cycle), or None."""
        tc = t % self.period_s
        return next((s for s in self.spans if s.t_start <= tc <= s.t_end), None)


def _smooth(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2)


def operator_cycle(
    shapes: tuple[str, ...] = SHAPES,
    tree: SensorTree | None = None,
    rate_hz: float = 100.0,
    shape_s: float = 6.0,
    return_s: float = 2.0,
    heading_rad: float = 0.0,
    size_m: float = 0.10,
) -> OperatorCycle:
    """The cycle (see the module docstring).

    Raises:
        ConfigError: no shape or an unknown one, or a non-positive duration.
    """
    unknown = [s for s in shapes if s not in SHAPES]
    if unknown or not shapes:
        raise ConfigError(f"shapes: expected some of {', '.join(SHAPES)}, got {list(shapes)}")
    if not (rate_hz > 0 and shape_s > 0 and return_s > 0):
        raise ConfigError(
            f"rate_hz, shape_s and return_s: expected positive numbers, got {rate_hz}, "
            f"{shape_s}, {return_s}"
        )
    tree = tree or SensorTree.preset("right_arm_2")
    rest = npose_coordinates(tree)
    n_ret = round(return_s * rate_hz)
    u = _smooth(np.arange(1, n_ret + 1) / n_ret)[:, None]
    parts = []
    spans = []
    t0 = 0.0
    for shape in shapes:
        m = operator_motion(
            shape, tree, rate_hz, shape_s=shape_s, size_m=size_m, heading_rad=heading_rad
        )
        q = m.coordinates.values
        parts.append(np.vstack([q, q[-1] + u * (rest - q[-1])]))
        w0, w1 = m.calib_window
        spans.append(
            ShapeSpan(
                shape, (t0 + w0, t0 + w1), t0 + m.engage_t, t0 + m.shape_start, t0 + m.shape_end
            )
        )
        t0 += len(parts[-1]) / rate_hz
    values = np.vstack(parts)
    time = np.arange(len(values)) / rate_hz
    first = spans[0]
    motion = motion_from_coordinates(
        tree,
        time,
        values,
        heading_rad,
        first.calib_window,
        first.engage_t,
        (first.t_start, first.t_end),
    )
    return OperatorCycle(motion, tuple(spans))


def arm_sensor_poses(
    shapes: tuple[str, ...],
    rate_hz: float = 100.0,
    shape_s: float = 6.0,
    seed: int = 0,
    preset: str = "right_arm_torso_3",
) -> dict[str, PoseSeries]:
    """The sensors' true poses (``q_world_sensor``, position) over one cycle of the
    operator tracing ``shapes`` (by sensor name; mountings 5 deg off, drawn with ``seed``,
    10 cm down each segment: :func:`mocapkit.teleop.operator_suit.sensor_poses`): arm
    motion for testing orientation filters on body segments."""
    from mocapkit.teleop.operator_suit import sensor_poses

    cycle = operator_cycle(shapes, SensorTree.preset(preset), rate_hz, shape_s)
    return sensor_poses(cycle.motion, np.random.default_rng(seed))
