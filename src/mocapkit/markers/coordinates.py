"""Named joint coordinates from configurations, in OpenSim's conventions where they exist.

Columns: ``pelvis_tx, pelvis_ty, pelvis_tz`` [m] and ``pelvis_tilt, pelvis_list,
pelvis_rotation`` [rad] in OpenSim's ground frame (y up: ``v_os = (x, z, -y)`` of our z-up
world) with OpenSim's intrinsic Z-X-Y sequence, then every revolute DOF [rad] by name.
"""

from __future__ import annotations

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.human_model import HumanModel
from mocapkit.geometry import euler_from_quat, quat_from_matrix, quat_from_xyzw, quat_to_matrix

PELVIS_COLUMNS = (
    "pelvis_tx",
    "pelvis_ty",
    "pelvis_tz",
    "pelvis_tilt",
    "pelvis_list",
    "pelvis_rotation",
)
# our z-up world (x fwd, y left, z up) -> OpenSim ground (x fwd, y up, z right)
Z_UP_TO_OPENSIM = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def coordinate_names(human: HumanModel) -> tuple[str, ...]:
    return (*PELVIS_COLUMNS, *human.dof_names)


def coordinates_from_q(human: HumanModel, Q: FloatArray) -> FloatArray:
    """(N, 6 + n_dof) coordinates [m, rad] from configurations (N, nq)."""
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    C = Z_UP_TO_OPENSIM
    R = quat_to_matrix(quat_from_xyzw(Q[:, 3:7]))  # (N, 3, 3) world <- pelvis, ours
    R_os = C @ R @ C.T
    angles = euler_from_quat(quat_from_matrix(R_os), "ZXY")
    out = np.empty((Q.shape[0], 6 + Q.shape[1] - 7))
    out[:, :3] = Q[:, :3] @ C.T
    out[:, 3:6] = angles
    out[:, 6:] = Q[:, 7:]
    return out


def angular_columns(human: HumanModel) -> np.ndarray:
    """(6 + n_dof,) bool: columns that are angles (degrees at the edges)."""
    mask = np.ones(6 + len(human.dof_names), dtype=bool)
    mask[:3] = False
    return mask
