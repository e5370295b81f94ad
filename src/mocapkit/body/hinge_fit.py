"""Joint axes from two sensors' relative motion: the dominant rotation axis of a segment,
a hinge's axis seen from both sides, and a two-axis joint's axes (the elbow's flexion and
the forearm's pronation, the ankle and the subtalar joint). Used by the automatic
calibration (:mod:`mocapkit.body.functional`)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import eigh
from scipy.ndimage import uniform_filter1d

from mocapkit._validate import FloatArray
from mocapkit.geometry import quat_to_matrix

# A two-axis joint's first axis (elbow, ankle flexion) is at least this far from the
# parent segment's long axis (anatomically ~90 deg).
MIN_FIRST_FROM_LONG_DEG = 60.0
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
    # (3,) a two-axis joint's second axis, fixed in the child, in the child sensor's frame
    # (the forearm's pronation axis); None for a hinge fitted with one axis
    second_in_child: FloatArray | None = None
    two_axis_share: float = 0.0  # share of the relative rotation energy the two axes explain


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
    return replace(hinge, in_parent=j1, second_in_child=fit[1], two_axis_share=fit[2])


def _central(rate_world: FloatArray) -> FloatArray:
    """Backward-difference world rates (the mean over each step, whichever end's
    orientation expresses them) -> rates at the samples (mean of the steps either side):
    in step with the orientations they are paired with."""
    out = rate_world.copy()
    out[:-1] = 0.5 * (rate_world[:-1] + rate_world[1:])
    return out


def _first_of_two_axes(
    w: FloatArray, r_rel: FloatArray, smooth: int, long_axis: FloatArray
) -> tuple[FloatArray, FloatArray, float] | None:
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
    returns it, the second axis (in the child's frame) and the share of the relative
    rotation energy the two axes explain. The
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
    best: tuple[FloatArray, FloatArray, float] | None = None
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
        if best is None or explained > best[2]:
            best = (j1, j2, explained)
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
