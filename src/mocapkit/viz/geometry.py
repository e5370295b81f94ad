"""Drawing geometry: a skeleton from segment orientations, a robot arm from its joints.

No viewer import here: these are plain arrays, tested alone.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.geometry import quat_rotate
from mocapkit.robot.model import ArmModel
from mocapkit.viz.live_api import SegmentPose


def skeleton_segments(
    tree: SensorTree,
    q_world_segment: Any,
    q_world_ground: Any,
    root_position: Any = (0.0, 0.0, 0.0),
) -> tuple[SegmentPose, ...]:
    """Segment start and end points from orientations and the tree's offsets.

    A root's joint sits at ``root_position + R_world_ground @ offset`` (the ground frame is
    OpenSim's y-up ground turned into the z-up world); a child's at
    ``start_parent + R_world_parent @ offset``; a segment ends at ``start + R_world_seg @
    end``. Segments with a NaN orientation (a lost sensor) and their children are left out.

    Args:
        tree: the sensor tree (``offset`` and ``end`` [m] per segment).
        q_world_segment: (S, 4) in ``tree.segment_names`` order.
        q_world_ground: (4,) the ground frame in the world.
        root_position: (3,) [m] where the ground origin is drawn.
    """
    q = np.asarray(q_world_segment, dtype=float)
    qg = np.asarray(q_world_ground, dtype=float)
    origin = np.asarray(root_position, dtype=float)
    starts: dict[str, FloatArray] = {}
    out = []
    for i, seg in enumerate(tree.segments):
        if not np.isfinite(q[i]).all():
            continue
        if seg.parent == "ground":
            start = origin + quat_rotate(qg, seg.offset)
        elif seg.parent in starts:
            parent_i = tree.segment_names.index(seg.parent)
            start = starts[seg.parent] + quat_rotate(q[parent_i], seg.offset)
        else:
            continue
        starts[seg.name] = start
        end = start + quat_rotate(q[i], seg.end)
        out.append(SegmentPose(seg.name, start, end, q[i].copy()))
    return tuple(out)


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
