"""Joint angles from segment orientations: the readable reference implementation (numpy,
through :mod:`mocapkit.geometry`). The fast numba path is :mod:`mocapkit.body.kinematics`.

For a segment with parent p (seed eq. 16, ``q2_local = q1^-1 q2``):

    q_parent_child = q_world_parent^-1 * q_world_child          (p = ground for a root)
    q_joint        = q_F^-1 * q_parent_child * q_F       (F: the joint decomposition frame)
    (a1, a2, a3)   = euler(q_joint, "XYZ")      (intrinsic; F's axes in rotation order)
    coordinate     = sign * a + offset           (per slot; see JointSpec.slots)

Each coordinate is then unwrapped over time (no jumps of 2 pi), and where the middle angle
reaches +-90 deg (gimbal lock, only ``a1 +- a3`` defined) the third angle is held at its
previous value and the first takes the rest, so the output stays continuous.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.sensor_tree import SegmentSpec, SensorTree
from mocapkit.errors import ConfigError, DataError
from mocapkit.geometry import euler_from_quat, quat_conj, quat_from_euler, quat_mul
from mocapkit.series import JointAngleSeries, OrientationSeries

logger = logging.getLogger(__name__)

# Middle angles closer than this to +-90 deg are reported as "near gimbal lock": there the
# outer angles amplify orientation noise by 1/cos(middle) > 5.7.
NEAR_GIMBAL_DEG = 10.0


def _wrap(a: FloatArray) -> FloatArray:
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


def joint_tables(tree: SensorTree) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per segment, in the XYZ slots of its decomposition frame F: ``q_parent_F`` (S, 4),
    signs (S, 3) and offsets (S, 3) [rad]."""
    q_b = np.stack([s.joint.q_parent_joint for s in tree.segments])
    slots = [s.joint.slots() for s in tree.segments]
    signs = np.stack([sl[1] for sl in slots])
    offsets = np.stack([sl[2] for sl in slots])
    return q_b, signs, offsets


def coordinate_slots(tree: SensorTree) -> tuple[np.ndarray, np.ndarray]:
    """For each reported coordinate (in ``tree.coordinate_names`` order), its segment
    index and its XYZ slot (0-2) in the segment's decomposition frame."""
    seg, ang = [], []
    for i, s in enumerate(tree.segments):
        order = s.joint.slots()[0]
        for k, c in enumerate(s.joint.coordinates):
            if c is not None:
                seg.append(i)
                ang.append(order.index(k))
    return np.array(seg, dtype=np.int64), np.array(ang, dtype=np.int64)


def compose_pose(tree: SensorTree, coordinates: Mapping[str, Any]) -> FloatArray:
    """``q_ground_segment`` of every segment for the given coordinates [rad]: (S, 4) for
    scalar values, (N, S, 4) for arrays of N values (absent coordinates are zero). The
    inverse of the decomposition."""
    unknown = sorted(set(coordinates) - set(tree.coordinate_names))
    if unknown:
        raise ConfigError(
            f"coordinates {', '.join(unknown)} are not in tree {tree.name!r}; its coordinates: "
            f"{', '.join(tree.coordinate_names)}"
        )
    values = {k: np.asarray(v, dtype=np.float64) for k, v in coordinates.items()}
    shape = np.broadcast_shapes(*(v.shape for v in values.values())) if values else ()
    q_b, signs, offsets = joint_tables(tree)
    parents = tree.parent_index
    out = np.zeros((*shape, len(tree.segments), 4))
    for i, seg in enumerate(tree.segments):
        order = seg.joint.slots()[0]
        angles = np.zeros((*shape, 3))
        for j in range(3):
            c = seg.joint.coordinates[order[j]]
            # an unreported coordinate is a zero angle (not a zero coordinate)
            if c is not None and c in values:
                angles[..., j] = (values[c] - offsets[i, j]) / signs[i, j]
            elif c is not None:
                angles[..., j] = -offsets[i, j] / signs[i, j]
        q_joint = quat_from_euler(angles, "XYZ")
        q_rel = quat_mul(quat_mul(q_b[i], q_joint), quat_conj(q_b[i]))
        out[..., i, :] = q_rel if parents[i] < 0 else quat_mul(out[..., parents[i], :], q_rel)
    return out


