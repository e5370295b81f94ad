"""How the pipeline maps the body onto the robot: eq. 16 along the robot's own axes
(``segments``, Robonaut 2) or the robot's YAML joint map (``map``), set up for a tree.

The chest frame (the robot's command frame, x forward, y left, z up) in OpenSim segment
coordinates (x anterior, y up, z right) is :data:`CHEST_IN_SEGMENT`:
``R_world_chest = R_world_segment @ CHEST_IN_SEGMENT``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from mocapkit.body.calibration import pose_coordinates
from mocapkit.body.joint_angles import compose_pose
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_to_matrix
from mocapkit.robot.model import ArmModel
from mocapkit.robot.retarget_map import CompiledMap, packaged_map
from mocapkit.robot.segment_retarget import (
    SegmentRetargeter,
    robonaut2_groups,
    robonaut2_init_posture,
)

log = logging.getLogger("mocapkit.teleop.pipeline")

#: chest coordinates (x forward, y left, z up) -> OpenSim segment coordinates.
CHEST_IN_SEGMENT = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
CHEST_SEGMENT = "torso"


@dataclass
class RetargetSetup:
    """Attributes:
    retargeter: eq. 16 (``segments``), or None (``map``).
    segments: the retargeter's segments, in its order.
    index: (R,) their indices in the tree.
    chest_index: the tree's ``torso`` segment, or -1 (the chest is the body's heading).
    compiled_map: the joint map (``map``), or None.
    map_extra: human coordinates the map reads that the tree does not measure (held at 0).
    """

    retargeter: SegmentRetargeter | None
    segments: tuple[str, ...]
    index: np.ndarray
    chest_index: int
    compiled_map: CompiledMap | None = None
    map_extra: list[str] = field(default_factory=list)


def setup_retarget(
    tree: SensorTree, arm: ArmModel, robot: str, retarget: str, pose: str
) -> RetargetSetup:
    """The retargeting for ``tree`` onto ``arm`` (registry name ``robot``); ``pose`` is the
    calibration pose, whose segment orientations are the robot's initialisation posture."""
    names = tree.segment_names
    chest = names.index(CHEST_SEGMENT) if CHEST_SEGMENT in names else -1
    if retarget != "segments":
        rmap = packaged_map(robot)
        extra = [h for h in rmap.human_names if h not in tree.coordinate_names]
        compiled = rmap.compile(arm, [*tree.coordinate_names, *extra])
        if extra:
            log.info("map: %s not measured by tree %s, held at 0 (neutral)", ", ".join(extra),
                     tree.name)  # fmt: skip
        return RetargetSetup(None, (), np.zeros(0, dtype=np.int64), chest, compiled, extra)
    side = {"robonaut2-right": "right", "robonaut2-left": "left"}.get(robot)
    if side is None:
        raise ConfigError(
            f"retarget 'segments' (eq. 16 along the robot's own axes) is set up for "
            f"Robonaut 2; for {robot!r} use retarget='map' (its YAML joint map)"
        )
    groups = [g for g in robonaut2_groups(side) if g.segment in names]
    if not groups or groups[0].segment != f"humerus_{side[0]}":
        raise ConfigError(f"tree {tree.name!r} has no humerus_{side[0]} segment for the {side} arm")
    groups = [g for g in groups if g.parent is None or g.parent in names]
    rt = SegmentRetargeter(arm, groups, robonaut2_init_posture(side))
    index = np.array([names.index(s) for s in rt.segments], dtype=np.int64)
    # the segments in the chest frame at the calibration pose: what the suit's
    # initialisation posture means for the robot (q_init)
    R_g = quat_to_matrix(compose_pose(tree, pose_coordinates(tree, pose)))
    R_chest_g = np.eye(3) if chest < 0 else R_g[chest].T  # ground -> chest segment
    rt.calibrate(
        {
            s: CHEST_IN_SEGMENT.T @ R_chest_g @ R_g[i]
            for s, i in zip(rt.segments, index, strict=True)
        }
    )
    return RetargetSetup(rt, tuple(rt.segments), index, chest)
