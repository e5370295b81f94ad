"""Rotation maths: Hamilton quaternions [w, x, y, z], Euler sequences, rigid transforms.

Pure numpy; never imports I/O, the CLI or a viewer.
"""

from mocapkit.geometry.euler import ALL_SEQUENCES, euler_from_quat, quat_from_euler
from mocapkit.geometry.quaternion import (
    quat_angle,
    quat_angle_between,
    quat_canonical,
    quat_conj,
    quat_exp,
    quat_from_axis_angle,
    quat_from_matrix,
    quat_from_rotvec,
    quat_from_two_vectors,
    quat_from_xyzw,
    quat_identity,
    quat_inv,
    quat_log,
    quat_mul,
    quat_normalize,
    quat_rotate,
    quat_rotate_inv,
    quat_slerp,
    quat_to_axis_angle,
    quat_to_matrix,
    quat_to_rotvec,
    quat_to_xyzw,
)

__all__ = [
    "ALL_SEQUENCES",
    "euler_from_quat",
    "quat_angle",
    "quat_angle_between",
    "quat_canonical",
    "quat_conj",
    "quat_exp",
    "quat_from_axis_angle",
    "quat_from_euler",
    "quat_from_matrix",
    "quat_from_rotvec",
    "quat_from_two_vectors",
    "quat_from_xyzw",
    "quat_identity",
    "quat_inv",
    "quat_log",
    "quat_mul",
    "quat_normalize",
    "quat_rotate",
    "quat_rotate_inv",
    "quat_slerp",
    "quat_to_axis_angle",
    "quat_to_matrix",
    "quat_to_rotvec",
    "quat_to_xyzw",
]
