"""The per-frame joint-error bound of the paper (eq. 14-17), made a figure one can trust.

Eq. 15 maps the marker errors of a frame to joint errors, ``Δq = Jbar_⊗ Δx_⊗`` (eq. 16:
``|Δq| <= |Jbar_⊗| |Δx_⊗|``); eq. 17 takes the largest and smallest over the joints.
Taken literally it spikes to meaningless values (1800 deg in one frame of walking2):
the dynamically consistent inverse spreads a marker error over *every* DOF, including
those no visible marker determines (an arm without markers swings with the trunk), and a
nearly singular pose divides by a vanishing singular value. So:

1. Only determined coordinates (:mod:`mocapkit.markers.determined`): direct marker control
   holds the others (they get no share of ``Jbar``); their bound is NaN, not zero ("no
   marker says anything" is not "no error").
2. Capped at the joint's range: the reconstructed and the true angle both lie within the
   model's limits, so they cannot differ by more; capped entries are counted.
3. Reported with the conditioning: per frame and determined DOF i the sensitivity
   ``s_i = sqrt([(Jᵀ W J)⁻¹]_ii)`` (J: the visible tracked markers' Jacobian over the
   determined DOFs, W their weights), in degrees per millimetre of marker error: the
   joint change that the least-squares fit makes for a 1 mm marker error. A DOF above
   :data:`POORLY_DETERMINED_DEG_PER_MM` is named in a warning: its bound, however small,
   rests on a poorly conditioned fit.

For a full-rank, well-conditioned frame ``Jbar_⊗ = J⁺`` whatever the inertia (the
dynamically consistent inverse of a matrix with full column rank is its least-squares
inverse), so the bound is the joint correction that would remove the frame's residual
marker errors to first order.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.human_model import HumanModel
from mocapkit.markers import rigid_fast
from mocapkit.markers.kinematics import MarkerKinematics

# A DOF moving more than this per millimetre of marker error is poorly determined.
POORLY_DETERMINED_DEG_PER_MM = 2.0
_EIG_CUT = 1e-12  # eigenvalues of JᵀWJ below this fraction of the largest: no information


def joint_error_bounds(
    human: HumanModel,
    names: Sequence[str],
    Q: FloatArray,
    X: FloatArray,
    weights: FloatArray,
    held: np.ndarray,
    locked: Sequence[str] = (),
) -> FloatArray:
    """Eq. 15 for IK solutions: Δq = A⁻¹ Jᵀ (J A⁻¹ Jᵀ)⁺ Δx per frame (J: the weighted marker
    rows at the solution, Δx their residuals), below the locked coordinates and the DOFs
    ``held`` (N, n_dof) in that frame, as direct marker control does; the same kernel."""
    from mocapkit.markers.prioritized import DEFAULT_DAMPING, prioritized_torque

    kin = MarkerKinematics(human, names)
    fm = rigid_fast.flatten(human.model, kin.frame_ids)
    sw = np.sqrt(np.maximum(weights, 0.0))
    out = np.zeros((len(Q), human.nv))
    lock_idx = [human.dof_index(n) for n in locked]
    for f, q in enumerate(Q):
        R, t, S, _, _, A, h = rigid_fast.dynamics_terms(
            fm.parent, fm.R0, fm.p0, fm.axis, fm.mass, fm.com, fm.inertia, fm.gravity, q,
            np.zeros(human.nv),
        )  # fmt: skip
        P, J = rigid_fast.marker_kinematics(fm.parent, R, t, S, fm.marker_joint, fm.marker_offset)
        vis = np.isfinite(X[f, :, 0]) & (weights > 0)
        if not vis.any():
            continue
        rows = sorted(set(lock_idx) | {6 + int(k) for k in np.flatnonzero(held[f])})
        lock_rows = np.zeros((len(rows), human.nv))
        for r, iv in enumerate(rows):
            lock_rows[r, iv] = 1.0
        Jm = (J[vis] * sw[vis, None, None]).reshape(-1, human.nv)
        Jr = np.ascontiguousarray(np.vstack([lock_rows, Jm]))
        dx = ((X[f, vis] - P[vis]) * sw[vis, None]).reshape(-1)
        LA = np.linalg.cholesky(A)
        zeros = np.zeros(len(Jr))
        rows_dx = np.concatenate([np.zeros(len(rows)), dx])
        _, _, out[f] = prioritized_torque(
            A, LA, h, Jr, zeros, zeros, np.array([0, len(rows), len(Jr)]),
            np.zeros(human.nv), rows_dx, True, DEFAULT_DAMPING,
        )  # fmt: skip
    return out


@dataclass(frozen=True)
class BoundReport:
    """The bound of every frame and how far to trust it.

    Attributes:
        dq: (N, nv) Δq [rad; root translation m]: NaN where not determined, capped at the
            joint range.
        capped: (N, nv) bool, entries that were capped.
        sensitivity_deg_per_mm: (N, n_dof) per determined DOF (NaN elsewhere; inf where
            the markers carry no information on it).
        poorly_determined: {DOF: frames} over POORLY_DETERMINED_DEG_PER_MM.
    """

    dq: FloatArray
    capped: np.ndarray
    sensitivity_deg_per_mm: FloatArray
    poorly_determined: dict[str, int]

    @property
    def worst_sensitivity_deg_per_mm(self) -> FloatArray:
        """(N,) the least determined DOF of each frame [deg/mm] (NaN: nothing determined)."""
        s = self.sensitivity_deg_per_mm
        out = np.full(s.shape[0], np.nan)
        has = np.isfinite(s) | np.isinf(s)
        for f in np.flatnonzero(has.any(axis=1)):
            out[f] = np.max(s[f][has[f]])
        return out


def sensitivities(
    human: HumanModel,
    names: Sequence[str],
    Q: FloatArray,
    X: FloatArray,
    weights: FloatArray,
    root: np.ndarray,
    dofs: np.ndarray,
) -> FloatArray:
    """(N, n_dof) ``sqrt([(Jᵀ W J)⁻¹]_ii)`` [rad/m] over the determined DOFs (and the root
    when determined) of each frame; NaN for undetermined DOFs, inf without information."""
    kin = MarkerKinematics(human, names)
    fm = rigid_fast.flatten(human.model, kin.frame_ids)
    sw = np.sqrt(np.maximum(weights, 0.0))
    n_dof = len(human.dof_names)
    out = np.full((len(Q), n_dof), np.nan)
    for f, q in enumerate(Q):
        cols = np.flatnonzero(dofs[f])
        vis = np.isfinite(X[f, :, 0]) & (weights > 0)
        if cols.size == 0 or not vis.any():
            continue
        R, t, S = rigid_fast.forward_kinematics(fm.parent, fm.R0, fm.p0, fm.axis, q)
        _, J = rigid_fast.marker_kinematics(fm.parent, R, t, S, fm.marker_joint, fm.marker_offset)
        use = np.concatenate([np.arange(6), 6 + cols]) if root[f] else 6 + cols
        Jw = (J[vis][:, :, use] * sw[vis, None, None]).reshape(-1, use.size)
        w, V = np.linalg.eigh(Jw.T @ Jw)
        good = w > _EIG_CUT * max(float(w.max()), 1e-300)
        var = (V[:, good] ** 2) @ (1.0 / w[good])
        var[(np.abs(V[:, ~good]) > 1e-6).any(axis=1)] = np.inf  # in a null direction
        out[f, cols] = np.sqrt(var[-cols.size :])
    return out


def bound_report(
    human: HumanModel,
    names: Sequence[str],
    Q: FloatArray,
    X: FloatArray,
    weights: FloatArray,
    dq: FloatArray,
    root: np.ndarray,
    dofs: np.ndarray,
) -> BoundReport:
    """Apply rules 1-3 of the module docstring to a method's raw Δq (N, nv)."""
    out = np.array(dq, dtype=float, copy=True)
    out[~root, :6] = np.nan
    out[:, 6:][~dofs] = np.nan
    lo, hi = human.dof_limits()
    span = np.concatenate([np.full(6, np.inf), hi - lo])
    with np.errstate(invalid="ignore"):
        capped = np.abs(out) > span
    out = np.where(capped, np.sign(out) * span, out)
    sens = np.degrees(sensitivities(human, names, Q, X, weights, root, dofs)) / 1000.0
    with np.errstate(invalid="ignore"):
        poor = sens > POORLY_DETERMINED_DEG_PER_MM
    counts = {d: int(poor[:, k].sum()) for k, d in enumerate(human.dof_names) if poor[:, k].any()}
    return BoundReport(out, capped, sens, counts)
