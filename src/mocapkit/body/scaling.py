"""Scale the human model to a subject and register its markers, as OpenSim's Scale tool does.

From a static trial (:func:`scale_from_static`):

1. the stillest window (0.5 s) of the trial is averaged (a warning when it still moves);
2. measurement-based scaling: each measurement's segments get the mean ratio of the
   experimental to the model distance of its marker pairs (model distances at the
   static pose), unmeasured segments follow stature;
3. joint-centre landmarks refine lengths: a segment whose two joint centres are known
   (a landmark such as mid-condyles, or the model's joint at the static pose) gets the
   length between them;
4. marker registration (OpenSim's MarkerPlacer): static IK with the generic offsets, then
   every marker seen in the static trial moves to its measured position, expressed in its
   segment frame. Markers the static trial lacks keep the generic guess, with a warning.

From a dynamic trial (:func:`estimate_scales_from_motion`, the paper's future work): see
its docstring.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.anthropometry import Sex
from mocapkit.body.human_model import HumanModel, build_human_model
from mocapkit.body.markersets import MarkerSet
from mocapkit.errors import DataError

log = logging.getLogger(__name__)

STATIC_WINDOW_S = 0.5
STATIC_SPEED_WARN_M_S = 0.02  # mean marker speed above which a "static" trial is moving
LANDMARK_WEIGHT = 10.0
# The static trial is taken as the neutral pose of the joints the generic markers cannot
# pin down well (like OpenSim's MarkerPlacer holding lumbar_extension at 0): these DOFs get
# a prior of this weight [m² / rad²] towards 0 in the static IK (a 10° deviation then costs
# like a 17 cm error on a marker of weight 1).
STATIC_NEUTRAL_WEIGHT = 1.0
STATIC_NEUTRAL_PREFIXES = ("abdomen_", "thorax_", "cervical_", "head_", "sc_")


@dataclass(frozen=True)
class Subject:
    """A scaled model with registered markers, ready for reconstruction.

    Attributes:
        human: the model; ``human.markers`` are the registered marker offsets.
        markerset: the generic marker set it came from.
        static_q: (nq,) configuration of the static pose.
        report: what was measured and changed (scale factors, residuals, warnings).
    """

    human: HumanModel
    markerset: MarkerSet
    static_q: FloatArray
    report: dict[str, Any] = field(default_factory=dict)


def stillest_window(time: FloatArray, X: FloatArray, window_s: float = STATIC_WINDOW_S) -> slice:
    """Frames of the ``window_s`` window with the lowest mean marker speed."""
    n = len(time)
    if n < 3:
        return slice(0, n)
    rate = 1.0 / float(np.median(np.diff(time)))
    w = max(2, min(n, round(window_s * rate)))
    with np.errstate(invalid="ignore"):
        speed = np.linalg.norm(np.diff(X, axis=0), axis=2) * rate  # (n-1, M)
        per_frame = np.nanmean(np.where(np.isfinite(speed), speed, np.nan), axis=1)
    per_frame = np.where(np.isfinite(per_frame), per_frame, np.inf)
    csum = np.concatenate([[0.0], np.cumsum(np.minimum(per_frame, 1e6))])
    means = (csum[w - 1 :] - csum[: len(csum) - w + 1]) / (w - 1)
    start = int(np.argmin(means))
    return slice(start, start + w)


def static_speed(time: FloatArray, X: FloatArray, window_s: float = STATIC_WINDOW_S) -> float:
    """Mean marker speed [m/s] in the stillest ``window_s`` of a trial (0 if too short)."""
    window = stillest_window(time, X, window_s)
    Xw = X[window]
    if len(Xw) < 2 or len(time) < 2:
        return 0.0
    rate = 1.0 / float(np.median(np.diff(time)))
    d = np.linalg.norm(np.diff(Xw, axis=0), axis=2)
    d = d[np.isfinite(d)]
    return float(d.mean()) * rate if d.size else 0.0


def _landmarks(ms: MarkerSet, names: Sequence[str], Xs: FloatArray) -> dict[str, FloatArray]:
    """Joint-centre virtual markers measured in the static average (all members visible)."""
    out: dict[str, FloatArray] = {}
    index = {n: i for i, n in enumerate(names)}
    for c in ms.joint_centres:
        pts = [Xs[index[m]] for m in c.markers if m in index]
        if len(pts) == len(c.markers) and all(np.isfinite(p).all() for p in pts):
            out[c.name] = np.mean(pts, axis=0)
    return out


def static_coordinate_tasks(human: HumanModel, ms: MarkerSet) -> dict[str, tuple[float, float]]:
    """Coordinate tasks of the static IK: spine/girdle neutral, then the set's own tasks."""
    tasks = {
        d: (0.0, STATIC_NEUTRAL_WEIGHT)
        for d in human.dof_names
        if d.startswith(STATIC_NEUTRAL_PREFIXES)
    }
    tasks.update(ms.coordinate_tasks)
    tasks.update(ms.static_coordinate_tasks)
    return tasks


