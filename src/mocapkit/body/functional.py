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
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import eigh
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
from mocapkit.geometry import (
    quat_conj,
    quat_from_matrix,
    quat_mul,
    quat_rotate,
    quat_to_matrix,
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
# A two-axis joint's first axis (elbow, ankle flexion) is at least this far from the
# parent segment's long axis (anatomically ~90 deg).
MIN_FIRST_FROM_LONG_DEG = 60.0
# The automatic calibration uses the motion up to this long after the still window [s].
MAX_MOTION_S = 300.0
# The hinge fits use at most this many samples of motion (evenly spread): enough for a
# 3x3 eigenproblem, bounded whatever the recording's length.
MAX_FIT_SAMPLES = 20_000
# Alternations of the two-axis fit (each a pair of 3x3 eigenproblems; settled by ~10).
SECOND_AXIS_ITERATIONS = 30
# Starts of the two-axis fit across the parent's long axis, besides the relative rate's
# principal axes (every 22.5 deg: the first axis is anatomically near 90 deg from it).
PERPENDICULAR_STARTS = 8
# Samples of the joint least-squares step of the two-axis fit (evenly spread).
LEAST_SQUARES_SAMPLES = 5_000
# Starts whose alternation ends within this cosine of one already refined are not refined
# again (the same valley; 0.5 deg).
SAME_START_COS = float(np.cos(np.radians(0.5)))
# Moving-average length [s] for the angular rate before the principal axis (twice: a
# triangular window of 2 x 0.1 s, first zero near 10 Hz; gait is below 5 Hz).
SMOOTH_S = 0.1

#: how the sensors' world headings are reconciled (calibrate_functional docstring)
HEADING_ALIGNMENTS = ("hinges", "shared", "pose", "joints")


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


@dataclass(frozen=True)
class HingeAxes:
    """A joint's dominant relative rotation axis, seen from both sensors."""

    in_parent: FloatArray  # (3,) in the parent sensor's frame
    in_child: FloatArray  # (3,) in the child sensor's frame (mean direction)
    share_parent: float  # share of the relative rotation energy about the axis
    share_child: float  # the same times how steady the axis is in the child's frame


def hinge_axes(
    q_parent: FloatArray,
    q_child: FloatArray,
    rate_p: FloatArray,
    rate_c: FloatArray,
    use: np.ndarray,
    smooth: int,
    second_axis: FloatArray | None = None,
) -> HingeAxes:
    """A hinge's axis in both sensors' frames from their relative motion.

    ``q_parent``, ``q_child`` (N, 4) ``q_world_sensor`` in one world (9D, or 6D after
    :mod:`mocapkit.body.joint_headings`) on one clock; ``rate_p``, ``rate_c`` (N, 3) their
    angular rates in their own frames; ``use`` (N,) the samples to use. The child's rate
    relative to the parent, ``R_p^T (w_c - w_p)`` in the world, is about one axis fixed in
    the parent (and, seen from the child, one fixed in the child) when the joint is a
    hinge. ``second_axis``: the joint has a second axis, fixed in the child, and this is
    the parent's long axis (3,) in its sensor's frame (gravity in the held pose): the
    axis in the parent's frame is then refined, kept well away from the long axis. The
    axes' sign is arbitrary (the same for both).

    (Searching the relative heading of two unrelated 6D worlds for the most hinge-like
    motion was tried and dropped: on the x-IMU3 recording it turned a knee by 86 deg.)"""
    rp_all, rc_all = quat_to_matrix(q_parent), quat_to_matrix(q_child)
    rp, rc = rp_all[use], rc_all[use]
    wp = _central(np.einsum("nij,nj->ni", rp_all, rate_p))[use]  # world rates
    wc = _central(np.einsum("nij,nj->ni", rc_all, rate_c))[use]
    w = np.einsum("nji,nj->ni", rp, wc - wp)  # relative rate in the parent's frame
    axis_p, energy, _ = dominant_axis(w, smooth=smooth)
    if not np.isfinite(axis_p).all():
        return HingeAxes(axis_p, axis_p, 0.0, 0.0)
    # the same axis seen from the child, averaged (a hinge keeps it fixed; its spread
    # lowers the child's share)
    mean_c = np.einsum("nji,nj->ni", rc, np.einsum("nij,j->ni", rp, axis_p)).mean(axis=0)
    steady = float(np.linalg.norm(mean_c))
    hinge = HingeAxes(axis_p, mean_c / max(steady, 1e-12), energy, energy * steady)
    if second_axis is None:
        return hinge
    r_rel = np.einsum("nji,njk->nik", rp, rc)  # child -> parent frame
    fit = _first_of_two_axes(w, r_rel, smooth, second_axis)
    if fit is None:
        return hinge
    j1 = fit[0] if float(fit[0] @ axis_p) >= 0.0 else -fit[0]
    # the share stays the dominant axis': with little motion two axes explain almost
    # anything (the first 20 s of the 15-IMU recording, sitting down: 0.99+ for an elbow
    # axis 58 deg off), so it is not a test that the joint showed its axis
    return replace(hinge, in_parent=j1)


def _central(rate_world: FloatArray) -> FloatArray:
    """Backward-difference world rates (the mean over each step, whichever end's
    orientation expresses them) -> rates at the samples (mean of the steps either side):
    in step with the orientations they are paired with."""
    out = rate_world.copy()
    out[:-1] = 0.5 * (rate_world[:-1] + rate_world[1:])
    return out


def _first_of_two_axes(
    w: FloatArray, r_rel: FloatArray, smooth: int, long_axis: FloatArray
) -> tuple[FloatArray, float] | None:
    """The first axis of a joint with a second axis fixed in the child (the forearm's
    pronation after the elbow's flexion, the subtalar joint after the ankle).

    The relative rate ``w`` (parent frame) lies in span{j1, R_rel j2} (``j1`` fixed in the
    parent, ``j2`` in the child), so ``j1 . (R_rel j2 x w) = 0`` and ``j2 . (w_c x R_rel^T
    j1) = 0``; solved alternately, each a small generalised eigenproblem, from each of the
    relative rate's three principal axes (the second axis may move more than the first:
    a forearm turning from the held pose into the walk) and from
    :data:`PERPENDICULAR_STARTS` directions across the parent's long axis (where the first
    axis lies: on a walk whose elbows hardly move the alternation stops in local minima,
    10 deg off the elbow's axis from the principal axes alone), keeping the one the two
    axes explain best, each start's result finished by :func:`_two_axes_least_squares`;
    returns it and the share of the relative rotation energy the two axes explain. The
    dominant axis alone is pulled towards the second axis by as much as the two move
    together. With the elbow straight, a turn about the upper arm's long axis and a
    flexion fixed in the forearm fit as well as the anatomy: solutions whose first axis
    lies within ``MIN_FIRST_FROM_LONG_DEG`` of the parent's ``long_axis`` are not taken.
    None without enough motion, or when every start degenerates (nearly a pure hinge:
    ``j2 ~ R_rel^T j1``) or lies along the long axis."""
    # the fit itself on the rates as they are (smoothing them would no longer pair them
    # with the orientations); the smoothed ones pick the samples with motion
    speed = np.linalg.norm(np.nan_to_num(w), axis=1)
    if smooth > 1:
        speed = uniform_filter1d(uniform_filter1d(speed, smooth, mode="nearest"), smooth,
                                 mode="nearest")  # fmt: skip
    fast = np.isfinite(w).all(axis=1) & (speed > 0.5)
    if fast.sum() < 50:
        return None
    w, r_rel = w[fast], r_rel[fast]
    if len(w) > MAX_FIT_SAMPLES:  # evenly spread (an average of exact constraints is exact)
        pick = np.linspace(0, len(w) - 1, MAX_FIT_SAMPLES).astype(int)
        w, r_rel = w[pick], r_rel[pick]
    w_c = np.einsum("nji,nj->ni", r_rel, w)
    energy = float(np.sum(w * w))
    best: tuple[FloatArray, float] | None = None
    refined: list[FloatArray] = []
    for start in (*np.linalg.eigh(w.T @ w)[1].T, *_across(long_axis, PERPENDICULAR_STARTS)):
        j1 = start
        u = np.einsum("nji,j->ni", r_rel, j1)
        j2 = dominant_axis(w_c - np.sum(w_c * u, axis=1, keepdims=True) * u, min_rate=0.0)[0]
        if not np.isfinite(j2).all():
            continue
        for _ in range(SECOND_AXIS_ITERATIONS):
            before = j1
            j1 = _plane_normal_fit(np.einsum("nij,j->ni", r_rel, j2), w, smooth)
            j2 = _plane_normal_fit(np.einsum("nji,j->ni", r_rel, j1), w_c, smooth)
            if abs(float(before @ j1)) > 1.0 - 1e-12:  # settled
                break
        if any(abs(float(j1 @ seen)) > SAME_START_COS for seen in refined):
            continue  # this valley is already searched
        refined.append(j1)
        j1, j2 = _two_axes_least_squares(j1, j2, w, r_rel)
        v = np.einsum("nij,j->ni", r_rel, j2)
        normal = np.cross(j1, v)
        size = np.linalg.norm(normal, axis=1)
        if float(np.mean(size)) < 0.3:
            continue  # degenerate: the second axis slid onto the first
        if abs(float(j1 @ long_axis)) > np.cos(np.radians(MIN_FIRST_FROM_LONG_DEG)):
            continue
        off = np.einsum("ni,ni->n", normal / np.maximum(size, 1e-9)[:, None], w)
        explained = 1.0 - float(np.sum(off * off)) / max(energy, 1e-300)
        if best is None or explained > best[1]:
            best = (j1, explained)
    return best


def _two_axes_least_squares(
    j1: FloatArray, j2: FloatArray, w: FloatArray, r_rel: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Both axes at once (Levenberg-Marquardt on the distances of the relative rates from
    the plane of ``j1`` and ``R_rel j2``), from the alternation's result: the alternation
    moves one axis at a time and stalls in the narrow valleys that little motion makes
    (an elbow in a walk: 10 deg off on exact rates; 0.1-0.8 deg after this step)."""
    from scipy.optimize import least_squares

    if len(w) > LEAST_SQUARES_SAMPLES:  # evenly spread: each step is a pass over them
        pick = np.linspace(0, len(w) - 1, LEAST_SQUARES_SAMPLES).astype(int)
        w, r_rel = w[pick], r_rel[pick]
    frames = [_across(j1, 2), _across(j2, 2)]

    def axes(p: FloatArray) -> tuple[FloatArray, FloatArray]:
        a = j1 + p[0] * frames[0][0] + p[1] * frames[0][1]
        b = j2 + p[2] * frames[1][0] + p[3] * frames[1][1]
        return a / np.linalg.norm(a), b / np.linalg.norm(b)

    def residuals(p: FloatArray) -> FloatArray:
        a, b = axes(p)
        normal = np.cross(a, np.einsum("nij,j->ni", r_rel, b))
        size = np.maximum(np.linalg.norm(normal, axis=1), 1e-9)
        return np.asarray(np.einsum("ni,ni->n", normal, w) / size)

    sol = least_squares(residuals, np.zeros(4), method="lm", xtol=1e-12, ftol=1e-12)
    return axes(sol.x)


def _across(axis: FloatArray, n: int) -> list[FloatArray]:
    """``n`` unit directions perpendicular to ``axis``, evenly over half a turn."""
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    e = np.eye(3)[int(np.argmin(np.abs(a)))]
    u = np.cross(a, e)
    u /= np.linalg.norm(u)
    v = np.cross(a, u)
    return [np.cos(t) * u + np.sin(t) * v for t in np.arange(n) * np.pi / n]


def _plane_normal_fit(v: FloatArray, w: FloatArray, smooth: int = 1) -> FloatArray:
    """(3,) unit ``j`` such that each ``w[n]`` lies in the plane of ``j`` and ``v[n]``:
    minimises sum ((j x v) . w)^2 / sum |j x v|^2 (a generalised eigenproblem; the
    denominator keeps ``j`` from sliding onto the ``v`` that would make every plane
    vanish). The constraints ``j . (v x w) = 0`` are averaged over ``smooth`` samples
    (twice) first: an average of exact constraints is exact, and the rates' noise
    averages out."""
    a = np.cross(v, w)
    if smooth > 1:
        a = uniform_filter1d(uniform_filter1d(a, smooth, axis=0, mode="nearest"), smooth,
                             axis=0, mode="nearest")  # fmt: skip
    num = a.T @ a
    den = v.shape[0] * np.eye(3) - v.T @ v  # sum (|v|^2 I - v v^T) for unit v
    vecs = eigh(num, den)[1]
    j = vecs[:, 0]
    return j / np.linalg.norm(j)


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
            best choice in every case measured (``"shared"``: 1.44 -> 0.55 deg, with a
            steel floor 2.05 -> 1.24, with a pose held 4 deg off 3.49 -> 3.16), and on the
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
    diag: dict[str, dict[str, float]] = {}
    for i, seg in enumerate(tree.segments):
        s = orientations[seg.sensor]
        idx = window_indices(s.time, still_window)
        q_cal[seg.sensor], dev = still_orientation(s, idx, seg.sensor, still_tolerance_deg)
        d: dict[str, float] = {"still_deviation_deg": dev}
        diag[seg.name] = d
        if seg.functional != "flexion":
            continue
        use = _motion_mask(s, idx, motion_window)
        smooth = max(1, round(SMOOTH_S / float(np.median(np.diff(s.time)))))
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
    window = motion_window or (-np.inf, float(still_window[1]) + MAX_MOTION_S)
    return _choose_forward(tree, orientations, [build(p) for p in psis], window)


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
