"""Where two sensors' segments are joined: the joint-centre constraint between IMU pairs.

Two segments joined by a spherical (or hinge) joint share one point, the joint centre.
Its acceleration seen from either sensor must agree (Seel et al. 2012; Graurock et al.
2016 use the residual to tell which sensors are neighbours)::

    a_i + K_i o_i = a_j + K_j o_j,      K = ([alpha]x + [omega]x^2) R

with ``a`` the specific force in the world, ``omega`` and ``alpha`` the angular rate and
acceleration in the world, ``R`` the sensor's orientation and ``o`` the joint centre in the
sensor's frame. Gravity is in both ``a`` and cancels. The equation is linear in
``(o_i, o_j)``: least squares over the motion gives the joint centre in both sensors'
frames and a residual [m/s^2] that is small only when the two segments really share a
point (sensors two joints apart have none: the joint between them moves). The mountings
drop out (they are inside ``o``). With 6D orientations, whose headings differ per sensor,
the residual is minimised over a constant heading between the two.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d

from mocapkit._validate import FloatArray
from mocapkit.geometry import quat_conj, quat_mul, quat_rotate, quat_to_matrix

SMOOTH_S = 0.04  # moving average (twice) on the angular rate before differentiating
MAX_ROWS = 2500  # samples per pair in the least squares (evenly spread, moving ones)
MIN_RATE = 0.3  # rad/s: samples slower than this carry little information
YAWS = 36  # heading grid for independent (6D) headings
MAX_ACC = 15.0  # m/s^2 (1.5 g): samples near an impact are left out


@dataclass(frozen=True)
class PairFit:
    residual: float  # RMS [m/s^2]
    o_i: FloatArray  # joint centre in sensor i's frame [m]
    o_j: FloatArray
    yaw: float = 0.0  # heading of j's world in i's [rad] (independent headings only)
    se_i: float = np.inf  # standard error of o_i [m] (large: the motion does not show it)
    se_j: float = np.inf


def _skew(v: FloatArray) -> FloatArray:
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack(
        [np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2
    )


def world_rates(
    q: FloatArray, rate_hz: float, smooth: bool = True
) -> tuple[FloatArray, FloatArray]:
    """(N, 3) angular rate and (N, 3) angular acceleration in the world frame from
    orientations (N, 4) ``q_world_sensor``, central differences, lightly smoothed (or not:
    ``smooth=False``, for :func:`joint_terms`, which filters its products instead)."""
    rel = quat_mul(q[2:], quat_conj(q[:-2]))
    rel = np.where(rel[:, :1] < 0.0, -rel, rel)
    s = np.linalg.norm(rel[:, 1:], axis=1, keepdims=True)
    angle = 2.0 * np.arctan2(s, rel[:, :1])
    axis = np.where(s > 1e-12, rel[:, 1:] / np.where(s > 1e-12, s, 1.0), 0.0)
    w = axis * angle * rate_hz / 2.0
    w = np.vstack([w[:1], w, w[-1:]])
    if smooth:
        w = smoothed(w, rate_hz)
    alpha = np.gradient(w, 1.0 / rate_hz, axis=0)
    return w, alpha


def smoothed(x: FloatArray, rate_hz: float) -> FloatArray:
    """``x`` along its first axis through the moving average of ``SMOOTH_S``, twice."""
    k = max(1, round(SMOOTH_S * rate_hz))
    return uniform_filter1d(uniform_filter1d(x, k, axis=0, mode="nearest"), k, axis=0,
                            mode="nearest")  # fmt: skip


def joint_terms(
    q: FloatArray, acc: FloatArray, rate_hz: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """One sensor's terms of the joint-centre equation: K (N, 3, 3), its specific force in
    the world (N, 3), both through the same low-pass (:func:`smoothed`), and its angular
    rate (N, 3), smoothed. The equation is linear in the joint centre, so one linear filter
    on both of its sides keeps it exact while it takes the noise out; smoothing the rates
    alone (before 2026-11-27) left K and the accelerations with different spectra: a
    0.13 m/s^2 residual and hip centres 3-9 cm off on a simulated walk with perfect
    sensors (0.002 and 1 mm filtered together)."""
    w, alpha = world_rates(q, rate_hz, smooth=False)
    sw = _skew(w)
    k = (_skew(alpha) + sw @ sw) @ quat_to_matrix(q)
    a = quat_rotate(q, acc)
    return smoothed(k, rate_hz), smoothed(a, rate_hz), smoothed(w, rate_hz)


@dataclass(frozen=True)
class Kinematics:
    """Per sensor, on the rows used: K (M, 3, 3), a_world (M, 3)."""

    k: FloatArray  # (M, S, 3, 3)
    a: FloatArray  # (M, S, 3)
    q: FloatArray  # (M, S, 4) q_world_sensor


def kinematics(q: FloatArray, acc: FloatArray, rate_hz: float) -> Kinematics:
    """From orientations (N, S, 4) and accelerometer samples (N, S, 3) [m/s^2, sensor
    frame] on one time base: the rows of the joint-centre equation (moving samples, at
    most MAX_ROWS evenly spread)."""
    n, s, _ = q.shape
    ks, aw, speed, peak = [], [], np.zeros(n), np.zeros(n)
    for j in range(s):
        k, a, w = joint_terms(q[:, j], acc[:, j], rate_hz)
        ks.append(k)
        aw.append(a)
        speed = np.maximum(speed, np.linalg.norm(w, axis=1))
        peak = np.maximum(peak, np.linalg.norm(acc[:, j], axis=1))
    # impacts (heel strikes while running) shake the soft tissue: no rigid-body sample
    calm = uniform_filter1d((peak > MAX_ACC).astype(float), max(1, round(0.1 * rate_hz))) == 0
    k_all, a_all = np.stack(ks, 1), np.stack(aw, 1)
    # a gap (NaN orientation) spreads through the differences: rows with any NaN go
    finite = np.isfinite(k_all).all(axis=(1, 2, 3)) & np.isfinite(a_all).all(axis=(1, 2))
    rows = np.flatnonzero((speed > MIN_RATE) & calm & finite)
    rows = rows[(rows > 2) & (rows < n - 3)]
    if rows.size > MAX_ROWS:
        rows = rows[np.linspace(0, rows.size - 1, MAX_ROWS).astype(int)]
    return Kinematics(k_all[rows], a_all[rows], q[rows])


def _solve(ki: FloatArray, kj: FloatArray, rhs: FloatArray) -> tuple[float, FloatArray, FloatArray]:
    """(residual RMS, (o_i, o_j), standard errors (2,) of o_i and o_j [m])."""
    a = np.concatenate([ki, -kj], axis=2).reshape(-1, 6)
    b = rhs.reshape(-1)
    x, *_ = np.linalg.lstsq(a, b, rcond=None)
    res = float(np.sqrt(np.mean((a @ x - b) ** 2)))
    try:
        cov = np.linalg.inv(a.T @ a) * res**2
        se = np.sqrt(np.array([np.trace(cov[:3, :3]), np.trace(cov[3:, 3:])]).clip(0.0))
    except np.linalg.LinAlgError:
        se = np.array([np.inf, np.inf])
    return res, x, se


def fit_pair(kin: Kinematics, i: int, j: int, headings: str = "shared") -> PairFit:
    """Joint centre of sensors i and j and its residual (module docstring)."""
    ki, kj, ai, aj = kin.k[:, i], kin.k[:, j], kin.a[:, i], kin.a[:, j]
    if len(ki) < 10:
        return PairFit(np.inf, np.full(3, np.nan), np.full(3, np.nan))
    if headings == "shared":
        res, x, se = _solve(ki, kj, aj - ai)
        return PairFit(res, x[:3], x[3:], 0.0, float(se[0]), float(se[1]))
    best = PairFit(np.inf, np.full(3, np.nan), np.full(3, np.nan))
    for yaw in np.linspace(0.0, 2.0 * np.pi, YAWS, endpoint=False):
        c, sn = np.cos(yaw), np.sin(yaw)
        rz = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
        res, x, se = _solve(ki, rz @ kj, aj @ rz.T - ai)
        if res < best.residual:
            best = PairFit(res, x[:3], x[3:], float(yaw), float(se[0]), float(se[1]))
    return best


def pair_fits(kin: Kinematics, headings: str = "shared") -> dict[tuple[int, int], PairFit]:
    """Every pair (i < j) of sensors."""
    s = kin.k.shape[1]
    return {(i, j): fit_pair(kin, i, j, headings) for i, j in itertools.combinations(range(s), 2)}


def residual_matrix(fits: dict[tuple[int, int], PairFit], s: int) -> FloatArray:
    out = np.zeros((s, s))
    for (i, j), f in fits.items():
        out[i, j] = out[j, i] = f.residual
    return out


def centre_in(fits: dict[tuple[int, int], PairFit], i: int, j: int) -> FloatArray:
    """Joint centre of the pair (i, j) in sensor i's frame."""
    return fits[(i, j)].o_i if i < j else fits[(j, i)].o_j