def _static_ik(
    human: HumanModel,
    names: list[str],
    X: FloatArray,
    weights: FloatArray,
    ms: MarkerSet,
    q0: FloatArray,
) -> FloatArray:
    from mocapkit.markers.ik import IKParams, initial_root_pose, solve_ik

    q_start = initial_root_pose(human, names, X, q0)
    sol = solve_ik(
        human, names, X[None], weights, q_start, static_coordinate_tasks(human, ms),
        q_posture=human.neutral(), params=IKParams(max_iter_first=300, posture_weight=1e-3),
    )  # fmt: skip
    return np.asarray(sol.q[0])


def _segment_frames(human: HumanModel, q: FloatArray) -> dict[str, tuple[FloatArray, FloatArray]]:
    import pinocchio as pin

    data = human.model.createData()
    pin.framesForwardKinematics(human.model, data, q)
    out = {}
    for seg in human.segments:
        M = data.oMf[human.model.getFrameId(seg)]
        out[seg] = (np.array(M.rotation), np.array(M.translation))
    return out


def _base_child_offset(human: HumanModel, segment: str, child: str) -> FloatArray:
    for j in human.joints:
        if j.parent == segment and j.child == child:
            return np.asarray(j.position, dtype=float)
    raise DataError(f"no joint from {segment} to {child}")


def scale_from_static(
    static_names: Sequence[str],
    static_time: FloatArray,
    static_X: FloatArray,
    markerset: MarkerSet,
    height_m: float,
    mass_kg: float,
    sex: Sex = "male",
    iterations: int = 3,
) -> Subject:
    """Scale and register from a static trial.

    Args:
        static_names: the trial's marker names (already matched to the set's names).
        static_time: (N,) s.
        static_X: (N, M, 3) positions [m], z-up.
        markerset: the generic set (offsets, measurements, landmarks, weights).
        height_m, mass_kg, sex: the subject.
        iterations: scale -> static IK rounds before registration.
    """
    window = stillest_window(static_time, static_X)
    Xw = static_X[window]
    report: dict[str, Any] = {"static_frames": [window.start, window.stop]}
    rate = 1.0 / float(np.median(np.diff(static_time))) if len(static_time) > 1 else 0.0
    with np.errstate(invalid="ignore"):
        speed = (
            float(np.nanmean(np.linalg.norm(np.diff(Xw, axis=0), axis=2))) * rate
            if len(Xw) > 1
            else 0.0
        )
        Xs = np.nanmean(Xw, axis=0) if len(Xw) else np.full(static_X.shape[1:], np.nan)
    report["static_speed_m_s"] = speed
    if speed > STATIC_SPEED_WARN_M_S:
        log.warning(
            "static trial: its stillest %.1f s still moves (mean marker speed %.0f mm/s); the "
            "scaling assumes a still pose. Fix: record the subject standing still",
            STATIC_WINDOW_S,
            speed * 1000,
        )
    index = {n: i for i, n in enumerate(static_names)}
    seen = [
        m.name
        for m in markerset.markers
        if m.name in index and np.isfinite(Xs[index[m.name]]).all()
    ]
    if len(seen) < 4:
        raise DataError(
            f"static trial: only {len(seen)} markers of set {markerset.name!r} are visible "
            f"({', '.join(seen)}); does the static trial match the marker set?"
        )
    landmarks = _landmarks(markerset, static_names, Xs)
    names = seen + list(landmarks)
    X = np.array([Xs[index[n]] for n in seen] + [landmarks[c] for c in landmarks]).reshape(-1, 3)
    weights = np.array(
        [markerset.static_weights.get(n, markerset.spec(n).weight) for n in seen]
        + [LANDMARK_WEIGHT] * len(landmarks)
    )
    weights = np.maximum(weights, 0.1)  # static: every marker counts a little

    scales: dict[str, float] = {}
    human = build_human_model(height_m, mass_kg, sex)
    q = human.neutral()
    for _ in range(iterations):
        human = build_human_model(height_m, mass_kg, sex, scales)
        human = human.with_markers(markerset.placements(height_m, human.segment_scales))
        q = _static_ik(human, names, X, weights, markerset, human.neutral() if _ == 0 else q)
        scales = _measurement_scales(human, markerset, names, X, q, scales)
        scales = _landmark_scales(human, markerset, landmarks, q, scales, names, X)
    human = build_human_model(height_m, mass_kg, sex, scales)
    human = human.with_markers(markerset.placements(height_m, human.segment_scales))
    q = _static_ik(human, names, X, weights, markerset, q)
    from mocapkit.markers.kinematics import MarkerKinematics

    before = np.linalg.norm(MarkerKinematics(human, names).positions(q) - X, axis=1)
    frames = _segment_frames(human, q)
    placed = dict(human.markers)
    for n, x in zip(seen, X[: len(seen)], strict=True):
        seg = placed[n][0]
        R, t = frames[seg]
        placed[n] = (seg, R.T @ (x - t))
    unregistered = [m.name for m in markerset.markers if m.name not in seen]
    if unregistered:
        log.warning(
            "static trial lacks %d markers of the set (%s); they keep the marker set's generic "
            "offsets (errors of several cm are possible). Fix: include them in the static trial",
            len(unregistered),
            ", ".join(unregistered[:12]) + (" ..." if len(unregistered) > 12 else ""),
        )
    human = human.with_markers(placed)
    report.update(
        {
            "segment_scales": {k: round(v, 4) for k, v in scales.items()},
            "registration_residual_mm": {
                n: round(float(e) * 1000, 1) for n, e in zip(names, before, strict=True)
            },
            "unregistered_markers": unregistered,
            "landmarks": list(landmarks),
        }
    )
    return Subject(human, markerset, q, report)


