"""A humanoid drawn from its URDF's visual meshes in a viser scene, placed by Pinocchio's
forward kinematics (shared by ``mocapkit view`` and the live viewer)."""

from __future__ import annotations

from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.geometry import quat_from_matrix

ROBOT_RGB = (255, 140, 0)


def full_configuration(
    robot: Any, base_pos: FloatArray, base_quat_wxyz: FloatArray, joints: FloatArray
) -> FloatArray:
    """Pinocchio's q (nq,) from a base pose (position, [w, x, y, z]) and the one-DOF joints
    in the order of ``robot.iq`` (what the JOINTS message and the reports carry)."""
    q = robot.q_ref.copy()
    if robot.spec.floating_base:
        w, x, y, z = (float(v) for v in base_quat_wxyz)
        q[:7] = [*np.asarray(base_pos, dtype=float), x, y, z, w]
    q[robot.iq] = joints
    return q


class RobotMeshes:
    """Mesh handles under ``root`` for every visual geometry of ``robot`` (a
    :class:`~mocapkit.retarget.robot_model.Humanoid`); ``notes`` names meshes that could
    not be read."""

    def __init__(self, scene: Any, root: str, robot: Any, rgb: tuple[int, int, int] = ROBOT_RGB):
        import pinocchio as pin
        import trimesh

        self.robot = robot
        urdf = str(robot.spec.urdf)
        dirs = [urdf.split("share/example-robot-data")[0] + "share"] if "share/" in urdf else []
        dirs.append(str(robot.spec.urdf.parent))
        self.gm = pin.buildGeomFromUrdf(
            robot.model, urdf, pin.GeometryType.VISUAL, package_dirs=dirs
        )
        self.gd = self.gm.createData()
        self.data = robot.model.createData()
        self.notes: list[str] = []
        self.handles: list[tuple[int, Any]] = []
        for g, obj in enumerate(self.gm.geometryObjects):
            try:
                mesh: Any = trimesh.load(obj.meshPath, force="mesh")
            except (ValueError, OSError) as exc:  # a mesh format trimesh cannot read
                self.notes.append(f"{obj.name}: not drawn ({exc})")
                continue
            mesh.apply_scale(np.asarray(obj.meshScale))
            mesh.visual = trimesh.visual.ColorVisuals(mesh, face_colors=(*rgb, 255))
            self.handles.append((g, scene.add_mesh_trimesh(f"{root}/{obj.name}", mesh)))

    def place(self, q: FloatArray, offset: FloatArray | None = None) -> None:
        """Every mesh at configuration ``q`` (nq,), shifted by ``offset`` (3,)."""
        import pinocchio as pin

        off = np.zeros(3) if offset is None else np.asarray(offset, dtype=float)
        pin.forwardKinematics(self.robot.model, self.data, q)
        pin.updateGeometryPlacements(self.robot.model, self.data, self.gm, self.gd)
        for g, h in self.handles:
            pl = self.gd.oMg[g]
            h.position = tuple(np.asarray(pl.translation) + off)
            h.wxyz = tuple(quat_from_matrix(np.asarray(pl.rotation)))

    def show(self, visible: bool) -> None:
        for _, h in self.handles:
            h.visible = visible
