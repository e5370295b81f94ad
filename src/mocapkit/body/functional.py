"""Automatic sensor-to-segment calibration when the mountings are unknown (functional
calibration), and the body heading from motion.

Per segment, two directions known in the segment frame are measured in the sensor frame:

- **up**: gravity in a still window (the calibration pose says where up is in each
  segment: ``q_ground_segment(pose)^-1 * y_ground``);
- **flexion axis** (for segments marked ``functional: flexion``): the dominant rotation
  axis of the sensor while the subject moves (principal axis of its angular rate, computed
  from the orientations, without the part about the world vertical, so that turning on
  the spot does not count) is taken to be the first axis of the segment's own joint (hip,
  knee and ankle flexion, shoulder flexion, elbow flexion: in gait and most everyday
  motion close to the body's lateral axis).

The two give the mounting ``q_sensor_segment`` up to the sign of the lateral axis, and
without using any world heading (so they hold for 6D filters whose headings are unrelated).
Each such segment then says which way the body faced at calibration (``psi_k``, modulo
180 deg); their axial mean is the body heading ``psi`` (section 6: the global heading), and
forward is told from backward by the knees (or elbows) flexing positive. Segments without
a usable functional axis (pelvis, trunk) are calibrated from the pose at heading ``psi``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np
from scipy.ndimage import uniform_filter1d

from mocapkit._validate import FloatArray
from mocapkit.body.calibration import (
    STILL_TOLERANCE_DEG,
    BodyCalibration,
    CalibrationError,
    HeadingFixed,
    HeadingFromSensor,
    SegmentCalibration,
    angular_rate,
    heading_from_sensor,
    pose_coordinates,
    q_world_ground,
    still_orientation,
    window_indices,
    yaw_quat,
)
from mocapkit.body.joint_angles import compose_pose
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_conj, quat_from_matrix, quat_mul, quat_rotate
from mocapkit.series import OrientationSeries

# Coordinates that are positive (flexion) for most of any everyday motion: they tell a
# forward-facing body from a backward-facing one.
FLEXION_COORDINATES = ("knee_angle_r", "knee_angle_l", "elbow_flex_r", "elbow_flex_l")

# A functional axis is used when the dominant direction carries at least this share of
# the rotation energy and is at least this far from the segment's up axis.
MIN_SHARE = 0.6
MIN_AXIS_FROM_UP_DEG = 45.0
# Moving-average length [s] for the angular rate before the principal axis (twice: a
# triangular window of 2 x 0.1 s, first zero near 10 Hz; gait is below 5 Hz).
SMOOTH_S = 0.1


def dominant_axis(
    rate: FloatArray, min_rate: float = 0.5, smooth: int = 1
) -> tuple[FloatArray, float, int]:
    """Principal axis (3,) of angular rates (N, 3) [rad/s], its share of the rotation
    energy (largest eigenvalue / trace) and the number of samples used.

    Rates are smoothed twice with a ``smooth``-sample moving average (a triangular
    window: the wobble of a sensor on soft tissue, 10-25 Hz, is faster than the limb's
    motion) and only samples faster than ``min_rate`` count. The axis sign is arbitrary."""
    r = rate[np.isfinite(rate).all(axis=1)]
    if smooth > 1 and len(r) >= smooth:
        r = uniform_filter1d(r, size=smooth, axis=0, mode="nearest")
        r = uniform_filter1d(r, size=smooth, axis=0, mode="nearest")
    r = r[np.linalg.norm(r, axis=1) > min_rate]
    if len(r) < 10:
        return np.array([np.nan, np.nan, np.nan]), 0.0, len(r)
    cov = r.T @ r
    vals, vecs = np.linalg.eigh(cov)
    return vecs[:, -1], float(vals[-1] / max(vals.sum(), 1e-300)), len(r)


def horizontal_rate(series: OrientationSeries) -> FloatArray:
    """(N, 3) angular rate in the sensor frame [rad/s] without its component about the
    world's vertical: turning on the spot rotates every segment about the vertical and
    would otherwise hide the flexion axis (uses the inclination only, no heading)."""
    rate = angular_rate(series)
    up = quat_rotate(quat_conj(series.quat), np.array([0.0, 0.0, 1.0]))
    return rate - np.sum(rate * up, axis=1, keepdims=True) * up


def flexion_axis_in_segment(tree: SensorTree, q_ground_seg: FloatArray, i: int) -> FloatArray:
    """(3,) the first axis of segment i's joint (hip, knee, ankle, shoulder flexion, elbow
    axis), expressed in segment i's frame at the calibration pose: the direction its
    dominant rotation is expected about."""
    b1 = tree.segments[i].joint.frame[:, 0]  # in the parent frame
    p = int(tree.parent_index[i])
    in_ground = b1 if p < 0 else quat_rotate(q_ground_seg[p], b1)
    return quat_rotate(quat_conj(q_ground_seg[i]), in_ground)


def mounting_from_two_axes(
    up_sensor: FloatArray,
    lateral_sensor: FloatArray,
    up_segment: FloatArray,
    lateral_segment: FloatArray,
) -> FloatArray:
    """``q_sensor_segment`` mapping ``up_segment`` exactly onto ``up_sensor`` and
    ``lateral_segment`` onto the part of ``lateral_sensor`` perpendicular to it (TRIAD)."""

    def triad(a: FloatArray, b: FloatArray) -> FloatArray:
        e1 = a / np.linalg.norm(a)
        e2 = b - (b @ e1) * e1
        e2 = e2 / np.linalg.norm(e2)
        return np.column_stack([e1, e2, np.cross(e1, e2)])

    rot = triad(up_sensor, lateral_sensor) @ triad(up_segment, lateral_segment).T
    return quat_from_matrix(rot)


def _axial_mean(angles: FloatArray, weights: FloatArray) -> tuple[float, float]:
    """Mean of directions modulo pi (angle doubling): (mean [rad], spread [rad])."""
    z = np.sum(weights * np.exp(2j * angles)) / np.sum(weights)
    spread = float(np.sqrt(-2.0 * np.log(max(abs(z), 1e-12))) / 2.0)
    return float(np.angle(z) / 2.0), spread


def _wrap(a: float) -> float:
    return float(np.pi - np.mod(np.pi - a, 2.0 * np.pi))


def calibrate_functional(
    tree: SensorTree,
    orientations: Mapping[str, OrientationSeries],
    still_window: tuple[float, float],
    motion_window: tuple[float, float] | None = None,
    *,
    pose: str | Mapping[str, float] = "npose",
    heading: HeadingFixed | HeadingFromSensor | None = None,
    heading_alignment: str = "shared",
    still_tolerance_deg: float = STILL_TOLERANCE_DEG,
) -> BodyCalibration:
    """Estimate every mounting and the body heading automatically (module docstring).

    Args:
        orientations: {sensor: OrientationSeries ``q_world_sensor``} on one time base.
        still_window: (t0, t1) [s] with the subject still in ``pose``.
        motion_window: (t0, t1) [s] of motion for the functional axes (default: the
            whole recording outside the still window).
        heading: where the body faced; None estimates it from the motion.
        heading_alignment: ``"shared"`` when the sensors share one world heading (9D, or
            a recording's own fused orientations); ``"pose"`` rotates each functionally
            calibrated sensor's world about z so its segment faces the body heading at
            calibration (6D filters whose headings differ, by up to +-90 deg from the
            consensus: a larger offset cannot be told from a mounting turned round; with
            known mountings use :func:`mocapkit.body.calibration.reset_headings`).
    """
    if heading_alignment not in ("shared", "pose"):
        raise ConfigError(
            f"heading_alignment: expected 'shared' or 'pose', got {heading_alignment!r}"
        )
    tree.check_sensors(list(orientations))
    coords = pose_coordinates(tree, pose)
    q_ground_seg = compose_pose(tree, coords)
    e_x, e_y, e_z = np.eye(3)
    q_cal: dict[str, FloatArray] = {}
    cand: dict[str, tuple[FloatArray, float]] = {}
    diag: dict[str, dict[str, float]] = {}
    for i, seg in enumerate(tree.segments):
        s = orientations[seg.sensor]
        idx = window_indices(s.time, still_window)
        q_cal[seg.sensor], dev = still_orientation(s, idx, seg.sensor, still_tolerance_deg)
        d: dict[str, float] = {"still_deviation_deg": dev}
        diag[seg.name] = d
        if seg.functional != "flexion":
            continue
        rate = horizontal_rate(s)
        if motion_window is None:
            use = np.ones(s.n_samples, dtype=bool)
            use[idx] = False
        else:
            use = np.zeros(s.n_samples, dtype=bool)
            use[window_indices(s.time, motion_window)] = True
        smooth = max(1, round(SMOOTH_S / float(np.median(np.diff(s.time)))))
        axis, share, n_used = dominant_axis(rate[use], smooth=smooth)
        up_sensor = quat_rotate(quat_conj(q_cal[seg.sensor]), e_z)
        d["functional_share"] = share
        d["functional_samples"] = float(n_used)
        if not np.isfinite(axis).all():
            continue
        from_up = float(np.rad2deg(np.arccos(min(1.0, abs(float(axis @ up_sensor))))))
        d["functional_axis_from_up_deg"] = from_up
        if share < MIN_SHARE or from_up < MIN_AXIS_FROM_UP_DEG:
            continue
        up_seg = quat_rotate(quat_conj(q_ground_seg[i]), e_y)
        lat_seg = flexion_axis_in_segment(tree, q_ground_seg, i)
        mount = mounting_from_two_axes(up_sensor, axis, up_seg, lat_seg)
        fwd = quat_rotate(
            q_cal[seg.sensor], quat_rotate(mount, quat_rotate(quat_conj(q_ground_seg[i]), e_x))
        )
        cand[seg.name] = (mount, float(np.arctan2(fwd[1], fwd[0])))

    # body heading psi
    if isinstance(heading, HeadingFromSensor):
        if heading.sensor not in q_cal:
            raise ConfigError(
                f"heading sensor {heading.sensor!r} is not in tree {tree.name!r}; sensors: "
                f"{', '.join(tree.sensor_names)}"
            )
        psis = [heading_from_sensor(q_cal[heading.sensor], heading)]
        spread = 0.0
    elif isinstance(heading, HeadingFixed):
        psis = [float(heading.heading_rad)]
        spread = 0.0
    else:
        if not cand:
            raise CalibrationError(
                "no segment gave a usable functional axis (the sensors hardly moved, or not "
                "mainly in flexion); record some walking or arm swinging, or give the "
                "heading (HeadingFromSensor / HeadingFixed, CLI --heading-sensor)"
            )
        names = list(cand)
        ang = np.array([cand[n][1] for n in names])
        w = np.array([diag[n]["functional_share"] for n in names])
        psi0, spread = _axial_mean(ang, w)
        psis = [psi0, _wrap(psi0 + np.pi)]

    def build(psi: float) -> BodyCalibration:
        q_wg = q_world_ground(psi)
        segs = {}
        for i, seg in enumerate(tree.segments):
            d = dict(diag[seg.name])
            q_heading = np.array([1.0, 0.0, 0.0, 0.0])
            if seg.name in cand:
                mount, psi_k = cand[seg.name]
                off = _wrap(psi_k - psi)
                if abs(off) > np.pi / 2:  # the lateral axis' sign: face the body's way
                    mount = quat_mul(mount, quat_conj(yaw_segment(q_ground_seg[i])))
                    off = _wrap(off - np.pi)
                d["heading_offset_deg"] = float(np.rad2deg(off))
                d["functional"] = 1.0
                if heading_alignment == "pose":
                    q_heading = yaw_quat(-off)
            else:
                target = quat_mul(q_wg, q_ground_seg[i])
                mount = quat_mul(quat_conj(q_cal[seg.sensor]), target)
                d["functional"] = 0.0
            segs[seg.name] = SegmentCalibration(seg.sensor, mount, q_heading, d)
        return BodyCalibration(
            tree_name=tree.name,
            segments=segs,
            heading_rad=psi,
            method="functional",
            pose=coords,
            window=(float(still_window[0]), float(still_window[1])),
            diagnostics={
                "heading_spread_deg": float(np.rad2deg(spread)),
                "functional_segments": sorted(cand),
                "heading_alignment": heading_alignment,
            },
        )

    if len(psis) == 1:
        return build(psis[0])
    return _choose_forward(tree, orientations, [build(p) for p in psis])


def yaw_segment(q_ground_segment: FloatArray) -> FloatArray:
    """(4,) half-turn about the ground's vertical, expressed in the segment frame: flips a
    segment to face backwards while keeping its up axis (right-multiplies a mounting)."""
    up_seg = quat_rotate(quat_conj(q_ground_segment), np.array([0.0, 1.0, 0.0]))
    return np.concatenate([[0.0], up_seg])


def _choose_forward(
    tree: SensorTree, orientations: Mapping[str, OrientationSeries], options: list[BodyCalibration]
) -> BodyCalibration:
    """Of two calibrations facing opposite ways, the one whose knees/elbows flex positive."""
    from mocapkit.body.kinematics import body_angles

    present = [c for c in FLEXION_COORDINATES if c in tree.coordinate_names]
    if not present:
        raise CalibrationError(
            f"tree {tree.name!r} has no knee or elbow to tell forward from backward; give the "
            "heading (HeadingFromSensor / HeadingFixed, CLI --heading-sensor)"
        )
    scores = []
    for cal in options:
        res, _ = body_angles(tree, cal, orientations)
        vals = np.column_stack([res.angles.column(c) for c in present])
        scores.append(float(np.nanmean(vals)))
    best = int(np.argmax(scores))
    chosen = options[best]
    diagnostics = dict(chosen.diagnostics)
    diagnostics["forward_score_deg"] = float(np.rad2deg(scores[best]))
    diagnostics["backward_score_deg"] = float(np.rad2deg(scores[1 - best]))
    return replace(chosen, diagnostics=diagnostics)