def relative_rotations(
    q_world_segment: FloatArray, parents: np.ndarray, q_world_ground: FloatArray
) -> FloatArray:
    """(N, S, 4) ``q_parent_child`` from (N, S, 4) world orientations (NaN propagates)."""
    q_parent = np.where(
        (parents < 0)[None, :, None],
        np.broadcast_to(q_world_ground, q_world_segment.shape),
        q_world_segment[:, np.maximum(parents, 0)],
    )
    return quat_mul(quat_conj(q_parent), q_world_segment)


def unwrap_valid(x: FloatArray) -> FloatArray:
    """np.unwrap along time over the finite samples only (NaN gaps stay NaN; the first
    finite sample keeps its value, later ones are continued from the last finite one)."""
    out = x.copy()
    flat = out.reshape(out.shape[0], -1)
    for c in range(flat.shape[1]):
        good = np.isfinite(flat[:, c])
        if good.sum() > 1:
            flat[good, c] = np.unwrap(flat[good, c])
    return out


def hold_gimbal(angles: FloatArray, gimbal: np.ndarray) -> FloatArray:
    """Continuity through gimbal lock (..., intrinsic XYZ): hold the third angle at its
    last value outside the lock and give the first the rest (``a1 + s a3`` is what is
    defined, ``s = sign(a2)``). Works along the first (time) axis."""
    out = angles.copy()
    if not gimbal.any():
        return out
    n = out.shape[0]
    flat = out.reshape(n, -1, 3)
    gflat = gimbal.reshape(n, -1)
    for j in range(flat.shape[1]):
        last_third = 0.0
        for t in range(n):
            a = flat[t, j]
            if not np.isfinite(a).all():
                continue
            if gflat[t, j]:
                s = 1.0 if a[1] > 0.0 else -1.0
                # euler_from_quat put the whole rotation in the first angle (third = 0)
                a[0] = _wrap(np.array(a[0] - s * last_third))
                a[2] = last_third
            else:
                last_third = float(a[2])
    return out


@dataclass(frozen=True)
class BodyAngles:
    """Joint angles with what happened on the way.

    Attributes:
        angles: the coordinates over time [rad] (NaN where unknown).
        gimbal: {joint name: sample indices in exact gimbal lock (third angle held)}.
        near_gimbal: {joint name: number of samples within NEAR_GIMBAL_DEG of the lock}.
        missing: {coordinate: number of NaN samples}.
        held: {sensor: number of samples whose orientation was held (dropout="hold")}.
    """

    angles: JointAngleSeries
    gimbal: dict[str, np.ndarray] = field(default_factory=dict)
    near_gimbal: dict[str, int] = field(default_factory=dict)
    missing: dict[str, int] = field(default_factory=dict)
    held: dict[str, int] = field(default_factory=dict)


def report_gimbal(
    tree: SensorTree, gimbal: np.ndarray, near: np.ndarray, time: FloatArray
) -> tuple[dict[str, np.ndarray], dict[str, int]]:
    """Collect and log gimbal-lock samples per joint; the warning names the fix."""
    exact: dict[str, np.ndarray] = {}
    close: dict[str, int] = {}
    for i, seg in enumerate(tree.segments):
        idx = np.flatnonzero(gimbal[:, i])
        n_near = int(near[:, i].sum())
        if n_near:
            close[seg.joint.name] = n_near
        if idx.size:
            exact[seg.joint.name] = idx
        if idx.size or n_near:
            first = int(idx[0]) if idx.size else int(np.flatnonzero(near[:, i])[0])
            log_gimbal(seg, n_near, int(idx.size), first, float(time[first]))
    return exact, close


