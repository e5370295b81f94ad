"""Segment orientations <-> BVH channels (the maths side of :mod:`mocapkit.io.bvh`).

BVH's world is y-up, like OpenSim's ground frame, and our segment frames are all aligned
with ground at zero pose, so a joint's BVH rotation is just ``q_parent_child`` (the root's
is ``q_ground_root``), written as ``Zrotation Xrotation Yrotation`` (``R = Rz Rx Ry``,
intrinsic ZXY, OpenSim's hip and shoulder order) in degrees. Offsets come from the tree.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.sensor_tree import GROUND, SensorTree
from mocapkit.errors import ConfigError, DataError
from mocapkit.geometry import euler_from_quat, quat_conj, quat_from_euler, quat_mul
from mocapkit.io.bvh import BvhJoint, BvhMotion
from mocapkit.series import OrientationSeries

ROTATION_CHANNELS = ("Zrotation", "Xrotation", "Yrotation")
POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
_SEQ = "ZXY"


def _hold_nan_rows(x: FloatArray) -> tuple[FloatArray, int]:
    """Fill non-finite rows with the previous finite row (the first finite row backwards)."""
    good = np.isfinite(x).all(axis=1)
    if good.all():
        return x, 0
    if not good.any():
        raise DataError("no frame with a valid orientation to write")
    idx = np.where(good, np.arange(len(x)), -1)
    idx = np.maximum.accumulate(idx)
    first = int(np.flatnonzero(good)[0])
    idx[idx < 0] = first
    return x[idx], int((~good).sum())


def bvh_from_segments(
    tree: SensorTree,
    segments: Mapping[str, OrientationSeries],
    q_world_ground: FloatArray,
    *,
    bone_names: Mapping[str, str] | None = None,
    scale: float = 100.0,
) -> BvhMotion:
    """BVH motion of the tree's segments ``{segment: q_world_segment}`` (one time base).

    Args:
        q_world_ground: (4,) the ground frame (BodyCalibration.q_world_ground).
        bone_names: {segment: BVH joint name}; default the segment names.
        scale: file length units per metre (100: centimetres, the usual BVH unit).

    A tree with several roots gets a fixed ``Ground`` root joint. Frames where a segment
    is unknown (NaN) repeat the last known rotation (``meta["held_frames"]``), because
    BVH cannot store gaps.
    """
    names = dict(bone_names or {})
    unknown = sorted(set(names) - set(tree.segment_names))
    if unknown:
        raise ConfigError(
            f"bone_names: unknown segment(s) {', '.join(unknown)}; segments: "
            f"{', '.join(tree.segment_names)}"
        )
    bone = [names.get(s.name, s.name) for s in tree.segments]
    roots = [i for i, s in enumerate(tree.segments) if s.parent == GROUND]
    time = segments[tree.segments[0].name].time
    q = np.stack([segments[s.name].quat for s in tree.segments], axis=1)  # (N, S, 4)
    q_g = quat_mul(quat_conj(q_world_ground), q)  # q_ground_segment
    parents = tree.parent_index
    joints: list[BvhJoint] = []
    columns: list[FloatArray] = []
    offset_root = 0
    if len(roots) > 1:
        joints.append(BvhJoint("Ground", -1, np.zeros(3), POSITION_CHANNELS + ROTATION_CHANNELS))
        columns.append(np.zeros((len(time), 6)))
        offset_root = 1
    index: dict[int, int] = {}
    children = {i: [k for k in range(len(parents)) if parents[k] == i] for i in range(len(parents))}
    for i, seg in enumerate(tree.segments):  # parents come first in the tree: valid BVH order
        p = parents[i]
        rel = q_g[:, i] if p < 0 else quat_mul(quat_conj(q_g[:, p]), q_g[:, i])
        valid = np.asarray(np.isfinite(rel).all(axis=1))
        safe = np.where(valid[:, None], rel, np.array([1.0, 0.0, 0.0, 0.0]))
        euler = np.rad2deg(euler_from_quat(safe, _SEQ))
        euler[~valid] = np.nan
        is_root = p < 0 and offset_root == 0
        parent_joint = -1 if is_root else (0 if p < 0 else index[p])
        channels = (POSITION_CHANNELS if is_root else ()) + ROTATION_CHANNELS
        end = seg.end * scale if not children[i] else None
        joints.append(BvhJoint(bone[i], parent_joint, seg.offset * scale, channels, end))
        if is_root:
            columns.append(np.tile(seg.offset * scale, (len(time), 1)))
        columns.append(euler)
        index[i] = len(joints) - 1
    if len(set(bone)) != len(bone):
        raise ConfigError(f"bone_names: names must be unique, got {bone}")
    values, held = _hold_nan_rows(np.hstack(columns))
    dt = float(np.median(np.diff(time))) if len(time) > 1 else 0.01
    return BvhMotion(tuple(joints), dt, values, meta={"held_frames": held})


def local_rotations(motion: BvhMotion) -> dict[str, FloatArray]:
    """{joint name: (N, 4) local rotation ``q_parent_joint``} from a BVH's rotation channels
    (any order of the three rotation channels)."""
    out = {}
    for j in motion.joints:
        rot = [c for c in j.channels if c.endswith("rotation")]
        if len(rot) != 3:
            continue
        cols = [j.channels.index(c) for c in rot]
        seq = "".join(c[0] for c in rot).upper()
        vals = motion.joint_channels(j.name)[:, cols]
        out[j.name] = quat_from_euler(np.deg2rad(vals), seq)
    return out
