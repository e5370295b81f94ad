"""Numba kernels of the weighted least-squares IK baseline (readable reference:
:mod:`mocapkit.markers.ik`, ``backend="reference"``).

Per frame, minimise ``Σ_i w_i ‖x_i − p_i(q)‖² + Σ_j w_j (q_j − q̄_j)²`` over visible markers
(the second sum holds OpenSim's coordinate tasks, w_j large, and a weak posture prior that
removes the flat directions of redundant joints such as neck + head nod) by projected
Levenberg–Marquardt: the step solves
``(H_ff + μ diag(H_ff) + λ₀ I) δ_f = g_f`` on the free DOFs (a revolute DOF at a limit whose
gradient points out of the box is frozen), ``q ← clamp(q ⊕ δ)``; μ shrinks after a step that
lowers the cost and grows after one that does not. λ₀ = 1e-6 keeps DOFs that no marker
sees (e.g. the wrists without hand markers) where they are.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mocapkit.markers.rigid_fast import forward_kinematics, integrate, marker_kinematics

FloatArray = np.ndarray  # numba kernels: mypy does not track their dtypes

LAMBDA0 = 1e-6


@njit(cache=True)
def _cost(
    P: FloatArray,
    X: FloatArray,
    w: FloatArray,
    q: FloatArray,
    prior_value: FloatArray,
    prior_weight: FloatArray,
) -> float:
    c = 0.0
    for m in range(X.shape[0]):
        if w[m] > 0.0 and np.isfinite(X[m, 0]):
            d = X[m] - P[m]
            c += w[m] * (d @ d)
    for i in range(7, q.shape[0]):
        e = q[i] - prior_value[i]
        c += prior_weight[i] * e * e
    return c


@njit(cache=True)
def _clamp(q: FloatArray, lower: FloatArray, upper: FloatArray) -> FloatArray:
    out = q.copy()
    for i in range(7, q.shape[0]):
        out[i] = min(max(q[i], lower[i]), upper[i])
    return out


@njit(cache=True)
def ik_frame(
    parent: np.ndarray,
    R0: FloatArray,
    p0: FloatArray,
    axis: FloatArray,
    marker_joint: np.ndarray,
    marker_offset: FloatArray,
    q: FloatArray,
    X: FloatArray,
    w: FloatArray,
    prior_value: FloatArray,
    prior_weight: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    max_iter: int,
    tol: float,
) -> tuple[FloatArray, float, int]:
    """Solve one frame from the warm start ``q``; returns (q, cost, iterations)."""
    nv = q.shape[0] - 1
    q = _clamp(q, lower, upper)
    R, t, S = forward_kinematics(parent, R0, p0, axis, q)
    P, J = marker_kinematics(parent, R, t, S, marker_joint, marker_offset)
    cost = _cost(P, X, w, q, prior_value, prior_weight)
    mu = 1e-3
    it = 0
    for _ in range(max_iter):
        it += 1
        n_vis = 0
        for m in range(X.shape[0]):
            if w[m] > 0.0 and np.isfinite(X[m, 0]):
                n_vis += 1
        Jw = np.empty((3 * n_vis, nv))
        rw = np.empty(3 * n_vis)
        r = 0
        for m in range(X.shape[0]):
            if w[m] > 0.0 and np.isfinite(X[m, 0]):
                sw = np.sqrt(w[m])
                for c in range(3):
                    Jw[r + c] = sw * J[m, c]
                    rw[r + c] = sw * (X[m, c] - P[m, c])
                r += 3
        H = Jw.T @ Jw
        g = Jw.T @ rw
        for i in range(7, q.shape[0]):
            H[i - 1, i - 1] += prior_weight[i]
            g[i - 1] += prior_weight[i] * (prior_value[i] - q[i])
        free = np.ones(nv, dtype=np.bool_)
        for iq in range(7, q.shape[0]):
            if (q[iq] <= lower[iq] and g[iq - 1] < 0.0) or (q[iq] >= upper[iq] and g[iq - 1] > 0.0):
                free[iq - 1] = False
        idx = np.flatnonzero(free)
        Hf = H[idx][:, idx]
        gf = g[idx]
        accepted = False
        step_max = 0.0
        decrease = 0.0
        while mu < 1e10:
            A = Hf.copy()
            for i in range(idx.shape[0]):
                A[i, i] += mu * Hf[i, i] + LAMBDA0
            df = np.linalg.solve(A, gf)
            dv = np.zeros(nv)
            dv[idx] = df
            q_new = _clamp(integrate(q, dv), lower, upper)
            R, t, S = forward_kinematics(parent, R0, p0, axis, q_new)
            P_new, J_new = marker_kinematics(parent, R, t, S, marker_joint, marker_offset)
            c_new = _cost(P_new, X, w, q_new, prior_value, prior_weight)
            if c_new <= cost:
                decrease = cost - c_new
                q, P, J, cost = q_new, P_new, J_new, c_new
                mu = max(mu / 3.0, 1e-9)
                accepted = True
                step_max = np.max(np.abs(df)) if df.shape[0] else 0.0
                break
            mu *= 4.0
        if not accepted or step_max < tol or decrease < 1e-7 * cost:
            break
    return q, cost, it


@njit(cache=True)
def ik_trial(
    parent: np.ndarray,
    R0: FloatArray,
    p0: FloatArray,
    axis: FloatArray,
    marker_joint: np.ndarray,
    marker_offset: FloatArray,
    q_init: FloatArray,
    X: FloatArray,
    w: FloatArray,
    prior_value: FloatArray,
    prior_weight: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    max_iter_first: int,
    max_iter: int,
    tol: float,
) -> tuple[FloatArray, FloatArray, np.ndarray]:
    """All frames of X (N, M, 3), each warm-started from the previous solution.

    Returns Q (N, nq), the final cost per frame (N,) and iterations per frame (N,).
    """
    N = X.shape[0]
    Q = np.empty((N, q_init.shape[0]))
    C = np.empty(N)
    It = np.empty(N, dtype=np.int64)
    q = q_init.copy()
    for f in range(N):
        q, c, it = ik_frame(
            parent, R0, p0, axis, marker_joint, marker_offset, q, X[f], w,
            prior_value, prior_weight, lower, upper,
            max_iter_first if f == 0 else max_iter, tol,
        )  # fmt: skip
        Q[f] = q
        C[f] = c
        It[f] = it
    return Q, C, It
