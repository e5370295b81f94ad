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
2. Per reported coordinate (the OpenSim coordinates users read, some computed from several
   model DOFs): ``Δc = G Δq`` with G the coordinates' Jacobian, so a split spine's
   internal redistribution, which no marker sees and no output shows, does not count.
3. Capped at the joint's range: the reconstructed and the true angle both lie within the
   model's limits, so they cannot differ by more (180 deg for a computed angle); capped
   entries are counted and reported.
4. Reported with the conditioning: per frame and determined coordinate the sensitivity
   ``s_k = sqrt(g_kᵀ (Jᵀ W J)⁻¹ g_k)`` (J: the visible tracked markers' Jacobian over the
   determined, not held DOFs, W their weights, g_k the coordinate's gradient), in degrees
   per millimetre of marker error: how far the least-squares fit moves the coordinate for
   a 1 mm marker error. A coordinate above :data:`POORLY_DETERMINED_DEG_PER_MM` is named
   in a warning: its bound, however small, rests on a poorly conditioned fit. A coordinate
   whose gradient reaches a direction no visible marker sees (infinite sensitivity: one
   head marker for four neck DOFs) is numerically undetermined: NaN, like rule 1.

For a full-rank, well-conditioned frame ``Jbar_⊗ = J⁺`` whatever the inertia (the
dynamically consistent inverse of a matrix with full column rank is its least-squares
inverse), so the bound is the joint correction that would remove the frame's residual
marker errors to first order.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.human_model import HumanModel
from mocapkit.markers import rigid_fast
from mocapkit.markers.bound_fit import total_bound
from mocapkit.markers.coordinates import CoordinateMap, coordinates_from_q
from mocapkit.markers.coordinates import coordinate_jacobian as _analytic_jacobian
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
            np.zeros(human.nv), rows_dx, True, DEFAULT_DAMPING, True,
        )  # fmt: skip
    return out


def _perturbed(Q: FloatArray, nv: int, eps: float) -> FloatArray:
    """(N, 2 nv, nq): each configuration moved by +eps then -eps along each velocity
    coordinate (the free-flyer's local twist as ``pin.integrate`` moves it: a translation
    along the pelvis axes, a rotation about them; the joints additively)."""
    out = np.repeat(Q[:, None, :], 2 * nv, axis=1)
    x, y, z, w = Q[:, 3], Q[:, 4], Q[:, 5], Q[:, 6]
    # pelvis axes in the world (columns of R from the xyzw quaternion)
    axes = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)], 1),
            np.stack([2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)], 1),
            np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], 1),
        ],
        axis=1,
    )  # (N, 3 axes, 3)
    c, s = np.cos(eps / 2), np.sin(eps / 2)
    for sign, base in ((1.0, 0), (-1.0, nv)):
        for k in range(3):
            out[:, base + k, :3] += sign * eps * axes[:, k]
            # q (x) [c, sign s e_k] in xyzw
            e = np.zeros(3)
            e[k] = sign * s
            out[:, base + 3 + k, 3] = w * e[0] + x * c + y * e[2] - z * e[1]
            out[:, base + 3 + k, 4] = w * e[1] - x * e[2] + y * c + z * e[0]
            out[:, base + 3 + k, 5] = w * e[2] + x * e[1] - y * e[0] + z * c
            out[:, base + 3 + k, 6] = w * c - x * e[0] - y * e[1] - z * e[2]
        for k in range(6, nv):
            out[:, base + k, k + 1] += sign * eps
    return out


def coordinate_jacobian(
    human: HumanModel, cmap: CoordinateMap, Q: FloatArray, coords: FloatArray | None = None
) -> FloatArray:
    """(N, K, nv) derivative of the reported coordinates (:mod:`mocapkit.markers.coordinates`)
    with respect to the model's velocity coordinates, analytically
    (:func:`mocapkit.markers.coordinates.coordinate_jacobian`; equal to the central
    differences of :func:`coordinate_jacobian_reference` to 1e-8)."""
    return _analytic_jacobian(human, Q, cmap, coords)