def centre_error(fits: dict[tuple[int, int], PairFit], i: int, j: int) -> float:
    """Standard error [m] of :func:`centre_in`."""
    return fits[(i, j)].se_i if i < j else fits[(j, i)].se_j


def yaw_between(fits: dict[tuple[int, int], PairFit], i: int, j: int) -> FloatArray:
    """(4,) the heading rotation taking sensor j's world into sensor i's (identity when the
    headings are shared)."""
    yaw = fits[(i, j)].yaw if i < j else -fits[(j, i)].yaw
    return np.array([np.cos(yaw / 2.0), 0.0, 0.0, np.sin(yaw / 2.0)])


def centre_swing(kin: Kinematics, fits: dict[tuple[int, int], PairFit], i: int, j: int) -> float:
    """RMS [m/s^2] of the horizontal acceleration of the pair's joint centre about its
    mean, from sensor i: with independent (6D) headings, what shows the heading between
    the two worlds (a pelvis gliding at constant speed: 0.2-0.3; walking: 0.6-1.4 on the
    real recordings, 1.2-2.7 simulated with the pelvis bouncing and swaying)."""
    a = kin.a[:, i] + np.einsum("nij,j->ni", kin.k[:, i], centre_in(fits, i, j))
    h = a[:, :2] - np.mean(a[:, :2], axis=0)
    return float(np.sqrt(np.mean(np.sum(h * h, axis=1))))


def in_frame_of(
    kin: Kinematics, fits: dict[tuple[int, int], PairFit], i: int, j: int, v: FloatArray
) -> FloatArray:
    """(M, 3) a vector ``v`` fixed in sensor j's frame, seen in sensor i's frame over the
    rows of ``kin`` (through the pair's heading when the headings are independent)."""
    q_ij = quat_mul(quat_conj(kin.q[:, i]), quat_mul(yaw_between(fits, i, j), kin.q[:, j]))
    return quat_rotate(q_ij, np.broadcast_to(v, (len(q_ij), 3)))
