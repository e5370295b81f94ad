"""Prioritized operational-space control in marker space (the seed paper, eq. 6-13) and the
joint-error bound (eq. 14-17), as numba kernels shared by the online and offline paths.

One control step, for levels k = 1..n in priority order (a level is a marker subset, or
a set of joint rows for joint limits / locked coordinates):

    J_k|p   = J_k N_{k-1}                                  projected task Jacobian
    Λ_k|p   = (J_k|p A^-1 J_k|p^T)^+                       task-space inertia (eq. 2)
    F_k|p   = Λ_k|p (F*_k - J̇_k v + J_k A^-1 (b + g - Γ))   = Λ F* + μ + p - (higher levels)
    Γ      += J_k|p^T F_k|p                                (eq. 9-11)
    Jbar    = A^-1 J_k|p^T Λ_k|p                           dynamically consistent inverse
    N_k     = N_{k-1} - Jbar J_k|p

then the posture, last: ``Γ += N_n^T (A a_p + b + g - Γ)``, and the dynamics
``A q̈ + b + g = Γ`` give ``q̈ = A^-1 (Γ - b - g)``.

Pseudo-inverses are truncated (see :func:`prioritized_torque`): directions that are
singular — three markers on one rigid segment, a marker whose level has no DOF left — get
no force instead of an unbounded one, and projectors stay exact.
"""

from __future__ import annotations

import numpy as np
from numba import njit

FloatArray = np.ndarray  # numba kernels: mypy does not track their dtypes


RANK_TOLERANCE = 1e-10  # eigenvalues of CᵀC below this fraction of ‖B_k‖²: rank lost
# Damped least squares within a level: s / (s² + λ²) with λ² = damping ‖B_k‖² / rows, so
# nearly singular directions (three markers almost in line on a segment, a level with as many
# rows as free DOFs) get a bounded answer. Projectors stay exact (hard rank cut above).
DEFAULT_DAMPING = 0.01


@njit(cache=True)
def _tri_solve_lower(L: FloatArray, B: FloatArray) -> FloatArray:
    """L⁻¹ B for lower-triangular L and a matrix B (forward substitution on every column)."""
    n, m = B.shape
    X = np.empty((n, m))
    for i in range(n):
        for c in range(m):
            acc = B[i, c]
            for k in range(i):
                acc -= L[i, k] * X[k, c]
            X[i, c] = acc / L[i, i]
    return X


@njit(cache=True)
def tri_inverse_lower(L: FloatArray) -> FloatArray:
    """L⁻¹ of a lower-triangular L, row by row (contiguous inner loops: ~4x faster than
    LAPACK's general inverse through numba at 48 DOF, which copies and pivots)."""
    n = L.shape[0]
    X = np.zeros((n, n))
    for i in range(n):
        for k in range(i):
            a = L[i, k]
            if a != 0.0:
                for c in range(k + 1):
                    X[i, c] -= a * X[k, c]
        d = 1.0 / L[i, i]
        for c in range(i):
            X[i, c] *= d
        X[i, i] = d
    return X


@njit(cache=True)
def _tri_solve_upper_t(L: FloatArray, b: FloatArray) -> FloatArray:
    """L⁻ᵀ b for lower-triangular L and a vector b (back substitution)."""
    n = L.shape[0]
    x = np.empty(n)
    for i in range(n - 1, -1, -1):
        acc = b[i]
        for k in range(i + 1, n):
            acc -= L[k, i] * x[k]
        x[i] = acc / L[i, i]
    return x


