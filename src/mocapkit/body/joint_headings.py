"""Heading without a magnetometer: neighbouring sensors' headings kept consistent through
the joints that join their segments.

In 6D each sensor's orientation has a world of its own, and its heading drifts on its own:
joint angles between two segments then drift too (hip and shoulder rotation first). The
joint joining two segments ties the two worlds together. Its centre has one acceleration,
whichever sensor it is computed from (:mod:`mocapkit.body.joint_centres`)::

    u_p(t) = Rz(delta(t)) u_c(t),      u_s = a_s + K_s o_s  (in sensor s's world)

with ``delta`` the heading of the child's world in the parent's. Gravity and the vertical
parts agree by construction (both worlds share the vertical); the horizontal parts give
``delta`` in closed form (a 2-D Procrustes fit: ``atan2(sum hc x hp, sum hc . hp)``). It is
estimated in windows of ``WINDOW_S`` every ``STEP_S``, from the windows whose horizontal
joint acceleration is coherent enough (``MIN_COHERENCE``), and its course over time fitted
as a piecewise-linear curve with a knot every ``KNOT_S`` (drift is slow), weighted by
each window's coherence; the joint centres ``o_p, o_c`` come from a fit over the whole
recording with a heading search, refit once with the first pass's headings applied. Every
child's orientation is then turned into its parent's world, from the root out: all sensors
share the root sensor's heading (which still drifts, as one: joint angles do not see it),
as a 9D suit in a clean magnetic field would. Then calibrate with ``heading_alignment=
"shared"``.

Needs accelerometer samples and motion that moves the joints (walking does; standing
still does not: those stretches hold the heading). A pair whose joint shows in under a
quarter of the windows is not followed (noted): it keeps the pose alignment alone. On the
real recordings here the hips are such pairs (the pelvis sensor's and the thigh's
horizontal joint-centre accelerations agree poorly: coherence ~0.5, soft tissue), while
knees, ankles, spine, shoulders, elbows and wrists are followed.

Honest caveat: the constants below (window, knots, coherence and window-share thresholds,
smoothness) were set while looking at the simulated closed loop and the real recordings
that docs/benchmarks.md reports them on; there is no held-out set of recordings yet.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import uniform_filter1d

from mocapkit._validate import FloatArray
from mocapkit.body.joint_centres import (
    MAX_ACC,
    MIN_RATE,
    fit_pair,
    joint_terms,
    kinematics,
    world_rates,
)
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.body.timebase import align_orientations
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_mul
from mocapkit.series import ImuRecording, OrientationSeries

WINDOW_S = 6.0  # s of motion per heading estimate
STEP_S = 1.0  # s between window centres
MIN_COHERENCE = 0.6  # |sum hc x hp, sum hc . hp| / sum |hc||hp|: 1 when the two agree
MIN_SAMPLES_S = 1.0  # s of moving samples in a window
KNOT_S = 30.0  # s between the knots of the heading's piecewise-linear course
SMOOTHNESS = 0.01  # pull of neighbouring knots together (relative to the data)
MIN_WINDOW_SHARE = 0.25  # of the windows must pass, else the pair is not followed


@dataclass
class PairHeading:
    parent: str  # sensor names
    child: str
    delta: FloatArray  # (N,) heading of the child's world in the parent's [rad]
    windows: int  # windows used
    windows_total: int
    centre_residual: float  # joint-centre fit RMS [m/s^2]
    note: str = ""


@dataclass
class JointHeadings:
    time: FloatArray
    correction: dict[str, FloatArray]  # sensor -> (N,) heading turned by [rad]
    pairs: list[PairHeading] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def drift_deg(self) -> dict[str, float]:
        """Per child sensor: how far its heading correction moved over the recording
        [deg] (last minus first): the relative drift taken out."""
        return {p.child: float(np.degrees(p.delta[-1] - p.delta[0])) for p in self.pairs}


def _rz(yaw: FloatArray) -> FloatArray:
    """(N, 4) quaternions of turns about the vertical."""
    return np.stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)], axis=-1)


def _joint_acc(q: FloatArray, acc: FloatArray, o: FloatArray, rate: float) -> FloatArray:
    """(N, 3) acceleration of the point ``o`` (sensor frame) in the sensor's world, both
    terms through one low-pass (:func:`mocapkit.body.joint_centres.joint_terms`)."""
    k, a, _ = joint_terms(q, acc, rate)
    return a + np.einsum("nij,j->ni", k, o)


def _usable(qs: list[FloatArray], accs: list[FloatArray], rate: float) -> np.ndarray:
    """(N,) bool: samples where the joints move and no impact shakes the sensors."""
    speed = np.zeros(len(qs[0]))
    peak = np.zeros(len(qs[0]))
    for q, a in zip(qs, accs, strict=True):
        w, _ = world_rates(q, rate)
        speed = np.maximum(speed, np.linalg.norm(w, axis=1))
        peak = np.maximum(peak, np.linalg.norm(a, axis=1))
    calm = uniform_filter1d((peak > MAX_ACC).astype(float), max(1, round(0.1 * rate))) == 0
    ok = (speed > MIN_RATE) & calm
    ok[:3] = ok[-3:] = False
    return ok


def _window_headings(
    t: FloatArray, hp: FloatArray, hc: FloatArray, ok: np.ndarray, rate: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(window centres, headings, weights): the weight is the window's coherence squared
    times its moving samples, zero for windows that do not pass."""
    centres = np.arange(t[0] + WINDOW_S / 2, max(t[-1] - WINDOW_S / 2, t[0] + WINDOW_S / 2)
                        + 1e-9, STEP_S)  # fmt: skip
    cross = hc[:, 0] * hp[:, 1] - hc[:, 1] * hp[:, 0]
    dot = np.einsum("ij,ij->i", hc, hp)
    mag = np.linalg.norm(hc, axis=1) * np.linalg.norm(hp, axis=1)
    cs = np.concatenate([[0.0], np.cumsum(np.where(ok, cross, 0.0))])
    ds = np.concatenate([[0.0], np.cumsum(np.where(ok, dot, 0.0))])
    ms = np.concatenate([[0.0], np.cumsum(np.where(ok, mag, 0.0))])
    ns = np.concatenate([[0], np.cumsum(ok)])
    lo = np.searchsorted(t, centres - WINDOW_S / 2)
    hi = np.searchsorted(t, centres + WINDOW_S / 2)
    c, d, m, n = cs[hi] - cs[lo], ds[hi] - ds[lo], ms[hi] - ms[lo], ns[hi] - ns[lo]
    coherence = np.hypot(c, d) / np.maximum(m, 1e-12)
    good = (n >= MIN_SAMPLES_S * rate) & (coherence >= MIN_COHERENCE)
    return centres, np.arctan2(c, d), np.where(good, coherence**2 * n, 0.0)


