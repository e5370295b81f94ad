"""A joint-error bound that holds: the distance to the markers' best fit plus what marker
noise can move that fit.

Eq. 15 (``Δq = Jbar_⊗ Δx_⊗``, :mod:`mocapkit.markers.bounds`) is a first-order map of the
marker errors: it measures how far the model lags the markers, damped, linearised, and it
says nothing of the noise the markers themselves carry (at an IK solution it is ~0 however
noisy the markers). Per frame and reported coordinate k this module gives instead

    B_k = |c_k(q_fit) - c_k(q)| + Z · ‖a_k‖ · σ̂

- ``q_fit``: Gauss-Newton fit of the visible tracked markers from the model's pose ``q``
  over the same free DOFs as the sensitivities (pelvis when determined, determined DOFs
  not held), so the first term is the exact (not linearised, not damped) joint distance
  between the model and the pose its markers say;
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
_STEP_TOL = 1e-10  # [rad, m] Gauss-Newton converged
Z = 4.0  # standard deviations: exceeded with probability 6e-5 (two-sided normal)


def fit_to_markers(
    human: HumanModel,
    names: Sequence[str],
    Q: FloatArray,
    X: FloatArray,
    weights: FloatArray,
    free: np.ndarray,
) -> FloatArray:
    """(N, nq) per frame, Gauss-Newton from Q[f] over the velocity columns ``free[f]``
    (N, nv) bool to the visible markers X[f] with weights (M,) (minimum-norm steps where
    rank-deficient; Q[f] kept where nothing is visible or free)."""
    kin = MarkerKinematics(human, names)
    fm = rigid_fast.flatten(human.model, kin.frame_ids)
    sw = np.sqrt(np.maximum(weights, 0.0))
    Q_fit = np.array(Q, dtype=float, copy=True)
    lo = np.asarray(human.model.lowerPositionLimit, dtype=float)
    hi = np.asarray(human.model.upperPositionLimit, dtype=float)
    for f in range(len(Q)):
        cols = np.flatnonzero(free[f])
        vis = np.isfinite(X[f, :, 0]) & (weights > 0)
        if cols.size == 0 or not vis.any():
            continue
        q = Q_fit[f]
        for _ in range(_ITERATIONS):
            R, t, S = rigid_fast.forward_kinematics(fm.parent, fm.R0, fm.p0, fm.axis, q)
            P, J = rigid_fast.marker_kinematics(
                fm.parent, R, t, S, fm.marker_joint, fm.marker_offset
            )
            Jw = (J[vis][:, :, cols] * sw[vis, None, None]).reshape(-1, cols.size)
            ew = ((X[f, vis] - P[vis]) * sw[vis, None]).reshape(-1)
            step = np.linalg.lstsq(Jw, ew, rcond=None)[0]
            dv = np.zeros(human.nv)
            dv[cols] = step
            q = rigid_fast.integrate(q, dv)
            q[7:] = np.clip(q[7:], lo[7:], hi[7:])
            if np.abs(step).max() < _STEP_TOL:
                break
        Q_fit[f] = q
    return Q_fit


def total_bound(
    human: HumanModel,
    cmap: CoordinateMap,
    names: Sequence[str],
    Q: FloatArray,
    X: FloatArray,
    weights: FloatArray,
    free: np.ndarray,
    columns: np.ndarray,
) -> FloatArray:
    """(N, K) the bound B of the module docstring [rad] for the reported angles ``columns``
    (N, K) bool (NaN elsewhere), free DOFs ``free`` (N, nv) bool."""
    from mocapkit.markers.bounds import coordinate_jacobian

    Q_fit = fit_to_markers(human, names, Q, X, weights, free)
    d = coordinates_from_q(human, Q_fit, cmap) - coordinates_from_q(human, Q, cmap)
    ang = cmap.angular
    d[:, ang] = np.pi - np.mod(np.pi - d[:, ang], 2.0 * np.pi)  # across the +-pi seam
    G = coordinate_jacobian(human, cmap, Q_fit)
    rows = columns & ang[None, :]
    kin = MarkerKinematics(human, names)
    fm = rigid_fast.flatten(human.model, kin.frame_ids)
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
    out = np.abs(d) + spread
    out[~rows] = np.nan
    out[~np.isfinite(out)] = np.nan
    return out