def coordinate_jacobian_reference(
    human: HumanModel, cmap: CoordinateMap, Q: FloatArray
) -> FloatArray:
    """(N, K, nv) derivative of the reported coordinates (:mod:`mocapkit.markers.coordinates`)
    with respect to the model's velocity coordinates, by central differences (step 1e-6:
    the coordinates are smooth away from gimbal lock, where the derivative is rightly huge).
    All perturbed configurations of a block of frames go through one vectorised call."""
    eps = 1e-6
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    n, nv = Q.shape[0], human.nv
    G = np.zeros((n, len(cmap.names), nv))
    block = max(1, 4096 // (2 * nv))  # frames per call: ~4k configurations
    ang = cmap.angular
    for a in range(0, n, block):
        b = min(n, a + block)
        P = _perturbed(Q[a:b], nv, eps).reshape(-1, Q.shape[1])
        C = coordinates_from_q(human, P, cmap).reshape(b - a, 2 * nv, -1)
        d = C[:, :nv] - C[:, nv:]  # (B, nv, K)
        d[..., ang] = np.pi - np.mod(np.pi - d[..., ang], 2.0 * np.pi)  # across the +-pi seam
        G[a:b] = np.swapaxes(d, 1, 2) / (2.0 * eps)
    return G


@dataclass(frozen=True)
class BoundReport:
    """The bound of every frame and how far to trust it.

    Attributes:
        dq: (N, nv) Δq of the model's DOFs [rad; root translation m]: NaN where not
            determined, capped at the joint range.
        dc: (N, K) the same for the reported coordinates (``G Δq``, G the coordinates'
            Jacobian): NaN where not determined, capped at the joint range (direct DOFs) or
            at 180 deg (angles computed from several DOFs).
        capped: (N, K) bool, entries of ``dc`` that were capped.
        sensitivity_deg_per_mm: (N, K) per determined rotational coordinate (NaN elsewhere;
            inf where the markers carry no information on it).
        poorly_determined: {coordinate: frames} over POORLY_DETERMINED_DEG_PER_MM (finite).
        unobserved: (N, K) bool, coordinates some visible marker reaches structurally but
            that move along a direction no visible marker sees (infinite sensitivity):
            numerically undetermined; ``dc`` is NaN there.
        total: (N, K) the bound that holds, |distance to the markers' best fit| plus what
            the markers' noise can move that fit (:mod:`mocapkit.markers.bound_fit`), capped
            like ``dc``; NaN where undetermined or without redundancy to estimate the noise;
            None when not requested (``with_total=False``).
        per_frame: the sensitivities are every frame's (else each visibility pattern's
            sampled frames', :func:`_sampled_sensitivities`).
    """

    dq: FloatArray
    dc: FloatArray
    capped: np.ndarray
    sensitivity_deg_per_mm: FloatArray
    poorly_determined: dict[str, int]
    unobserved: np.ndarray
    total: FloatArray | None
    per_frame: bool = True

    @property
    def worst_sensitivity_deg_per_mm(self) -> FloatArray:
        """(N,) the least determined coordinate of each frame [deg/mm] (NaN: none)."""
        s = self.sensitivity_deg_per_mm
        out = np.full(s.shape[0], np.nan)
        has = ~np.isnan(s)
        for f in np.flatnonzero(has.any(axis=1)):
            out[f] = np.max(s[f][has[f]])
        return out


def sensitivities(
    human: HumanModel,
    names: Sequence[str],
    Q: FloatArray,
    X: FloatArray,
    weights: FloatArray,
    free: np.ndarray,
    G: FloatArray,
    rows: np.ndarray,
    backend: str = "fast",
) -> FloatArray:
    """(N, K) ``sqrt(g_kᵀ (Jᵀ W J)⁻¹ g_k)`` [rad/m] for the coordinates ``rows`` (N, K) bool,
    J over the model velocity columns ``free`` (N, nv) bool of each frame (the determined,
    not held ones), g_k the coordinate's gradient (G: (N, K, nv)); NaN outside ``rows``, inf
    when g_k reaches a direction the markers do not see. ``backend``: "fast" (numba,
    :mod:`mocapkit.markers.bound_kernels`) or "reference" (this function's numpy loop)."""
    kin = MarkerKinematics(human, names)
    fm = rigid_fast.flatten(human.model, kin.frame_ids)
    if backend == "fast":
        from mocapkit.markers.bound_kernels import sensitivities_kernel

        return sensitivities_kernel(
            fm.parent, fm.R0, fm.p0, fm.axis, fm.marker_joint, fm.marker_offset,
            np.ascontiguousarray(Q, dtype=float), np.ascontiguousarray(X, dtype=float),
            np.ascontiguousarray(weights, dtype=float), np.ascontiguousarray(free),
            np.ascontiguousarray(G), np.ascontiguousarray(rows),
        )  # fmt: skip
    sw = np.sqrt(np.maximum(weights, 0.0))
    out = np.full(rows.shape, np.nan)
    for f, q in enumerate(Q):
        cols = np.flatnonzero(free[f])
        vis = np.isfinite(X[f, :, 0]) & (weights > 0)
        if cols.size == 0 or not vis.any() or not rows[f].any():
            continue
        R, t, S = rigid_fast.forward_kinematics(fm.parent, fm.R0, fm.p0, fm.axis, q)
        _, J = rigid_fast.marker_kinematics(fm.parent, R, t, S, fm.marker_joint, fm.marker_offset)
        Jw = (J[vis][:, :, cols] * sw[vis, None, None]).reshape(-1, cols.size)
        w, V = np.linalg.eigh(Jw.T @ Jw)
        good = w > _EIG_CUT * max(float(w.max()), 1e-300)
        g = G[f][:, cols][rows[f]]  # (k, c)
        proj = g @ V  # (k, c) components along the eigenvectors
        var = (proj[:, good] ** 2) @ (1.0 / w[good])
        gnorm = np.linalg.norm(g, axis=1)
        blind = (np.abs(proj[:, ~good]) > 1e-6 * np.maximum(gnorm, 1e-12)[:, None]).any(axis=1)
        var[blind] = np.inf
        out[f, rows[f]] = np.sqrt(var)
    return out


def _pattern_samples(keys: np.ndarray, per_group: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Frames sharing a row of ``keys`` (N, k) bool form a group (their visible markers,
    free DOFs and reported columns are the same); returns (N,) group ids and the sampled
    frames (first, middle and last of each group's frames, ``per_group`` at most)."""
    packed = np.packbits(keys, axis=1)
    _, group = np.unique(packed, axis=0, return_inverse=True)
    group = np.asarray(group).reshape(-1)
    samples: list[int] = []
    for g in range(int(group.max()) + 1 if group.size else 0):
        idx = np.flatnonzero(group == g)
        pick = np.unique(
            idx[np.linspace(0, idx.size - 1, min(per_group, idx.size)).round().astype(int)]
        )
        samples.extend(int(i) for i in pick)
    return group, np.array(sorted(samples), dtype=np.int64)


def _sampled_sensitivities(
    human: HumanModel,
    names: Sequence[str],
    Q: FloatArray,
    X: FloatArray,
    weights: FloatArray,
    free: np.ndarray,
    rows: np.ndarray,
    cmap: CoordinateMap,
    coords: FloatArray,
) -> FloatArray:
    """Sensitivities (N, K) [rad/m] evaluated at up to three frames of each visibility
    pattern (same visible markers, free DOFs and reported columns) and given to all its
    frames: the largest finite value seen, inf when every sample is blind. The rank of the
    markers' Jacobian is a property of the pattern away from singular poses, so the
    "unobserved" test is the same as frame by frame; the deg/mm figures are the pattern's
    worst sampled value (``per_frame=True`` computes every frame)."""
    vis = np.isfinite(X[:, :, 0]) & (weights > 0)[None, :]
    group, samples = _pattern_samples(np.concatenate([vis, free, rows], axis=1))
    if samples.size == 0:
        return np.full(rows.shape, np.nan)
    Gs = coordinate_jacobian(human, cmap, Q[samples], coords[samples])
    sens_s = sensitivities(
        human, names, Q[samples], X[samples], weights, free[samples], Gs, rows[samples]
    )
    out = np.full(rows.shape, np.nan)
    for g in np.unique(group[samples]):
        members = group == g
        vals = sens_s[group[samples] == g]  # (s, K)
        fin = np.where(np.isfinite(vals), vals, -np.inf).max(axis=0)
        allinf = np.isinf(vals).all(axis=0) & ~np.isnan(vals).any(axis=0)
        val = np.where(np.isfinite(fin), fin, np.nan)
        val[allinf] = np.inf
        out[members] = val[None, :]
    out[~rows] = np.nan
    return out


_BLOCK = 1024  # frames per block of the coordinate Jacobian (N x K x nv floats)


def bound_report(
    human: HumanModel,
    cmap: CoordinateMap,
    names: Sequence[str],
    Q: FloatArray,
    X: FloatArray,
    weights: FloatArray,
    dq: FloatArray,
    root: np.ndarray,
    dofs: np.ndarray,
    held: Sequence[str] = (),
    columns: np.ndarray | None = None,
    with_total: bool = True,
    coords: FloatArray | None = None,
    per_frame: bool | None = None,
    progress: Callable[[str, float, float], None] | None = None,
) -> BoundReport:
    """Apply rules 1-3 of the module docstring to a method's raw Δq (N, nv): ``root``,
    ``dofs`` from :func:`mocapkit.markers.determined.dof_determined`, ``held`` the
    coordinate tasks' DOFs, ``columns`` (N, K) the determined reported coordinates;
    ``with_total``: also the bound that holds (:mod:`mocapkit.markers.bound_fit`: a fit per
    frame, the costlier part; the CLI computes it on request, ``--total-bound``);
    ``coords`` (N, K): the coordinates of Q if already computed; ``per_frame``: the
    conditioning (sensitivities) of every frame rather than of each visibility pattern's
    sampled frames (:func:`_sampled_sensitivities`); default: with the total bound."""
    per_frame = with_total if per_frame is None else per_frame
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    coords = coordinates_from_q(human, Q, cmap) if coords is None else coords
    out = np.array(dq, dtype=float, copy=True)
    out[~root, :6] = np.nan
    out[:, 6:][~dofs] = np.nan
    lo, hi = human.dof_limits()
    span = np.concatenate([np.full(6, np.inf), hi - lo])
    with np.errstate(invalid="ignore"):
        capped_q = np.abs(out) > span
    out = np.where(capped_q, np.copysign(span, out), out)
    cols = np.ones((len(Q), len(cmap.names)), dtype=bool) if columns is None else columns
    dc = np.empty((len(Q), len(cmap.names)))
    dep = np.empty((len(Q), len(cmap.names)), dtype=bool)
    for a in range(0, len(Q), _BLOCK):
        b = min(len(Q), a + _BLOCK)
        G = coordinate_jacobian(human, cmap, Q[a:b], coords[a:b])
        dc[a:b] = np.einsum("nkv,nv->nk", G, np.nan_to_num(out[a:b]))
        # a coordinate is capped if a model DOF it depends on was
        dep[a:b] = ((np.abs(G) > 1e-9) & capped_q[a:b, None, :]).any(axis=2)
        if progress is not None:
            progress("joint-error bounds", b, len(Q))
    dc[~cols] = np.nan
    cspan = np.full(len(cmap.names), np.inf)
    for k, (kind, a, _) in enumerate(cmap.source):
        if kind == "dof":
            cspan[k] = hi[a] - lo[a]
        elif cmap.angular[k]:
            cspan[k] = np.pi
    with np.errstate(invalid="ignore"):
        over = np.abs(dc) > cspan
    dc = np.where(over, np.copysign(cspan, dc), dc)
    capped = (over | dep) & cols
    held_idx = [6 + human.dof_names.index(d) for d in held if d in human.dof_names]
    free = np.concatenate([np.repeat(root[:, None], 6, axis=1), dofs], axis=1)
    free[:, held_idx] = False
    rows = cols & cmap.angular[None, :]
    for k, (kind, a, _) in enumerate(cmap.source):
        if kind == "dof" and (6 + a) in held_idx:
            rows[:, k] = False  # held by a coordinate task: no marker fit behind it
    if per_frame:
        sens = sensitivities(
            human, names, Q, X, weights, free, coordinate_jacobian(human, cmap, Q, coords), rows
        )
    else:
        sens = _sampled_sensitivities(human, names, Q, X, weights, free, rows, cmap, coords)
    sens = np.degrees(sens) / 1000.0
    unobserved = np.isinf(sens)
    dc[unobserved] = np.nan
    capped &= ~unobserved
    with np.errstate(invalid="ignore"):
        poor = (sens > POORLY_DETERMINED_DEG_PER_MM) & ~unobserved
    counts = {c: int(poor[:, k].sum()) for k, c in enumerate(cmap.names) if poor[:, k].any()}
    total = None
    if with_total:
        if progress is not None:
            progress("total bound (a fit per frame)", 0, 1)
        total = total_bound(human, cmap, names, Q, X, weights, free, rows & ~unobserved)
        if progress is not None:
            progress("total bound (a fit per frame)", 1, 1)
        total = np.minimum(total, cspan[None, :])
    return BoundReport(out, dc, capped, sens, counts, unobserved, total, per_frame)
