"""A joint-error bound that holds: the distance to the markers' best fit plus what marker
noise can move that fit.

Eq. 15 (``Δq = Jbar_⊗ Δx_⊗``, :mod:`mocapkit.markers.bounds`) is a first-order map of the
marker errors: it measures how far the model lags the markers, damped, linearised, and it
says nothing of the noise the markers themselves carry (at an IK solution it is ~0 however
noisy the markers). Per frame and reported coordinate k this module gives instead

    B_k = |c_k(q_fit) - c_k(q)| + Z · ‖a_k‖ · σ̂

- ``q_fit``: least-squares fit (projected Levenberg-Marquardt) of the visible tracked
  markers from the model's pose ``q`` over the same free DOFs as the sensitivities
  (pelvis when determined, determined DOFs not held), so the first term is the exact (not
  linearised, not damped) joint distance between the model and the pose its markers say;
- ``a_k = W J (Jᵀ W J)⁻¹ g_k`` (J: the visible markers' rows over the free DOFs at
  ``q_fit``, W their weights, g_k the coordinate's gradient): marker noise ν (independent,
  σ per coordinate, whatever the weights, which are a preference of the fit as in
  OpenSim) moves the fit's coordinate by ``a_kᵀ ν`` (first order), a normal variable of
  deviation ‖a_k‖ σ;
- σ̂ the noise level the fit's residual r shows: ``‖r‖² / tr((I - H)ᵀ (I - H))`` with
  ``H = J (Jᵀ W J)⁻¹ Jᵀ W`` the fit's hat matrix (m - n for equal weights);
- :data:`Z` = 4: |a_kᵀ ν| > 4 ‖a_k‖ σ has probability 6e-5 per coordinate and frame.

With exact markers (synthetic, exact answer) r = 0 and B_k is the actual error; with
noisy markers B_k ≥ the actual error except with that probability (tested on noisy
synthetic cases). It is a confidence bound under the noise model: soft-tissue artefacts
(markers sliding together with the skin) are correlated and the residual cannot see the
part of them that looks like a joint motion. Frames with no redundancy (m <= n) have no
noise estimate, and coordinates along a direction no visible marker sees no fit: NaN.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.human_model import HumanModel
from mocapkit.markers import rigid_fast
from mocapkit.markers.coordinates import CoordinateMap, coordinates_from_q
from mocapkit.markers.kinematics import MarkerKinematics

_EIG_CUT = 1e-12  # as mocapkit.markers.bounds: eigenvalues below this share carry nothing
_ITERATIONS = 30
_LM_START = 1e-3  # Levenberg-Marquardt damping: start, floor, ceiling (relative to diag)
_LM_MIN = 1e-9
_LM_MAX = 1e8
_LM_FLOOR = 1e-12  # share of the largest diagonal added to zero diagonals
_STEP_TOL = 1e-10  # [rad, m] the fit converged: the largest move of an iteration
Z = 4.0  # standard deviations: exceeded with probability 6e-5 (two-sided normal)


def fit_to_markers(
    human: HumanModel,
    names: Sequence[str],
    Q: FloatArray,
    X: FloatArray,
    weights: FloatArray,
    free: np.ndarray,
    backend: str = "fast",
) -> FloatArray:
    """(N, nq) per frame, the best fit from Q[f] over the velocity columns ``free[f]``
    (N, nv) bool to the visible markers X[f] with weights (M,) (projected
    Levenberg-Marquardt, :func:`_lm_reference`; Q[f] kept where nothing is visible or
    free). ``backend``: "fast" (numba, :mod:`mocapkit.markers.bound_kernels`) or
    "reference" (this numpy loop)."""
    kin = MarkerKinematics(human, names)
    fm = rigid_fast.flatten(human.model, kin.frame_ids)
    lo = np.asarray(human.model.lowerPositionLimit, dtype=float)
    hi = np.asarray(human.model.upperPositionLimit, dtype=float)
    if backend == "fast":
        from mocapkit.markers.bound_kernels import fit_kernel

        return fit_kernel(
            fm.parent, fm.R0, fm.p0, fm.axis, fm.marker_joint, fm.marker_offset,
            np.ascontiguousarray(Q, dtype=float), np.ascontiguousarray(X, dtype=float),
            np.ascontiguousarray(weights, dtype=float), np.ascontiguousarray(free), lo, hi,
            _ITERATIONS, _STEP_TOL, np.array([_LM_START, _LM_MIN, _LM_MAX, _LM_FLOOR]),
        )  # fmt: skip
    sw = np.sqrt(np.maximum(weights, 0.0))
    Q_fit = np.array(Q, dtype=float, copy=True)
    for f in range(len(Q)):
        cols = np.flatnonzero(free[f])
        vis = np.isfinite(X[f, :, 0]) & (weights > 0)
        if cols.size == 0 or not vis.any():
            continue
        Q_fit[f] = _lm_reference(fm, q0=Q_fit[f], x=X[f], vis=vis, sw=sw, cols=cols, lo=lo, hi=hi)
    return Q_fit


def _residual(
    fm: rigid_fast.FlatModel, q: FloatArray, x: FloatArray, vis: np.ndarray, sw: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Weighted residual (3 m,) of the visible markers and their Jacobian (3 m, nv)."""
    R, t, S = rigid_fast.forward_kinematics(fm.parent, fm.R0, fm.p0, fm.axis, q)
    P, J = rigid_fast.marker_kinematics(fm.parent, R, t, S, fm.marker_joint, fm.marker_offset)
    e = ((x[vis] - P[vis]) * sw[vis, None]).reshape(-1)
    return e, (J[vis] * sw[vis, None, None]).reshape(e.size, -1)


