"""The demo's simulated operator (kept for ``mocapkit.demo.operator_cycle``): a Pinocchio
human arm of its own. The evaluation's operator is :mod:`mocapkit.teleop.operator`, made
of the body model itself (its truth is the body model's coordinates).

A human right arm (Pinocchio, OpenSim coordinate names and senses: ``arm_flex_r`` about
the lateral axis, ``arm_add_r`` about the forward axis, ``arm_rot_r`` about the humerus,
``elbow_flex_r``, ``pro_sup_r`` about the forearm, ``wrist_flex_r``, ``wrist_dev_r``)
hangs in the suit's initialisation posture at zero, except ``pro_sup_r = 90 deg``
(palm towards the thigh). Its hand traces one of six shapes in a vertical plane in front
of the chest; the arm motion comes from position-only damped-least-squares IK along the
path (continuous, from the previous solution).

Frames: the chest frame (x forward, y left, z up), which is also the world frame of the
simulation (the operator faces world +x).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError
from mocapkit.robot.ik import IkParams, solve_ik
from mocapkit.robot.model import ArmModel
from mocapkit.series import JointAngleSeries

SHAPES = ("vertical", "horizontal", "diagonal", "circle", "box", "infinity")
HUMAN_COORDS = (
    "arm_flex_r",
    "arm_add_r",
    "arm_rot_r",
    "elbow_flex_r",
    "pro_sup_r",
    "wrist_flex_r",
    "wrist_dev_r",
)
#: segment -> frame of the human arm model
SEGMENT_FRAMES = {"humerus_r": "arm_rot_r", "radius_r": "pro_sup_r", "hand_r": "wrist_dev_r"}
INIT_POSTURE = np.radians([0.0, 0.0, 0.0, 0.0, 90.0, 0.0, 0.0])


def human_right_arm(
    upper_arm_m: float = 0.30, forearm_m: float = 0.27, hand_m: float = 0.08
) -> ArmModel:
    """Human right arm in the chest frame (shoulder 0.18 m to the right, at chest height)."""
    m = pin.Model()
    m.name = "human-right-arm"
    lateral = np.array([0.0, -1.0, 0.0])  # to the right: flexion positive forward
    spec = [
        ("arm_flex_r", lateral, np.array([0.0, -0.18, 0.0]), (-1.2, 3.0)),
        ("arm_add_r", np.array([1.0, 0.0, 0.0]), np.zeros(3), (-2.5, 0.6)),
        ("arm_rot_r", np.array([0.0, 0.0, 1.0]), np.zeros(3), (-1.5, 1.5)),
        ("elbow_flex_r", lateral, np.array([0.0, 0.0, -upper_arm_m]), (0.0, 2.6)),
        ("pro_sup_r", np.array([0.0, 0.0, 1.0]), np.zeros(3), (-0.5, 2.8)),
        ("wrist_flex_r", lateral, np.array([0.0, 0.0, -forearm_m]), (-1.2, 1.2)),
        ("wrist_dev_r", np.array([1.0, 0.0, 0.0]), np.zeros(3), (-0.4, 0.6)),
    ]
    parent = 0
    for name, axis, offset, (lo, hi) in spec:
        jid = m.addJoint(
            parent,
            pin.JointModelRevoluteUnaligned(axis),
            pin.SE3(np.eye(3), offset),
            name,
            np.array([100.0]),
            np.array([10.0]),
            np.array([lo]),
            np.array([hi]),
        )
        m.appendBodyToJoint(jid, pin.Inertia.Zero(), pin.SE3.Identity())
        m.addFrame(pin.Frame(name, jid, 0, pin.SE3.Identity(), pin.FrameType.BODY))
        parent = jid
    m.addFrame(
        pin.Frame(
            "hand", parent, 0, pin.SE3(np.eye(3), np.array([0, 0, -hand_m])), pin.FrameType.OP_FRAME
        )
    )
    return ArmModel(m, "hand", np.full(7, 10.0), q_ref=INIT_POSTURE, name=m.name)


def shape_path(shape: str, s: FloatArray, size_m: float = 0.10) -> FloatArray:
    """Displacement (N, 3) [m] in the chest's y-z plane for path parameter s in [0, 1];
    every shape starts and ends at its centre (0, 0, 0), so recordings loop."""
    if shape not in SHAPES:
        raise ConfigError(f"shape: expected one of {', '.join(SHAPES)}, got {shape!r}")
    a = 2 * np.pi * s
    y = np.zeros_like(s)
    z = np.zeros_like(s)
    if shape == "vertical":
        z = size_m * np.sin(a)
    elif shape == "horizontal":
        y = size_m * np.sin(a)
    elif shape == "diagonal":
        y = z = size_m * np.sin(a) / np.sqrt(2)
    elif shape == "circle":
        y, z = size_m * np.sin(a), size_m * np.cos(a) - size_m  # starts at the top centre
    elif shape == "box":
        # centre -> top-middle -> corners -> back, piecewise linear, side 2 * size
        pts = size_m * np.array(
            [[0, 0], [0, 1], [1, 1], [1, -1], [-1, -1], [-1, 1], [0, 1], [0, 0]], dtype=float
        )
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        cum = np.concatenate([[0], np.cumsum(seg)]) / seg.sum()
        y = np.interp(s, cum, pts[:, 0])
        z = np.interp(s, cum, pts[:, 1])
    elif shape == "infinity":
        y, z = size_m * np.sin(a), 0.5 * size_m * np.sin(2 * a)
    return np.stack([np.zeros_like(s), y, z], axis=1)


@dataclass(frozen=True)
class OperatorMotion:
    """The operator's truth over time: human joint angles and segment orientations."""

    time: FloatArray  # (N,) [s]
    joints: JointAngleSeries  # human joint angles, OpenSim names
    R_segments: dict[str, FloatArray]  # segment -> (N, 3, 3) in the chest/world frame
    hand: FloatArray  # (N, 3) hand position [m]
    shape_start: float  # time the shape begins [s]
    shape_end: float


