"""Automatic sensor-to-segment calibration when the mountings are unknown (functional
calibration), and the body heading from motion.

Per segment, two directions known in the segment frame are measured in the sensor frame:

- **up**: gravity in a still window (the calibration pose says where up is in each
  segment: ``q_ground_segment(pose)^-1 * y_ground``);
- **flexion axis** (for segments marked ``functional: flexion``), preferably from a
  **hinge** the segment takes part in (knee, elbow, ankle; :func:`hinge_axes`): the
  rotation of the child's sensor relative to the parent's is about the joint's axis,
  fixed in both, whatever the rest of the body does; the elbow and the ankle have a
  second axis fixed in the child (pronation, subtalar), taken out by a two-axis fit. This
  needs the two sensors in one world (``shared``, or ``joints`` after
  :mod:`mocapkit.body.joint_headings`); ball joints (hip, shoulder) are not hinges.
  Otherwise the dominant rotation axis of the sensor itself while the subject moves
  (principal axis of its angular rate, without the part about the world vertical, so
  that turning on the spot does not count) is taken to be the first axis of the
  segment's own joint (hip flexion, shoulder flexion: in gait close to the body's lateral
  axis, but a shoulder's swing leans 15-20 deg with its abduction and rotation).

The two give the mounting ``q_sensor_segment`` up to the sign of the lateral axis, and
without using any world heading (so they hold for 6D filters whose headings are unrelated).
Each such segment then says which way the body faced at calibration (``psi_k``, modulo
180 deg); their axial mean is the body heading ``psi`` (section 6: the global heading), and
forward is told from backward by the knees (or elbows) flexing positive. Segments without
a usable functional axis (pelvis, trunk) are calibrated from the pose at heading ``psi``.

A **twist** segment (``functional: twist``, the forearms in the presets) is calibrated
from the pose, then turned the least way that lays its joint's second axis (pronation,
fixed in the forearm, from the elbow's two-axis fit) onto the direction the motion
showed. A held pose a few degrees off tilts a pose-calibrated mounting by as much, and a
forearm later turns far about its long axis: the tilt, fixed in the forearm, then
crosses into the elbow's flexion by as much as the forearm turned (elbow_flex 9-14 deg
on the closed loop with the pose held 4 deg off; 1.8-7.6 with the twist). Pose-calibrated
children (the hand) are turned with it. Only the turn about the long axis is the pose's.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace

import numpy as np

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
from mocapkit.body.hinge_fit import dominant_axis, hinge_axes
from mocapkit.body.joint_angles import compose_pose
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError
from mocapkit.geometry import (
    quat_angle,
    quat_conj,
    quat_from_matrix,
    quat_from_two_vectors,
    quat_mul,
    quat_rotate,
)
from mocapkit.series import OrientationSeries

# Coordinates that are positive (flexion) for most of any everyday motion: they tell a
# forward-facing body from a backward-facing one.
FLEXION_COORDINATES = ("knee_angle_r", "knee_angle_l", "elbow_flex_r", "elbow_flex_l")

# A functional axis is used when the dominant direction carries at least this share of
# the rotation energy and is at least this far from the segment's up axis.
MIN_SHARE = 0.6
MIN_AXIS_FROM_UP_DEG = 45.0
# A joint's relative rotation counts as a hinge's when this share of its energy is about
# one axis (simulated walking: knees 0.99, ankles 0.98, elbows 0.85-0.88 with the
# forearm's pronation beside the flexion; the 15-IMU recording's walks: knees 0.84-0.87,
# elbows 0.82-0.89; its sit-down alone: knees 0.71-0.84). Set while looking at those
# runs, which docs/benchmarks.md also reports: there is no held-out set of recordings yet.
HINGE_MIN_SHARE = 0.8
# The automatic calibration uses the motion up to this long after the still window [s].
MAX_MOTION_S = 300.0
# A twist segment's pose calibration is corrected by its joint's second axis when the
# correction is at most this large [deg]: a held pose is off by a few degrees per joint
# (more says the fit did not find the axis).
MAX_TWIST_CORRECTION_DEG = 20.0
# ... and when its joint's two axes explain at least this share of the relative rotation
# energy.
TWIST_MIN_SHARE = 0.9
# Moving-average length [s] for the angular rate before the principal axis (twice: a
# triangular window of 2 x 0.1 s, first zero near 10 Hz; gait is below 5 Hz).
SMOOTH_S = 0.1

#: how the sensors' world headings are reconciled (calibrate_functional docstring)
HEADING_ALIGNMENTS = ("hinges", "shared", "pose", "joints")


def horizontal_rate(series: OrientationSeries, rate: FloatArray | None = None) -> FloatArray:
    """(N, 3) angular rate in the sensor frame [rad/s] without its component about the
    world's vertical: turning on the spot rotates every segment about the vertical and
    would otherwise hide the flexion axis (uses the inclination only, no heading).
    ``rate``: the series' :func:`angular_rate`, when already computed."""
    rate = angular_rate(series) if rate is None else rate
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
    heading_alignment: str = "hinges",
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
            known mountings use :func:`mocapkit.body.calibration.reset_headings`);
            ``"joints"``: as ``"pose"``, for 6D orientations whose headings were kept
            consistent through the joints first (:mod:`mocapkit.body.joint_headings`),
            so that knees, elbows and ankles can be compared across the joint (hinge
            axes, below), as with ``"shared"``; ``"hinges"`` (the default): the same on
            worlds that share one heading (9D, a device's orientations): the hinges
            compared across the joints, then each segment aligned at the pose rather than
            headed by its own functional axis. On the simulated closed loop this is the
            best choice in every case measured (``"shared"``: 1.48 -> 0.57 deg, with a
            steel floor 1.96 -> 1.08, with a pose held 4 deg off 3.53 -> 3.17), and on the
            x-IMU3 recording it makes left and right agree (subtalar means 9 / -14 deg
            with ``"shared"``, 2 / 1 deg), agreeing as well with the vendor's orientations
            (docs/benchmarks.md).
    """
    if heading_alignment not in HEADING_ALIGNMENTS:
        raise ConfigError(
            f"heading_alignment: expected one of {', '.join(HEADING_ALIGNMENTS)}, got "
            f"{heading_alignment!r}"
        )
    tree.check_sensors(list(orientations))
    coords = pose_coordinates(tree, pose)
    q_ground_seg = compose_pose(tree, coords)
    e_x, e_y, e_z = np.eye(3)
    rates: dict[str, FloatArray] = {}

    def rate_of(sensor: str) -> FloatArray:
        """A sensor's angular rate, computed once (each hinge reads two sensors')."""
        if sensor not in rates:
            rates[sensor] = angular_rate(orientations[sensor])
        return rates[sensor]

    q_cal: dict[str, FloatArray] = {}
    cand: dict[str, tuple[FloatArray, float]] = {}
    twist: dict[str, tuple[FloatArray, FloatArray, float]] = {}
    diag: dict[str, dict[str, float]] = {}
    for i, seg in enumerate(tree.segments):
        s = orientations[seg.sensor]
        idx = window_indices(s.time, still_window)
        q_cal[seg.sensor], dev = still_orientation(s, idx, seg.sensor, still_tolerance_deg)
        d: dict[str, float] = {"still_deviation_deg": dev}
        diag[seg.name] = d
        if seg.functional == "none":
            continue
        use = _motion_mask(s, idx, motion_window)
        smooth = max(1, round(SMOOTH_S / float(np.median(np.diff(s.time)))))
        if seg.functional == "twist":
            # the sensors' worlds must agree to compare them across a joint
            found = None if heading_alignment == "pose" else _twist_axis(
                tree, orientations, i, use, smooth, q_cal, rate_of)  # fmt: skip
            if found is not None:
                twist[seg.name] = found
                d["twist_share"] = found[2]
            continue
        axis, share, n_used = dominant_axis(horizontal_rate(s, rate_of(seg.sensor))[use],
                                            smooth=smooth)  # fmt: skip
        d["functional_share"] = share
        d["functional_samples"] = float(n_used)
        options = [(axis, flexion_axis_in_segment(tree, q_ground_seg, i), share, 0.0)]
        # the sensors' worlds must agree to compare them across a joint
        hinge = None
        if heading_alignment != "pose":
            hinge = _best_hinge(tree, orientations, i, q_ground_seg, use, smooth, q_cal,
                                rate_of)  # fmt: skip
        if hinge is not None:  # a hinge's axis is fixed in the segment: preferred
            options.insert(0, (*hinge, 1.0))
        up_sensor = quat_rotate(quat_conj(q_cal[seg.sensor]), e_z)
        usable = None
        for axis, lat_seg, share, is_hinge in options:
            if not np.isfinite(axis).all():
                continue
            from_up = float(np.rad2deg(np.arccos(min(1.0, abs(float(axis @ up_sensor))))))
            d.update(functional_share=share, functional_axis_from_up_deg=from_up,
                     hinge=is_hinge)  # fmt: skip
            if share >= MIN_SHARE and from_up >= MIN_AXIS_FROM_UP_DEG:
                usable = axis, lat_seg
                break
        if usable is None:
            continue
        axis, lat_seg = usable
        up_seg = quat_rotate(quat_conj(q_ground_seg[i]), e_y)
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
        moved: dict[str, FloatArray] = {}  # pose segments turned from the held pose
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
                if heading_alignment in ("pose", "joints", "hinges"):
                    q_heading = yaw_quat(-off)
            else:
                target = quat_mul(q_wg, q_ground_seg[i])
                p = int(tree.parent_index[i])
                turned = moved.get(tree.segments[p].name) if p >= 0 else None
                if turned is not None:  # held as its parent was: turned with it
                    moved[seg.name] = turned
                    target = quat_mul(turned, target)
                mount = quat_mul(quat_conj(q_cal[seg.sensor]), target)
                d["functional"] = 0.0
                if seg.name in twist:
                    before = quat_mul(q_cal[seg.sensor], mount)  # q_world_segment at the pose
                    mount, d = _corrected_tilt(mount, twist[seg.name], d)
                    after = quat_mul(q_cal[seg.sensor], mount)
                    moved[seg.name] = quat_mul(after, quat_conj(before))
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
    window = motion_window or (-np.inf, float(still_window[1]) + MAX_MOTION_S)
    return _choose_forward(tree, orientations, [build(p) for p in psis], window)


def _twist_axis(
    tree: SensorTree,
    orientations: Mapping[str, OrientationSeries],
    i: int,
    use: np.ndarray,
    smooth: int,
    q_still: Mapping[str, FloatArray],
    rate_of: Callable[[str], FloatArray],
) -> tuple[FloatArray, FloatArray, float] | None:
    """Segment i's twist axis (its joint's second axis, fixed in it: the forearm's
    pronation) from the two-axis fit of its joint: (axis in its sensor's frame, the same
    in the segment's frame, the share the two axes explain); None without a parent on the
    same clock, or enough motion that two axes explain."""
    seg = tree.segments[i]
    p = int(tree.parent_index[i])
    axis_seg = seg.joint.second_axis_in_child()
    if p < 0 or axis_seg is None:
        return None
    parent = tree.segments[p]
    me, other = orientations[seg.sensor], orientations[parent.sensor]
    if other.n_samples != me.n_samples or not np.array_equal(other.time, me.time):
        return None
    ok = use & np.isfinite(me.quat).all(axis=1) & np.isfinite(other.quat).all(axis=1)
    up_p = quat_rotate(quat_conj(q_still[parent.sensor]), np.array([0.0, 0.0, 1.0]))
    h = hinge_axes(other.quat, me.quat, rate_of(parent.sensor), rate_of(seg.sensor), ok,
                   smooth, second_axis=up_p)  # fmt: skip
    if h.second_in_child is None or h.two_axis_share < TWIST_MIN_SHARE:
        return None
    return h.second_in_child, axis_seg, h.two_axis_share


def _corrected_tilt(
    mount: FloatArray, twist: tuple[FloatArray, FloatArray, float], d: dict[str, float]
) -> tuple[FloatArray, dict[str, float]]:
    """A pose calibration's ``q_sensor_segment`` turned the least way that lays the
    segment's twist axis onto the one the motion showed (the pose keeps the turn about
    it): the held pose's tilt no longer enters, however far the segment later turns about
    that axis. Not applied past :data:`MAX_TWIST_CORRECTION_DEG` (diagnostics say so)."""
    axis_sensor, axis_seg, _ = twist
    now = quat_rotate(mount, axis_seg)
    if float(now @ axis_sensor) < 0.0:  # the fitted axis' sign is arbitrary
        axis_sensor = -axis_sensor
    turn = quat_from_two_vectors(now, axis_sensor)
    d = dict(d, twist_correction_deg=float(np.rad2deg(quat_angle(turn))))
    if d["twist_correction_deg"] > MAX_TWIST_CORRECTION_DEG:
        return mount, d
    d["functional"] = 1.0
    return quat_mul(turn, mount), d


def _motion_mask(
    s: OrientationSeries, still_idx: np.ndarray, motion_window: tuple[float, float] | None
) -> np.ndarray:
    """(N,) samples of motion: the window given, else everything outside the still one up
    to ``MAX_MOTION_S`` after it (an hour's recording calibrates from its first minutes:
    bounded time and memory, and a strap that slips later does not pull the calibration)."""
    if motion_window is None:
        use = s.time <= (s.time[still_idx[-1]] if still_idx.size else s.time[0]) + MAX_MOTION_S
        use[still_idx] = False
    else:
        use = np.zeros(s.n_samples, dtype=bool)
        use[window_indices(s.time, motion_window)] = True
    return use


def _best_hinge(
    tree: SensorTree,
    orientations: Mapping[str, OrientationSeries],
    i: int,
    q_ground_seg: FloatArray,
    use: np.ndarray,
    smooth: int,
    q_still: Mapping[str, FloatArray],
    rate_of: Callable[[str], FloatArray],
) -> tuple[FloatArray, FloatArray, float] | None:
    """Segment i's flexion axis from the hinges it takes part in (its own joint seen from
    its side, its children's joints seen from its side): (axis in its sensor's frame, the
    same axis in the segment's frame, share), the most hinge-like one with a share of at
    least ``HINGE_MIN_SHARE``; None when none is (a ball joint, too little motion, sensors
    on different clocks)."""
    seg = tree.segments[i]
    me = orientations[seg.sensor]
    rate_me = rate_of(seg.sensor)
    options: list[tuple[int, FloatArray, FloatArray, float]] = []
    parents = tree.parent_index
    pairs = [(int(parents[i]), i)] if parents[i] >= 0 else []
    pairs += [(i, j) for j in range(len(tree.segments)) if parents[j] == i]
    # a ball joint (three coordinates: hip, shoulder, spine) has no fixed axis, however
    # much of a walk's motion is about one
    pairs = [(p, c) for p, c in pairs if _degrees_of_freedom(tree, c) < 3]
    for p, c in pairs:
        other = orientations[tree.segments[c if p == i else p].sensor]
        if other.n_samples != me.n_samples or not np.array_equal(other.time, me.time):
            continue
        rate_other = rate_of(tree.segments[c if p == i else p].sensor)
        qp, qc = (me.quat, other.quat) if p == i else (other.quat, me.quat)
        rp, rc = (rate_me, rate_other) if p == i else (rate_other, rate_me)
        ok = use & np.isfinite(qp).all(axis=1) & np.isfinite(qc).all(axis=1)
        dof = _degrees_of_freedom(tree, c)
        up_p = quat_rotate(quat_conj(q_still[tree.segments[p].sensor]), np.array([0.0, 0.0, 1.0]))
        h = hinge_axes(qp, qc, rp, rc, ok, smooth, second_axis=up_p if dof == 2 else None)
        if p == i:  # the child's joint axis, in this (its parent) segment's frame
            options.append((dof, h.in_parent, tree.segments[c].joint.frame[:, 0],
                            h.share_parent))  # fmt: skip
        else:
            options.append((dof, h.in_child, flexion_axis_in_segment(tree, q_ground_seg, i),
                            h.share_child))  # fmt: skip
    good = [o for o in options if o[3] >= HINGE_MIN_SHARE and np.isfinite(o[1]).all()]
    if not good:
        return None
    # a one-axis joint (a knee) before a two-axis one (an ankle), then the clearer
    dof, axis, in_segment, share = min(good, key=lambda o: (o[0], -o[3]))
    return axis, in_segment, share


def _degrees_of_freedom(tree: SensorTree, i: int) -> int:
    """How many coordinates segment i's joint reports."""
    return sum(c is not None for c in tree.segments[i].joint.coordinates)


def yaw_segment(q_ground_segment: FloatArray) -> FloatArray:
    """(4,) half-turn about the ground's vertical, expressed in the segment frame: flips a
    segment to face backwards while keeping its up axis (right-multiplies a mounting)."""
    up_seg = quat_rotate(quat_conj(q_ground_segment), np.array([0.0, 1.0, 0.0]))
    return np.concatenate([[0.0], up_seg])


def _choose_forward(
    tree: SensorTree,
    orientations: Mapping[str, OrientationSeries],
    options: list[BodyCalibration],
    window: tuple[float, float],
) -> BodyCalibration:
    """Of two calibrations facing opposite ways, the one whose knees/elbows flex positive
    over the calibration's motion ``window`` [s]."""
    from mocapkit.body.kinematics import body_angles

    cut = {}
    for name, s in orientations.items():
        keep = (s.time >= window[0]) & (s.time <= window[1])
        cut[name] = s if keep.all() else OrientationSeries(s.time[keep], s.quat[keep], s.name,
                                                           s.frame)  # fmt: skip
    orientations = cut

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
