"""Numba kernels for the per-frame loops of the error bounds.

Each is the same arithmetic as its readable counterpart, frame by frame, without the Python
round trip per frame (which made the bound report ~90 % of a reconstruction's wall time):

- :func:`sensitivities_kernel` = :func:`mocapkit.markers.bounds.sensitivities_reference`;
- :func:`fit_kernel` = :func:`mocapkit.markers.bound_fit.fit_to_markers_reference`;
- :func:`spread_kernel` = the per-frame part of
  :func:`mocapkit.markers.bound_fit.total_bound_reference`.

Tests check each pair on real and synthetic trials (tests/markers/test_bound_kernels.py).
Linear algebra is LAPACK through numba (``eigh``, ``lstsq``), as numpy's is.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mocapkit._validate import FloatArray
from mocapkit.markers.rigid_fast import forward_kinematics, integrate, marker_kinematics

EIG_CUT = 1e-12  # eigenvalues below this share of the largest carry nothing
BLIND_TOL = 1e-6  # a gradient reaching an unseen direction by more than this share is blind


@njit(cache=True)
def _weighted_rows(J: FloatArray, vis: np.ndarray, cols: np.ndarray, w: FloatArray) -> FloatArray:
    """Rows of the visible markers' Jacobians over ``cols``, each scaled by ``w`` (M,)."""
    n_vis = 0
    for i in range(vis.shape[0]):
        if vis[i]:
            n_vis += 1
    out = np.empty((3 * n_vis, cols.shape[0]))
    r = 0
    for i in range(vis.shape[0]):
        if not vis[i]:
            continue
        for a in range(3):
            for c in range(cols.shape[0]):
                out[r, c] = J[i, a, cols[c]] * w[i]
            r += 1
    return out


@njit(cache=True)
def sensitivities_kernel(
    parent: np.ndarray,
    R0: FloatArray,
    p0: FloatArray,
    axis: FloatArray,
    marker_joint: np.ndarray,
    marker_offset: FloatArray,
    Q: FloatArray,
    X: FloatArray,
    weights: FloatArray,
    free: np.ndarray,
    G: FloatArray,
    rows: np.ndarray,
) -> FloatArray:
    """(N, K) ``sqrt(g_k^T (J^T W J)^-1 g_k)`` [rad/m]; NaN outside ``rows``, inf where g_k
    reaches a direction the visible markers do not see."""
    n, k_all = rows.shape
    out = np.full((n, k_all), np.nan)
    sw = np.sqrt(np.maximum(weights, 0.0))
    for f in range(n):
        cols = np.flatnonzero(free[f])
        vis = np.zeros(X.shape[1], dtype=np.bool_)
        any_vis = False
        for i in range(X.shape[1]):
            vis[i] = np.isfinite(X[f, i, 0]) and weights[i] > 0
            any_vis = any_vis or vis[i]
        any_row = False
        for k in range(k_all):
            any_row = any_row or rows[f, k]
        if cols.shape[0] == 0 or not any_vis or not any_row:
            continue
        R, t, S = forward_kinematics(parent, R0, p0, axis, Q[f])
        _, J = marker_kinematics(parent, R, t, S, marker_joint, marker_offset)
        Jw = _weighted_rows(J, vis, cols, sw)
        lam, V = np.linalg.eigh(Jw.T @ Jw)
        cut = EIG_CUT * max(lam.max(), 1e-300)
        for k in range(k_all):
            if not rows[f, k]:
                continue
            gnorm = 0.0
            for c in range(cols.shape[0]):
                gnorm += G[f, k, cols[c]] ** 2
            gnorm = max(np.sqrt(gnorm), 1e-12)
            var = 0.0
            blind = False
            for e in range(lam.shape[0]):
                p = 0.0
                for c in range(cols.shape[0]):
                    p += G[f, k, cols[c]] * V[c, e]
                if lam[e] > cut:
                    var += p * p / lam[e]
                elif abs(p) > BLIND_TOL * gnorm:
                    blind = True
            out[f, k] = np.inf if blind else np.sqrt(var)
    return out