def _measurement_scales(
    human: HumanModel,
    ms: MarkerSet,
    names: list[str],
    X: FloatArray,
    q: FloatArray,
    previous: Mapping[str, float],
) -> dict[str, float]:
    from mocapkit.markers.kinematics import MarkerKinematics

    out = dict(previous)
    P = MarkerKinematics(human, names).positions(q)
    index = {n: i for i, n in enumerate(names)}
    for meas in ms.scaling:
        ratios = []
        for a, b in meas.pairs:
            if a in index and b in index:
                model_d = np.linalg.norm(P[index[a]] - P[index[b]])
                exp_d = np.linalg.norm(X[index[a]] - X[index[b]])
                if model_d > 1e-6:
                    ratios.append(exp_d / model_d)
        if not ratios:
            continue
        r = float(np.mean(ratios))
        for seg in meas.segments:
            out[seg] = float(np.clip(human.segment_scales.get(seg, 1.0) * r, 0.5, 2.0))
    return out


def _kabsch(A: FloatArray, B: FloatArray) -> tuple[FloatArray, FloatArray]:
    """R, t with B ≈ R A + t (rows are points)."""
    ca, cb = A.mean(axis=0), B.mean(axis=0)
    U, _, Vt = np.linalg.svd((A - ca).T @ (B - cb))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, cb - R @ ca


