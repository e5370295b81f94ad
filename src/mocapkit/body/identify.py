"""Which sensor is on which segment: placement found from a short motion.

Given a sensor tree and as many unlabelled orientation streams as it has segments, find
the labelling in three steps, each with its own evidence:

1. **Neighbours** (mounting-free). For every pair of sensors, the dispersion of their
   relative orientation ``q_i^-1 q_j`` over the motion: ``1 - lambda_max(M) / N`` with
   ``M = sum r r^T`` over the relative quaternions ``r``. A constant mounting on either side
   multiplies every ``r`` by the same unit quaternion, an orthogonal map of R^4, so the
   dispersion does not depend on how a sensor is strapped on. Sensors on neighbouring
   segments turn less against each other than sensors two joints apart. With 6D
   orientations, whose headings differ per sensor, the dispersion is minimised over an
   unknown constant heading between the two (``headings="independent"``).
2. **Topology**. The labelling that minimises the summed dispersion over the tree's joints
   (a small quadratic assignment; exhaustive below 9 segments, else swap descent from many
   starts), with a weak tie-break that proximal segments turn less than distal ones (a
   chain's two ends). Per segment, the confidence is the relative cost of the best single
   swap that moves its sensor elsewhere.
3. **Left and right**. Mirror-image branches (the two legs, the two arms) cost the same
   in step 2. They are told apart by gait: while walking, the pelvis turns to bring the
   swinging leg's hip forward (``pelvis_rotation`` in phase with ``hip_flexion_r -
   hip_flexion_l``), and each arm swings against the leg of its side. The joint angles come
   from the body model under the automatic calibration. When the motion shows no such
   coupling (no walking, the arms held still) the pair is reported as undecided with the
   reason; a sensor pinned with ``known`` decides its branch.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.identify_sides import decide_sides, mirror_pairs, same_mirror
from mocapkit.body.joint_centres import kinematics, pair_fits, residual_matrix
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.body.timebase import common_time, resample_orientation
from mocapkit.errors import ConfigError, DataError
from mocapkit.geometry import quat_conj, quat_mul
from mocapkit.series import ImuRecording, OrientationSeries

RATE_HZ = 25.0  # dispersion rate: the motion is slow; 25 Hz keeps 15 sensors fast
MIN_DURATION_S = 5.0
MIN_VALID_FRACTION = 0.5
MIN_MOTION_DEG = 10.0  # RMS relative rotation a tree's joints must show in all
# Two segments whose sensors swap at less than this extra cost look alike: undecided.
MIN_MARGIN = 0.01
# Tie-break weight (share of the mean joint dispersion) for "proximal turns less".
PROXIMAL_WEIGHT = 0.001
EXHAUSTIVE_MAX = 8
RESTARTS = 150


class IdentifyError(DataError):
    """The recording cannot identify the placement (the message names why and the fix)."""


@dataclass(frozen=True)
class Assignment:
    segment: str
    sensor: str
    confidence: float  # 0..1
    evidence: str


@dataclass(frozen=True)
class Identification:
    """``mapping`` is ``{segment: sensor}`` (for :meth:`SensorTree.with_sensor_names` or
    the CLI's ``--map``); ``undecided`` lists the pairs that could not be told apart, with
    the reason; their segments keep the topology's guess at confidence 0.5."""

    tree: str
    assignments: tuple[Assignment, ...]
    undecided: tuple[str, ...] = ()
    dispersion_deg: dict[str, dict[str, float]] = field(default_factory=dict)

    @property
    def mapping(self) -> dict[str, str]:
        return {a.segment: a.sensor for a in self.assignments}

    @property
    def decided(self) -> bool:
        return not self.undecided

    def to_dict(self) -> dict[str, Any]:
        return {
            "tree": self.tree,
            "decided": self.decided,
            "mapping": self.mapping,
            "assignments": [
                {
                    "segment": a.segment,
                    "sensor": a.sensor,
                    "confidence": round(a.confidence, 3),
                    "evidence": a.evidence,
                }
                for a in self.assignments
            ],
            "undecided": list(self.undecided),
        }


# -- step 0: one time base, only frames every sensor has ----------------------------------
def _common(
    orientations: Mapping[str, OrientationSeries],
    recordings: Mapping[str, HasAcc] | None,
) -> tuple[list[str], FloatArray, FloatArray, FloatArray | None]:
    """(sensor names, time (N,), q (N, S, 4), acc (N, S, 3) or None) at the recordings'
    own rate, only the frames where every sensor has data."""
    names = list(orientations)
    for name, s in orientations.items():
        frac = float(s.valid.mean()) if s.n_samples else 0.0
        if frac < MIN_VALID_FRACTION:
            raise IdentifyError(
                f"sensor {name!r}: only {100 * frac:.0f} % of its samples are valid (it "
                "stopped or dropped out); identify on a stretch where every sensor "
                "records (--start/--stop), or leave it out and label it by hand"
            )
    t = common_time(orientations)
    q = np.stack([resample_orientation(orientations[n], t).quat for n in names], axis=1)
    acc = None
    if recordings is not None:
        missing = [n for n in names if n not in recordings]
        if missing:
            raise ConfigError(f"no raw samples for sensor(s) {', '.join(missing)}")
        acc = np.stack([_interp_rows(t, recordings[n].time, recordings[n].acc) for n in names], 1)
    ok = np.isfinite(q).all(axis=(1, 2))
    if acc is not None:
        ok &= np.isfinite(acc).all(axis=(1, 2))
    span = float(t[-1] - t[0]) * float(ok.mean()) if t.size > 1 else 0.0
    if ok.sum() < 2 or span < MIN_DURATION_S:
        raise IdentifyError(
            f"only {span:.1f} s in which every sensor records; identification needs at "
            f"least {MIN_DURATION_S:.0f} s of motion (walk for 10-20 s, swinging the arms)"
        )
    return names, t[ok], q[ok], None if acc is None else acc[ok]


class HasAcc(Protocol):
    """Raw samples of one sensor: ``time`` (N,) [s] and ``acc`` (N, 3) [m/s^2] (an
    :class:`ImuRecording`, an Xsens export...)."""

    time: FloatArray
    acc: FloatArray


def align_sensor_frames(
    orientation: OrientationSeries, recording: ImuRecording, name: str = "sensor"
) -> ImuRecording:
    """``recording`` rotated into ``orientation``'s sensor frame: some devices report
    their orientation for a frame turned against the accelerometer's (the qmt full-body
    file does). The rotation is fitted between the gyroscope and the orientation's own
    angular rate (Kabsch); a poor fit is refused, naming the sensor."""
    from mocapkit.body.calibration import angular_rate

    w_q = angular_rate(orientation)
    g = np.column_stack(
        [np.interp(orientation.time, recording.time, recording.gyr[:, k]) for k in range(3)]
    )
    ok = np.isfinite(w_q).all(axis=1) & np.isfinite(g).all(axis=1)
    if ok.sum() < 20:
        raise IdentifyError(f"sensor {name!r}: too few samples to match its frames")
    h = g[ok].T @ w_q[ok]
    u, _, vt = np.linalg.svd(h)
    d = float(np.sign(np.linalg.det(vt.T @ u.T)))
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T  # w_q ~ rot @ g
    resid = float(np.sqrt(np.mean(np.sum((w_q[ok] - g[ok] @ rot.T) ** 2, axis=1))))
    scale = float(np.sqrt(np.mean(np.sum(w_q[ok] ** 2, axis=1))))
    if resid > 0.6 * scale:
        raise IdentifyError(
            f"sensor {name!r}: its orientations do not follow its gyroscope (residual "
            f"{resid:.2f} of {scale:.2f} rad/s): not the same sensor or time base. Run a "
            "filter on the raw samples instead (--filter polaris-body)"
        )
    return replace(recording, gyr=recording.gyr @ rot.T, acc=recording.acc @ rot.T)


def _interp_rows(t: FloatArray, src_t: FloatArray, x: FloatArray) -> FloatArray:
    return np.column_stack(
        [np.interp(t, src_t, x[:, k], left=np.nan, right=np.nan) for k in range(3)]
    )


# -- step 1: pairwise dispersion ----------------------------------------------------------
def dispersion_matrix(q: FloatArray, headings: str = "shared") -> FloatArray:
    """(S, S) dispersion ``1 - lambda_max / N`` of every pair's relative orientation
    (module docstring) for quaternions ``q`` (N, S, 4); ``headings="independent"``
    minimises it over a constant heading between the two sensors."""
    if headings not in ("shared", "independent"):
        raise ConfigError(f"headings: expected 'shared' or 'independent', got {headings!r}")
    n, s, _ = q.shape
    out = np.zeros((s, s))
    ez = np.array([0.0, 0.0, 0.0, 1.0])
    yaw = np.linspace(0.0, 2.0 * np.pi, 73)[:-1]  # half-angles over a full turn
    for i, j in itertools.combinations(range(s), 2):
        qi_c = quat_conj(q[:, i])
        a = quat_mul(qi_c, q[:, j])
        if headings == "shared":
            lam = float(np.linalg.eigvalsh(a.T @ a / n)[-1])
        else:
            b = quat_mul(qi_c, quat_mul(np.broadcast_to(ez, q[:, j].shape), q[:, j]))
            aa, bb, ab = a.T @ a / n, b.T @ b / n, (a.T @ b + b.T @ a) / n
            c, sn = np.cos(yaw / 2.0), np.sin(yaw / 2.0)
            m = c[:, None, None] ** 2 * aa + sn[:, None, None] ** 2 * bb
            m = m + (c * sn)[:, None, None] * ab
            lam = float(np.linalg.eigvalsh(m)[:, -1].max())
        out[i, j] = out[j, i] = max(0.0, 1.0 - lam)
    return out


def dispersion_deg(d: FloatArray) -> FloatArray:
    """Dispersion as an angle: ``2 asin(sqrt(d))`` [deg] (the RMS-like rotation)."""
    return np.degrees(2.0 * np.arcsin(np.sqrt(np.clip(d, 0.0, 1.0))))


# -- step 2: topology ----------------------------------------------------------------------
def _edges(tree: SensorTree) -> tuple[np.ndarray, np.ndarray]:
    parent = tree.parent_index
    child = np.flatnonzero(parent >= 0)
    return parent[child], child


def _depths(tree: SensorTree) -> np.ndarray:
    parent = tree.parent_index
    depth = np.zeros(len(parent))
    for i, p in enumerate(parent):
        depth[i] = 0.0 if p < 0 else depth[p] + 1.0
    return depth


def _costs(
    perms: np.ndarray, d: FloatArray, pe: np.ndarray, ce: np.ndarray, prox: FloatArray
) -> FloatArray:
    """perms (K, S): sensor index per segment -> (K,) cost."""
    return d[perms[:, pe], perms[:, ce]].sum(axis=1) + prox[np.arange(perms.shape[1]), perms].sum(
        axis=1
    )


def _swaps(perm: np.ndarray, free: np.ndarray) -> tuple[np.ndarray, list[tuple[int, int]]]:
    pairs = list(itertools.combinations(free.tolist(), 2))
    out = np.repeat(perm[None], len(pairs), axis=0)
    for k, (a, b) in enumerate(pairs):
        out[k, a], out[k, b] = perm[b], perm[a]
    return out, pairs


def best_labelling(
    d: FloatArray,
    tree: SensorTree,
    speed: FloatArray,
    pinned: Mapping[int, int] | None = None,
    seed: int = 0,
) -> tuple[np.ndarray, float, FloatArray]:
    """(perm (S,) sensor index per segment, its cost, the proximal tie-break table)."""
    s = d.shape[0]
    pe, ce = _edges(tree)
    pinned = dict(pinned or {})
    scale = float(np.mean(d[np.triu_indices(s, 1)])) if s > 1 else 1.0
    rel_speed = speed / max(float(speed.mean()), 1e-12)
    # prox[segment, sensor]: proximal segments should carry the slower sensors
    prox = PROXIMAL_WEIGHT * scale * np.outer(-_depths(tree), rel_speed)
    free_seg = np.array([k for k in range(s) if k not in pinned], dtype=np.int64)
    free_sen = [j for j in range(s) if j not in pinned.values()]
    base = np.zeros(s, dtype=np.int64)
    for k, j in pinned.items():
        base[k] = j
    if len(free_seg) <= EXHAUSTIVE_MAX:
        perms = np.array(list(itertools.permutations(free_sen)), dtype=np.int64)
        full = np.repeat(base[None], len(perms), axis=0)
        if len(free_seg):
            full[:, free_seg] = perms
        costs = _costs(full, d, pe, ce, prox)
        k = int(np.argmin(costs))
        return full[k], float(costs[k]), prox
    rng = np.random.default_rng(seed)
    best, best_cost = base, np.inf
    for _ in range(RESTARTS):
        perm = base.copy()
        perm[free_seg] = rng.permutation(free_sen)
        cost = float(_costs(perm[None], d, pe, ce, prox)[0])
        while True:
            cand, _ = _swaps(perm, free_seg)
            costs = _costs(cand, d, pe, ce, prox)
            k = int(np.argmin(costs))
            if costs[k] >= cost - 1e-15:
                break
            perm, cost = cand[k], float(costs[k])
        if cost < best_cost:
            best, best_cost = perm, cost
    return best, best_cost, prox


def swap_margins(
    perm: np.ndarray, cost: float, d: FloatArray, tree: SensorTree, prox: FloatArray,
    free: np.ndarray,
) -> tuple[FloatArray, list[int]]:  # fmt: skip
    """Per segment: relative extra cost of the cheapest swap that moves its sensor (inf
    when pinned), and the segment it would swap with (-1: none)."""
    s = len(perm)
    pe, ce = _edges(tree)
    margin = np.full(s, np.inf)
    partner = [-1] * s
    if len(free) < 2:
        return margin, partner
    cand, pairs = _swaps(perm, free)
    costs = _costs(cand, d, pe, ce, prox)
    for c, (a, b) in zip(costs, pairs, strict=True):
        rel = (float(c) - cost) / max(cost, 1e-12)
        for x, y in ((a, b), (b, a)):
            if rel < margin[x]:
                margin[x], partner[x] = rel, y
    return margin, partner


def identify(
    tree: SensorTree,
    orientations: Mapping[str, OrientationSeries],
    recordings: Mapping[str, HasAcc] | None = None,
    *,
    headings: str = "shared",
    known: Mapping[str, str] | None = None,
) -> Identification:
    """Label ``orientations`` (``{sensor: q_world_sensor}``, one per segment of ``tree``)
    with the tree's segments (module docstring). ``recordings``: the same sensors' raw
    samples (their accelerometers add the joint-centre evidence; their frames must be the
    orientations' sensor frames, see :func:`align_sensor_frames`). ``known``:
    ``{segment: sensor}`` pins. ``headings="independent"`` for 6D orientations."""
    segs = list(tree.segment_names)
    if len(orientations) != len(segs):
        raise IdentifyError(
            f"tree {tree.name!r} has {len(segs)} segments ({', '.join(segs)}) but "
            f"{len(orientations)} sensors were given ({', '.join(orientations)}); give one "
            "sensor per segment (leave out extra sensors, CLI --sensors, or use a tree that has "
            "them)"
        )
    names, t, q, acc = _common(orientations, recordings)
    rate = 1.0 / float(np.median(np.diff(t)))
    pinned: dict[int, int] = {}
    for seg, sensor in (known or {}).items():
        if seg not in segs:
            raise ConfigError(
                f"known: no segment {seg!r} in tree {tree.name!r}; segments: {', '.join(segs)}"
            )
        if sensor not in names:
            raise ConfigError(f"known: no sensor {sensor!r}; sensors: {', '.join(names)}")
        pinned[segs.index(seg)] = names.index(sensor)
    step = max(1, round(rate / RATE_HZ))
    d = dispersion_matrix(q[::step], headings)
    joint_deg = dispersion_deg(d)[np.triu_indices(len(names), 1)]
    if joint_deg.size and float(np.median(joint_deg)) < MIN_MOTION_DEG:
        raise IdentifyError(
            f"the sensors hardly turn against each other (median {np.median(joint_deg):.1f} "
            f"deg over {len(names)} sensors): the motion does not show which sensors are "
            "neighbours. Record 10-20 s of walking with arm swing, or of bending every joint"
        )
    cost = d / max(float(np.mean(d[np.triu_indices(len(names), 1)])), 1e-12)
    fits, kin = None, None
    if acc is not None:
        kin = kinematics(q, acc, rate)
        fits = pair_fits(kin, headings)
        r = residual_matrix(fits, len(names))
        # the joint centres alone: the dispersion misleads in fast motion (running)
        cost = r / max(float(np.mean(r[np.triu_indices(len(names), 1)])), 1e-12)
    w = np.diff(q[::step], axis=0)
    speed = np.sqrt(np.mean(np.sum(w * w, axis=2), axis=0))  # chordal rate per sensor
    perm, total, prox = best_labelling(cost, tree, speed, pinned)
    free = np.array([k for k in range(len(segs)) if k not in pinned], dtype=np.int64)
    margin, partner = swap_margins(perm, total, cost, tree, prox, free)
    perm, side_conf, undecided = decide_sides(
        tree, names, perm, orientations, headings, pinned, fits, kin
    )
    assignments = []
    pairs = mirror_pairs(tree)
    alike: set[tuple[int, int]] = set()
    for k in range(len(segs)):
        o = partner[k]
        if o >= 0 and margin[k] < MIN_MARGIN and not same_mirror(tree, k, o, pairs):
            alike.add((min(k, o), max(k, o)))
    for k, o in sorted(alike):
        undecided.append(
            f"{segs[k]} / {segs[o]}: their sensors could be exchanged at "
            f"+{100 * margin[k]:.1f} % cost; the motion does not show which is which. Move "
            f"both joints (bend, twist) during the recording, or pin one (--known "
            f"{segs[k]}=SENSOR)"
        )
    for k, seg in enumerate(segs):
        if k in pinned:
            conf, ev = 1.0, "pinned (known)"
        else:
            m = float(margin[k])
            conf = 1.0 if not np.isfinite(m) else float(min(1.0, max(0.0, m / 0.1)))
            if any(k in pair for pair in alike):
                conf = min(conf, 0.5)
            other = segs[partner[k]] if partner[k] >= 0 else "-"
            ev = f"neighbours: next best swaps with {other} at +{100 * m:.1f} % cost"
            if k in side_conf and partner[k] >= 0 and same_mirror(tree, k, partner[k], pairs):
                conf, ev = side_conf[k]  # the only cheap swap is the mirror image
            elif k in side_conf:
                conf = min(conf, side_conf[k][0])
                ev = f"{ev}; {side_conf[k][1]}"
        assignments.append(Assignment(seg, names[int(perm[k])], conf, ev))
    table = dispersion_deg(d)
    disp = {
        names[i]: {names[j]: round(float(table[i, j]), 1) for j in range(len(names)) if j != i}
        for i in range(len(names))
    }
    return Identification(tree.name, tuple(assignments), tuple(undecided), disp)
