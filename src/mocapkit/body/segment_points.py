"""Where the segments are: joint and end points from segment orientations and the tree's
offsets (for drawing a skeleton, or a simulated sensor's position on its segment).

A root segment's joint sits at ``root_position + R_world_ground @ offset`` (the ground
frame is OpenSim's y-up ground placed in the z-up world); a child's joint at
``start_parent + R_world_parent @ offset``; a segment ends at
``start + R_world_segment @ end``. Offsets and ends are the tree's [m], in the parent's
(resp. the segment's) frame.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mocapkit._validate import FloatArray, as_float_array, check_shape
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.geometry import quat_rotate


def segment_points(
    tree: SensorTree,
    q_world_segment: Any,
    q_world_ground: Any,
    root_position: Any = (0.0, 0.0, 0.0),
) -> tuple[FloatArray, FloatArray]:
    """Joint (start) and end points of every segment (see the module docstring).

    Args:
        tree: the sensor tree (``offset`` and ``end`` per segment).
        q_world_segment: (..., S, 4) in ``tree.segment_names`` order.
        q_world_ground: (4,) or (..., 4): the ground frame in the world.
        root_position: (3,) [m] where the ground origin is.

    Returns:
        ``(start, end)``, each (..., S, 3) [m] in the world. A NaN orientation makes its
        segment's end and its children's points NaN (a lost sensor).
    """
    q = as_float_array(q_world_segment, "q_world_segment")
    n_seg = len(tree.segments)
    if q.ndim < 2 or q.shape[-2:] != (n_seg, 4):
        check_shape(q, "q_world_segment", n_seg, 4)
    qg = as_float_array(q_world_ground, "q_world_ground")
    origin = as_float_array(root_position, "root_position")
    check_shape(origin, "root_position", 3)
    start = np.empty((*q.shape[:-1], 3))
    end = np.empty_like(start)
    parents = tree.parent_index
    for i, seg in enumerate(tree.segments):
        j = int(parents[i])
        if j < 0:
            start[..., i, :] = origin + quat_rotate(qg, seg.offset)
        else:
            start[..., i, :] = start[..., j, :] + quat_rotate(q[..., j, :], seg.offset)
        end[..., i, :] = start[..., i, :] + quat_rotate(q[..., i, :], seg.end)
    return start, end