def _landmark_scales(
    human: HumanModel,
    ms: MarkerSet,
    landmarks: Mapping[str, FloatArray],
    q: FloatArray,
    previous: Mapping[str, float],
    names: Sequence[str] = (),
    X: FloatArray | None = None,
) -> dict[str, float]:
    """Segments whose proximal and distal joint centres are known get that length.

    A distal centre is a landmark (e.g. mid-condyles). A proximal centre is a landmark too,
    or the joint's position in the parent segment placed by a rigid fit of the parent's own
    markers (so the thigh length does not depend on the leg's static IK), or else the static
    IK pose.
    """
    out = dict(previous)
    frames = _segment_frames(human, q)
    index = {n: i for i, n in enumerate(names)}
    poses: dict[str, tuple[FloatArray, FloatArray]] = {}
    if X is not None:
        for seg in human.segments:
            own = [n for n, (sg, _) in human.markers.items() if sg == seg and n in index]
            own = [n for n in own if np.isfinite(X[index[n]]).all()]
            if len(own) >= 3:
                A = np.array([human.markers[n][1] for n in own])
                B = np.array([X[index[n]] for n in own])
                poses[seg] = _kabsch(A, B)
    seg_of_landmark = {c.name: c.segment for c in ms.joint_centres if c.name in landmarks}
    centre: dict[str, FloatArray] = {seg: frames[seg][1] for seg in human.segments}
    for j in human.joints:
        if j.parent in poses:
            R, t = poses[j.parent]
            offset = np.asarray(j.position) * human.segment_scales.get(j.parent, 1.0)
            centre[j.child] = R @ offset + t
    for name, seg in seg_of_landmark.items():
        centre[seg] = np.asarray(landmarks[name])
    for child in seg_of_landmark.values():
        parent = next((j.parent for j in human.joints if j.child == child), None)
        if parent is None:
            continue
        base = np.linalg.norm(_base_child_offset(human, parent, child))
        if base < 1e-6:
            continue
        length = float(np.linalg.norm(centre[child] - centre[parent]))
        out[parent] = float(np.clip(length / base, 0.5, 2.0))
    return out


# -- limb lengths from a dynamic trial (the paper's future work) -------------------------------
MOTION_FRAMES = 30
OFFSET_PRIOR_WEIGHT = 0.05  # relative weight pulling offsets towards the marker set's guess
SCALE_PRIOR_WEIGHT = 0.03  # relative weight pulling segment scales towards the tables


def _path_joints(human: HumanModel, segment: str) -> list[Any]:
    """The joints from the pelvis down to ``segment`` (root first)."""
    by_child = {j.child: j for j in human.joints}
    path = []
    seg = segment
    while seg in by_child:
        path.append(by_child[seg])
        seg = by_child[seg].parent
    return path[::-1]


def estimate_scales_from_motion(
    names: Sequence[str],
    X: FloatArray,
    markerset: MarkerSet,
    height_m: float,
    mass_kg: float,
    sex: Sex = "male",
    iterations: int = 6,
    n_frames: int = MOTION_FRAMES,
) -> Subject:
    """Segment lengths and marker offsets that best track a *dynamic* trial.

    With the segment orientations of an IK solution held fixed, a marker's world position is
    linear in the unknowns::

        x_m(f) = t(f) + Σ_{joints j above m} R_parent(j)(f) s_parent(j) p_j + R_seg(m)(f) o_m

    (t: pelvis position per frame, s: segment scale factors, p_j: a joint's position in its
    parent at table lengths, o_m: the marker's offset). Alternating IK over a frame subset
    and one linear least-squares solve (weak priors: scales 1, offsets the set's guesses)
    lowers the total marker residual at every round.

    Args:
        names: trial marker names (set names); X: (N, M, 3) positions [m], z-up.
    """
    from mocapkit.markers.ik import IKParams, initial_root_pose, solve_ik
    from mocapkit.markers.kinematics import MarkerKinematics

    names = [n for n in names if n in set(markerset.names)]
    idx_all = list(range(len(names)))
    X = np.asarray(X, dtype=float)
    visible = np.isfinite(X[..., 0])
    good = np.flatnonzero(visible.sum(axis=1) >= max(4, int(0.8 * visible.sum(axis=1).max())))
    if len(good) < 3:
        raise DataError(
            "estimating limb lengths from the trial needs frames where most markers are visible; "
            "give a static trial (--static)"
        )
    frames = good[np.linspace(0, len(good) - 1, min(n_frames, len(good))).round().astype(int)]
    Xf = X[frames]
    weights = np.array([markerset.spec(n).weight for n in names])
    scales: dict[str, float] = {}
    human = build_human_model(height_m, mass_kg, sex)
    offsets = {n: np.asarray(markerset.placements(height_m, {})[n][1]) for n in names}
    generic = dict(offsets)
    report: dict[str, Any] = {"motion_frames": frames.tolist(), "residual_mm": []}
    q_prev = human.neutral()
    for _ in range(iterations):
        human = build_human_model(height_m, mass_kg, sex, scales)
        human = human.with_markers({n: (markerset.spec(n).segment, offsets[n]) for n in names})
        q0 = initial_root_pose(human, names, Xf[0], q_prev)
        sol = solve_ik(
            human, names, Xf, weights, q0, markerset.coordinate_tasks,
            q_posture=human.neutral(), params=IKParams(max_iter_first=300, max_iter=60),
        )  # fmt: skip
        q_prev = sol.q[0]
        P = np.array([MarkerKinematics(human, names).positions(q) for q in sol.q])
        err = np.linalg.norm(P - Xf, axis=2)
        report["residual_mm"].append(round(float(np.nanmean(err)) * 1000, 2))
        scales, offsets = _linear_update(human, names, sol.q, Xf, weights, generic, scales)
    human = build_human_model(height_m, mass_kg, sex, scales)
    human = human.with_markers({n: (markerset.spec(n).segment, offsets[n]) for n in names})
    del idx_all
    report["segment_scales"] = {k: round(v, 4) for k, v in scales.items()}
    report["unregistered_markers"] = []
    return Subject(human, markerset, q_prev, report)


