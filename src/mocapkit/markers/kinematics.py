"""Marker positions, Jacobians and J̇v on a :class:`~mocapkit.body.human_model.HumanModel`.

All world-aligned: a marker's Jacobian ``J_m`` (3, nv) maps the generalised velocity
``v`` (Pinocchio's: the free-flyer twist in the pelvis frame, then joint rates) to the
marker's velocity in the world frame.

Fast path (used by IK and direct marker control): one Pinocchio call
(``computeJointJacobians`` or ``computeJointJacobiansTimeVariation``) gives the world
spatial Jacobian ``J = [J_lin; J_ang]`` of every joint at the world origin; a point ``p``
attached to joint j then has ``J_p = (J_lin - [p]x J_ang) S_j`` where ``S_j`` keeps the
columns of the DOFs that support j, and

    J̇_p v = J̇_lin v_j + (J̇_ang v_j) x p + ω x ṗ,   v_j = S_j v, ω = J_ang v_j, ṗ = J_p v.

Reference path: ``getFrameJacobian`` per marker frame (tests check the two agree).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.human_model import HumanModel
from mocapkit.errors import ConfigError


class MarkerKinematics:
    """Evaluates a fixed list of markers of a model; owns one ``pinocchio.Data``.

    Args:
        human: the model with markers attached (:meth:`HumanModel.with_markers`).
        names: which markers, in the order rows are returned.
    """

    def __init__(self, human: HumanModel, names: Sequence[str]) -> None:
        import pinocchio as pin

        self._pin = pin
        self.human = human
        self.model = human.model
        self.data = self.model.createData()
        self.names = tuple(names)
        missing = [n for n in self.names if n not in human.markers]
        if missing:
            raise ConfigError(
                f"markers {', '.join(missing)} are not attached to the model; attached: "
                f"{', '.join(human.markers)}"
            )
        self.frame_ids = [self.model.getFrameId(f"marker:{n}") for n in self.names]
        seg_joint = human.segment_joint
        self.joint_ids = np.array([seg_joint[human.markers[n][0]] for n in self.names], dtype=int)
        self.offsets = np.array([human.markers[n][1] for n in self.names], dtype=float).reshape(
            -1, 3
        )
        nv = self.model.nv
        self.support = np.zeros((len(self.names), nv), dtype=bool)
        for i, jid in enumerate(self.joint_ids):
            for k in self.model.supports[int(jid)]:
                if k == 0:
                    continue
                jm = self.model.joints[k]
                self.support[i, jm.idx_v : jm.idx_v + jm.nv] = True
        self._unique_joints = np.unique(self.joint_ids)
        self._row_of_joint = {int(j): i for i, j in enumerate(self._unique_joints)}
        self._joint_row = np.array([self._row_of_joint[int(j)] for j in self.joint_ids])

    @property
    def n_markers(self) -> int:
        return len(self.names)

    # -- internals -------------------------------------------------------------------------
    def _joint_poses(self) -> tuple[FloatArray, FloatArray]:
        """Rotations (K, 3, 3) and translations (K, 3) of the joints carrying markers."""
        oMi = self.data.oMi
        R = np.empty((len(self._unique_joints), 3, 3))
        t = np.empty((len(self._unique_joints), 3))
        for i, j in enumerate(self._unique_joints):
            M = oMi[int(j)]
            R[i] = M.rotation
            t[i] = M.translation
        return R, t

    def _points(self) -> FloatArray:
        R, t = self._joint_poses()
        rows = self._joint_row
        return np.einsum("mij,mj->mi", R[rows], self.offsets) + t[rows]

    def _point_jacobians(self, P: FloatArray, J6: FloatArray) -> FloatArray:
        Jlin, Jang = J6[:3], J6[3:]
        # (M, 3, nv): J_lin - p x J_ang, restricted to each marker's supporting DOFs
        cross = np.cross(P[:, None, :], Jang.T[None, :, :])  # (M, nv, 3)
        J = Jlin.T[None, :, :] - cross
        J *= self.support[:, :, None]
        return np.ascontiguousarray(np.transpose(J, (0, 2, 1)))

    # -- public ----------------------------------------------------------------------------
    def positions(self, q: FloatArray) -> FloatArray:
        """(M, 3) world positions [m] at configuration ``q`` (nq,)."""
        self._pin.forwardKinematics(self.model, self.data, q)
        return self._points()

    def positions_jacobians(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Positions (M, 3) [m] and world-aligned Jacobians (M, 3, nv)."""
        J6 = self._pin.computeJointJacobians(self.model, self.data, q)
        P = self._points()
        return P, self._point_jacobians(P, J6)

    def positions_jacobians_bias(
        self, q: FloatArray, v: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Positions (M, 3), Jacobians (M, 3, nv) and the bias accelerations J̇v (M, 3)."""
        pin = self._pin
        pin.computeJointJacobiansTimeVariation(self.model, self.data, q, v)
        J6 = np.asarray(self.data.J)
        dJ6 = np.asarray(self.data.dJ)
        P = self._points()
        J = self._point_jacobians(P, J6)
        vm = self.support * v[None, :]  # (M, nv): each marker's supporting velocities
        omega = vm @ J6[3:].T  # (M, 3)
        pdot = np.einsum("mij,mj->mi", J, vm)
        bias = vm @ dJ6[:3].T + np.cross(vm @ dJ6[3:].T, P) + np.cross(omega, pdot)
        return P, J, bias

    def reference_positions_jacobians(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The same through Pinocchio frames (``getFrameJacobian`` per marker): readable and
        slow; the tests compare it with :meth:`positions_jacobians`."""
        pin = self._pin
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        P = np.array([self.data.oMf[f].translation for f in self.frame_ids]).reshape(-1, 3)
        J = np.array(
            [
                pin.getFrameJacobian(
                    self.model, self.data, f, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
                )[:3]
                for f in self.frame_ids
            ]
        ).reshape(-1, 3, self.model.nv)
        return P, J

    def reference_bias(self, q: FloatArray, v: FloatArray) -> FloatArray:
        """J̇v per marker (M, 3) through Pinocchio frame classical accelerations."""
        pin = self._pin
        pin.forwardKinematics(self.model, self.data, q, v, np.zeros(self.model.nv))
        return np.array(
            [
                pin.getFrameClassicalAcceleration(
                    self.model, self.data, f, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
                ).linear
                for f in self.frame_ids
            ]
        ).reshape(-1, 3)


def integrate(model: Any, q: FloatArray, dv: FloatArray) -> FloatArray:
    """``q ⊕ dv`` on the configuration manifold (free-flyer through SE(3) exp)."""
    import pinocchio as pin

    return np.asarray(pin.integrate(model, q, dv))


def difference(model: Any, q0: FloatArray, q1: FloatArray) -> FloatArray:
    """``q1 ⊖ q0`` (nv,)."""
    import pinocchio as pin

    return np.asarray(pin.difference(model, q0, q1))
