"""Robonaut 2's arms, written here from the joint origins, axes and limits of the public
R2 URDF (``r2c6.urdf``, NASA Open Source Agreement 1.3: we use its numbers to build our
own model and do not ship the file).

Miller et al. (section 5, Fig. 7): 7 DOF per arm, "2 in the shoulder, 1 in the upper
arm, 1 in the elbow, 1 in the lower arm, and 2 in the wrist":

=====================  ======================  ==========================
joint                  role                    right-arm limits [rad]
=====================  ======================  ==========================
``joint0``             shoulder roll           [-2.8270, 2.8270]
``joint1``             shoulder pitch          [-1.6758, 0.4292]
``joint2``             upper-arm roll          [0.3318, 4.5028]
``joint3``             elbow                   [-2.7930, 0.0]
``joint4``             forearm roll            [-4.6770, 1.5360]
``wrist/pitch``        wrist pitch             [-0.8, 0.8]
``wrist/yaw``          wrist yaw               [-0.15, 0.75]
=====================  ======================  ==========================

Every joint rotates about its frame's z axis; origins are URDF ``xyz`` [m] and ``rpy``
[rad] (``R = Rz(yaw) Ry(pitch) Rx(roll)``), parent to child. The URDF's velocity
limit (1000) is a placeholder; ours (``VELOCITY_LIMIT``) are typical of a
human-speed arm and documented as our choice.

The command frame is the chest: origin midway between the two shoulder JR3 frames,
x forward, y left, z up (the URDF's world axes; its torso frame ``waist_center``
has y and z flipped), with the waist joint at zero.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import pinocchio as pin

from mocapkit.errors import ConfigError
from mocapkit.robot.model import ArmModel

Side = Literal["right", "left"]


@dataclass(frozen=True)
class _Origin:
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]

    def se3(self) -> pin.SE3:
        return pin.SE3(pin.rpy.rpyToMatrix(*self.rpy), np.array(self.xyz))


@dataclass(frozen=True)
class _Joint:
    name: str  # suffix after "r2/<side>_arm/"
    origin: _Origin  # placement in the previous joint's frame (after fixed links)
    lower: float
    upper: float


# waist_center -> shoulder JR3 frame, and the chest frame in waist_center
_SHOULDER = {
    "right": _Origin((-0.0240898, 0.0996837, -0.413899), (0.0, 0.0, -1.83259)),
    "left": _Origin((-0.0240898, -0.0996837, -0.413899), (0.0, 0.0, 1.8326)),
}
_CHEST_IN_WAIST_CENTER = _Origin((-0.0240898, 0.0, -0.413899), (np.pi, 0.0, 0.0))

# The two fixed links between joint4 and the wrist (forearm JR3, then lower arm),
# identical on both sides; folded into the wrist-pitch placement below.
_FOREARM_FIXED = (
    _Origin((0.0, 0.0, 0.0897574), (3.1416, 0.0, 0.78539)),
    _Origin((0.0, 0.0, 0.0897574), (3.1416, 0.0, 0.7854)),
)

_JOINTS: dict[str, tuple[_Joint, ...]] = {
    "right": (
        _Joint("joint0", _Origin((0.0054611, 0.0, -0.13041), (0.0, -1.5708, 0.0)), -2.8270, 2.8270),
        _Joint(
            "joint1", _Origin((0.0, -0.0466596, 0.210022), (0.0, -1.5708, 1.5708)), -1.6758, 0.4292
        ),
        _Joint(
            "joint2", _Origin((0.169324, 0.0, -0.0458976), (-1.5708, 0.0, -1.5708)), 0.3318, 4.5028
        ),
        _Joint(
            "joint3", _Origin((0.05334, -0.0313243, 0.185006), (0.0, -1.5708, 1.5708)), -2.7930, 0.0
        ),
        _Joint(
            "joint4",
            _Origin((0.0541223, 0.0533300, -0.0305397), (-0.9550, 1.5708, -0.9550)),
            -4.6770,
            1.5360,
        ),
        _Joint("wrist/pitch", _Origin((-0.000616510, 0.0, 0.301768), (0.0, -1.5708, 0.0)), -0.8, 0.8),  # noqa: E501
        _Joint(
            "wrist/yaw", _Origin((0.00635, 0.0, -0.00041451), (1.5708, 0.0646, -0.0802)), -0.15, 0.75  # noqa: E501
        ),
    ),
    "left": (
        _Joint("joint0", _Origin((0.0054611, 0.0, -0.13041), (0.0, -1.5708, 0.0)), -2.8270, 2.8270),
        _Joint(
            "joint1", _Origin((0.0, 0.0466596, 0.210022), (0.0, -1.5708, 1.5708)), -1.6758, 0.4292
        ),
        _Joint(
            "joint2", _Origin((0.169324, 0.0, 0.0458976), (-1.5708, 0.0, -1.5708)), -4.5028, -0.3318
        ),
        _Joint(
            "joint3", _Origin((0.05334, 0.0313243, 0.185006), (0.0, -1.5708, 1.5708)), -2.7930, 0.0
        ),
        _Joint(
            "joint4",
            _Origin((0.0541223, 0.0533300, 0.0305397), (-0.9550, 1.5708, -0.9550)),
            -1.5360,
            4.6770,
        ),
        _Joint("wrist/pitch", _Origin((0.000616510, 0.0, 0.301768), (0.0, -1.5708, 0.0)), -0.8, 0.8),  # noqa: E501
        _Joint(
            "wrist/yaw", _Origin((0.00635, 0.0, 0.00041451), (1.5708, 0.0646, -0.0802)), -0.75, 0.15
        ),
    ),
}  # fmt: skip

# Palm centre in the wrist-yaw frame: 60 mm towards the finger bases (the middle finger's
# base is at x = 0.1065 m), at the finger bases' depth (z = -0.0162 m).
_TOOL = {"right": (0.06, 0.0, -0.0161544), "left": (0.06, 0.0, -0.0161544)}

#: Our joint speed limits [rad/s] (shoulder, upper arm, elbow, forearm, wrist x2).
VELOCITY_LIMIT = np.array([1.5, 1.5, 2.0, 2.0, 2.5, 3.0, 3.0])

#: Ready posture [rad]: upper arm down and slightly forward, elbow bent 90 degrees,
#: forearm pointing forward, wrist neutral (away from singularities and limits).
READY_POSTURE = {
    "right": np.array([0.3, -1.3, 1.7, -1.6, -1.5, 0.0, 0.3]),
    "left": np.array([-0.3, -1.3, -1.7, -1.6, 1.5, 0.0, -0.3]),
}


def joint_names(side: Side = "right") -> tuple[str, ...]:
    """Full R2 joint names of one arm, e.g. ``r2/right_arm/joint0``."""
    _check_side(side)
    return tuple(f"r2/{side}_arm/{j.name}" for j in _JOINTS[side])


def _check_side(side: str) -> None:
    if side not in ("right", "left"):
        raise ConfigError(f"side: expected 'right' or 'left', got {side!r}")


def robonaut2_arm(side: Side = "right", q_ref: np.ndarray | None = None) -> ArmModel:
    """Robonaut 2's 7-DOF arm as an :class:`ArmModel` in the chest frame.

    Frames added: ``chest`` (the universe), ``shoulder`` (the JR3 frame), one body
    frame per joint's child link (``r2/<side>_arm/<joint>``), ``palm`` (wrist-yaw
    frame) and ``tool`` (palm centre, the end effector).
    """
    _check_side(side)
    model = pin.Model()
    model.name = f"robonaut2-{side}"
    T_wc_chest = _CHEST_IN_WAIST_CENTER.se3()
    T_chest_shoulder = T_wc_chest.inverse() * _SHOULDER[side].se3()
    model.addFrame(pin.Frame("chest", 0, 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
    model.addFrame(pin.Frame("shoulder", 0, 0, T_chest_shoulder, pin.FrameType.OP_FRAME))
    parent = 0
    for k, joint in enumerate(_JOINTS[side]):
        pre = T_chest_shoulder if k == 0 else pin.SE3.Identity()
        if joint.name == "wrist/pitch":
            # fold the two fixed forearm links in front of the wrist pitch
            pre = _FOREARM_FIXED[0].se3() * _FOREARM_FIXED[1].se3()
        placement = pre * joint.origin.se3()
        name = f"r2/{side}_arm/{joint.name}"
        jid = model.addJoint(
            parent,
            pin.JointModelRZ(),
            placement,
            name,
            np.array([100.0]),
            np.array([VELOCITY_LIMIT[k]]),
            np.array([joint.lower]),
            np.array([joint.upper]),
        )
        model.appendBodyToJoint(jid, pin.Inertia.Zero(), pin.SE3.Identity())
        model.addFrame(pin.Frame(name, jid, 0, pin.SE3.Identity(), pin.FrameType.BODY))
        parent = jid
    model.addFrame(pin.Frame("palm", parent, 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
    tool = pin.SE3(np.eye(3), np.array(_TOOL[side]))
    model.addFrame(pin.Frame("tool", parent, 0, tool, pin.FrameType.OP_FRAME))
    return ArmModel(
        model,
        ee_frame="tool",
        velocity_limit=VELOCITY_LIMIT,
        q_ref=READY_POSTURE[side] if q_ref is None else q_ref,
        name=model.name,
    )