@njit(cache=True)
def prioritized_torque(
    Amat: FloatArray,
    LA: FloatArray,
    h: FloatArray,
    J: FloatArray,
    acc: FloatArray,
    bias: FloatArray,
    level_ptr: np.ndarray,
    posture_acc: FloatArray,
    dx: FloatArray,
    want_bound: bool,
    damping: float,
    exact_first: bool = False,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Γ (nv,), the resulting q̈ = A⁻¹ (Γ − b − g) (nv,) and, if ``want_bound``, the joint-error
    bound Δq = Jbar_⊗ Δx_⊗ (eq. 15) for the row errors ``dx`` (R,), where Jbar_⊗ is the
    dynamically consistent generalised inverse of the stacked projected Jacobian
    J_⊗ = [J_1; J_2|1; ...] (eq. 12) (else zeros).

    Computed in the coordinates ``y = L_Aᵀ q̈`` (A = L_A L_Aᵀ), where the A-weighted norm of
    q̈ is the Euclidean norm of y: the dynamically consistent inverse
    ``Jbar = A⁻¹ Jᵀ (J A⁻¹ Jᵀ)⁺`` is the ordinary pseudo-inverse of ``B = J L_A⁻ᵀ`` and the
    null-space projector N of eq. 6-11 is an orthogonal projector ``P = I − W Wᵀ`` in y
    (W: orthonormal basis of the directions the levels above have used):

        y = −L_A⁻¹ (b + g)                     (Γ = 0: free motion)
        level k: C = B_k P = U S Vᵀ             (eigen-decomposition of the smaller of CCᵀ, CᵀC;
                                                  s² < 1e-10 ‖B_k‖² is rank lost)
                 y += V S/(S² + λ²) Uᵀ (F*_k − J̇_k v − B_k y)   (Jbar_k|p of eq. 9-11 applied)
                 W ← [W, V]                     (N_k = N_{k-1} − Jbar_k|p J_k|p)
        posture: y += P (L_Aᵀ a_p − y)          (Γ_posture = Nᵀ (A a_p + b + g − Γ))
        Γ = A q̈ + b + g = L_A y + b + g

    The last marker level has nothing but the posture below it, so it is solved by a
    Cholesky factorisation of ``CᵀC + λ² I`` instead of an eigen-decomposition (four times
    cheaper at 48 DOF) and the posture gets the matching damped projector
    ``P − (CᵀC + λ² I)⁻¹ CᵀC``. λ² = damping ‖B_k‖² / rows (damped least squares; 0 gives
    the exact pseudo-inverses of the paper). The row spaces of the levels are orthogonal in
    y, so ``Jbar_⊗ Δx = L_A⁻ᵀ Σ_k (level k's inverse) Δx_k``.

    Args:
        Amat: joint-space inertia (nv, nv); LA its Cholesky factor.
        h: b + g (nv,).
        J: task Jacobians of all levels stacked (R, nv), highest priority first.
        acc: commanded task accelerations F* (R,).
        bias: J̇v (R,).
        level_ptr: (L + 1,) rows of level k are ``level_ptr[k]:level_ptr[k + 1]``.
        posture_acc: a_p (nv,), the posture's joint acceleration.
        dx: (R,) row errors for the bound (ignored unless ``want_bound``).
        want_bound: compute the bound.
        damping: relative damping of the least squares within a level (DEFAULT_DAMPING).
        exact_first: solve the first level without damping (held coordinates: rows of the
            identity, never ill-conditioned; damped, a held DOF would creep by 1 % of its
            free acceleration every step).
    """
    nv = Amat.shape[0]
    LAi = tri_inverse_lower(LA)  # one inverse instead of many substitutions
    LAiT = np.ascontiguousarray(LAi.T)
    y = -(LAi @ h)
    yb = np.zeros(nv)  # Σ_k (level k's inverse) dx_k, in y
    W = np.zeros((nv, 0))
    last = -1
    for k in range(level_ptr.shape[0] - 1):
        if level_ptr[k + 1] > level_ptr[k]:
            last = k
    yp = np.ascontiguousarray(LA.T) @ posture_acc
    posture_done = False
    for k in range(level_ptr.shape[0] - 1):
        a, b = level_ptr[k], level_ptr[k + 1]
        r = b - a
        if r == 0:
            continue
        Bk = np.ascontiguousarray(J[a:b]) @ LAiT  # (r, nv) = J_k L_A^-T
        scale = 0.0
        for i in range(r):
            for c in range(nv):
                scale += Bk[i, c] * Bk[i, c]
        if scale <= 0.0:
            continue
        lam2 = (0.0 if exact_first and k == 0 else damping * scale / r) + 1e-10 * scale
        if W.shape[1] == 0:
            C = Bk
        else:
            C = Bk - (Bk @ W) @ np.ascontiguousarray(W.T)  # B_k P
        Ct = np.ascontiguousarray(C.T)
        res = acc[a:b] - bias[a:b] - Bk @ y
        if k == last:
            CtC = Ct @ C
            H = CtC.copy()
            for i in range(nv):
                H[i, i] += lam2
            L = np.linalg.cholesky(H)
            # H⁻¹ keeps range(P) in exact arithmetic; projecting again removes the rounding
            # that H's tiny eigenvalues (λ², on the used-up directions) would amplify
            y = y + _project(W, _chol_solve(L, Ct @ res))
            if want_bound:
                yb = yb + _project(W, _chol_solve(L, Ct @ dx[a:b]))
            # posture through the damped projector P - H^-1 CᵀC (symmetric: H commutes with CᵀC)
            e = _project(W, yp - y)
            y = y + _project(W, e - _chol_solve(L, CtC @ e))
            posture_done = True
            continue
        if r <= nv:
            w, U = np.linalg.eigh(C @ Ct)
            rank = 0
            for i in range(r):
                if w[i] > RANK_TOLERANCE * scale:
                    rank += 1
            Ur = np.ascontiguousarray(U[:, r - rank :])
            UrT = np.ascontiguousarray(Ur.T)
            wr = w[r - rank :]
            Vr = Ct @ Ur  # (nv, rank), columns with norm sqrt(w)
            for i in range(rank):
                Vr[:, i] /= np.sqrt(wr[i])
            coef = np.sqrt(wr) / (wr + lam2)  # damped s / (s² + λ²)
            y = y + Vr @ (coef * (UrT @ res))
            if want_bound:
                yb = yb + Vr @ (coef * (UrT @ dx[a:b]))
        else:
            w, V = np.linalg.eigh(Ct @ C)
            rank = 0
            for i in range(nv):
                if w[i] > RANK_TOLERANCE * scale:
                    rank += 1
            Vr = np.ascontiguousarray(V[:, nv - rank :])
            VrT = np.ascontiguousarray(Vr.T)
            wr = w[nv - rank :]
            inv = 1.0 / (wr + lam2)
            y = y + Vr @ (inv * (VrT @ (Ct @ res)))
            if want_bound:
                yb = yb + Vr @ (inv * (VrT @ (Ct @ dx[a:b])))
        W = np.hstack((W, Vr))
    if not posture_done:
        y = y + _project(W, yp - y)
    Gamma = LA @ y + h
    qdd = LAiT @ y
    return Gamma, qdd, LAiT @ yb


@njit(cache=True)
def _chol_solve_vec(L: FloatArray, b: FloatArray) -> FloatArray:
    """x with L Lᵀ x = b (forward then back substitution; L lower-triangular)."""
    n = L.shape[0]
    z = np.empty(n)
    for i in range(n):
        acc = b[i]
        for k in range(i):
            acc -= L[i, k] * z[k]
        z[i] = acc / L[i, i]
    x = np.empty(n)
    for i in range(n - 1, -1, -1):
        acc = z[i]
        for k in range(i + 1, n):
            acc -= L[k, i] * x[k]
        x[i] = acc / L[i, i]
    return x


@njit(cache=True)
def _small_cholesky(S: FloatArray) -> FloatArray:
    """Lower Cholesky factor of a small positive definite matrix."""
    n = S.shape[0]
    L = np.zeros((n, n))
    for i in range(n):
        for k in range(i + 1):
            acc = S[i, k]
            for m in range(k):
                acc -= L[i, m] * L[k, m]
            L[i, k] = np.sqrt(acc) if i == k else acc / L[k, k]
    return L


@njit(cache=True)
def prioritized_torque_single(
    Amat: FloatArray,
    LA: FloatArray,
    h: FloatArray,
    lock_cols: np.ndarray,
    lock_acc: FloatArray,
    J: FloatArray,
    acc: FloatArray,
    bias: FloatArray,
    posture_acc: FloatArray,
    dx: FloatArray,
    want_bound: bool,
    damping: float,
    Ainv: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`prioritized_torque` for the levels direct marker control uses by default, the
    same numbers by a cheaper route: [held DOFs ``lock_cols`` (velocity indices) at the
    accelerations ``lock_acc``, exact] > [one marker level J (R, nv), damped] > posture.

    In joint space (x = q̈ = L_A⁻ᵀ y) the y-space steps of :func:`prioritized_torque` are:

        x₀ = −A⁻¹ h                                                free motion
        x₁ = x₀ + A⁻¹Eᵀ (E A⁻¹ Eᵀ + λ₁² I)⁻¹ (a_lock − E x₀)      held DOFs (E: their rows)
        markers, on the free DOFs f (the null space of the held rows is {x: E x = 0}, and
        the y-norm is the A-norm):  K = J_fᵀ J_f + λ² A_ff,  x₂ = x₁ + K⁻¹ J_fᵀ (F* − J̇v − J x₁)
        posture: d = a_p − x₂ projected A-orthogonally on {E x = 0}:
                 u = d − A⁻¹Eᵀ (E A⁻¹ Eᵀ)⁻¹ E d,  x₃ = x₂ + u − K⁻¹ J_fᵀ J_f u
        bound (eq. 15): Δq = K⁻¹ J_fᵀ Δx on f

    with λ₁² = 1e-10 ‖E L_A⁻ᵀ‖² and λ² = (damping / R + 1e-10) ‖J L_A⁻ᵀ‖² as there
    (‖·‖: Frobenius; ‖J L_A⁻ᵀ‖² = Σ (A⁻¹ ∘ JᵀJ)). A Cholesky of the free block replaces
    the eigen-decompositions and the R × nv products in y; tests check both routes agree.
    Needs R > 0 (no marker row: use :func:`prioritized_torque`). ``Ainv``: A⁻¹ when the
    caller has it (else computed from L_A)."""
    nv = Amat.shape[0]
    R = J.shape[0]
    nl = lock_cols.shape[0]
    if Ainv is None:
        LAi = tri_inverse_lower(LA)
        Ainv = np.ascontiguousarray(LAi.T) @ LAi
    x = -(Ainv @ h)
    is_lock = np.zeros(nv, dtype=np.bool_)
    for c in range(nl):
        is_lock[lock_cols[c]] = True
    AinvEt = np.empty((nv, nl))
    S = np.empty((nl, nl))
    for c in range(nl):
        for i in range(nv):
            AinvEt[i, c] = Ainv[i, lock_cols[c]]
    for a in range(nl):
        for c in range(nl):
            S[a, c] = Ainv[lock_cols[a], lock_cols[c]]
    LS = np.zeros((nl, nl))
    if nl > 0:
        scale1 = 0.0
        for c in range(nl):
            scale1 += S[c, c]
        Sd = S.copy()
        for c in range(nl):
            Sd[c, c] += 1e-10 * scale1
        res1 = np.empty(nl)
        for c in range(nl):
            res1[c] = lock_acc[c] - x[lock_cols[c]]
        # E A⁻¹ Eᵀ is small (the held DOFs) and positive definite: Cholesky by hand, no
        # LAPACK call overhead
        x = x + AinvEt @ _chol_solve_vec(_small_cholesky(Sd), res1)
        LS = _small_cholesky(S)
    free = np.empty(nv - nl, dtype=np.int64)
    n_f = 0
    for i in range(nv):
        if not is_lock[i]:
            free[n_f] = i
            n_f += 1
    JtJ = np.ascontiguousarray(J.T) @ J
    scale = 0.0
    for i in range(nv):
        for k in range(nv):
            scale += Ainv[i, k] * JtJ[i, k]
    lam2 = (damping / R + 1e-10) * scale
    K = np.empty((n_f, n_f))
    for a in range(n_f):
        for c in range(n_f):
            K[a, c] = JtJ[free[a], free[c]] + lam2 * Amat[free[a], free[c]]
    L = np.linalg.cholesky(K)
    res = acc - bias - J @ x
    Jtr = np.ascontiguousarray(J.T) @ res
    g = np.empty(n_f)
    for a in range(n_f):
        g[a] = Jtr[free[a]]
    step = _chol_solve_vec(L, g)
    for a in range(n_f):
        x[free[a]] += step[a]
    dq = np.zeros(nv)
    if want_bound:
        Jtd = np.ascontiguousarray(J.T) @ dx
        for a in range(n_f):
            g[a] = Jtd[free[a]]
        sb = _chol_solve_vec(L, g)
        for a in range(n_f):
            dq[free[a]] = sb[a]
    d = posture_acc - x
    if nl > 0:
        Ed = np.empty(nl)
        for c in range(nl):
            Ed[c] = d[lock_cols[c]]
        d = d - AinvEt @ _chol_solve_vec(LS, Ed)
    for a in range(n_f):
        acc_a = 0.0
        for c in range(n_f):
            acc_a += JtJ[free[a], free[c]] * d[free[c]]
        g[a] = acc_a
    corr = _chol_solve_vec(L, g)
    for a in range(n_f):
        d[free[a]] -= corr[a]
    x = x + d
    Gamma = Amat @ x + h
    return Gamma, x, dq


@njit(cache=True)
def _project(W: FloatArray, e: FloatArray) -> FloatArray:
    """P e with P = I − W Wᵀ."""
    if W.shape[1] == 0:
        return e
    return e - W @ (np.ascontiguousarray(W.T) @ e)


@njit(cache=True)
def _chol_solve(L: FloatArray, b: FloatArray) -> FloatArray:
    """x with L Lᵀ x = b."""
    n = L.shape[0]
    z = _tri_solve_lower(L, b.reshape(n, 1))[:, 0]
    return _tri_solve_upper_t(L, z)


def joint_error_bound_reference(Ainv: FloatArray, Jx: FloatArray, dx: FloatArray) -> FloatArray:
    """Eq. 15 with numpy's SVD pseudo-inverse (readable reference for the tests)."""
    if Jx.shape[0] == 0:
        return np.zeros(Ainv.shape[0])
    M = Jx @ Ainv @ Jx.T
    return np.asarray(Ainv @ Jx.T @ np.linalg.pinv(M, rcond=1e-9, hermitian=True) @ dx)