def _linear_update(
    human: HumanModel,
    names: list[str],
    Q: FloatArray,
    X: FloatArray,
    weights: FloatArray,
    generic: Mapping[str, FloatArray],
    scales: Mapping[str, float],
) -> tuple[dict[str, float], dict[str, FloatArray]]:
    """One linear least-squares solve for (t per frame, segment scales, marker offsets)."""
    segs = [s for s in human.segments if any(j.parent == s for j in human.joints)]
    seg_col = {s: i for i, s in enumerate(segs)}
    F, M = X.shape[0], len(names)
    n_t, n_s = 3 * F, len(segs)
    n = n_t + n_s + 3 * M
    rows: list[FloatArray] = []
    rhs: list[float] = []
    frames = [_segment_frames(human, q) for q in Q]
    paths = {n_: _path_joints(human, human.markers[n_][0]) for n_ in names}
    for f in range(F):
        for m, name in enumerate(names):
            if not np.isfinite(X[f, m, 0]) or weights[m] <= 0:
                continue
            w = np.sqrt(weights[m])
            seg = human.markers[name][0]
            block = np.zeros((3, n))
            block[:, 3 * f : 3 * f + 3] = np.eye(3)
            for j in paths[name]:
                Rp = frames[f][j.parent][0]
                block[:, n_t + seg_col[j.parent]] += Rp @ np.asarray(j.position)
            block[:, n_t + n_s + 3 * m : n_t + n_s + 3 * m + 3] = frames[f][seg][0]
            rows.append(w * block)
            rhs += list(w * X[f, m])
    A = np.vstack(rows)
    b = np.asarray(rhs)
    # weak priors, scaled to the data's size
    lam = np.sqrt(len(b) / max(1, n_s + 3 * M))
    prior_rows = np.zeros((n_s + 3 * M, n))
    prior_rhs = np.zeros(n_s + 3 * M)
    for i in range(n_s):
        prior_rows[i, n_t + i] = lam * SCALE_PRIOR_WEIGHT
        prior_rhs[i] = lam * SCALE_PRIOR_WEIGHT * 1.0
    for m, name in enumerate(names):
        for c in range(3):
            r = n_s + 3 * m + c
            prior_rows[r, n_t + n_s + 3 * m + c] = lam * OFFSET_PRIOR_WEIGHT
            prior_rhs[r] = lam * OFFSET_PRIOR_WEIGHT * generic[name][c]
    # normal equations (the priors make them positive definite): ~40x faster than the SVD
    # of lstsq at 30 frames x 60 markers, which took 2 s a round
    Aall = np.vstack([A, prior_rows])
    ball = np.concatenate([b, prior_rhs])
    H = Aall.T @ Aall
    try:
        L = np.linalg.cholesky(H)
        sol = np.linalg.solve(L.T, np.linalg.solve(L, Aall.T @ ball))
    except np.linalg.LinAlgError:
        sol, *_ = np.linalg.lstsq(Aall, ball, rcond=None)
    new_scales = dict(scales)
    for i, s in enumerate(segs):
        new_scales[s] = float(np.clip(sol[n_t + i], 0.5, 2.0))
    offsets = {name: sol[n_t + n_s + 3 * m : n_t + n_s + 3 * m + 3] for m, name in enumerate(names)}
    return new_scales, offsets
