"""A serial robot arm on Pinocchio, expressed in its command frame (e.g. the chest).

``ArmModel`` wraps a Pinocchio model of the arm's joints only (other joints locked) and
re-expresses every pose in the *base frame*, the frame in which end-effector commands
are given (Robonaut: a frame in the chest, Miller et al. section 5):

- ``fk(q)`` -> ``T_base_ee`` (4, 4);
- ``jacobian(q)`` -> (6, n), linear first ``[v; w]``, both expressed in the base frame
  at the end-effector origin (Pinocchio's LOCAL_WORLD_ALIGNED, rotated into the base);
- position limits, our velocity limits, and a reference posture ``q_ref``.

Pinocchio keeps a mutable ``Data`` per model: an ``ArmModel`` is not thread-safe, use
one per thread or process (``copy()``).
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from mocapkit._validate import FloatArray, as_float_array, check_finite, check_shape
from mocapkit.errors import ConfigError, DataError
from mocapkit.geometry import quat_from_matrix, quat_to_matrix


def pose_matrix(pos: Any, quat: Any) -> FloatArray:
    """4x4 homogeneous transform from a position (3,) [m] and a quaternion (4,) [w,x,y,z]."""
    T = np.eye(4)
    T[:3, :3] = quat_to_matrix(np.asarray(quat, dtype=float))
    T[:3, 3] = np.asarray(pos, dtype=float)
    return T


def pose_parts(T: Any) -> tuple[FloatArray, FloatArray]:
    """(position (3,), quaternion (4,) [w,x,y,z]) of a 4x4 transform."""
    M = np.asarray(T, dtype=float)
    return M[:3, 3].copy(), quat_from_matrix(M[:3, :3])


def rotation_angle(R_a: Any, R_b: Any) -> float:
    """Angle [rad] of the rotation taking R_a to R_b (robust near 0 and pi)."""
    R = np.asarray(R_a, dtype=float).T @ np.asarray(R_b, dtype=float)
    # atan2 of |axis * sin| and cos keeps precision at both ends of [0, pi]
    s = 0.5 * np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    c = 0.5 * (np.trace(R) - 1.0)
    return float(np.arctan2(s, c))


def pose_distance(T_a: Any, T_b: Any) -> tuple[float, float]:
    """(position distance [m], rotation angle [rad]) between two 4x4 poses."""
    A = np.asarray(T_a, dtype=float)
    B = np.asarray(T_b, dtype=float)
    return float(np.linalg.norm(A[:3, 3] - B[:3, 3])), rotation_angle(A[:3, :3], B[:3, :3])


def rotation_log(R: Any) -> FloatArray:
    """Rotation vector (3,) [rad] of a rotation matrix (Pinocchio's log3)."""
    return np.asarray(pin.log3(np.asarray(R, dtype=float)), dtype=float)


class ArmModel:
    """A serial arm whose poses are expressed in the base (command) frame.

    Args:
        model: Pinocchio model holding exactly the arm's joints (1-DOF each).
        ee_frame: name of the end-effector frame in ``model``.
        base_frame: name of the command frame in ``model``; ``None`` = the universe.
        velocity_limit: (n,) joint speed limits [rad/s].
        q_ref: (n,) reference posture [rad] (the ready pose); defaults to mid-range.
        name: label used in messages.
    """

    def __init__(
        self,
        model: pin.Model,
        ee_frame: str,
        velocity_limit: Any,
        q_ref: Any = None,
        base_frame: str | None = None,
        name: str = "arm",
    ) -> None:
        if model.nq != model.nv:
            raise ConfigError(
                f"{name}: only 1-DOF revolute/prismatic joints are supported "
                f"(nq={model.nq}, nv={model.nv}); lock the other joints first"
            )
        self.name = name
        self.model = model
        self.data = model.createData()
        if not model.existFrame(ee_frame):
            raise ConfigError(f"{name}: no frame {ee_frame!r} in the model")
        self.ee_frame = ee_frame
        self._ee_id = model.getFrameId(ee_frame)
        self.joint_names: tuple[str, ...] = tuple(model.names[1:])
        self.n = int(model.nq)
        self.lower = np.array(model.lowerPositionLimit, dtype=float)
        self.upper = np.array(model.upperPositionLimit, dtype=float)
        self.lower.setflags(write=False)
        self.upper.setflags(write=False)
        vel = as_float_array(velocity_limit, f"{name}.velocity_limit")
        check_shape(vel, f"{name}.velocity_limit", self.n)
        if not (np.isfinite(vel).all() and (vel > 0).all()):
            raise ConfigError(f"{name}.velocity_limit: expected positive rad/s, got {vel}")
        self.velocity_limit = vel
        self.velocity_limit.setflags(write=False)
        # pose of the universe in the base frame (constant: the base is upstream)
        self.base_frame = base_frame
        self._T_base_root = np.eye(4)
        if base_frame is not None:
            if not model.existFrame(base_frame):
                raise ConfigError(f"{name}: no base frame {base_frame!r} in the model")
            pin.framesForwardKinematics(model, self.data, pin.neutral(model))
            T_root_base = self.data.oMf[model.getFrameId(base_frame)].homogeneous
            self._T_base_root = np.linalg.inv(T_root_base)
        if q_ref is None:
            q_ref = 0.5 * (self.lower + self.upper)
        qr = self.check_q(q_ref, f"{name}.q_ref")
        if (qr < self.lower - 1e-12).any() or (qr > self.upper + 1e-12).any():
            raise ConfigError(f"{name}.q_ref: outside the joint limits: {qr}")
        self.q_ref = qr
        self.q_ref.setflags(write=False)

    # -- helpers ---------------------------------------------------------------------------
    def check_q(self, q: Any, name: str = "q") -> FloatArray:
        """Convert and check a joint vector (n,) [rad]; raise naming ``name``."""
        arr = as_float_array(q, name)
        check_shape(arr, name, self.n)
        check_finite(arr, name, "Joint angles must be finite radians.")
        return arr

    def joint_index(self, joint: str) -> int:
        """Index of a joint in ``q``; the error lists the arm's joints."""
        if joint not in self.joint_names:
            raise ConfigError(
                f"{self.name}: no joint {joint!r}; joints are {', '.join(self.joint_names)}"
            )
        return self.joint_names.index(joint)

    def clamp(self, q: Any) -> FloatArray:
        """q clipped to the position limits."""
        return np.clip(np.asarray(q, dtype=float), self.lower, self.upper)

    def copy(self) -> ArmModel:
        """An independent copy (own Pinocchio Data): one per thread or process."""
        new = copy.copy(self)
        new.data = self.model.createData()
        return new

    # -- kinematics ------------------------------------------------------------------------
    def fk(self, q: Any) -> FloatArray:
        """End-effector pose ``T_base_ee`` (4, 4) at configuration q (n,) [rad]."""
        qa = np.asarray(q, dtype=float)
        pin.framesForwardKinematics(self.model, self.data, qa)
        return self._T_base_root @ self.data.oMf[self._ee_id].homogeneous

    def frame_pose(self, q: Any, frame: str) -> FloatArray:
        """Pose ``T_base_frame`` (4, 4) of any frame of the model."""
        if not self.model.existFrame(frame):
            raise ConfigError(f"{self.name}: no frame {frame!r} in the model")
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        return self._T_base_root @ self.data.oMf[self.model.getFrameId(frame)].homogeneous

    def fk_batch(self, Q: Any) -> FloatArray:
        """End-effector poses (N, 4, 4) for configurations (N, n)."""
        Qa = as_float_array(Q, "Q")
        check_shape(Qa, "Q", None, self.n)
        return np.stack([self.fk(q) for q in Qa]) if len(Qa) else np.zeros((0, 4, 4))

    def jacobian(self, q: Any) -> FloatArray:
        """Frame Jacobian (6, n) of the end effector, ``[v; w]`` in the base frame."""
        qa = np.asarray(q, dtype=float)
        pin.computeJointJacobians(self.model, self.data, qa)
        pin.updateFramePlacements(self.model, self.data)
        J = pin.getFrameJacobian(
            self.model, self.data, self._ee_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )
        R = self._T_base_root[:3, :3]
        out = np.empty((6, self.n))
        out[:3] = R @ J[:3]
        out[3:] = R @ J[3:]
        return out

    def within_limits(self, q: Any, tol: float = 1e-9) -> np.ndarray:
        """(n,) bool: which joints are inside their limits (with ``tol`` [rad])."""
        qa = np.asarray(q, dtype=float)
        return np.asarray((qa >= self.lower - tol) & (qa <= self.upper + tol))

    def describe_limit_violation(self, q: Any) -> str | None:
        """A message naming the joints outside their limits, or None."""
        qa = np.asarray(q, dtype=float)
        bad = np.flatnonzero(~self.within_limits(qa))
        if not bad.size:
            return None
        parts = [
            f"{self.joint_names[i]}={np.degrees(qa[i]):.1f} deg outside "
            f"[{np.degrees(self.lower[i]):.1f}, {np.degrees(self.upper[i]):.1f}]"
            for i in bad
        ]
        return "; ".join(parts)


def check_joint_names(arm: ArmModel, names: Sequence[str], what: str) -> None:
    """Raise DataError if some names are not joints of the arm."""
    unknown = [n for n in names if n not in arm.joint_names]
    if unknown:
        raise DataError(
            f"{what}: unknown joint(s) {', '.join(unknown)} for {arm.name}; "
            f"joints are {', '.join(arm.joint_names)}"
        )