def _delta_series(
    t: FloatArray, centres: FloatArray, yaw: FloatArray, weight: FloatArray
) -> FloatArray | None:
    """The heading over time: piecewise linear with a knot every ``KNOT_S`` (drift is slow:
    the gyroscopes' residual biases), weighted least squares on the windows' headings with
    a light pull between neighbouring knots, so noisy windows average out; None when under
    ``MIN_WINDOW_SHARE`` of the windows pass."""
    good = weight > 0.0
    if good.sum() < MIN_WINDOW_SHARE * weight.size:
        return None
    yaw = np.unwrap(yaw[good])
    tc, w = centres[good], weight[good]
    n_knots = max(2, int(np.ceil((t[-1] - t[0]) / KNOT_S)) + 1)
    knots = np.linspace(t[0], t[-1], n_knots)
    basis = _hats(tc, knots)
    a = basis * np.sqrt(w)[:, None]
    b = yaw * np.sqrt(w)
    # first differences of the knot values, lightly: where no window speaks, the heading
    # holds (a slope is never extrapolated into a stretch without data)
    step = np.diff(np.eye(n_knots), 1, axis=0) * np.sqrt(SMOOTHNESS * w.sum())
    a = np.vstack([a, step])
    b = np.concatenate([b, np.zeros(n_knots - 1)])
    values, *_ = np.linalg.lstsq(a, b, rcond=None)
    return _hats(t, knots) @ values


def _hats(x: FloatArray, knots: FloatArray) -> FloatArray:
    """(len(x), len(knots)) piecewise-linear basis (held beyond the ends)."""
    eye = np.eye(knots.size)
    return np.stack([np.interp(x, knots, eye[k]) for k in range(knots.size)], axis=1)