def _lm_reference(
    fm: rigid_fast.FlatModel,
    q0: FloatArray,
    x: FloatArray,
    vis: np.ndarray,
    sw: FloatArray,
    cols: np.ndarray,
    lo: FloatArray,
    hi: FloatArray,
) -> FloatArray:
    """One frame's fit: Levenberg-Marquardt (Marquardt's diagonal scaling; a step is taken
    only if it lowers the cost), projected on the joint limits (a DOF a step pushes through
    its limit stays there). Plain Gauss-Newton diverges on poorly conditioned frames."""
    q = q0.copy()
    frozen = np.zeros(fm.nv, dtype=bool)
    e, J = _residual(fm, q, x, vis, sw)
    cost = float(e @ e)
    lam = _LM_START
    for _ in range(_ITERATIONS):
        c = cols[~frozen[cols]]
        if c.size == 0:
            break
        A = J[:, c].T @ J[:, c]
        g = J[:, c].T @ e
        diag = np.diag(A) + _LM_FLOOR * max(float(np.diag(A).max()), 1e-300)
        while True:
            step = np.linalg.solve(A + lam * np.diag(diag), g)
            dv = np.zeros(fm.nv)
            dv[c] = step
            q_try = rigid_fast.integrate(q, dv)
            out = (q_try[7:] < lo[7:]) | (q_try[7:] > hi[7:])
            q_try[7:] = np.clip(q_try[7:], lo[7:], hi[7:])
            e_try, J_try = _residual(fm, q_try, x, vis, sw)
            cost_try = float(e_try @ e_try)
            if cost_try <= cost or lam > _LM_MAX:
                break
            lam *= 4.0
        if cost_try > cost:  # no step lowers the cost: converged as far as it goes
            break
        moved = max(float(np.abs(dv[:6]).max()), float(np.abs(q_try[7:] - q[7:]).max()))
        frozen[6:] |= out
        q, e, J, cost = q_try, e_try, J_try, cost_try
        lam = max(lam / 3.0, _LM_MIN)
        if moved < _STEP_TOL:
            break
    return q


