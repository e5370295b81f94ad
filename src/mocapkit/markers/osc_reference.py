"""Readable reference of direct marker control: Pinocchio's rigid-body algorithms and the
paper's formulas written out in joint space (eq. 6-13), no numba.

The fast kernels (:mod:`mocapkit.markers.osc_kernels`) work in the coordinates
``y = L_Aᵀ q̈``; this module uses ``Λ``, ``Jbar`` and ``N`` as the paper writes them, and
the tests check that both give the same frames.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.human_model import HumanModel
from mocapkit.markers.kinematics import MarkerKinematics
from mocapkit.markers.osc_kernels import LIMIT_ROUNDS, STEP_GROWTH, STEP_HALVINGS
from mocapkit.markers.prioritized import RANK_TOLERANCE

if TYPE_CHECKING:  # pragma: no cover
    from mocapkit.markers.osc import ControlProblem


def prioritized_torque_reference(
    Amat: FloatArray,
    h: FloatArray,
    J: FloatArray,
    acc: FloatArray,
    bias: FloatArray,
    level_ptr: Sequence[int],
    posture_acc: FloatArray,
    damping: float,
    exact_first: bool = False,
) -> tuple[FloatArray, FloatArray]:
    """Γ (eq. 11) and Jbar_⊗ (nv, R) with the damped task-space inertia of each level
    ``Λ = (J_k|p A⁻¹ J_k|pᵀ + λ² I)⁻¹`` and exact null-space projectors (see
    :func:`mocapkit.markers.prioritized.prioritized_torque` for λ and the last level)."""
    nv = Amat.shape[0]
    Ainv = np.linalg.inv(Amat)
    N = np.eye(nv)
    Gamma = np.zeros(nv)
    Jbar_all = np.zeros((nv, J.shape[0]))
    levels = [(k, level_ptr[k], level_ptr[k + 1]) for k in range(len(level_ptr) - 1)]
    levels = [(k, a, b) for k, a, b in levels if b > a]
    for i, (k0, a, b) in enumerate(levels):
        Jk = J[a:b]
        scale = float(np.trace(Jk @ Ainv @ Jk.T))
        if scale <= 0:
            continue
        lam2 = 0.0 if exact_first and k0 == 0 else damping * scale / (b - a)
        lam2 += 1e-10 * scale
        Jp = Jk @ N
        X = Jp @ Ainv @ Jp.T
        w, U = np.linalg.eigh(X)
        keep = w > RANK_TOLERANCE * scale
        Uk, wk = U[:, keep], w[keep]
        Lam = Uk @ np.diag(1.0 / (wk + lam2)) @ Uk.T  # damped, on the range of X
        F = Lam @ (acc[a:b] - bias[a:b] + Jk @ Ainv @ (h - Gamma))
        Gamma = Gamma + Jp.T @ F
        Jbar = Ainv @ Jp.T @ Lam
        Jbar_all[:, a:b] = Jbar
        if i == len(levels) - 1:
            Lam_full = np.linalg.inv(X + lam2 * np.eye(b - a))
            N = N - Ainv @ Jp.T @ Lam_full @ Jp  # damped projector below the last level
        else:
            exact = Uk @ np.diag(1.0 / wk) @ Uk.T
            N = N - Ainv @ Jp.T @ exact @ Jp
    Gamma = Gamma + N.T @ (Amat @ posture_acc + h - Gamma)
    return Gamma, Jbar_all


class ReferenceStepper:
    """One capture frame of direct marker control on Pinocchio (same contract as
    :func:`mocapkit.markers.osc_kernels.osc_frame`)."""

    def __init__(self, human: HumanModel, names: Sequence[str], problem: ControlProblem) -> None:
        import pinocchio as pin

        self._pin = pin
        self.human = human
        self.kin = MarkerKinematics(human, names)
        self.model = human.model
        self.data = self.model.createData()

    @staticmethod
    def _lock_rows(
        q: FloatArray, v: FloatArray, lock_dof: Any, lock_value: Any, lo: Any, hi: Any,
        determined: np.ndarray, push: FloatArray,
    ) -> tuple[list[int], list[float]]:  # fmt: skip
        """Held q indices and targets: coordinate tasks, undetermined DOFs (at their angle),
        joints at a limit that move or are pushed outward (see the kernel's ``_lock_rows``)."""
        rows, target = list(map(int, lock_dof)), list(map(float, lock_value))
        for iq in range(7, q.shape[0]):
            if iq in rows:
                continue
            iv = iq - 1
            if not determined[iq - 7]:
                rows.append(iq)
                target.append(float(q[iq]))
            elif q[iq] <= lo[iq] + 1e-9 and (v[iv] < 0 or (v[iv] == 0 and push[iv] <= 0)):
                rows.append(iq)
                target.append(float(lo[iq]))
            elif q[iq] >= hi[iq] - 1e-9 and (v[iv] > 0 or (v[iv] == 0 and push[iv] >= 0)):
                rows.append(iq)
                target.append(float(hi[iq]))
        return rows, target

    def _reacquire(
        self, q: FloatArray, v: FloatArray, x0: FloatArray, x1: FloatArray,
        row_weight: FloatArray, level_markers: Any, dof_ptr: Any, dof_markers: Any,
        lock_dof: Any, lower: FloatArray, upper: FloatArray,
    ) -> FloatArray:  # fmt: skip
        """q after fitting the pelvis and the DOFs carrying newly visible markers; v in
        place (the kernel's ``reacquire``)."""
        level = np.zeros(len(x1), dtype=bool)
        level[np.asarray(level_markers, dtype=int)] = True
        vis1 = level & np.isfinite(x1[:, 0])
        appeared = vis1 & ~np.isfinite(x0[:, 0])
        if not appeared.any():
            return q
        n_dof = len(v) - 6
        carries = np.array(
            [appeared[dof_markers[dof_ptr[k] : dof_ptr[k + 1]]].any() for k in range(n_dof)]
        )
        carries[[int(i) - 7 for i in lock_dof]] = False
        cols = np.concatenate([np.arange(6), 6 + np.flatnonzero(carries)])
        w = row_weight[vis1]
        for _ in range(20):
            P, J = self.kin.reference_positions_jacobians(q)
            Jc = J[vis1][:, :, cols]  # (m, 3, n)
            H = np.einsum("m,mci,mcj->ij", w, Jc, Jc)
            g = np.einsum("m,mci,mc->i", w, Jc, x1[vis1] - P[vis1])
            mu = 1e-6 * max(float(np.trace(H)) / cols.size, 1e-12)
            H[np.diag_indices_from(H)] += 1e-3 * np.diag(H) + mu
            step = np.linalg.solve(H, g)
            big = float(np.abs(step).max())
            if big > 0.5:
                step *= 0.5 / big
            dv = np.zeros(len(v))
            dv[cols] = step
            q = np.asarray(self._pin.integrate(self.model, q, dv))
            q[7:] = np.clip(q[7:], lower[7:], upper[7:])
            if big < 1e-9:
                break
        v[cols[6:]] = 0.0
        return q

    def frame(
        self,
        q: FloatArray,
        v: FloatArray,
        x0: FloatArray,
        x1: FloatArray,
        xd0: FloatArray,
        xdd0: FloatArray,
        row_weight: FloatArray,
        level_ptr: Any,
        level_markers: Any,
        dof_ptr: Any,
        dof_markers: Any,
        lock_dof: Any,
        lock_value: Any,
        lower: FloatArray,
        upper: FloatArray,
        q_posture: FloatArray,
        gains: FloatArray,
        dt_frame: float,
        n_sub: int,
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        pin, model, data = self._pin, self.model, self.data
        kp, kd, kpl, kdl, kpp, kdp, damping, max_speed, e_max, reacq = (float(g) for g in gains)
        nv, M = model.nv, len(x1)
        dt = dt_frame / n_sub
        tracked = np.isfinite(x0[:, 0]) | np.isfinite(x1[:, 0])
        determined = np.array(
            [tracked[dof_markers[dof_ptr[k] : dof_ptr[k + 1]]].any() for k in range(nv - 6)]
        )
        q, v = q.copy(), v.copy()
        if reacq > 0.0:
            q = self._reacquire(q, v, x0, x1, row_weight, level_markers, dof_ptr, dof_markers,
                                lock_dof, lower, upper)  # fmt: skip
        dq = np.zeros(nv)
        for j in range(n_sub):
            s = j * dt
            if j == 0:  # the kernel's: rigid-body terms once per capture frame
                Amat = pin.crba(model, data, q).copy()
                h = pin.nonLinearEffects(model, data, q, v).copy()
            P, J = self.kin.reference_positions_jacobians(q)
            B = self.kin.reference_bias(q, v)
            Jm: list[FloatArray] = []
            accm: list[float] = []
            biasm: list[float] = []
            dx: list[float] = []
            mptr = []
            for lv in range(len(level_ptr) - 1):
                for k in range(level_ptr[lv], level_ptr[lv + 1]):
                    m = int(level_markers[k])
                    if not tracked[m]:
                        continue
                    if np.isfinite(x0[m, 0]):
                        xdes = x0[m] + xd0[m] * s + 0.5 * xdd0[m] * s * s
                        vdes, ades = xd0[m] + xdd0[m] * s, xdd0[m]
                    else:
                        xdes, vdes, ades = x1[m], np.zeros(3), np.zeros(3)
                    sw = np.sqrt(row_weight[m])
                    e = xdes - P[m]
                    sat = min(1.0, e_max / max(float(np.linalg.norm(e)), 1e-300))
                    a_task = ades + kd * (vdes - J[m] @ v) + kp * sat * e
                    Jm += list(sw * J[m])
                    accm += list(sw * a_task)
                    biasm += list(sw * B[m])
                    dx += list(sw * (xdes - P[m]))
                mptr.append(len(accm))
            Jmat = np.array(Jm).reshape(-1, nv)
            push = Jmat.T @ (np.array(accm) - np.array(biasm)) if accm else np.zeros(nv)
            rows, target = self._lock_rows(
                q, v, lock_dof, lock_value, lower, upper, determined, push
            )
            cols = [int(iq) - 1 for iq in rows]
            lock_acc = [
                kpl * (tgt - q[iq]) - kdl * v[iq - 1] for iq, tgt in zip(rows, target, strict=True)
            ]
            a_post = -kdp * v
            a_post[6:] += kpp * (q_posture[7:] - q[7:])
            for _round in range(LIMIT_ROUNDS):  # the kernel's active set of the limits
                lock_J = np.zeros((len(cols), nv))
                for c, iv in enumerate(cols):
                    lock_J[c, iv] = 1.0
                ptr = [0, len(cols), *(len(cols) + p for p in mptr)]
                Gamma, Jbar = prioritized_torque_reference(
                    Amat, h, np.vstack([lock_J, Jmat]), np.array(lock_acc + accm),
                    np.array([0.0] * len(cols) + biasm), ptr, a_post, damping, True,
                )  # fmt: skip
                qdd = np.linalg.solve(Amat, Gamma - h)
                q_next = q[7:] + (v[6:] + qdd[6:] * dt) * dt
                cross = [
                    k for k in range(nv - 6)
                    if 6 + k not in cols
                    and (q_next[k] < lower[7 + k] - 1e-12 or q_next[k] > upper[7 + k] + 1e-12)
                ]  # fmt: skip
                if not cross:
                    break
                for k in cross:
                    limit = lower[7 + k] if q_next[k] < lower[7 + k] else upper[7 + k]
                    cols.append(6 + k)
                    lock_acc.append((limit - q[7 + k] - v[6 + k] * dt) / (dt * dt))
            if dx:
                dq = Jbar[:, len(cols) :] @ np.array(dx)  # eq. 15, the last step's errors
            v_new = v + qdd * dt
            lin, ang = np.linalg.norm(v_new[:3]), np.linalg.norm(v_new[3:6])
            if lin > 0.25 * max_speed:
                v_new[:3] *= 0.25 * max_speed / lin
            if ang > max_speed:
                v_new[3:6] *= max_speed / ang
            v_new[6:] = np.clip(v_new[6:], -max_speed, max_speed)
            # the kernel's step safeguard: a step away from the targets is shortened
            s_next = s + dt
            x_next = np.where(
                np.isfinite(x0[:, :1]), x0 + xd0 * s_next + 0.5 * xdd0 * s_next**2, x1
            )

            def errors(P_: FloatArray, x_next: FloatArray = x_next) -> FloatArray:
                out = np.zeros(len(level_ptr) - 1)
                for lv in range(len(level_ptr) - 1):
                    ms = [int(m) for m in level_markers[level_ptr[lv] : level_ptr[lv + 1]]]
                    ms = [m for m in ms if tracked[m]]
                    d = x_next[ms] - P_[ms]
                    out[lv] = float(np.sum(row_weight[ms][:, None] * d * d))
                return out

            def worse(e_try: FloatArray, e_hold: FloatArray, slack: FloatArray) -> bool:
                for a, b, sl in zip(e_try, e_hold, slack, strict=True):
                    if a > STEP_GROWTH * b + sl:
                        return True
                    if a < b - sl:
                        return False
                return False

            err_hold = errors(P)
            slack = 1e-6 * np.diff(np.array([0, *mptr], dtype=float)) / 3.0
            for half in range(STEP_HALVINGS + 1):
                q_try = np.asarray(pin.integrate(model, q, v_new * dt))
                q_try[7:] = np.clip(q_try[7:], lower[7:], upper[7:])
                if half == STEP_HALVINGS:
                    break
                if not worse(errors(self.kin.positions(q_try)), err_hold, slack):
                    break
                v_new = 0.5 * v_new
            low, high = q_try[7:] <= lower[7:], q_try[7:] >= upper[7:]
            v_new[6:][low] = np.maximum(v_new[6:][low], 0.0)
            v_new[6:][high] = np.minimum(v_new[6:][high], 0.0)
            q, v = q_try, v_new
        P = self.kin.positions(q)
        err = np.full(M, np.nan)
        vis = np.isfinite(x1[:, 0])
        err[vis] = np.linalg.norm(x1[vis] - P[vis], axis=1)
        return q, v, P, dq, err