def log_gimbal(seg: SegmentSpec, n_near: int, n_exact: int, first: int, t_first: float) -> None:
    """The gimbal-lock warning for one joint (``first``: its first sample, at ``t_first``)."""
    order = seg.joint.slots()[0]
    c = [seg.joint.coordinates[k] for k in order]  # in rotation order
    logger.warning(
        "joint %s (segment %s, sensor %s): middle angle %s within %.0f deg of +-90 deg "
        "(gimbal lock) in %d samples, first at sample %d (t = %.2f s); %s and %s are "
        "ill-defined there (%d samples exactly locked: the third angle is held). Fix: "
        "keep the motion away from this posture, or give the joint axes in another "
        "order so that the singular posture is one the subject never reaches.",
        seg.joint.name, seg.name, seg.sensor, c[1] or "(unnamed)", NEAR_GIMBAL_DEG,
        n_near, first, t_first, c[0] or "(unnamed)", c[2] or "(unnamed)", n_exact,
    )  # fmt: skip


def decompose(
    tree: SensorTree, q_world_segment: FloatArray, q_world_ground: FloatArray
) -> tuple[FloatArray, np.ndarray, np.ndarray]:
    """Raw joint Euler angles (N, S, 3) [rad], with gimbal-locked (N, S) and near-gimbal
    (N, S) masks. Reference implementation; NaN rows stay NaN."""
    q_b, _, _ = joint_tables(tree)
    q_rel = relative_rotations(q_world_segment, tree.parent_index, q_world_ground)
    q_joint = quat_mul(quat_mul(quat_conj(q_b)[None], q_rel), q_b[None])
    valid = np.asarray(np.isfinite(q_joint).all(axis=-1))
    safe = np.where(valid[..., None], q_joint, np.array([1.0, 0.0, 0.0, 0.0]))
    angles, gimbal = euler_from_quat(safe, "XYZ", return_gimbal=True)
    angles = np.where(valid[..., None], angles, np.nan)
    gimbal = gimbal & valid
    near = valid & (np.abs(angles[..., 1]) > np.deg2rad(90.0 - NEAR_GIMBAL_DEG))
    return angles, gimbal, near


def joint_angles_reference(
    tree: SensorTree,
    segments: Mapping[str, OrientationSeries],
    q_world_ground: FloatArray,
    name: str = "joint_angles",
) -> BodyAngles:
    """Joint coordinates from segment orientations ``{segment: q_world_segment}``, all on
    one time base (see :func:`mocapkit.body.timebase.align_orientations`)."""
    missing = [s.name for s in tree.segments if s.name not in segments]
    if missing:
        raise DataError(
            f"no orientation for segment(s) {', '.join(missing)}; have: {', '.join(segments)}"
        )
    first = segments[tree.segments[0].name]
    time = first.time
    for s in tree.segments:
        t = segments[s.name].time
        if t.shape != time.shape or not np.array_equal(t, time):
            raise DataError(
                f"segment {s.name!r}: time base differs from {tree.segments[0].name!r}; "
                "resample first (mocapkit.body.timebase.align_orientations)"
            )
    q = np.stack([segments[s.name].quat for s in tree.segments], axis=1)
    raw, gimbal, near = decompose(tree, q, np.asarray(q_world_ground, dtype=np.float64))
    held = hold_gimbal(raw, gimbal)
    _, signs, offsets = joint_tables(tree)
    cont = unwrap_valid(held) * signs[None] + offsets[None]
    seg_idx, ang_idx = coordinate_slots(tree)
    values = cont[:, seg_idx, ang_idx]
    exact, close = report_gimbal(tree, gimbal, near, time)
    coords = tree.coordinate_names
    nan_counts = {c: int(np.isnan(values[:, k]).sum()) for k, c in enumerate(coords)}
    return BodyAngles(
        angles=JointAngleSeries(time, coords, values, name=name),
        gimbal=exact,
        near_gimbal=close,
        missing={c: n for c, n in nan_counts.items() if n},
    )
