"""Weighted least-squares inverse kinematics: the baseline the paper compares against.

Per frame: minimise ``Σ_i w_i ‖x_i − p_i(q)‖² + Σ_j w_j (q_j − q̄_j)²`` (markers, then
coordinate tasks and a weak posture prior) by projected Levenberg–Marquardt with joint
limits, warm-started from the previous frame. ``backend="fast"`` runs
:mod:`mocapkit.markers.ik_kernels` (numba) over the whole trial; ``backend="reference"``
runs the same algorithm in numpy on Pinocchio's kinematics (frame Jacobians) and is what
the fast path is tested against.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.human_model import HumanModel
from mocapkit.errors import ConfigError, DataError
from mocapkit.markers import rigid_fast
from mocapkit.markers.ik_kernels import LAMBDA0, ik_trial
from mocapkit.markers.kinematics import MarkerKinematics

BLOCK_FRAMES = 2000  # frames per kernel call (progress is reported between calls)

Backend = Literal["fast", "reference"]


@dataclass(frozen=True)
class IKParams:
    """Solver settings.

    Attributes:
        max_iter_first: LM iterations for the first frame (cold start).
        max_iter: LM iterations per later frame (warm start).
        tol: stop when the largest step is below this [rad or m].
        posture_weight: weight of the posture prior per revolute DOF [m² / rad²]: a 1 rad
            deviation costs as much as a 1 cm error on a marker of weight 1 at 1e-4.
        backend: ``"fast"`` (numba) or ``"reference"`` (Pinocchio + numpy).
    """

    max_iter_first: int = 200
    max_iter: int = 30
    tol: float = 1e-5
    posture_weight: float = 1e-4
    backend: Backend = "fast"

    def __post_init__(self) -> None:
        if self.backend not in ("fast", "reference"):
            raise ConfigError(f"backend: expected 'fast' or 'reference', got {self.backend!r}")
        if self.max_iter < 1 or self.max_iter_first < 1 or not self.tol > 0:
            raise ConfigError("max_iter, max_iter_first must be >= 1 and tol > 0")


@dataclass(frozen=True)
class IKSolution:
    q: FloatArray  # (N, nq)
    cost: FloatArray  # (N,)
    iterations: np.ndarray  # (N,)


def prior_arrays(
    human: HumanModel,
    coordinate_tasks: Mapping[str, tuple[float, float]],
    q_posture: FloatArray,
    posture_weight: float,
) -> tuple[FloatArray, FloatArray]:
    """(nq,) values and weights of the quadratic terms on revolute coordinates."""
    from mocapkit.markers.coordinates import resolve_coordinate_tasks

    value = np.asarray(q_posture, dtype=float).copy()
    weight = np.zeros(human.nq)
    weight[7:] = posture_weight
    tasks, _ = resolve_coordinate_tasks(human, coordinate_tasks)
    for name, (val, w) in tasks.items():
        i = human.dof_index(name) + 1
        value[i] = val
        weight[i] = w
    return value, weight


def initial_root_pose(
    human: HumanModel, names: Sequence[str], X0: FloatArray, q: FloatArray
) -> FloatArray:
    """``q`` with the free-flyer set by a rigid fit (Kabsch) of the pelvis markers.

    Uses the model's pelvis markers at ``q``'s joint angles; needs >= 3 visible pelvis
    markers, otherwise the centroid of all visible markers sets the translation only.
    """
    from mocapkit.geometry import quat_from_matrix, quat_to_xyzw

    kin = MarkerKinematics(human, names)
    q = np.asarray(q, dtype=float).copy()
    q[:3] = 0.0
    q[3:7] = [0.0, 0.0, 0.0, 1.0]
    P = kin.positions(q)
    vis = np.isfinite(X0[:, 0])
    pelvis = np.array([human.markers[n][0] == "pelvis" for n in names]) & vis
    if pelvis.sum() >= 3:
        A, B = P[pelvis], X0[pelvis]
        ca, cb = A.mean(axis=0), B.mean(axis=0)
        U, _, Vt = np.linalg.svd((A - ca).T @ (B - cb))
        D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
        R = Vt.T @ D @ U.T
        q[3:7] = quat_to_xyzw(quat_from_matrix(R))
        q[:3] = cb - R @ ca
    elif vis.any():
        q[:3] = X0[vis].mean(axis=0) - P[vis].mean(axis=0)
    else:
        raise DataError("first frame: no visible marker to start the reconstruction from")
    return q


def solve_ik(
    human: HumanModel,
    names: Sequence[str],
    X: FloatArray,
    weights: FloatArray,
    q_init: FloatArray,
    coordinate_tasks: Mapping[str, tuple[float, float]] | None = None,
    q_posture: FloatArray | None = None,
    params: IKParams | None = None,
    progress: Callable[[int, int], None] | None = None,
    continues: bool = False,
) -> IKSolution:
    """Weighted least-squares IK over frames (in blocks of :data:`BLOCK_FRAMES`;
    ``progress(done, total)`` after each).

    Args:
        human: model with the markers ``names`` attached.
        names: M marker names, the columns of ``X``.
        X: (N, M, 3) targets [m], z-up world; NaN = not visible.
        weights: (M,) marker weights (0 ignores a marker).
        q_init: (nq,) start of the first frame (e.g. from :func:`initial_root_pose`).
        coordinate_tasks: DOF name -> (value [rad], weight) held softly (OpenSim's
            coordinate tasks).
        q_posture: (nq,) the posture prior's target (default: ``q_init``).
        continues: ``X`` continues a trial whose previous frame's solution is ``q_init``
            (a piece of a long trial): its first frame gets the usual iterations, not the
            first frame's (the same numbers as one call over both).
    """
    p = params or IKParams()
    X = np.ascontiguousarray(X, dtype=float)
    if X.ndim != 3 or X.shape[1:] != (len(names), 3):
        raise DataError(f"X: expected shape (N, {len(names)}, 3), got {X.shape}")
    w = np.asarray(weights, dtype=float)
    q0 = np.asarray(q_init, dtype=float).copy()
    post = q0 if q_posture is None else np.asarray(q_posture, dtype=float)
    pv, pw = prior_arrays(human, coordinate_tasks or {}, post, p.posture_weight)
    lo = np.asarray(human.model.lowerPositionLimit, dtype=float).copy()
    hi = np.asarray(human.model.upperPositionLimit, dtype=float).copy()
    kin = MarkerKinematics(human, names)
    if p.backend == "fast":
        fm = rigid_fast.flatten(human.model, kin.frame_ids)
        parts = []
        q = q0
        N = X.shape[0]
        for a in range(0, N, BLOCK_FRAMES):  # blocks: the same numbers as one call
            b = min(N, a + BLOCK_FRAMES)
            first_iter = p.max_iter_first if a == 0 and not continues else p.max_iter
            Qb, Cb, Itb = ik_trial(
                fm.parent, fm.R0, fm.p0, fm.axis, fm.marker_joint, fm.marker_offset,
                q, X[a:b], w, pv, pw, lo, hi, first_iter, p.max_iter, p.tol,
            )  # fmt: skip
            parts.append((Qb, Cb, Itb))
            q = Qb[-1]
            if progress is not None:
                progress(b, N)
        Q, C, It = (np.concatenate([part[k] for part in parts]) for k in range(3))
        return IKSolution(Q, C, It)
    Qs, Cs, Its = [], [], []
    q = q0
    for f in range(X.shape[0]):
        it_max = p.max_iter_first if f == 0 and not continues else p.max_iter
        q, c, it = _ik_frame_reference(kin, q, X[f], w, pv, pw, lo, hi, it_max, p.tol)
        Qs.append(q)
        Cs.append(c)
        Its.append(it)
    return IKSolution(np.array(Qs), np.array(Cs), np.array(Its))


def _cost(
    P: FloatArray, X: FloatArray, w: FloatArray, q: FloatArray, pv: FloatArray, pw: FloatArray
) -> float:
    vis = np.isfinite(X[:, 0]) & (w > 0)
    d = X[vis] - P[vis]
    return float((w[vis] * (d * d).sum(axis=1)).sum() + (pw[7:] * (q[7:] - pv[7:]) ** 2).sum())


def _ik_frame_reference(
    kin: MarkerKinematics,
    q: FloatArray,
    X: FloatArray,
    w: FloatArray,
    pv: FloatArray,
    pw: FloatArray,
    lo: FloatArray,
    hi: FloatArray,
    max_iter: int,
    tol: float,
) -> tuple[FloatArray, float, int]:
    """One frame of projected LM in numpy on Pinocchio's frame Jacobians (the reference)."""
    from mocapkit.markers.kinematics import integrate

    model = kin.model
    q = q.copy()
    q[7:] = np.clip(q[7:], lo[7:], hi[7:])
    P, J = kin.reference_positions_jacobians(q)
    cost = _cost(P, X, w, q, pv, pw)
    vis = np.isfinite(X[:, 0]) & (w > 0)
    sw = np.sqrt(w[vis])
    mu = 1e-3
    it = 0
    for _ in range(max_iter):
        it += 1
        Jw = (J[vis] * sw[:, None, None]).reshape(-1, model.nv)
        rw = ((X[vis] - P[vis]) * sw[:, None]).reshape(-1)
        H = Jw.T @ Jw + np.diag(np.concatenate([np.zeros(6), pw[7:]]))
        g = Jw.T @ rw
        g[6:] += pw[7:] * (pv[7:] - q[7:])
        at_lo = (q[7:] <= lo[7:]) & (g[6:] < 0)
        at_hi = (q[7:] >= hi[7:]) & (g[6:] > 0)
        free = np.concatenate([np.ones(6, bool), ~(at_lo | at_hi)])
        idx = np.flatnonzero(free)
        Hf, gf = H[np.ix_(idx, idx)], g[idx]
        accepted, step_max, decrease = False, 0.0, 0.0
        while mu < 1e10:
            A = Hf + np.diag(mu * np.diag(Hf) + LAMBDA0)
            df = np.linalg.solve(A, gf)
            dv = np.zeros(model.nv)
            dv[idx] = df
            q_new = integrate(model, q, dv)
            q_new[7:] = np.clip(q_new[7:], lo[7:], hi[7:])
            P_new, J_new = kin.reference_positions_jacobians(q_new)
            c_new = _cost(P_new, X, w, q_new, pv, pw)
            if c_new <= cost:
                decrease = cost - c_new
                q, P, J, cost = q_new, P_new, J_new, c_new
                mu = max(mu / 3.0, 1e-9)
                accepted = True
                step_max = float(np.abs(df).max()) if df.size else 0.0
                break
            mu *= 4.0
        if not accepted or step_max < tol or decrease < 1e-7 * cost:
            break
    return q, cost, it
