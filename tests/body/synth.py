"""Synthetic sensor orientations with exact answers: a tree moved through known coordinates,
seen by sensors with known mountings."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from mocapkit.body.calibration import q_world_ground
from mocapkit.body.joint_angles import compose_pose
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.geometry import quat_conj, quat_from_rotvec, quat_mul
from mocapkit.series import OrientationSeries


def random_mountings(tree: SensorTree, rng: np.random.Generator) -> np.ndarray:
    """(S, 4) arbitrary ``q_sensor_segment`` (any rotation, up to 180 deg)."""
    v = rng.normal(size=(len(tree.segments), 3))
    v *= (rng.uniform(0.0, np.pi, len(v)) / np.linalg.norm(v, axis=1))[:, None]
    return quat_from_rotvec(v)


def gait_like(
    tree: SensorTree,
    time: np.ndarray,
    still_s: float,
    pose: Mapping[str, float],
    amplitude: float = 0.4,
    seed: int = 0,
) -> dict[str, np.ndarray]:
    """Coordinates [rad]: the pose while t < still_s, then flexion-dominated motion at
    1 Hz (knees and elbows flex positive) plus small motion of every other coordinate;
    continuous at still_s."""
    rng = np.random.default_rng(seed)
    tau = np.maximum(time - still_s, 0.0)
    out = {}
    for c in tree.coordinate_names:
        base = pose.get(c, 0.0)
        if c.startswith(("knee_angle", "elbow_flex")):
            wave = amplitude * (1.0 - np.cos(2 * np.pi * tau))
        elif c.startswith(("hip_flexion", "ankle_angle", "arm_flex")):
            wave = amplitude * np.sin(2 * np.pi * tau)
        else:
            wave = 0.05 * np.sin(2 * np.pi * rng.uniform(0.3, 0.8) * tau)
        out[c] = base + wave
    return out


def sensor_orientations(
    tree: SensorTree,
    time: np.ndarray,
    coords: Mapping[str, np.ndarray],
    mountings: np.ndarray,
    heading_rad: float,
    sensor_yaw: np.ndarray | None = None,
) -> dict[str, OrientationSeries]:
    """``q_world_sensor`` of every sensor; ``sensor_yaw`` (S,) [rad] rotates each sensor's
    world about z (a 6D filter's own heading reference)."""
    q_wg = q_world_ground(heading_rad)
    q_gs = compose_pose(tree, coords)
    out = {}
    for i, s in enumerate(tree.segments):
        q = quat_mul(quat_mul(q_wg, q_gs[:, i]), quat_conj(mountings[i]))
        if sensor_yaw is not None:
            q = quat_mul(quat_from_rotvec([0.0, 0.0, sensor_yaw[i]]), q)
        out[s.sensor] = OrientationSeries(time, q, name=s.sensor)
    return out


def write_walk_mot(path, duration_s: float, still_s: float, speed: float = 1.2):  # type: ignore[no-untyped-def]
    """A synthetic full-body walk as a .mot (joint angles of ``full_body_15`` from
    :func:`mocapkit.body.simulate.gait_coordinates`, the pelvis standing ``still_s`` and
    then walking forward at ``speed`` [m/s], 0.93 m up); returns the written path."""
    from mocapkit.body.simulate import gait_coordinates
    from mocapkit.io.joint_angles_mot import write_joint_angles_mot

    tree = SensorTree.preset("full_body_15")
    t, coords, _ = gait_coordinates(tree, duration_s=duration_s, still_s=still_s)
    coords = dict(coords)
    coords["pelvis_tx"] = speed * np.clip(t - still_s, 0, None)
    coords["pelvis_ty"] = np.full_like(t, 0.93)
    coords["pelvis_tz"] = np.zeros_like(t)
    names = tuple(coords)
    values = np.column_stack([coords[n] for n in names])
    from mocapkit.series import JointAngleSeries

    return write_joint_angles_mot(path, JointAngleSeries(t, names, values))