@njit(cache=True)
def _residual(
    parent: np.ndarray,
    R0: FloatArray,
    p0: FloatArray,
    axis: FloatArray,
    marker_joint: np.ndarray,
    marker_offset: FloatArray,
    q: FloatArray,
    x: FloatArray,
    vis: np.ndarray,
    sw: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Weighted residual (3 m,) of the visible markers and their Jacobian (3 m, nv)."""
    R, t, S = forward_kinematics(parent, R0, p0, axis, q)
    P, J = marker_kinematics(parent, R, t, S, marker_joint, marker_offset)
    all_cols = np.arange(J.shape[2])
    Jw = _weighted_rows(J, vis, all_cols, sw)
    e = np.empty(Jw.shape[0])
    r = 0
    for i in range(vis.shape[0]):
        if vis[i]:
            for a in range(3):
                e[r] = (x[i, a] - P[i, a]) * sw[i]
                r += 1
    return e, Jw


@njit(cache=True)
def fit_kernel(
    parent: np.ndarray,
    R0: FloatArray,
    p0: FloatArray,
    axis: FloatArray,
    marker_joint: np.ndarray,
    marker_offset: FloatArray,
    Q: FloatArray,
    X: FloatArray,
    weights: FloatArray,
    free: np.ndarray,
    lo: FloatArray,
    hi: FloatArray,
    iterations: int,
    step_tol: float,
    lm: FloatArray,
) -> FloatArray:
    """(N, nq) per frame, the projected Levenberg-Marquardt fit of
    :func:`mocapkit.markers.bound_fit._lm_reference` from Q[f] over the velocity columns
    ``free[f]``; ``lm`` = (start, min, max, floor) of the damping."""
    out = Q.copy()
    sw = np.sqrt(np.maximum(weights, 0.0))
    nv = free.shape[1]
    for f in range(Q.shape[0]):
        cols = np.flatnonzero(free[f])
        vis = np.zeros(X.shape[1], dtype=np.bool_)
        any_vis = False
        for i in range(X.shape[1]):
            vis[i] = np.isfinite(X[f, i, 0]) and weights[i] > 0
            any_vis = any_vis or vis[i]
        if cols.shape[0] == 0 or not any_vis:
            continue
        q = Q[f].copy()
        frozen = np.zeros(nv, dtype=np.bool_)
        e, J = _residual(parent, R0, p0, axis, marker_joint, marker_offset, q, X[f], vis, sw)
        cost = np.sum(e * e)
        lam = lm[0]
        for _ in range(iterations):
            n_free = 0
            for c in range(cols.shape[0]):
                if not frozen[cols[c]]:
                    n_free += 1
            if n_free == 0:
                break
            act = np.empty(n_free, dtype=np.int64)
            a = 0
            for c in range(cols.shape[0]):
                if not frozen[cols[c]]:
                    act[a] = cols[c]
                    a += 1
            Jc = np.empty((J.shape[0], n_free))
            for r in range(J.shape[0]):
                for c in range(n_free):
                    Jc[r, c] = J[r, act[c]]
            A = Jc.T @ Jc
            g = Jc.T @ e
            dmax = 0.0
            for c in range(n_free):
                dmax = max(dmax, A[c, c])
            floor = lm[3] * max(dmax, 1e-300)
            while True:
                M = A.copy()
                for c in range(n_free):
                    M[c, c] += lam * (A[c, c] + floor)
                step = np.linalg.solve(M, g)
                dv = np.zeros(nv)
                for c in range(n_free):
                    dv[act[c]] = step[c]
                q_try = integrate(q, dv)
                out_lim = np.zeros(nv, dtype=np.bool_)
                for j in range(7, q.shape[0]):
                    if q_try[j] < lo[j] or q_try[j] > hi[j]:
                        out_lim[j - 1] = True
                        q_try[j] = min(max(q_try[j], lo[j]), hi[j])
                e_try, J_try = _residual(
                    parent, R0, p0, axis, marker_joint, marker_offset, q_try, X[f], vis, sw
                )
                cost_try = np.sum(e_try * e_try)
                if cost_try <= cost or lam > lm[2]:
                    break
                lam *= 4.0
            if cost_try > cost:  # no step lowers the cost: converged as far as it goes
                break
            moved = 0.0
            for k in range(6):
                moved = max(moved, abs(dv[k]))
            for j in range(7, q.shape[0]):
                moved = max(moved, abs(q_try[j] - q[j]))
            for k in range(nv):
                frozen[k] = frozen[k] or out_lim[k]
            q, e, J, cost = q_try, e_try, J_try, cost_try
            lam = max(lam / 3.0, lm[1])
            if moved < step_tol:
                break
        out[f] = q
    return out


@njit(cache=True)
def spread_kernel(
    parent: np.ndarray,
    R0: FloatArray,
    p0: FloatArray,
    axis: FloatArray,
    marker_joint: np.ndarray,
    marker_offset: FloatArray,
    Q_fit: FloatArray,
    X: FloatArray,
    weights: FloatArray,
    free: np.ndarray,
    G: FloatArray,
    rows: np.ndarray,
    z: float,
) -> FloatArray:
    """(N, K) ``z ||a_k|| sigma`` of :mod:`mocapkit.markers.bound_fit` at the fitted poses;
    NaN outside ``rows``, where blind, and in frames without redundancy."""
    n, k_all = rows.shape
    out = np.full((n, k_all), np.nan)
    ones = np.ones(X.shape[1])
    for f in range(n):
        cols = np.flatnonzero(free[f])
        vis = np.zeros(X.shape[1], dtype=np.bool_)
        any_vis = False
        for i in range(X.shape[1]):
            vis[i] = np.isfinite(X[f, i, 0]) and weights[i] > 0
            any_vis = any_vis or vis[i]
        kk = np.flatnonzero(rows[f])
        if cols.shape[0] == 0 or not any_vis or kk.shape[0] == 0:
            continue
        R, t, S = forward_kinematics(parent, R0, p0, axis, Q_fit[f])
        P, J = marker_kinematics(parent, R, t, S, marker_joint, marker_offset)
        Jf = _weighted_rows(J, vis, cols, ones)
        m = Jf.shape[0]
        w = np.empty(m)
        r = np.empty(m)
        row = 0
        for i in range(vis.shape[0]):
            if vis[i]:
                for a in range(3):
                    w[row] = weights[i]
                    r[row] = X[f, i, a] - P[i, a]
                    row += 1
        WJ = Jf * w.reshape(-1, 1)
        lam, V = np.linalg.eigh(Jf.T @ WJ)
        cut = EIG_CUT * max(lam.max(), 1e-300)
        good = lam > cut
        Vg = V[:, good]
        Hinv = (Vg / lam[good]) @ Vg.T
        g = np.empty((kk.shape[0], cols.shape[0]))
        for a in range(kk.shape[0]):
            for c in range(cols.shape[0]):
                g[a, c] = G[f, kk[a], cols[c]]
        a_mat = WJ @ (Hinv @ g.T)  # (m, k)
        I_H = np.eye(m) - (Jf @ Hinv @ Jf.T) * w.reshape(1, -1)
        dof = np.sum(I_H * I_H)
        if dof < 0.5:  # no redundancy: the residual says nothing of the noise
            continue
        res = I_H @ r
        sigma = np.sqrt(np.sum(res * res)) / np.sqrt(dof)
        Vb = V[:, ~good]
        for a in range(kk.shape[0]):
            gnorm = max(np.sqrt(np.sum(g[a] * g[a])), 1e-12)
            blind = False
            for e in range(Vb.shape[1]):
                if abs(np.sum(g[a] * Vb[:, e])) > BLIND_TOL * gnorm:
                    blind = True
            if not blind:
                out[f, kk[a]] = z * np.sqrt(np.sum(a_mat[:, a] ** 2)) * sigma
    return out