def _smooth(u: FloatArray) -> FloatArray:
    """0 -> 1 with zero velocity and acceleration at both ends (quintic)."""
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2)


def operator_motion(
    shape: str,
    rate_hz: float = 100.0,
    rest_s: float = 1.0,
    reach_s: float = 2.0,
    shape_s: float = 6.0,
    hold_s: float = 1.0,
    size_m: float = 0.10,
) -> OperatorMotion:
    """Rest in the initialisation posture, raise the hand to the working point, trace the
    shape once (time-smoothed), hold."""
    arm = human_right_arm()
    q_work = np.radians([35.0, 10.0, 20.0, 90.0, 90.0, 0.0, 0.0])  # forearm forward
    n = round((rest_s + reach_s + shape_s + hold_s) * rate_hz)
    t = np.arange(n) / rate_hz
    q = np.empty((n, arm.n))
    params = IkParams(rot_weight_m=1e-3, max_iters=50, tol_pos_m=1e-6, tol_rot_rad=10.0)
    centre = arm.fk(q_work)[:3, 3]
    t0, t1 = rest_s + reach_s, rest_s + reach_s + shape_s
    s = _smooth((t - t0) / shape_s)
    disp = shape_path(shape, s, size_m)
    prev = q_work.copy()
    hand = np.empty((n, 3))
    for k in range(n):
        if t[k] < t0:
            u = _smooth(np.array((t[k] - rest_s) / reach_s))
            q[k] = INIT_POSTURE + u * (q_work - INIT_POSTURE)
        else:
            target = arm.fk(prev)
            target[:3, 3] = centre + disp[k]
            res = solve_ik(arm, target, prev, params)
            # keep pronation and the wrist where they were: position-only task
            q[k] = res.q
            prev = res.q
        hand[k] = arm.fk(q[k])[:3, 3]
    R = {
        seg: np.stack([arm.frame_pose(qk, frame)[:3, :3] for qk in q])
        for seg, frame in SEGMENT_FRAMES.items()
    }
    joints = JointAngleSeries(t, HUMAN_COORDS, q, name="operator")
    return OperatorMotion(t, joints, R, hand, t0, t1)
