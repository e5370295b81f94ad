"""Drawing geometry: a skeleton from segment orientations, a robot arm from its joints.

No viewer import here: these are plain arrays, tested alone.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.segment_points import segment_points
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.robot.model import ArmModel
from mocapkit.viz.live_api import SegmentPose


def skeleton_segments(
    tree: SensorTree,
    q_world_segment: Any,
    q_world_ground: Any,
    root_position: Any = (0.0, 0.0, 0.0),
) -> tuple[SegmentPose, ...]:
    """Segment start and end points from orientations and the tree's offsets
    (:func:`mocapkit.body.segment_points.segment_points`). Segments with a NaN orientation
    (a lost sensor) and their children are left out.

    Args:
        tree: the sensor tree (``offset`` and ``end`` [m] per segment).
        q_world_segment: (S, 4) in ``tree.segment_names`` order.
        q_world_ground: (4,) the ground frame in the world.
        root_position: (3,) [m] where the ground origin is drawn.
    """
    q = np.asarray(q_world_segment, dtype=float)
    start, end = segment_points(tree, q, q_world_ground, root_position)
    return tuple(
        SegmentPose(seg.name, start[i], end[i], q[i].copy())
        for i, seg in enumerate(tree.segments)
        if np.isfinite(start[i]).all() and np.isfinite(end[i]).all()
    )


def arm_frames(arm: ArmModel) -> tuple[str, ...]:
    """The frames drawn for an arm: the base, every joint, and the end effector."""
    return ("__base__", *arm.joint_names, arm.ee_frame)


def arm_points(arm: ArmModel, q: Any, frames: Sequence[str] | None = None) -> FloatArray:
    """Positions (K, 3) [m] of the arm's drawn frames in its base (chest) frame, at q (n,)
    [rad]: the base origin, each joint origin, the end effector (a polyline of the links)."""
    names = arm_frames(arm) if frames is None else tuple(frames)
    qa = arm.check_q(q)
    pts = np.empty((len(names), 3))
    for k, name in enumerate(names):
        pts[k] = np.zeros(3) if name == "__base__" else arm.frame_pose(qa, name)[:3, 3]
    return pts


def polyline_segments(points: Any) -> FloatArray:
    """(K, 3) points -> (K-1, 2, 3) consecutive segments (the viewer's line format)."""
    p = np.asarray(points, dtype=float)
    return np.stack([p[:-1], p[1:]], axis=1)


def transform_points(T: Any, points: Any) -> FloatArray:
    """Apply a (4, 4) pose to (K, 3) points."""
    Ta = np.asarray(T, dtype=float)
    p = np.asarray(points, dtype=float)
    return p @ Ta[:3, :3].T + Ta[:3, 3]
