"""Numba kernels of direct marker control: one capture frame and a whole trial. The
readable reference is :mod:`mocapkit.markers.osc_reference`.

Between two capture frames the simulation runs ``n_sub`` steps of dt; every step:

1. rigid-body terms at (q, v): A, b + g, marker positions P, Jacobians J and J̇v
   (:mod:`mocapkit.markers.rigid_fast`, checked against Pinocchio);
2. per marker the commanded acceleration ``F* = ẍ_d + Kd (ẋ_d − J v) + Kp (x_d − P)`` on
   the target trajectory ``x_{f-1} + ẋ s + ẍ s² / 2`` (central differences at t_{f-1},
   which reach x_f exactly at s = T);
3. levels: first the held coordinates (rows of the identity): coordinate tasks, DOFs that
   no visible tracked marker determines (held at their angle: nothing else should move
   them, and the dynamically consistent inverse would otherwise swing them with every
   acceleration of the body, into their limits), and joints at a limit that move or are
   pushed outward (released as soon as the marker tasks pull them back in); then the
   marker subsets in priority order (markers not visible dropped), then the posture;
   Γ from :func:`mocapkit.markers.prioritized.prioritized_torque` (eq. 6-13);
4. ``A q̈ + b + g = Γ`` integrated by semi-implicit Euler, angles kept within limits.

Gains: with the model's own dynamics compensated, each task row is ẍ = F*; with
semi-implicit Euler, ``Kd = 1/dt`` and ``Kp = κ/dt²`` shrink the error by (1 − κ) per step
(the other pole is 0); :class:`~mocapkit.markers.osc.OSCParams` sets κ. A state that runs
away (|v| > 1e4) ends the frame with NaN outputs, which the callers report.

The frame's outputs are the state at t_f, the tracked markers P(q(t_f)), their errors to
the targets at t_f and the bound Δq = Jbar_⊗ Δx_⊗ (eq. 15) of the last step's marker errors.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mocapkit.markers.prioritized import (
    prioritized_torque,
    prioritized_torque_single,
    tri_inverse_lower,
)
from mocapkit.markers.rigid_fast import (
    body_velocities_bias,
    dynamics_terms,
    forward_kinematics,
    integrate,
    marker_bias,
    marker_kinematics,
    marker_positions,
)

FloatArray = np.ndarray  # numba kernels: mypy does not track their dtypes


@njit(cache=True)
def determined_dofs(
    tracked: np.ndarray, dof_ptr: np.ndarray, dof_markers: np.ndarray, n_dof: int
) -> np.ndarray:
    """(n_dof,) bool: a DOF is determined when some tracked marker at or below the segment it
    moves is visible (``dof_markers[dof_ptr[k]:dof_ptr[k + 1]]``: marker columns)."""
    out = np.zeros(n_dof, dtype=np.bool_)
    for k in range(n_dof):
        for i in range(dof_ptr[k], dof_ptr[k + 1]):
            if tracked[dof_markers[i]]:
                out[k] = True
                break
    return out


@njit(cache=True)
def _lock_rows(
    q: FloatArray,
    v: FloatArray,
    lock_dof: np.ndarray,
    lock_value: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    determined: np.ndarray,
    push: FloatArray,
) -> tuple[np.ndarray, FloatArray, np.ndarray]:
    """q indices held this step, their targets and kinds (0: coordinate task, 1: held
    because no visible marker determines it, 2: at a limit).

    A DOF at a limit is held only while it moves outward or the marker tasks push it
    outward (``push``: Jᵀ of the commanded marker accelerations, per velocity index, the
    IK's projected-gradient rule); otherwise it is free to leave the limit. A DOF that no
    visible marker determines keeps its angle (target = current value) until one does."""
    rows = np.empty(q.shape[0], dtype=np.int64)
    target = np.empty(q.shape[0])
    kind = np.empty(q.shape[0], dtype=np.int64)
    n = 0
    for c in range(lock_dof.shape[0]):
        rows[n] = lock_dof[c]
        target[n] = lock_value[c]
        kind[n] = 0
        n += 1
    for iq in range(7, q.shape[0]):
        held = False
        for c in range(lock_dof.shape[0]):
            if lock_dof[c] == iq:
                held = True
        if held:
            continue
        iv = iq - 1
        if not determined[iq - 7]:
            rows[n] = iq
            target[n] = q[iq]
            kind[n] = 1
            n += 1
        elif q[iq] <= lower[iq] + 1e-9 and (v[iv] < 0.0 or (v[iv] == 0.0 and push[iv] <= 0.0)):
            rows[n] = iq
            target[n] = lower[iq]
            kind[n] = 2
            n += 1
        elif q[iq] >= upper[iq] - 1e-9 and (v[iv] > 0.0 or (v[iv] == 0.0 and push[iv] >= 0.0)):
            rows[n] = iq
            target[n] = upper[iq]
            kind[n] = 2
            n += 1
    return rows[:n], target[:n], kind[:n]


@njit(cache=True)
def _cap_speed(v: FloatArray, max_speed: float) -> None:
    """In place: angular rates within ``max_speed`` [rad/s], the pelvis' linear velocity
    within ``max_speed / 4`` [m/s] (direction kept)."""
    lin = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if lin > 0.25 * max_speed:
        for c in range(3):
            v[c] *= 0.25 * max_speed / lin
    ang = np.sqrt(v[3] * v[3] + v[4] * v[4] + v[5] * v[5])
    if ang > max_speed:
        for c in range(3, 6):
            v[c] *= max_speed / ang
    for i in range(6, v.shape[0]):
        v[i] = min(max(v[i], -max_speed), max_speed)


@njit(cache=True)
def reacquire(
    parent: np.ndarray,
    R0: FloatArray,
    p0: FloatArray,
    axis: FloatArray,
    marker_joint: np.ndarray,
    marker_offset: FloatArray,
    q: FloatArray,
    v: FloatArray,
    x0: FloatArray,
    x1: FloatArray,
    row_weight: FloatArray,
    level_markers: np.ndarray,
    dof_ptr: np.ndarray,
    dof_markers: np.ndarray,
    lock_dof: np.ndarray,
    lower: FloatArray,
    upper: FloatArray,
) -> int:
    """In place on q, v: when tracked markers appear (visible at t_f, not at t_{f-1}), fit
    the pelvis and the DOFs that carry them (the chain from the pelvis to their segments,
    coordinate tasks excepted) to all visible tracked markers at t_f by damped
    Gauss-Newton; those DOFs restart at rest. Returns how many DOFs were fitted.

    Through a gap the simulation holds the DOFs no marker determines and leaves the
    directions no visible marker sees where they were (the pelvis with two markers in
    view, the head's roll about its one marker); a marker appearing far from the model
    would then be chased over many frames (walking2: a head marker 240 mm off took 25
    frames). The fit is IK of the visible markers over those DOFs alone; the rest of the
    state is untouched, so markers already tracked are refitted where they are."""
    M = marker_joint.shape[0]
    nv = v.shape[0]
    n_dof = nv - 6
    appeared = np.zeros(M, dtype=np.bool_)
    vis1 = np.zeros(M, dtype=np.bool_)
    any_new = False
    for k in range(level_markers.shape[0]):
        m = level_markers[k]
        vis1[m] = np.isfinite(x1[m, 0])
        appeared[m] = vis1[m] and not np.isfinite(x0[m, 0])
        any_new = any_new or appeared[m]
    if not any_new:
        return 0
    cols = np.empty(nv, dtype=np.int64)
    for c in range(6):
        cols[c] = c
    n = 6
    for k in range(n_dof):
        held = False
        for c in range(lock_dof.shape[0]):
            if lock_dof[c] == 7 + k:
                held = True
        carries = False
        for i in range(dof_ptr[k], dof_ptr[k + 1]):
            if appeared[dof_markers[i]]:
                carries = True
        if carries and not held:
            cols[n] = 6 + k
            n += 1
    cols = cols[:n]
    for _it in range(20):
        R, t, S = forward_kinematics(parent, R0, p0, axis, q)
        P, J = marker_kinematics(parent, R, t, S, marker_joint, marker_offset)
        H = np.zeros((n, n))
        g = np.zeros(n)
        for m in range(M):
            if not vis1[m]:
                continue
            Jc = J[m][:, cols]
            e = x1[m] - P[m]
            H += row_weight[m] * (Jc.T @ Jc)
            g += row_weight[m] * (Jc.T @ e)
        mu = 1e-6 * max(np.trace(H) / n, 1e-12)
        for c in range(n):
            H[c, c] += 1e-3 * H[c, c] + mu  # Marquardt: unseen directions stay put
        step = np.linalg.solve(H, g)
        big = np.abs(step).max()
        if big > 0.5:  # keep each iteration within the linearisation's reach [rad, m]
            step *= 0.5 / big
        dv = np.zeros(nv)
        for c in range(n):
            dv[cols[c]] = step[c]
        q[:] = integrate(q, dv)
        for iq in range(7, q.shape[0]):
            q[iq] = min(max(q[iq], lower[iq]), upper[iq])
        if big < 1e-9:
            break
    for c in range(6, n):
        v[cols[c]] = 0.0
    return n - 6


LIMIT_ROUNDS = 4  # solves per step at most: the first, then one per batch of DOFs held


@njit(cache=True)
def _solve_levels(
    Amat: FloatArray,
    LA: FloatArray,
    Ainv: FloatArray,
    h: FloatArray,
    lock_cols: np.ndarray,
    lock_acc: FloatArray,
    Jm: FloatArray,
    accm: FloatArray,
    biasm: FloatArray,
    dxm: FloatArray,
    mptr: np.ndarray,
    n_levels: int,
    n_marker_rows: int,
    a_post: FloatArray,
    want_bound: bool,
    damping: float,
) -> tuple[FloatArray, FloatArray]:
    """q̈ and the bound Δq of one control step: held DOFs (rows of the identity, exact) >
    the marker levels > posture (eq. 6-13); the default single marker level by the
    cheaper joint-space route (the same numbers)."""
    nv = Amat.shape[0]
    n_lock = lock_cols.shape[0]
    if n_levels == 1 and n_marker_rows > 0:
        _G, qdd, dq = prioritized_torque_single(
            Amat,
            LA,
            h,
            lock_cols,
            lock_acc,
            Jm,
            accm,
            biasm,
            a_post,
            dxm,
            want_bound,
            damping,
            Ainv,
        )
        return qdd, dq
    n_rows = n_lock + n_marker_rows
    Jall = np.zeros((n_rows, nv))
    acc = np.zeros(n_rows)
    bias = np.zeros(n_rows)
    dx = np.zeros(n_rows)
    ptr = np.zeros(n_levels + 2, dtype=np.int64)
    for c in range(n_lock):
        Jall[c, lock_cols[c]] = 1.0
        acc[c] = lock_acc[c]
    Jall[n_lock:] = Jm
    acc[n_lock:] = accm
    bias[n_lock:] = biasm
    dx[n_lock:] = dxm
    ptr[1] = n_lock
    for lv in range(n_levels):
        ptr[lv + 2] = n_lock + mptr[lv + 1]
    # the bound (eq. 15) of the last step's marker errors; lock rows have no error
    _G, qdd, dq = prioritized_torque(
        Amat, LA, h, Jall, acc, bias, ptr, a_post, dx, want_bound, damping, True
    )
    return qdd, dq


STEP_GROWTH = 1.5  # a step may raise the weighted marker error by this factor (+ slack)
STEP_HALVINGS = 6  # then its velocity is halved, this many times at most


@njit(cache=True)
def _target_errors(
    P: FloatArray,
    x0: FloatArray,
    x1: FloatArray,
    xd0: FloatArray,
    xdd0: FloatArray,
    tracked: np.ndarray,
    row_weight: FloatArray,
    level_ptr: np.ndarray,
    level_markers: np.ndarray,
    s: float,
) -> FloatArray:
    """Per priority level, Σ w_m ‖x_m(s) − P_m‖² over its tracked markers, x_m(s) the
    frame's target at time s after t_{f-1} (as the control law's; a marker not visible at
    t_{f-1}: x1)."""
    n_levels = level_ptr.shape[0] - 1
    out = np.zeros(n_levels)
    for lv in range(n_levels):
        for k in range(level_ptr[lv], level_ptr[lv + 1]):
            m = level_markers[k]
            if not tracked[m]:
                continue
            for c in range(3):
                if np.isfinite(x0[m, 0]):
                    xt = x0[m, c] + xd0[m, c] * s + 0.5 * xdd0[m, c] * s * s
                else:
                    xt = x1[m, c]
                d = xt - P[m, c]
                out[lv] += row_weight[m] * d * d
    return out


@njit(cache=True)
def _step_worse(err_try: FloatArray, err_hold: FloatArray, slack: FloatArray) -> bool:
    """Lexicographic over the priority levels: the first level whose error moves by more
    than its slack decides (worse: grown by more than STEP_GROWTH); a lower level may
    lose what a higher one gains."""
    for lv in range(err_try.shape[0]):
        if err_try[lv] > STEP_GROWTH * err_hold[lv] + slack[lv]:
            return True
        if err_try[lv] < err_hold[lv] - slack[lv]:
            return False
    return False


@njit(cache=True)
def osc_frame(
    parent: np.ndarray,
    R0: FloatArray,
    p0: FloatArray,
    axis: FloatArray,
    mass: FloatArray,
    com: FloatArray,
    inertia: FloatArray,
    gravity: FloatArray,
    marker_joint: np.ndarray,
    marker_offset: FloatArray,
    q: FloatArray,
    v: FloatArray,
    x0: FloatArray,
    x1: FloatArray,
    xd0: FloatArray,
    xdd0: FloatArray,
    row_weight: FloatArray,
    level_ptr: np.ndarray,
    level_markers: np.ndarray,
    dof_ptr: np.ndarray,
    dof_markers: np.ndarray,
    lock_dof: np.ndarray,
    lock_value: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    q_posture: FloatArray,
    gains: FloatArray,
    dt_frame: float,
    n_sub: int,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Advance the simulated body from t_{f-1} to t_f in ``n_sub`` control + simulation steps.

    Args:
        q, v: state at t_{f-1}.
        x0: (M, 3) marker targets at t_{f-1} (NaN: not visible); x1: at t_f.
        xd0, xdd0: (M, 3) target velocity and acceleration at t_{f-1}; within the frame the
            target follows ``x0 + xd0 s + xdd0 s² / 2`` (s = time since t_{f-1}).
        row_weight: (M,) weight of each marker within its level (rows scaled by √w).
        level_ptr, level_markers: priority levels of marker indices (CSR layout).
        dof_ptr, dof_markers: per revolute DOF, the level markers at or below the segment it
            moves (CSR); a DOF none of whose markers is visible this frame is held.
        lock_dof, lock_value: q indices held at values (coordinate tasks).
        lower, upper: (nq,) limits (root entries infinite).
        q_posture: (nq,) posture target.
        gains: [kp, kd, kp_lock, kd_lock, kp_posture, kd_posture, damping, max_speed,
            max_error_m, reacquire] (see :class:`~mocapkit.markers.osc.OSCParams`).

    Returns:
        q, v at t_f; P (M, 3) tracked markers; Δq (nv,) the bound of eq. 15 (zero on held
        DOFs); e (M,) marker error norms to x1 (NaN: not visible at t_f). All NaN if the
        simulation diverged.
    """
    nv = v.shape[0]
    M = marker_joint.shape[0]
    kp, kd, kpl, kdl, kpp, kdp = gains[0], gains[1], gains[2], gains[3], gains[4], gains[5]
    e_max = gains[8]
    dt = dt_frame / n_sub
    q = q.copy()
    v = v.copy()
    if gains[9] > 0.0:
        reacquire(
            parent, R0, p0, axis, marker_joint, marker_offset, q, v, x0, x1, row_weight,
            level_markers, dof_ptr, dof_markers, lock_dof, lower, upper,
        )  # fmt: skip
    tracked = np.zeros(M, dtype=np.bool_)
    for m in range(M):
        tracked[m] = np.isfinite(x0[m, 0]) or np.isfinite(x1[m, 0])
    n_marker_rows = 0
    for k in range(level_markers.shape[0]):
        if tracked[level_markers[k]]:
            n_marker_rows += 3
    determined = determined_dofs(tracked, dof_ptr, dof_markers, nv - 6)
    n_levels = level_ptr.shape[0] - 1
    dq = np.zeros(nv)
    Jm = np.zeros((n_marker_rows, nv))
    accm = np.zeros(n_marker_rows)
    biasm = np.zeros(n_marker_rows)
    dxm = np.zeros(n_marker_rows)
    mptr = np.zeros(n_levels + 1, dtype=np.int64)
    for j in range(n_sub):
        s_now = j * dt
        if j == 0:
            # the rigid-body terms (A, b + g, and A's factors) once per capture frame: the
            # substeps of a frame share them (the metric of the dynamically consistent
            # inverse moves little in 1/(rate * substeps) s; ~17 % of a frame's cost)
            R, t, S, V, Ab, Amat, h = dynamics_terms(
                parent, R0, p0, axis, mass, com, inertia, gravity, q, v
            )
            if not (np.isfinite(Amat).all() and np.isfinite(h).all()):
                nan = np.full(M, np.nan)
                return q * np.nan, v * np.nan, np.full((M, 3), np.nan), np.full(nv, np.nan), nan
            LA = np.linalg.cholesky(Amat)
            LAi = tri_inverse_lower(LA)
            Ainv = np.ascontiguousarray(LAi.T) @ LAi
        else:
            R, t, S = forward_kinematics(parent, R0, p0, axis, q)
            V, Ab = body_velocities_bias(parent, S, v)
        P, J = marker_kinematics(parent, R, t, S, marker_joint, marker_offset)
        B = marker_bias(R, t, V, Ab, marker_joint, marker_offset)
        if not np.isfinite(J).all():
            nan = np.full(M, np.nan)
            return q * np.nan, v * np.nan, np.full((M, 3), np.nan), np.full(nv, np.nan), nan
        r = 0
        for lv in range(n_levels):
            for k in range(level_ptr[lv], level_ptr[lv + 1]):
                m = level_markers[k]
                if not tracked[m]:
                    continue
                if np.isfinite(x0[m, 0]):
                    # the target at the end of this substep (error measured where we go)
                    xdes = x0[m] + xd0[m] * s_now + 0.5 * xdd0[m] * s_now * s_now
                    vdes = xd0[m] + xdd0[m] * s_now
                    ades = xdd0[m]
                else:
                    xdes, vdes, ades = x1[m], np.zeros(3), np.zeros(3)
                Jv = J[m] @ v
                sw = np.sqrt(row_weight[m])
                e = xdes - P[m]
                en = np.sqrt(e @ e)
                sat = 1.0 if en <= e_max else e_max / en  # a far marker: reached gradually
                for c in range(3):
                    Jm[r + c] = sw * J[m, c]
                    accm[r + c] = sw * (ades[c] + kd * (vdes[c] - Jv[c]) + kp * sat * e[c])
                    biasm[r + c] = sw * B[m, c]
                    dxm[r + c] = sw * e[c]
                r += 3
            mptr[lv + 1] = r
        push = Jm.T @ (accm - biasm)
        lock_rows, lock_target, _kind = _lock_rows(
            q, v, lock_dof, lock_value, lower, upper, determined, push
        )
        a_post = -kdp * v
        for iq in range(7, q.shape[0]):
            a_post[iq - 1] += kpp * (q_posture[iq] - q[iq])
        n_lock = lock_rows.shape[0]
        lock_cols = np.empty(nv, dtype=np.int64)
        lock_acc = np.empty(nv)
        for c in range(n_lock):
            iq = lock_rows[c]
            lock_cols[c] = iq - 1
            lock_acc[c] = kpl * (lock_target[c] - q[iq]) - kdl * v[iq - 1]
        want = j == n_sub - 1
        qdd = np.zeros(nv)
        dq_step = np.zeros(nv)
        # Active set of the joint limits: a free DOF that this step's solution would carry
        # through its limit is held landing exactly on it, and the step is solved again,
        # so the other DOFs get accelerations that do not count on it (clamping it after
        # the solve left them to overshoot, and the arm chattered between limits).
        for _round in range(LIMIT_ROUNDS):
            qdd, dq_step = _solve_levels(
                Amat, LA, Ainv, h, lock_cols[:n_lock], lock_acc[:n_lock], Jm, accm, biasm, dxm,
                mptr, n_levels, n_marker_rows, a_post, want, gains[6],
            )  # fmt: skip
            added = 0
            for iq in range(7, q.shape[0]):
                iv = iq - 1
                held = False
                for c in range(n_lock):
                    if lock_cols[c] == iv:
                        held = True
                        break
                if held:
                    continue
                q_next = q[iq] + (v[iv] + qdd[iv] * dt) * dt
                if q_next < lower[iq] - 1e-12 or q_next > upper[iq] + 1e-12:
                    limit = lower[iq] if q_next < lower[iq] else upper[iq]
                    lock_cols[n_lock] = iv
                    lock_acc[n_lock] = (limit - q[iq] - v[iv] * dt) / (dt * dt)
                    n_lock += 1
                    added += 1
            if added == 0:
                break
        if want:
            dq = dq_step
        v_new = v + qdd * dt
        _cap_speed(v_new, gains[7])
        # A step that carries the model away from its targets is shortened (its velocity
        # halved, up to STEP_HALVINGS times; levels compared in priority order): near a
        # singular pose (a shoulder's two axes aligned) the damped inverse can turn the
        # task accelerations into joint speeds at the cap, which threw CMU 85_12's arm
        # onto a far branch of its angles.
        s_next = s_now + dt
        err_hold = _target_errors(
            P, x0, x1, xd0, xdd0, tracked, row_weight, level_ptr, level_markers, s_next
        )
        slack = np.empty(n_levels)  # (1 mm)² per tracked marker of the level
        for lv in range(n_levels):
            slack[lv] = 1e-6 * (mptr[lv + 1] - mptr[lv]) / 3.0
        for _half in range(STEP_HALVINGS + 1):
            q_try = integrate(q, v_new * dt)
            for iq in range(7, q.shape[0]):
                q_try[iq] = min(max(q_try[iq], lower[iq]), upper[iq])
            if _half == STEP_HALVINGS:
                break
            Rt, tt, _St = forward_kinematics(parent, R0, p0, axis, q_try)
            P_try = marker_positions(Rt, tt, marker_joint, marker_offset)
            err_try = _target_errors(
                P_try, x0, x1, xd0, xdd0, tracked, row_weight, level_ptr, level_markers, s_next
            )
            if not _step_worse(err_try, err_hold, slack):
                break
            v_new = 0.5 * v_new
        for iq in range(7, q.shape[0]):
            if q_try[iq] <= lower[iq]:
                v_new[iq - 1] = max(v_new[iq - 1], 0.0)
            elif q_try[iq] >= upper[iq]:
                v_new[iq - 1] = min(v_new[iq - 1], 0.0)
        q, v = q_try, v_new
        if not (np.isfinite(q).all() and np.isfinite(v).all() and np.abs(v).max() < 1e4):
            nan = np.full(M, np.nan)
            return q * np.nan, v * np.nan, np.full((M, 3), np.nan), np.full(nv, np.nan), nan
    R, t, S = forward_kinematics(parent, R0, p0, axis, q)
    P, J = marker_kinematics(parent, R, t, S, marker_joint, marker_offset)
    err = np.full(M, np.nan)
    for m in range(M):
        if np.isfinite(x1[m, 0]):
            d = x1[m] - P[m]
            err[m] = np.sqrt(d @ d)
    return q, v, P, dq, err


@njit(cache=True)
def osc_trial(
    parent: np.ndarray,
    R0: FloatArray,
    p0: FloatArray,
    axis: FloatArray,
    mass: FloatArray,
    com: FloatArray,
    inertia: FloatArray,
    gravity: FloatArray,
    marker_joint: np.ndarray,
    marker_offset: FloatArray,
    q_init: FloatArray,
    v_init: FloatArray,
    X: FloatArray,
    Xd: FloatArray,
    Xdd: FloatArray,
    row_weight: FloatArray,
    level_ptr: np.ndarray,
    level_markers: np.ndarray,
    dof_ptr: np.ndarray,
    dof_markers: np.ndarray,
    lock_dof: np.ndarray,
    lock_value: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    q_posture: FloatArray,
    gains: FloatArray,
    dt_frame: float,
    n_sub: int,
    first: int,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Run :func:`osc_frame` over frames ``first`` .. N-1 of X (N, M, 3) with target
    velocities Xd and accelerations Xdd (N, M, 3), from the state ``q_init``, ``v_init``
    at frame ``first - 1``; ``first = 0``: frame 0 starts from ``q_init`` at rest, holding
    frame 0. Returns Q (n, nq), P (n, M, 3), ΔQ (n, nv), E (n, M) of those n = N - first
    frames and the last velocity (nv,). A trial run in blocks (``first = 1`` on a block
    that repeats the previous block's last frame) gives the same numbers as in one call.
    """
    N, M = X.shape[0], X.shape[1]
    nq = q_init.shape[0]
    nv = nq - 1
    n = N - first
    Q = np.empty((n, nq))
    P = np.empty((n, M, 3))
    DQ = np.empty((n, nv))
    E = np.empty((n, M))
    q = q_init.copy()
    v = v_init.copy()
    for f in range(first, N):
        if f == 0:
            x0, xd0, xdd0 = X[0], np.zeros((M, 3)), np.zeros((M, 3))
        else:
            x0, xd0, xdd0 = X[f - 1], Xd[f - 1], Xdd[f - 1]
        q, v, Pf, dq, e = osc_frame(
            parent, R0, p0, axis, mass, com, inertia, gravity, marker_joint, marker_offset,
            q, v, x0, X[f], xd0, xdd0, row_weight, level_ptr, level_markers, dof_ptr,
            dof_markers, lock_dof, lock_value, lower, upper, q_posture, gains, dt_frame, n_sub,
        )  # fmt: skip
        Q[f - first] = q
        P[f - first] = Pf
        DQ[f - first] = dq
        E[f - first] = e
    return Q, P, DQ, E, v
