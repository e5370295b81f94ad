"""A simulated operator for the paper's evaluation (Miller et al., section 5, Figs. 8-9).

The operator is the body model itself (:mod:`mocapkit.body`): a sensor tree (default the
paper's ``right_arm_2``; ``right_arm_torso_3`` adds the section-6 torso sensor) whose
coordinates (OpenSim names and senses, ``arm_flex_r``, ``arm_add_r``, ``arm_rot_r``,
``elbow_flex_r``, ``pro_sup_r``) are the simulated truth. So the body model's output can be
compared with the truth coordinate by coordinate, and the segment orientations are
exactly what the body model would reconstruct from perfect sensors.

A session, as a real one runs:

1. ``calib_s``: the operator stands still in the calibration pose (N-pose: arms at the
   sides, palms to the thighs, ``pro_sup_r = 90 deg``); the sensors initialise (still
   start) in the first second and the body model calibrates from the last second but
   0.2 s (``calib_window``);
2. ``reach_s``: the hand rises to a working point in front of the chest (forearm forward);
3. ``settle_s``: held still there; the session is engaged (reindexing) in this phase;
4. ``shape_s``: the hand traces one of the six shapes (vertical, horizontal, diagonal,
   circle, box, infinity) in the frontal plane, time-smoothed, starting and ending at the
   working point (so a recording loops);
5. ``hold_s``: held still.

The arm motion during the shape comes from position-only damped-least-squares IK on the
four arm coordinates (pronation stays neutral), continued from the previous frame.

Frames: the world is ENU (z up); the operator faces ``heading_rad`` from world x. Segment
frames are OpenSim's (x anterior, y up, z right), placed in the world by
``q_world_ground = Rz(heading) Rx(90 deg)`` (:func:`mocapkit.body.calibration.q_world_ground`).
Positions come from the tree's segment offsets [m].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.calibration import POSES_DEG, q_world_ground
from mocapkit.body.joint_angles import compose_pose
from mocapkit.body.segment_points import segment_points
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_mul, quat_rotate
from mocapkit.series import JointAngleSeries

SHAPES = ("vertical", "horizontal", "diagonal", "circle", "box", "infinity")
ARM = "humerus_r"
FOREARM = "radius_r"
#: Coordinates the IK moves to trace a shape.
IK_COORDS = ("arm_flex_r", "arm_add_r", "arm_rot_r", "elbow_flex_r")
#: Working posture [deg]: upper arm a little forward and out, elbow at 90 deg, forearm
#: forward, palm facing medially.
WORK_POSTURE_DEG = {
    "arm_flex_r": 30.0,
    "arm_add_r": -10.0,
    "arm_rot_r": 10.0,
    "elbow_flex_r": 90.0,
    "pro_sup_r": 90.0,
}
#: The hand point on the forearm segment (palm centre, beyond the wrist) [m].
HAND_IN_FOREARM = np.array([0.0, -0.32, 0.0])


def shape_path(shape: str, s: FloatArray, size_m: float = 0.10) -> FloatArray:
    """Displacement (N, 3) [m] in the frontal plane (forward, left, up) for the path
    parameter ``s`` in [0, 1]; every shape starts and ends at its centre (0, 0, 0)."""
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
        # centre -> top-middle -> the four corners -> back, piecewise linear, side 2 size
        pts = size_m * np.array(
            [[0, 0], [0, 1], [1, 1], [1, -1], [-1, -1], [-1, 1], [0, 1], [0, 0]], dtype=float
        )
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        cum = np.concatenate([[0], np.cumsum(seg)]) / seg.sum()
        y = np.interp(s, cum, pts[:, 0])
        z = np.interp(s, cum, pts[:, 1])
    elif shape == "infinity":
        y, z = size_m * np.sin(a), 0.5 * size_m * np.sin(2 * a)
    return np.stack([np.zeros_like(s), y, z], axis=-1)


@dataclass(frozen=True)
class OperatorMotion:
    """The operator's truth over time.

    Attributes:
        time: (N,) [s].
        tree: the sensor tree (the body model the operator is made of).
        coordinates: truth joint angles (the tree's coordinates) [rad].
        q_world_segment: (N, S, 4) segment orientations (tree order), ENU world.
        p_world_segment: (N, S, 3) segment origins (proximal joints) [m].
        hand: (N, 3) the hand point [m], world.
        heading_rad: the direction the operator faces [rad from world x].
        calib_window: (t0, t1) [s] of the still calibration pose.
        engage_t: when the evaluation engages the session [s] (working point, still).
        shape_start, shape_end: the shape's time span [s].
    """

    time: FloatArray
    tree: SensorTree
    coordinates: JointAngleSeries
    q_world_segment: FloatArray
    p_world_segment: FloatArray
    hand: FloatArray
    heading_rad: float
    calib_window: tuple[float, float]
    engage_t: float
    shape_start: float
    shape_end: float

    def segment_index(self, name: str) -> int:
        return self.tree.segment_names.index(name)


def _smooth(u: FloatArray) -> FloatArray:
    """0 -> 1 with zero velocity and acceleration at both ends (quintic)."""
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2)


class _ArmKinematics:
    """Segment orientations, origins and the hand point for given coordinates."""

    def __init__(self, tree: SensorTree, heading_rad: float) -> None:
        for seg in (ARM, FOREARM):
            if seg not in tree.segment_names:
                raise ConfigError(
                    f"operator: tree {tree.name!r} has no segment {seg!r}; use a right-arm "
                    "preset (right_arm_2, right_arm_torso_3, right_arm_hand_3)"
                )
        self.tree = tree
        self.q_wg = q_world_ground(heading_rad)
        self.fore = tree.segment_names.index(FOREARM)
        base = {k: np.deg2rad(v) for k, v in POSES_DEG["npose"].items()}
        self.base = {k: v for k, v in base.items() if k in tree.coordinate_names}

    def orientations(self, coords: dict[str, FloatArray]) -> FloatArray:
        q_g = compose_pose(self.tree, coords)
        return quat_mul(self.q_wg, q_g)

    def hand(self, coords: dict[str, FloatArray]) -> tuple[FloatArray, FloatArray, FloatArray]:
        q = self.orientations(coords)
        p, _ = segment_points(self.tree, q, self.q_wg)
        hand = p[..., self.fore, :] + quat_rotate(q[..., self.fore, :], HAND_IN_FOREARM)
        return hand, q, p


def _ik(kin: _ArmKinematics, coords: dict[str, float], target: FloatArray) -> dict[str, float]:
    """Position-only DLS on IK_COORDS from ``coords`` (finite-difference Jacobian)."""
    x = np.array([coords[c] for c in IK_COORDS])
    eps = 1e-6
    for _ in range(30):
        cand = np.vstack([x, x + eps * np.eye(len(x))])  # (5, 4): x and its perturbations
        vals = {k: np.full(len(cand), v) for k, v in coords.items()}
        for j, c in enumerate(IK_COORDS):
            vals[c] = cand[:, j]
        h, _, _ = kin.hand(vals)
        e = target - h[0]
        if np.linalg.norm(e) < 1e-7:
            break
        J = ((h[1:] - h[0]) / eps).T  # (3, 4)
        x = x + J.T @ np.linalg.solve(J @ J.T + 1e-6 * np.eye(3), e)
    out = dict(coords)
    out.update({c: float(v) for c, v in zip(IK_COORDS, x, strict=True)})
    return out


def operator_motion(
    shape: str,
    tree: SensorTree | None = None,
    rate_hz: float = 100.0,
    calib_s: float = 2.0,
    reach_s: float = 2.0,
    settle_s: float = 1.0,
    shape_s: float = 6.0,
    hold_s: float = 1.0,
    size_m: float = 0.10,
    heading_rad: float = 0.0,
) -> OperatorMotion:
    """The operator's motion for one shape (see the module docstring)."""
    tree = tree or SensorTree.preset("right_arm_2")
    kin = _ArmKinematics(tree, heading_rad)
    n = round((calib_s + reach_s + settle_s + shape_s + hold_s) * rate_hz)
    t = np.arange(n) / rate_hz
    names = tree.coordinate_names
    start = {c: kin.base.get(c, 0.0) for c in names}
    work = dict(start)
    work.update({c: float(np.deg2rad(v)) for c, v in WORK_POSTURE_DEG.items() if c in names})
    t_reach = calib_s
    t_shape = calib_s + reach_s + settle_s
    s = _smooth((t - t_shape) / shape_s)
    centre, _, _ = kin.hand({c: np.asarray(v) for c, v in work.items()})
    disp = shape_path(shape, s, size_m)
    # the frontal plane of the operator: (forward, left, up) turned by the heading
    c, si = np.cos(heading_rad), np.sin(heading_rad)
    R_world_body = np.array([[c, -si, 0.0], [si, c, 0.0], [0.0, 0.0, 1.0]])
    values = np.empty((n, len(names)))
    prev = work
    for k in range(n):
        if t[k] < t_shape:
            u = float(_smooth(np.array((t[k] - t_reach) / reach_s)))
            cur = {c: start[c] + u * (work[c] - start[c]) for c in names}
        else:
            cur = _ik(kin, prev, centre + R_world_body @ disp[k])
            prev = cur
        values[k] = [cur[c] for c in names]
    return motion_from_coordinates(
        tree,
        t,
        values,
        heading_rad,
        calib_window=(max(0.0, calib_s - 1.0), calib_s - 0.2),
        engage_t=t_shape - 0.5 * settle_s,
        shape_span=(t_shape, t_shape + shape_s),
    )


def npose_coordinates(tree: SensorTree) -> FloatArray:
    """The calibration pose (N-pose) as the tree's coordinates (K,) [rad]."""
    base = {k: np.deg2rad(v) for k, v in POSES_DEG["npose"].items()}
    return np.array([base.get(c, 0.0) for c in tree.coordinate_names])


def motion_from_coordinates(
    tree: SensorTree,
    time: FloatArray,
    values: FloatArray,
    heading_rad: float,
    calib_window: tuple[float, float],
    engage_t: float,
    shape_span: tuple[float, float],
) -> OperatorMotion:
    """The operator's truth from its coordinates (N, K) [rad] (the tree's, in order) at
    ``time`` (N,) [s]: segment orientations and origins, the hand point, by the body
    model's own forward kinematics."""
    kin = _ArmKinematics(tree, heading_rad)
    names = tree.coordinate_names
    coords = {c: values[:, j] for j, c in enumerate(names)}
    hand, q, p = kin.hand(coords)
    series = JointAngleSeries(time, names, values, name="operator")
    return OperatorMotion(
        time,
        tree,
        series,
        q,
        p,
        hand,
        heading_rad,
        calib_window,
        engage_t,
        shape_span[0],
        shape_span[1],
    )
