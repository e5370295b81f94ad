"""Damped-least-squares inverse kinematics with joint limits (what the robot server runs).

Pose error, in the base (chest) frame, linear first::

    e = [p* - p ; log(R* R^T)]                          (6,)  [m ; rad]

weighted ``W = diag(1, 1, 1, w, w, w)`` with ``w = rot_weight_m`` [m/rad] so that an
orientation error of 1 rad counts like ``w`` metres. One step::

    dq = J_W^T (J_W J_W^T + lambda^2 I)^-1 e_W         (n,)   (J_W = W J)

solved by SVD with the damping raised near singularities (Maciejewski & Klein 1988):
``lambda^2 = lambda0^2 + (1 - (s_min / eps)^2) lambda_max^2`` when the smallest singular
value ``s_min < eps``. Joint limits: a joint whose step would push it past a limit it is
already at (or would cross) is frozen and the step is re-solved without it; the result is
clamped. ``ik_step`` caps each joint's step (the server passes ``velocity * dt``),
scaling the whole step uniformly so its direction is kept.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError
from mocapkit.robot.model import ArmModel, rotation_log


@dataclass(frozen=True)
class IkParams:
    """Solver settings.

    Attributes:
        rot_weight_m: weight of orientation error [m/rad] (0.2: 1 deg ~ 3.5 mm).
        damping: base damping lambda0 [m].
        singular_eps: singular value below which damping grows.
        damping_max: extra damping lambda_max at a singularity.
        max_iters: iterations of :func:`solve_ik`.
        tol_pos_m, tol_rot_rad: convergence tolerances.
        max_step_rad: largest joint change per iteration (trust region) [rad].
    """

    rot_weight_m: float = 0.2
    damping: float = 1e-4
    singular_eps: float = 0.05
    damping_max: float = 0.05
    max_iters: int = 200
    tol_pos_m: float = 1e-5
    tol_rot_rad: float = 1e-4
    max_step_rad: float = 0.3

    def __post_init__(self) -> None:
        for name in ("rot_weight_m", "singular_eps", "max_step_rad", "tol_pos_m", "tol_rot_rad"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"IkParams.{name}: expected a positive number, got {v}")
        for name in ("damping", "damping_max"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ConfigError(f"IkParams.{name}: expected a number >= 0, got {v}")
        if self.max_iters < 1:
            raise ConfigError(f"IkParams.max_iters: expected >= 1, got {self.max_iters}")


@dataclass(frozen=True)
class IkResult:
    """Outcome of :func:`solve_ik`.

    ``reached`` is False when the target is unreachable (outside the workspace or beyond
    the joint limits): ``q`` is then the closest configuration found and the residuals say
    how far it is.
    """

    q: FloatArray
    reached: bool
    pos_err_m: float
    rot_err_rad: float
    iterations: int
    at_limit: tuple[str, ...] = field(default=())


def pose_error(T: Any, T_target: Any) -> FloatArray:
    """``[p* - p; log(R* R^T)]`` (6,) in the base frame [m; rad]."""
    A = np.asarray(T, dtype=float)
    B = np.asarray(T_target, dtype=float)
    e = np.empty(6)
    e[:3] = B[:3, 3] - A[:3, 3]
    e[3:] = rotation_log(B[:3, :3] @ A[:3, :3].T)
    return e


def _dls(J: FloatArray, e: FloatArray, params: IkParams) -> FloatArray:
    U, s, Vt = np.linalg.svd(J, full_matrices=False)  # J (6, k): U (6, m), s (m,), Vt (m, k)
    lam2 = params.damping**2
    s_min = s[-1] if s.size else 0.0
    if s_min < params.singular_eps:
        lam2 += (1.0 - (s_min / params.singular_eps) ** 2) * params.damping_max**2
    gain = s / (s * s + lam2)
    return np.asarray(Vt.T @ (gain * (U.T @ e)))


def _limited_direction(
    arm: ArmModel, q: FloatArray, J: FloatArray, e: FloatArray, params: IkParams
) -> tuple[FloatArray, list[int]]:
    """DLS step with joints pressing on their limits frozen (re-solved without them)."""
    free = np.ones(arm.n, dtype=bool)
    frozen: list[int] = []
    dq = np.zeros(arm.n)
    for _ in range(arm.n):
        dq = np.zeros(arm.n)
        if free.any():
            dq[free] = _dls(J[:, free], e, params)
        q_new = q + dq
        over = (q_new > arm.upper) & (dq > 0) & free
        under = (q_new < arm.lower) & (dq < 0) & free
        # freeze only joints already at (or within a hair of) the limit they press on;
        # others just get clamped this step
        press = (over & (q >= arm.upper - 1e-6)) | (under & (q <= arm.lower + 1e-6))
        if not press.any():
            break
        idx = np.flatnonzero(press)
        free[idx] = False
        frozen.extend(int(i) for i in idx)
    return dq, frozen


def ik_step(
    arm: ArmModel,
    q: Any,
    T_target: Any,
    params: IkParams | None = None,
    max_dq: Any = None,
) -> tuple[FloatArray, FloatArray, list[int]]:
    """One DLS step from q towards ``T_target``.

    Args:
        max_dq: per-joint cap on |dq| [rad] ((n,) or a scalar), e.g. ``velocity * dt``;
            the whole step is scaled down uniformly to respect it.

    Returns:
        (q_new (n,) clamped to the limits, error (6,) before the step, frozen joint indices)
    """
    p = params or IkParams()
    qa = np.asarray(q, dtype=float)
    e = pose_error(arm.fk(qa), T_target)
    J = arm.jacobian(qa)
    w = np.array([1.0, 1.0, 1.0, p.rot_weight_m, p.rot_weight_m, p.rot_weight_m])
    dq, frozen = _limited_direction(arm, qa, w[:, None] * J, w * e, p)
    cap = np.full(arm.n, p.max_step_rad)
    if max_dq is not None:
        cap = np.minimum(cap, np.broadcast_to(np.asarray(max_dq, dtype=float), (arm.n,)))
    ratio = np.max(np.abs(dq) / cap)
    if ratio > 1.0:
        dq = dq / ratio
    return arm.clamp(qa + dq), e, frozen


def solve_ik(
    arm: ArmModel, T_target: Any, q0: Any = None, params: IkParams | None = None
) -> IkResult:
    """Iterate :func:`ik_step` to convergence.

    Stops when the error is within tolerance (``reached=True``) or when an iteration no
    longer improves the weighted error by 1e-9 or the budget runs out (then ``reached``
    is False and ``q`` is the closest pose found).
    """
    p = params or IkParams()
    q = arm.q_ref.copy() if q0 is None else arm.clamp(arm.check_q(q0, "q0"))
    w = np.array([1.0, 1.0, 1.0, p.rot_weight_m, p.rot_weight_m, p.rot_weight_m])
    best_q, best_cost = q, np.inf
    iterations = 0
    stall = 0
    for it in range(1, p.max_iters + 1):
        iterations = it
        q_new, e, _frozen = ik_step(arm, q, T_target, p)
        cost = float(np.linalg.norm(w * e))
        if cost < best_cost - 1e-9:
            best_q, best_cost, stall = q, cost, 0
        else:
            stall += 1
        if np.linalg.norm(e[:3]) <= p.tol_pos_m and np.linalg.norm(e[3:]) <= p.tol_rot_rad:
            best_q = q
            break
        if stall >= 10:
            break
        q = q_new
    e = pose_error(arm.fk(best_q), T_target)
    pos, rot = float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:]))
    reached = pos <= p.tol_pos_m * 10 and rot <= p.tol_rot_rad * 10
    at_limit = tuple(
        arm.joint_names[i]
        for i in range(arm.n)
        if best_q[i] <= arm.lower[i] + 1e-6 or best_q[i] >= arm.upper[i] - 1e-6
    )
    return IkResult(best_q, reached, pos, rot, iterations, at_limit)
