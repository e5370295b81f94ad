"""Virtual IMU suits on a moving body: known motion -> segment poses -> raw samples.

The closed-loop benchmark (``benchmarks/body_closed_loop.py``) drives a sensor tree with
marker-reconstructed human motion; the tests drive it with :func:`gait_coordinates`, a
walking pattern with exact answers. :func:`segment_poses` places every segment in the
world (orientations from the coordinates, positions down the tree from the offsets);
:func:`virtual_suit` straps one IMU on each segment with a random mounting and simulates
its raw samples (``mocapkit.imu.simulate``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.calibration import pose_coordinates, q_world_ground
from mocapkit.body.joint_angles import compose_pose
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.geometry import quat_exp, quat_mul, quat_rotate
from mocapkit.imu.simulate import ImuErrorModel, MagDisturbance, simulate_imu
from mocapkit.series import ImuRecording, PoseSeries

# Sagittal gait pattern (deg): mean, amplitude, phase [cycles] against the right hip.
_GAIT_DEG = {
    "hip_flexion": (10.0, 25.0, 0.0),
    "knee_angle": (25.0, 28.0, -0.2),
    "ankle_angle": (0.0, 10.0, 0.15),
    "arm_flex": (0.0, 18.0, 0.5),  # the arm swings against the leg of its side
    "elbow_flex": (25.0, 10.0, 0.45),
}
# Smaller motions about the base pose (deg): amplitude, cycles per stride, phase.
_SIDE_EXTRA_DEG = {
    "arm_add": (4.0, 1.0, 0.2),
    "arm_rot": (6.0, 1.0, 0.35),
    "pro_sup": (12.0, 1.0, 0.1),
    "wrist_flex": (12.0, 1.0, 0.6),
    "wrist_dev": (6.0, 2.0, 0.3),
    "hip_adduction": (4.0, 1.0, 0.25),
    "hip_rotation": (5.0, 1.0, 0.1),
    "subtalar_angle": (5.0, 1.0, 0.3),
}


# Trunk and head (deg): amplitude, cycles per stride, phase: the thorax turns against the
# pelvis, the trunk and head nod twice per stride.
_TRUNK_DEG = {
    "lumbar_rotation": (4.0, 1.0, 0.0),
    "lumbar_extension": (2.5, 2.0, 0.1),
    "lumbar_bending": (2.0, 1.0, 0.25),
    "neck_extension": (4.0, 2.0, 0.3),
    "neck_rotation": (3.0, 1.0, 0.4),
}


def gait_coordinates(
    tree: SensorTree,
    duration_s: float = 20.0,
    rate_hz: float = 100.0,
    still_s: float = 3.0,
    stride_s: float = 1.1,
) -> tuple[FloatArray, dict[str, FloatArray], float]:
    """(time, {coordinate: rad}, walk start [s]): ``still_s`` in the N-pose, then walking
    (sinusoidal hip, knee, ankle, arm and elbow flexion, the left side half a stride
    later; pelvis rotation +-5 deg and list +-3 deg in phase with the stride; the thorax
    turning against the pelvis, trunk and head nodding)."""
    n = round(duration_s * rate_hz)
    t = np.arange(n) / rate_hz
    npose = pose_coordinates(tree, "npose")
    ramp = np.clip((t - still_s) / 1.0, 0.0, 1.0)
    ramp = 0.5 - 0.5 * np.cos(np.pi * ramp)  # 1 s blend from the pose into the walk
    phase = 2.0 * np.pi * np.clip(t - still_s, 0.0, None) / stride_s
    coords: dict[str, FloatArray] = {}
    for name in tree.coordinate_names:
        base = npose.get(name, 0.0)
        walk = np.zeros(n)
        stem, side = name[:-2], name[-1:]
        if name.endswith(("_r", "_l")) and stem in _GAIT_DEG:
            mean, amp, ph = _GAIT_DEG[stem]
            ph += 0.5 if side == "l" else 0.0
            walk = np.radians(mean + amp * np.sin(phase - 2.0 * np.pi * ph))
        elif name.endswith(("_r", "_l")) and stem in _SIDE_EXTRA_DEG:
            amp, mult, ph = _SIDE_EXTRA_DEG[stem]
            ph += 0.5 if side == "l" else 0.0
            walk = base + np.radians(amp) * np.sin(mult * phase - 2.0 * np.pi * ph)
        elif name == "pelvis_rotation":
            walk = np.radians(5.0) * np.sin(phase)  # the right hip forward with its leg
        elif name == "pelvis_list":
            walk = np.radians(3.0) * np.sin(2.0 * phase)
        elif name in _TRUNK_DEG:
            amp, mult, ph = _TRUNK_DEG[name]
            walk = base + np.radians(amp) * np.sin(mult * phase - 2.0 * np.pi * ph)
        else:
            walk = np.full(n, base)
        coords[name] = base + ramp * (walk - base)
    return t, coords, still_s


def gait_root_path(
    time: FloatArray, walk_start_s: float = 3.0, stride_s: float = 1.1
) -> FloatArray:
    """(N, 3) the pelvis's bounce, surge and sway about its mean speed for
    :func:`gait_coordinates`' walk, in the body's ground frame (x forward, y up, z right;
    ``segment_poses(root_path=...)``): 2.5 cm up and down twice a stride (lowest at the heel
    strikes, when the hips are furthest apart), 1.5 cm forward and back as the walk slows at
    mid-stance, 2 cm to the side of the standing leg once a stride (peak accelerations ~3,
    ~2 and ~0.7 m/s^2, as measured at the pelvis in walking). Without them the pelvis
    glides at constant speed, which leaves its accelerometer nearly nothing to show."""
    ramp = np.clip((time - walk_start_s) / 1.0, 0.0, 1.0)
    ramp = 0.5 - 0.5 * np.cos(np.pi * ramp)
    phase = 2.0 * np.pi * np.clip(time - walk_start_s, 0.0, None) / stride_s
    up = 0.025 * np.cos(2.0 * phase)  # the right heel strikes at a quarter stride
    forward = -0.015 * np.sin(2.0 * phase)  # slowest at mid-stance, the highest point
    right = 0.02 * np.sin(phase - 0.5 * np.pi)  # over the right foot at half a stride
    return ramp[:, None] * np.column_stack([forward, up, right])


def segment_poses(
    tree: SensorTree,
    time: FloatArray,
    coords: Mapping[str, FloatArray],
    *,
    heading_rad: float = 0.0,
    speed: float = 1.2,
    walk_start_s: float = 0.0,
    root_path: FloatArray | None = None,
) -> dict[str, PoseSeries]:
    """World poses (ENU) of every segment: orientations from the coordinates, positions
    down the tree from the offsets, the root moving forward at ``speed`` [m/s] from
    ``walk_start_s``, the body facing ``heading_rad`` from world x. ``root_path``: (N, 3)
    added to the root's position, in the body's ground frame (x forward, y up, z right:
    OpenSim's pelvis_tx/ty/tz), e.g. a real walk's bounce and sway."""
    q_ground = compose_pose(tree, dict(coords))  # (N, S, 4)
    q_wg = q_world_ground(heading_rad)
    n = time.size
    p_ground = np.zeros((n, len(tree.segments), 3))
    forward = np.clip(time - walk_start_s, 0.0, None) * speed
    for i, seg in enumerate(tree.segments):
        offset = np.asarray(seg.offset, dtype=float)
        j = tree.parent_index[i]
        if j < 0:
            p_ground[:, i] = offset + np.outer(forward, [1.0, 0.0, 0.0])
            if root_path is not None:
                p_ground[:, i] += root_path
        else:
            p_ground[:, i] = p_ground[:, j] + quat_rotate(q_ground[:, j], offset)
    out = {}
    for i, seg in enumerate(tree.segments):
        q = quat_mul(q_wg, q_ground[:, i])
        p = quat_rotate(q_wg, p_ground[:, i])
        out[seg.name] = PoseSeries(time, q, p, name=seg.name)
    return out


def virtual_suit(
    tree: SensorTree,
    poses: Mapping[str, PoseSeries],
    rng: np.random.Generator,
    *,
    max_mount_deg: float = 30.0,
    errors: ImuErrorModel | None = None,
    disturbances: Mapping[str, Sequence[MagDisturbance]] | None = None,
) -> tuple[dict[str, ImuRecording], dict[str, FloatArray]]:
    """One IMU per segment, at the segment's middle, mounted up to ``max_mount_deg`` off
    the segment's axes (a random axis each): ({sensor: raw samples}, {segment:
    q_segment_sensor}). ``errors`` defaults to consumer grade; ``disturbances``: magnetic
    disturbances per segment name (e.g. the feet near a steel floor)."""
    errors = ImuErrorModel.consumer_grade() if errors is None else errors
    recs, mounts = {}, {}
    for seg in tree.segments:
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = math.radians(rng.uniform(0.0, max_mount_deg))
        mount = quat_exp(0.5 * angle * axis)
        pose = poses[seg.name]
        middle = 0.5 * np.asarray(seg.end, dtype=float)
        p = pose.pos + quat_rotate(pose.quat, np.tile(middle, (pose.time.size, 1)))
        sensor_pose = PoseSeries(pose.time, quat_mul(pose.quat, mount), p, name=seg.sensor)
        dist = tuple((disturbances or {}).get(seg.name, ()))
        recs[seg.sensor] = simulate_imu(
            sensor_pose, errors, disturbances=dist, rng=rng, name=seg.sensor
        )
        mounts[seg.name] = mount
    return recs, mounts
