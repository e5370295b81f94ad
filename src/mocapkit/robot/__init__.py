"""Robot arms on Pinocchio: models in the command (chest) frame, forward kinematics and
frame Jacobians, damped-least-squares IK with limits, and retargeting from human segment
orientations (the paper's eq. 16) or human joint angles (a YAML map)."""

from mocapkit.robot.ik import IkParams, IkResult, ik_step, pose_error, solve_ik
from mocapkit.robot.model import ArmModel, pose_distance, pose_matrix, pose_parts
from mocapkit.robot.registry import available_robots, robot_arm
from mocapkit.robot.retarget_map import RetargetMap, packaged_map
from mocapkit.robot.robonaut2 import robonaut2_arm
from mocapkit.robot.segment_retarget import JointGroup, SegmentRetargeter

__all__ = [
    "ArmModel",
    "IkParams",
    "IkResult",
    "JointGroup",
    "RetargetMap",
    "SegmentRetargeter",
    "available_robots",
    "ik_step",
    "packaged_map",
    "pose_distance",
    "pose_error",
    "pose_matrix",
    "pose_parts",
    "robonaut2_arm",
    "robot_arm",
    "solve_ik",
]
