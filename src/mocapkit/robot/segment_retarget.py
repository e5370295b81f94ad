"""Segment orientations -> robot joint angles, the paper's way (Miller et al., section 5).

Each group of robot joints (2 or 3 consecutive revolute joints: the shoulder, the
elbow and forearm roll, the wrist) is driven by one human segment relative to its
parent segment:

1. Each segment's rotation since the suit's initialisation posture, in the chest frame,
   ``dR_s = R_chest_s(t) R_chest_s(0)^T``, is applied to the robot's segment in the
   robot's posture that matches the initialisation posture (``q_init``, the offsets):
   ``R*_s = dR_s R_chest_s^robot(q_init)``.
2. The child is made local to its parent (eq. 16, ``q2_local = q1^-1 q2``):
   ``R*_local = (R*_parent)^T R*_child``.
3. ``R*_local`` is decomposed into angles about the group's joint axes. With the joint
   axes ``a_k`` expressed in the parent frame at ``q_init`` (product of exponentials),
   ``R_local(q) = Rot(a_1, d_1) Rot(a_2, d_2) Rot(a_3, d_3) R_local(q_init)`` and
   ``q = q_init + d``: the offsets are the robot's initialisation posture, and an axis
   pointing the other way from the human's is the paper's negation. Consecutive axes
   must be perpendicular. The third axis ``a_3`` is written ``Rot(a_2, psi) a_1``, so the
   decomposition is the textbook proper Euler one ``(a_1, a_2, a_1)`` with the middle
   angle shifted by ``psi`` (Tait-Bryan when ``a_3 = a_1 x a_2``).
   A 2-joint group gets a virtual third axis ``a_1 x a_2``; its angle (the paper's
   alpha_6) has no joint and is dropped and reported.

Of the two Euler solutions and their 2 pi shifts, the one closest to the previous frame
(or ``q_init``) is kept, so angles are continuous; they are then clipped to the joint
limits and the clipped joints are reported.

Two backends with one result (to 1e-9, tested): ``"fast"`` (default), one numba call per
frame (:mod:`mocapkit.robot._retarget_kernel`, a few microseconds: the teleoperation
pipeline's per-packet path), and ``"reference"``, the readable numpy code below.
:meth:`SegmentRetargeter.solve` is the allocation-light form for streaming: (S, 3, 3)
matrices in :attr:`SegmentRetargeter.segments` order in, the joint vector out.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError, DataError
from mocapkit.geometry import quat_to_matrix
from mocapkit.robot import _retarget_kernel
from mocapkit.robot.model import ArmModel

# Consecutive joint axes must be perpendicular within this cosine (0.06 deg): URDF
# numbers rounded to 1.5708 are 4e-6 off; a genuinely oblique axis is far beyond.
_PERPENDICULAR_TOL = 1e-3
# A joint counts as clipped beyond its limit by more than this [rad]: an arm resting on a
# limit (R2's straight elbow is joint3's upper limit) is not a violation.
CLIP_TOL = 1e-6


@dataclass(frozen=True)
class JointGroup:
    """Robot joints driven by one human segment relative to its parent segment.

    Attributes:
        segment: human segment name driving the group (e.g. ``humerus_r``).
        parent: human parent segment (``None``: the chest, i.e. the command frame).
        joints: 2 or 3 robot joint names, in chain order.
    """

    segment: str
    parent: str | None
    joints: tuple[str, ...]


@dataclass(frozen=True)
class RetargetResult:
    """Joint angles for one frame.

    Attributes:
        q: (n,) robot joint angles [rad] (joints without a group keep ``q_init``).
        clipped: names of joints clipped to a limit this frame.
        dropped_rad: per group segment, the angle about the virtual third axis that no
            joint can follow [rad] (the paper's alpha_6).
    """

    q: FloatArray
    clipped: tuple[str, ...] = ()
    dropped_rad: dict[str, float] = field(default_factory=dict)


@dataclass
class _Prepared:
    group: JointGroup
    idx: FloatArray  # joint indices (int)
    C: FloatArray  # (3, 3) columns a1, a2, a1 x a2 in the parent robot frame
    psi: float  # a3 = Rot(a2, psi) a1
    virtual_third: bool
    R_local_init: FloatArray  # robot's local rotation of the group at q_init
    R_psi: FloatArray  # Rot(a2, psi)
    child_frame: str
    parent_frame: str | None


def _euler_xyx(R: FloatArray) -> FloatArray:
    """Intrinsic X-Y-X angles (a, b, c), b in [0, pi], of R = Rx(a) Ry(b) Rx(c) (the
    textbook matrix form: R00 = cos b, (R10, R20) = sin b (sin a, -cos a),
    (R01, R02) = sin b (sin c, cos c)). At b = 0 or pi, c = 0 (the geometry module's
    gimbal rule)."""
    sb = math.hypot(R[1, 0], R[2, 0])
    b = math.atan2(sb, R[0, 0])
    if sb < 1e-9:
        a = math.atan2(R[2, 1], R[1, 1])
        return np.array([a, b, 0.0])
    return np.array([math.atan2(R[1, 0], -R[2, 0]), b, math.atan2(R[0, 1], R[0, 2])])


def _rot(axis: FloatArray, angle: float) -> FloatArray:
    a = axis / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * (K @ K)


class SegmentRetargeter:
    """The paper's mapping for an arm: see the module docstring.

    Args:
        arm: the robot arm (intermediate kinematic model).
        groups: joint groups in chain order (a group's joints follow its parent's).
        q_init: (n,) robot posture matching the suit's initialisation posture [rad].
        backend: ``"fast"`` (numba) or ``"reference"`` (numpy); same results.
    """

    def __init__(
        self, arm: ArmModel, groups: Sequence[JointGroup], q_init: Any, backend: str = "fast"
    ) -> None:
        if backend not in ("fast", "reference"):
            raise ConfigError(f"backend: expected 'fast' or 'reference', got {backend!r}")
        self.backend = backend
        self.arm = arm
        self.q_init = arm.check_q(q_init, "q_init")
        if not groups:
            raise ConfigError("groups: expected at least one joint group")
        self._groups: list[_Prepared] = []
        used: set[str] = set()
        last_index = -1
        prev_child: str | None = None
        segments: set[str] = set()
        for g in groups:
            if not 2 <= len(g.joints) <= 3:
                raise ConfigError(f"group {g.segment}: expected 2 or 3 joints, got {len(g.joints)}")
            if g.parent is not None and g.parent not in segments:
                raise ConfigError(
                    f"group {g.segment}: parent segment {g.parent!r} must drive an earlier group"
                )
            idx = [arm.joint_index(j) for j in g.joints]
            if any(j in used for j in g.joints):
                raise ConfigError(f"group {g.segment}: joint used by two groups")
            if idx != list(range(idx[0], idx[0] + len(idx))) or idx[0] <= last_index:
                raise ConfigError(
                    f"group {g.segment}: joints must be consecutive and in chain order, got "
                    f"{', '.join(g.joints)}"
                )
            used.update(g.joints)
            segments.add(g.segment)
            last_index = idx[-1]
            parent_frame = prev_child if g.parent is not None else None
            child_frame = g.joints[-1]
            self._groups.append(self._prepare(g, np.array(idx), parent_frame, child_frame))
            prev_child = child_frame
        self.segments: tuple[str, ...] = tuple(sorted({g.segment for g in groups}))
        self._R_init_robot: dict[str, FloatArray] = {
            p.group.segment: self._frame_R(self.q_init, p.child_frame) for p in self._groups
        }
        self._R0_human: dict[str, FloatArray] | None = None
        self._q_prev = self.q_init.copy()
        self._build_tables()

    # -- setup -----------------------------------------------------------------------------
    def _frame_R(self, q: FloatArray, frame: str | None) -> FloatArray:
        if frame is None:
            return np.eye(3)
        return self.arm.frame_pose(q, frame)[:3, :3]

    def _prepare(
        self, g: JointGroup, idx: FloatArray, parent_frame: str | None, child_frame: str
    ) -> _Prepared:
        q = self.q_init
        R_parent = self._frame_R(q, parent_frame)
        # joint k's axis is the z axis of its own (child-link) frame in our models; take
        # it from the Jacobian instead so any URDF axis works: column k's angular part is
        # the axis in the base frame
        J = self.arm.jacobian(q)
        axes = [R_parent.T @ J[3:, int(i)] for i in idx]
        axes = [a / np.linalg.norm(a) for a in axes]
        for k in range(len(axes) - 1):
            c = abs(float(axes[k] @ axes[k + 1]))
            if c > _PERPENDICULAR_TOL:
                raise ConfigError(
                    f"group {g.segment}: joints {g.joints[k]} and {g.joints[k + 1]} are not "
                    f"perpendicular at q_init (cos = {c:.4f}); an Euler decomposition needs "
                    "perpendicular consecutive axes: use the joint-angle map instead"
                )
        a1, a2 = axes[0], axes[1]
        a2 = a2 - (a2 @ a1) * a1
        a2 /= np.linalg.norm(a2)
        a12 = np.cross(a1, a2)
        C = np.column_stack([a1, a2, a12])
        virtual = len(axes) == 2
        a3 = a12 if virtual else axes[2]
        # a3 = Rot(a2, psi) a1 = cos(psi) a1 - sin(psi) (a1 x a2)
        psi = float(np.arctan2(-(a3 @ a12), a3 @ a1))
        R_local_init = R_parent.T @ self._frame_R(q, child_frame)
        return _Prepared(
            g, idx, C, psi, virtual, R_local_init, _rot(a2, psi), child_frame, parent_frame
        )

    def _build_tables(self) -> None:
        """Arrays for the numba kernel (segments in :attr:`segments` order)."""
        seg_index = {s: i for i, s in enumerate(self.segments)}
        gs = self._groups
        self._k_seg = np.array([seg_index[p.group.segment] for p in gs], dtype=np.int64)
        self._k_parent = np.array(
            [-1 if p.group.parent is None else seg_index[p.group.parent] for p in gs],
            dtype=np.int64,
        )
        self._k_start = np.array([int(p.idx[0]) for p in gs], dtype=np.int64)
        self._k_len = np.array([len(p.idx) for p in gs], dtype=np.int64)
        self._k_C = np.ascontiguousarray(np.stack([p.C for p in gs]))
        self._k_Rpsi = np.ascontiguousarray(np.stack([p.R_psi for p in gs]))
        self._k_psi = np.array([p.psi for p in gs])
        self._k_virtual = np.array([p.virtual_third for p in gs], dtype=np.bool_)
        self._k_RliT = np.ascontiguousarray(np.stack([p.R_local_init.T for p in gs]))
        R_init = [self._R_init_robot[s] for s in self.segments]
        self._k_Rinit = np.ascontiguousarray(np.stack(R_init))
        self._k_R0T = np.ascontiguousarray(np.tile(np.eye(3), (len(self.segments), 1, 1)))
        self._k_lower = np.ascontiguousarray(self.arm.lower, dtype=np.float64)
        self._k_upper = np.ascontiguousarray(self.arm.upper, dtype=np.float64)
        self._k_targets = np.empty((len(self.segments), 3, 3))
        self._k_R = np.empty((len(self.segments), 3, 3))
        self.q = np.empty(self.arm.n)
        """(n,) the last frame's joint angles [rad] (the array :meth:`solve` returns)."""
        self.clipped = np.zeros(self.arm.n, dtype=np.bool_)
        """(n,) joints clipped to a limit in the last frame."""
        self.dropped = np.zeros(len(gs))
        """(G,) per group, the angle no joint follows in the last frame [rad]."""

    def calibrate(self, R_chest_segment: Mapping[str, Any]) -> None:
        """Store the human segments' orientations in the initialisation posture.

        Args:
            R_chest_segment: per segment, a quaternion (4,) [w,x,y,z] or a matrix (3, 3)
                of the segment in the chest frame.
        """
        self._R0_human = {s: self._as_matrix(R_chest_segment, s) for s in self.segments}
        self._k_R0T = np.ascontiguousarray(np.stack([self._R0_human[s].T for s in self.segments]))
        self._q_prev = self.q_init.copy()

    def _as_matrix(self, values: Mapping[str, Any], seg: str) -> FloatArray:
        if seg not in values:
            raise DataError(
                f"segment orientations: missing {seg!r}; the retargeting needs "
                f"{', '.join(self.segments)}"
            )
        a = np.asarray(values[seg], dtype=float)
        if a.shape == (4,):
            if not np.isfinite(a).all():
                raise DataError(f"segment orientations: {seg} is not finite ({a})")
            return quat_to_matrix(a)
        if a.shape == (3, 3):
            if not np.isfinite(a).all():
                raise DataError(f"segment orientations: {seg} is not finite")
            return a
        raise DataError(
            f"segment orientations: {seg}: expected a quaternion (4,) or a matrix (3, 3), "
            f"got shape {a.shape}"
        )

    # -- per frame -------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the previous frame (continuity restarts from ``q_init``)."""
        self._q_prev = self.q_init.copy()

    def solve(self, R_chest_segment: Any) -> FloatArray:
        """Fast path for streaming: (S, 3, 3) segment matrices (chest frame, finite, in
        :attr:`segments` order) -> :attr:`q` (n,) [rad], with :attr:`clipped` and
        :attr:`dropped` updated. No input checks beyond the calibration."""
        if self._R0_human is None:
            raise DataError("retargeting: call calibrate() in the initialisation posture first")
        _retarget_kernel.retarget_frame(
            R_chest_segment, self._k_R0T, self._k_Rinit, self._k_seg, self._k_parent,
            self._k_start, self._k_len, self._k_C, self._k_Rpsi, self._k_psi, self._k_virtual,
            self._k_RliT, self.q_init, self._k_lower, self._k_upper, self._q_prev, self.q,
            self.clipped, self.dropped, self._k_targets, CLIP_TOL,
        )  # fmt: skip
        return self.q

    def joint_angles(self, R_chest_segment: Mapping[str, Any]) -> RetargetResult:
        """Robot joint angles for the segment orientations of one frame (chest frame)."""
        if self._R0_human is None:
            raise DataError("retargeting: call calibrate() in the initialisation posture first")
        if self.backend == "fast":
            for i, seg in enumerate(self.segments):
                self._k_R[i] = self._as_matrix(R_chest_segment, seg)
            q = self.solve(self._k_R).copy()
            clipped = tuple(self.arm.joint_names[i] for i in np.flatnonzero(self.clipped))
            dropped = {
                p.group.segment: float(self.dropped[g])
                for g, p in enumerate(self._groups)
                if p.virtual_third
            }
            return RetargetResult(q, clipped, dropped)
        return self._joint_angles_reference(R_chest_segment)

    def _joint_angles_reference(self, R_chest_segment: Mapping[str, Any]) -> RetargetResult:
        assert self._R0_human is not None
        targets: dict[str, FloatArray] = {}
        for s in self.segments:
            dR = self._as_matrix(R_chest_segment, s) @ self._R0_human[s].T
            targets[s] = dR @ self._R_init_robot[s]
        q = self.q_init.copy()
        dropped: dict[str, float] = {}
        for p in self._groups:
            R_child = targets[p.group.segment]
            R_parent = np.eye(3) if p.group.parent is None else targets[p.group.parent]
            R_local = R_parent.T @ R_child  # eq. 16
            M = R_local @ p.R_local_init.T
            d, third = self._decompose(p, M)
            q[p.idx] = self.q_init[p.idx] + d
            if p.virtual_third:
                dropped[p.group.segment] = third
        clipped = tuple(
            self.arm.joint_names[i]
            for i in range(self.arm.n)
            if q[i] < self.arm.lower[i] - CLIP_TOL or q[i] > self.arm.upper[i] + CLIP_TOL
        )
        q = self.arm.clamp(q)
        self._q_prev = q.copy()
        return RetargetResult(q, clipped, dropped)

    def _decompose(self, p: _Prepared, M: FloatArray) -> tuple[FloatArray, float]:
        """Angles (k,) about the group's axes, and the virtual third angle (or 0)."""
        # Rot(a3, d3) = Rot(a2, psi) Rot(a1, d3) Rot(a2, -psi), so
        # M Rot(a2, psi) = Rot(a1, d1) Rot(a2, d2 + psi) Rot(a1, d3): proper Euler (1, 2, 1)
        local = p.C.T @ (M @ p.R_psi) @ p.C
        e = _euler_xyx(local)
        cands = [e, np.array([e[0] + np.pi, -e[1], e[2] + np.pi])]
        prev = self._q_prev[p.idx] - self.q_init[p.idx]
        k = len(p.idx)
        best: FloatArray | None = None
        best_cost = np.inf
        lo = self.arm.lower[p.idx] - self.q_init[p.idx]
        hi = self.arm.upper[p.idx] - self.q_init[p.idx]
        for c in cands:
            d = np.array([c[0], c[1] - p.psi, c[2]])
            # nearest 2 pi shift to the previous frame, per angle
            d = d - 2 * np.pi * np.round((d - np.append(prev, d[2])[:3]) / (2 * np.pi))
            dj = d[:k]
            excess = np.maximum(lo - dj, 0) + np.maximum(dj - hi, 0)
            cost = float(np.sum((dj - prev) ** 2) + 100.0 * np.sum(excess**2))
            if p.virtual_third:
                # a rotation no joint can follow is worse than hitting a limit
                cost += 1e3 * float(np.angle(np.exp(1j * d[2])) ** 2)
            if cost < best_cost:
                best, best_cost = d, cost
        assert best is not None
        return best[:k], float(np.angle(np.exp(1j * best[2]))) if p.virtual_third else 0.0


def robonaut2_groups(side: str = "right") -> tuple[JointGroup, ...]:
    """The paper's groups for Robonaut 2: shoulder (3) from the upper arm, elbow and
    forearm roll (2) from the forearm, wrist pitch and yaw (2) from the hand."""
    s = side[0]
    pre = f"r2/{side}_arm/"
    return (
        JointGroup(f"humerus_{s}", None, (pre + "joint0", pre + "joint1", pre + "joint2")),
        JointGroup(f"radius_{s}", f"humerus_{s}", (pre + "joint3", pre + "joint4")),
        JointGroup(f"hand_{s}", f"radius_{s}", (pre + "wrist/pitch", pre + "wrist/yaw")),
    )


def robonaut2_init_posture(side: str = "right") -> FloatArray:
    """R2 posture matching the suit's initialisation posture (standing, arm hanging, elbow
    straight, palm towards the thigh) [rad]: the paper's offsets."""
    if side == "right":
        return np.array([0.0, -np.pi / 2, np.pi / 2, 0.0, -np.pi / 2, 0.0, 0.0])
    return np.array([0.0, -np.pi / 2, -np.pi / 2, 0.0, np.pi / 2, 0.0, 0.0])


def chest_quats(q_world_chest: Any, q_world_segment: Mapping[str, Any]) -> dict[str, FloatArray]:
    """Segment orientations in the chest frame, ``R_chest_s = R_world_chest^T R_world_s``."""
    Rc = quat_to_matrix(np.asarray(q_world_chest, dtype=float))
    return {
        s: Rc.T @ quat_to_matrix(np.asarray(q, dtype=float)) for s, q in q_world_segment.items()
    }