def align_headings_by_joints(
    tree: SensorTree,
    orientations: Mapping[str, OrientationSeries],
    recordings: Mapping[str, ImuRecording],
) -> tuple[dict[str, OrientationSeries], JointHeadings]:
    """The tree's sensors' orientations turned into the root sensor's heading (module
    docstring), and what was done. ``recordings``: each sensor's raw samples (the
    accelerometer is used), on the orientations' clock."""
    tree.check_sensors(list(orientations))
    missing = [s.sensor for s in tree.segments if s.sensor not in recordings]
    if missing:
        raise ConfigError(
            f"joint headings need each sensor's accelerometer; no raw samples for "
            f"{', '.join(missing)} (run on a raw recording with --filter)"
        )
    use = align_orientations({s.sensor: orientations[s.sensor] for s in tree.segments})
    t = use[tree.segments[0].sensor].time
    if t.size < 10:
        raise ConfigError("joint headings: the recording is too short (under 10 samples)")
    rate = 1.0 / float(np.median(np.diff(t)))
    q = {k: v.quat for k, v in use.items()}
    acc = {}
    for s in tree.segments:
        rec = recordings[s.sensor]
        # raw: joint_terms filters the accelerations with the rest of the equation
        acc[s.sensor] = np.column_stack([np.interp(t, rec.time, rec.acc[:, i]) for i in range(3)])
    out = JointHeadings(t, {tree.segments[0].sensor: np.zeros(t.size)})
    parents = tree.parent_index
    for i, seg in enumerate(tree.segments):
        if parents[i] < 0:
            out.correction[seg.sensor] = np.zeros(t.size)
            continue
        p = tree.segments[int(parents[i])].sensor
        c = seg.sensor
        pair = _pair_heading(t, q[p], q[c], acc[p], acc[c], rate, p, c)
        out.pairs.append(pair)
        if pair.note:
            out.notes.append(pair.note)
        out.correction[c] = out.correction[p] + pair.delta
    turned = {
        k: OrientationSeries(s.time, quat_mul(_rz(out.correction[k]), s.quat), s.name, s.frame)
        for k, s in use.items()
    }
    return turned, out


def _pair_heading(
    t: FloatArray, qp: FloatArray, qc: FloatArray, ap: FloatArray, ac: FloatArray, rate: float,
    p: str, c: str,
) -> PairHeading:  # fmt: skip
    kin = kinematics(np.stack([qp, qc], 1), np.stack([ap, ac], 1), rate)
    fit = fit_pair(kin, 0, 1, headings="independent")
    ok = _usable([qp, qc], [ap, ac], rate)
    if not np.isfinite(fit.residual):
        return PairHeading(p, c, np.zeros(t.size), 0, 0, float("inf"),
                           f"{c}: too little motion for the joint with {p}; its heading is "
                           "not followed through the joint (aligned at the pose only)")  # fmt: skip
    delta = np.full(t.size, fit.yaw)
    o_p, o_c = fit.o_i, fit.o_j
    centres = np.array([])
    weight = np.array([])
    for _ in range(2):  # the centres from the whole recording, then refit with delta applied
        up = _joint_acc(qp, ap, o_p, rate)
        uc = _joint_acc(qc, ac, o_c, rate)
        fine = ok & np.isfinite(up).all(axis=1) & np.isfinite(uc).all(axis=1)  # gaps out
        up, uc = np.nan_to_num(up), np.nan_to_num(uc)
        centres, yaws, weight = _window_headings(t, up[:, :2], uc[:, :2], fine, rate)
        d = _delta_series(t, centres, yaws, weight)
        if d is None:
            return PairHeading(p, c, delta, 0, centres.size, fit.residual,
                               f"{c}: too few stretches of motion show the joint with {p} "
                               "well enough; its heading is not followed through the joint "
                               "(aligned at the pose only)")  # fmt: skip
        delta = d
        qc_turned = quat_mul(_rz(delta), qc)  # NaN rows (gaps) stay NaN
        kin = kinematics(np.stack([qp, qc_turned], 1), np.stack([ap, ac], 1), rate)
        refit = fit_pair(kin, 0, 1, headings="shared")
        if np.isfinite(refit.residual):
            o_p, o_c = refit.o_i, refit.o_j
    used = int((weight > 0).sum())
    return PairHeading(p, c, delta, used, centres.size, fit.residual)