def total_bound(
    human: HumanModel,
    cmap: CoordinateMap,
    names: Sequence[str],
    Q: FloatArray,
    X: FloatArray,
    weights: FloatArray,
    free: np.ndarray,
    columns: np.ndarray,
    backend: str = "fast",
) -> FloatArray:
    """(N, K) the bound B of the module docstring [rad] for the reported angles ``columns``
    (N, K) bool (NaN elsewhere), free DOFs ``free`` (N, nv) bool; ``backend`` as
    :func:`fit_to_markers`."""
    from mocapkit.markers.bounds import coordinate_jacobian

    Q_fit = fit_to_markers(human, names, Q, X, weights, free, backend)
    d = coordinates_from_q(human, Q_fit, cmap) - coordinates_from_q(human, Q, cmap)
    ang = cmap.angular
    d[:, ang] = np.pi - np.mod(np.pi - d[:, ang], 2.0 * np.pi)  # across the +-pi seam
    G = coordinate_jacobian(human, cmap, Q_fit)
    rows = columns & ang[None, :]
    kin = MarkerKinematics(human, names)
    fm = rigid_fast.flatten(human.model, kin.frame_ids)
    if backend == "fast":
        from mocapkit.markers.bound_kernels import spread_kernel

        spread = spread_kernel(
            fm.parent, fm.R0, fm.p0, fm.axis, fm.marker_joint, fm.marker_offset,
            np.ascontiguousarray(Q_fit), np.ascontiguousarray(X, dtype=float),
            np.ascontiguousarray(weights, dtype=float), np.ascontiguousarray(free),
            np.ascontiguousarray(G), np.ascontiguousarray(rows), Z,
        )  # fmt: skip
    else:
        spread = _spread_reference(fm, Q_fit, X, weights, free, G, rows)
    out = np.abs(d) + spread
    out[~rows] = np.nan
    out[~np.isfinite(out)] = np.nan
    return out


def _spread_reference(
    fm: rigid_fast.FlatModel,
    Q_fit: FloatArray,
    X: FloatArray,
    weights: FloatArray,
    free: np.ndarray,
    G: FloatArray,
    rows: np.ndarray,
) -> FloatArray:
    """(N, K) Z ‖a_k‖ σ̂ per frame, readable numpy (the kernel's reference)."""
    spread = np.full(rows.shape, np.nan)  # Z ‖a_k‖ σ̂
    for f, q in enumerate(Q_fit):
        cols = np.flatnonzero(free[f])
        vis = np.isfinite(X[f, :, 0]) & (weights > 0)
        if cols.size == 0 or not vis.any() or not rows[f].any():
            continue
        R, t, S = rigid_fast.forward_kinematics(fm.parent, fm.R0, fm.p0, fm.axis, q)
        P, J = rigid_fast.marker_kinematics(fm.parent, R, t, S, fm.marker_joint, fm.marker_offset)
        Jf = J[vis][:, :, cols].reshape(-1, cols.size)
        w = np.repeat(weights[vis], 3)
        r = (X[f, vis] - P[vis]).reshape(-1)
        lam, V = np.linalg.eigh(Jf.T @ (w[:, None] * Jf))
        good = lam > _EIG_CUT * max(float(lam.max()), 1e-300)
        Hinv = (V[:, good] / lam[good]) @ V[:, good].T
        g = G[f][:, cols][rows[f]]  # (k, n)
        proj = g @ V[:, ~good]
        blind = (np.abs(proj) > 1e-6 * np.maximum(np.linalg.norm(g, axis=1), 1e-12)[:, None]).any(
            axis=1
        )
        a = (w[:, None] * Jf) @ (Hinv @ g.T)  # (m, k)
        I_H = np.eye(len(r)) - Jf @ Hinv @ Jf.T * w[None, :]
        dof = float(np.sum(I_H * I_H))
        if dof < 0.5:  # no redundancy: the residual says nothing of the noise
            continue
        sigma = float(np.linalg.norm(I_H @ r)) / np.sqrt(dof)
        k_spread = Z * np.linalg.norm(a, axis=0) * sigma
        k_spread[blind] = np.nan
        spread[f, rows[f]] = k_spread
    return spread
