"""A humanoid built from its :class:`RobotSpec`: the Pinocchio model (floating or fixed
base), its reference configuration on the ground facing +x, limits and frame ids."""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError, FileFormatError
from mocapkit.retarget.robot_spec import RobotSpec

MARGIN = 1e-3  # rad: the reference posture keeps this far inside the limits


@dataclass
class Humanoid:
    spec: RobotSpec
    model: Any
    data: Any
    q_ref: FloatArray  # (nq,) standing on z = 0, facing +x
    q_min: FloatArray  # (nq,)
    q_max: FloatArray
    v_max: FloatArray  # (nv,) rad/s (inf on the floating base)
    frame_ids: dict[str, int]  # robot frame name -> id
    joint_names: tuple[str, ...]  # actuated joints, in q order after the base
    lateral: FloatArray  # (3,) robot left in the world at q_ref
    iq: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    iv: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    # iq/iv: q and v indices of the one-DOF joints (revolute, prismatic) that carry the
    # position and velocity limits; continuous joints (nq 2, nv 1) have no position limit
    ref_pose: dict[str, tuple[FloatArray, FloatArray]] = field(default_factory=dict)
    # ref_pose: every named frame's (position, rotation) in the reference posture, once

    @functools.cached_property
    def iq_names(self) -> tuple[str, ...]:
        """The one-DOF joints' names in the order of ``iq`` (what a JOINTS message and the
        robot server's reports carry)."""
        m = self.model
        by_q = {int(m.joints[j].idx_q): m.names[j] for j in range(1, m.njoints)}
        return tuple(str(by_q[int(i)]) for i in self.iq)

    @property
    def n_base_q(self) -> int:
        return 7 if self.spec.floating_base else 0

    @property
    def n_base_v(self) -> int:
        return 6 if self.spec.floating_base else 0

    def frame_pose(self, frame: str) -> tuple[FloatArray, FloatArray]:
        """(position (3,), rotation (3, 3)) after the last forward kinematics."""
        m = self.data.oMf[self.frame_ids[frame]]
        return np.array(m.translation), np.array(m.rotation)


def build_humanoid(spec: RobotSpec) -> Humanoid:
    import pinocchio as pin

    if not spec.urdf.is_file():
        raise FileNotFoundError(f"robot {spec.name}: URDF {spec.urdf} not found")
    try:
        if spec.floating_base:
            model = pin.buildModelFromUrdf(str(spec.urdf), pin.JointModelFreeFlyer())
        else:
            model = pin.buildModelFromUrdf(str(spec.urdf))
    except (RuntimeError, ValueError) as exc:
        raise FileFormatError(f"{spec.urdf}: Pinocchio cannot parse this URDF ({exc})") from exc
    frames = [k.frame for k in spec.keypoints] + [f.frame for f in spec.feet]
    if spec.root_frame:
        frames.append(spec.root_frame)
    known = sorted({f.name for f in model.frames if f.type == pin.FrameType.BODY})
    for f in frames:
        if not model.existFrame(f):
            raise ConfigError(
                f"robot {spec.name} ({spec.source}): no frame {f!r} in {spec.urdf.name}; its "
                f"links: {', '.join(known)}"
            )
    nb = 7 if spec.floating_base else 0
    q_min = np.array(model.lowerPositionLimit, dtype=float)
    q_max = np.array(model.upperPositionLimit, dtype=float)
    if nb:
        q_min[:nb], q_max[:nb] = -np.inf, np.inf
    q = np.array(pin.neutral(model), dtype=float)
    names = list(model.names)
    for jname, value in spec.q_ref.items():
        if jname not in names:
            raise ConfigError(f"robot {spec.name}: q_ref names no joint {jname!r}")
        q[model.joints[model.getJointId(jname)].idx_q] = value
    inner_lo, inner_hi = q_min + MARGIN, q_max - MARGIN
    ok = inner_lo <= inner_hi
    q[ok] = np.clip(q[ok], inner_lo[ok], inner_hi[ok])
    v = np.array(model.velocityLimit, dtype=float)
    v = np.where((v > 0) & (v < 100), v, spec.velocity_limit_default)
    if nb:
        v[:6] = np.inf
    data = model.createData()
    ids = {f: model.getFrameId(f) for f in frames}
    one = [j for j in range(2 if nb else 1, model.njoints)
           if model.joints[j].nq == 1 and model.joints[j].nv == 1]  # fmt: skip
    iq = np.array([model.joints[j].idx_q for j in one], dtype=np.int64)
    iv = np.array([model.joints[j].idx_v for j in one], dtype=np.int64)
    hum = Humanoid(spec, model, data, q, q_min, q_max, v, ids, tuple(names[2 if nb else 1 :]),
                   np.zeros(3), iq, iv)  # fmt: skip
    _stand(hum)
    return hum


def _stand(h: Humanoid) -> None:
    """Put the reference configuration's soles on z = 0 and its front towards +x."""
    import pinocchio as pin

    pin.framesForwardKinematics(h.model, h.data, h.q_ref)
    feet = {f.segment: f for f in h.spec.feet}
    if "foot_r" in feet and "foot_l" in feet:
        pr, _ = h.frame_pose(feet["foot_r"].frame)
        pl, _ = h.frame_pose(feet["foot_l"].frame)
        lateral = pl - pr
    else:
        pairs = [("hand_r", "hand_l"), ("upper_arm_r", "upper_arm_l"), ("thigh_r", "thigh_l")]
        found = None
        for r, left in pairs:
            kr, kl = h.spec.keypoint(r), h.spec.keypoint(left)
            if kr and kl:
                found = h.frame_pose(kl.frame)[0] - h.frame_pose(kr.frame)[0]
                break
        if found is None:
            raise ConfigError(f"robot {h.spec.name}: no left/right pair to find its front")
        lateral = found
    lateral[2] = 0.0
    lateral /= max(float(np.linalg.norm(lateral)), 1e-9)
    forward = np.cross(lateral, [0.0, 0.0, 1.0])  # left x up = forward
    yaw = float(np.arctan2(forward[1], forward[0]))
    if h.spec.floating_base:
        rot = pin.utils.rpyToMatrix(0.0, 0.0, -yaw)
        base = pin.XYZQUATToSE3(h.q_ref[:7])
        base = pin.SE3(rot, np.zeros(3)) * base
        h.q_ref[:7] = pin.SE3ToXYZQUAT(base)
        pin.framesForwardKinematics(h.model, h.data, h.q_ref)
        if feet:
            soles = [h.frame_pose(f.frame)[0] + h.frame_pose(f.frame)[1] @ f.sole for f in
                     feet.values()]  # fmt: skip
            h.q_ref[2] -= min(s[2] for s in soles)
        pin.framesForwardKinematics(h.model, h.data, h.q_ref)
        lateral = np.array([0.0, 1.0, 0.0])
    h.lateral = lateral
    h.ref_pose = {f: h.frame_pose(f) for f in h.frame_ids}
