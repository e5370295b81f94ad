"""Direct marker control (Demircan, Sentis, De Sapio, Khatib): reconstruct motion by
driving a simulated body so that its markers track the captured ones, with a prioritized
hierarchy of marker subsets (eq. 6-13); joint angles are read off the simulation, with a
per-frame joint-error bound (eq. 14-17).

- :class:`DirectMarkerController` is the online form: :meth:`~DirectMarkerController.step`
  takes one capture frame (M, 3), runs ``substeps`` simulation steps and returns the
  frame's joint configuration, tracked markers and error bound.
- :func:`reconstruct_offline` runs a whole trial in one numba call (same numbers).

The controller runs at the capture rate, the simulation in substeps between frames (see
:mod:`mocapkit.markers.osc_kernels`). The target at t_{f-1} is the captured position with
central-difference velocity and acceleration, which only needs the frame that has just
arrived, so online and offline are the same computation.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.human_model import HumanModel
from mocapkit.errors import ConfigError, DataError
from mocapkit.markers import rigid_fast
from mocapkit.markers.coordinates import resolve_coordinate_tasks
from mocapkit.markers.determined import dof_marker_table
from mocapkit.markers.kinematics import MarkerKinematics
from mocapkit.markers.osc_kernels import osc_frame, osc_trial
from mocapkit.markers.prioritized import DEFAULT_DAMPING

Backend = Literal["fast", "reference"]
BLOCK_FRAMES = 2000  # frames per kernel call (progress is reported between calls)


@dataclass(frozen=True)
class OSCParams:
    """Simulation and gain settings.

    Attributes:
        substeps: simulation steps per capture frame.
        kappa: fraction of a task error removed per simulation step, 0 < kappa < 1; with
            dt = 1 / (rate · substeps): ``kp = kappa / dt²``, ``kd = 1 / dt`` (an error
            shrinks by (1 - kappa)^substeps per capture frame).
        posture_kp, posture_kd: posture task gains [1/s², 1/s].
        damping: relative damping of the least squares within a priority level (0: the
            paper's exact pseudo-inverses; see :mod:`mocapkit.markers.prioritized`).
        max_speed: cap on each joint's (and the pelvis') angular speed [rad/s] and, as
            ``max_speed / 4`` [m/s], on the pelvis' linear speed in the simulation: a
            safety net above human motion (pitching peaks near 120 rad/s at the shoulder,
            gait below 10) that stops the runaway a nearly singular set of markers can
            start (walking2 with four visible markers diverged without it).
        max_error_m: a marker's position error enters its commanded acceleration at most
            this long [m] (direction kept): a marker far from the model is reached over a
            few frames instead of in one leap that the linearisation cannot follow (the
            bound, eq. 15, still sees the whole error). A safety net: markers that appear
            are placed by ``reacquire`` first.
        reacquire: when tracked markers appear (after a gap, or for the first time), fit
            the pelvis and the DOFs carrying them to the visible markers before simulating
            the frame (:func:`mocapkit.markers.osc_kernels.reacquire`); False: the paper's
            pure simulation, which chases such markers over several frames.
        backend: ``"fast"`` (numba) or ``"reference"`` (Pinocchio + numpy).
    """

    substeps: int = 2
    kappa: float = 0.3
    posture_kp: float = 25.0
    posture_kd: float = 10.0
    damping: float = DEFAULT_DAMPING
    max_speed: float = 150.0
    max_error_m: float = 0.1
    reacquire: bool = True
    backend: Backend = "fast"

    def __post_init__(self) -> None:
        if self.substeps < 1:
            raise ConfigError(f"substeps: expected >= 1, got {self.substeps}")
        if not (0.0 < self.kappa < 1.0):
            raise ConfigError(f"kappa: expected 0 < kappa < 1, got {self.kappa}")
        if self.backend not in ("fast", "reference"):
            raise ConfigError(f"backend: expected 'fast' or 'reference', got {self.backend!r}")
        if not (0.0 <= self.damping < 10.0):
            raise ConfigError(f"damping: expected 0 <= damping < 10, got {self.damping}")
        if not (self.max_speed > 0.0):
            raise ConfigError(f"max_speed: expected > 0 rad/s, got {self.max_speed}")
        if not (self.max_error_m > 0.0):
            raise ConfigError(f"max_error_m: expected > 0 m, got {self.max_error_m}")

    def gains(self, rate_hz: float) -> FloatArray:
        dt = 1.0 / (rate_hz * self.substeps)
        kp, kd = self.kappa / dt**2, 1.0 / dt
        row = [kp, kd, kp, kd, self.posture_kp, self.posture_kd, self.damping, self.max_speed]
        return np.array([*row, self.max_error_m, float(self.reacquire)])


@dataclass(frozen=True)
class ControlProblem:
    """What the kernels need, derived once from the model, markers and levels."""

    flat: rigid_fast.FlatModel
    level_ptr: np.ndarray
    level_markers: np.ndarray
    dof_ptr: np.ndarray
    dof_markers: np.ndarray
    lock_dof: np.ndarray
    lock_value: FloatArray
    lower: FloatArray
    upper: FloatArray
    q_posture: FloatArray
    row_weight: FloatArray


def control_problem(
    human: HumanModel,
    names: Sequence[str],
    levels: Sequence[Sequence[str]],
    coordinate_tasks: Mapping[str, tuple[float, float]],
    q_posture: FloatArray,
    weights: Mapping[str, float] | None = None,
) -> ControlProblem:
    """Flatten the model and encode the priority levels (marker names -> column indices)."""
    kin = MarkerKinematics(human, names)
    index = {n: i for i, n in enumerate(names)}
    ptr = [0]
    members: list[int] = []
    for level in levels:
        for n in level:
            if n not in index:
                raise ConfigError(f"level marker {n!r} is not tracked; tracked: {', '.join(names)}")
            members.append(index[n])
        ptr.append(len(members))
    tasks, _ = resolve_coordinate_tasks(human, coordinate_tasks)
    lock_dof = np.array([human.dof_index(c) + 1 for c in tasks], dtype=np.int64)
    lock_value = np.array([v for v, _ in tasks.values()], dtype=float)
    dof_ptr, dof_markers = dof_marker_table(human, names, {names[i] for i in members})
    return ControlProblem(
        rigid_fast.flatten(human.model, kin.frame_ids),
        np.array(ptr, dtype=np.int64),
        np.array(members, dtype=np.int64),
        dof_ptr,
        dof_markers,
        lock_dof,
        lock_value,
        np.asarray(human.model.lowerPositionLimit, dtype=float).copy(),
        np.asarray(human.model.upperPositionLimit, dtype=float).copy(),
        np.asarray(q_posture, dtype=float).copy(),
        np.array([max((weights or {}).get(n, 1.0), 1e-6) for n in names], dtype=float),
    )


@dataclass(frozen=True)
class FrameResult:
    q: FloatArray  # (nq,)
    tracked: FloatArray  # (M, 3) model markers
    dq: FloatArray  # (nv,) joint-error bound (eq. 15) [rad; root translation in m]
    error: FloatArray  # (M,) marker error norms [m], NaN where not tracked


class DirectMarkerController:
    """Online direct marker control: one capture frame in, one configuration out.

    Args:
        human: model with ``names`` attached.
        names: the M tracked markers (columns of every frame passed to :meth:`step`).
        levels: priority levels (marker names), highest first.
        coordinate_tasks: DOFs held at a value (highest priority).
        q_init: (nq,) initial configuration (at rest), e.g. IK of the first frame.
        rate_hz: capture rate.
        q_posture: (nq,) posture target (default: ``q_init``).
        weights: marker -> weight within its level (rows scaled by √w; default 1).
    """

    def __init__(
        self,
        human: HumanModel,
        names: Sequence[str],
        levels: Sequence[Sequence[str]],
        coordinate_tasks: Mapping[str, tuple[float, float]],
        q_init: FloatArray,
        rate_hz: float,
        q_posture: FloatArray | None = None,
        params: OSCParams | None = None,
        weights: Mapping[str, float] | None = None,
    ) -> None:
        if not (np.isfinite(rate_hz) and rate_hz > 0):
            raise ConfigError(f"rate_hz: expected a positive frame rate, got {rate_hz}")
        self.params = params or OSCParams()
        self.human = human
        self.names = tuple(names)
        self.rate_hz = float(rate_hz)
        q0 = np.asarray(q_init, dtype=float).copy()
        self.problem = control_problem(
            human, names, levels, coordinate_tasks, q0 if q_posture is None else q_posture, weights
        )
        self.gains = self.params.gains(rate_hz)
        self.q = q0
        self.v = np.zeros(human.nv)
        self._history: list[FloatArray] = []
        if self.params.backend == "reference":
            from mocapkit.markers.osc_reference import ReferenceStepper

            self._reference: ReferenceStepper | None = ReferenceStepper(human, names, self.problem)
        else:
            self._reference = None

    def step(self, x: FloatArray) -> FrameResult:
        """Track one frame of marker positions (M, 3) [m] (NaN rows: not visible)."""
        x1 = np.ascontiguousarray(x, dtype=float)
        if x1.shape != (len(self.names), 3):
            raise DataError(f"x: expected shape ({len(self.names)}, 3), got {x1.shape}")
        dt = 1.0 / self.rate_hz
        hist = self._history
        if not hist:
            x0, xd, xdd = x1, np.zeros_like(x1), np.zeros_like(x1)
        else:
            window = np.stack([*hist[-2:], x1])  # the target at t_{f-1} needs x_f
            xd_all, xdd_all = target_derivatives(window, self.rate_hz)
            x0, xd, xdd = window[-2], xd_all[-2], xdd_all[-2]
        fm, pb = self.problem.flat, self.problem
        args = (
            self.q, self.v, x0, x1, xd, xdd, pb.row_weight, pb.level_ptr, pb.level_markers,
            pb.dof_ptr, pb.dof_markers, pb.lock_dof, pb.lock_value, pb.lower, pb.upper,
            pb.q_posture, self.gains, dt, self.params.substeps,
        )  # fmt: skip
        if self._reference is not None:
            q, v, P, dq, err = self._reference.frame(*args)
        else:
            q, v, P, dq, err = osc_frame(
                fm.parent, fm.R0, fm.p0, fm.axis, fm.mass, fm.com, fm.inertia, fm.gravity,
                fm.marker_joint, fm.marker_offset, *args,
            )  # fmt: skip
        if not np.isfinite(q).all():
            raise DataError(
                "direct marker control diverged (non-finite state); lower kappa or add substeps"
            )
        self.q, self.v = q, v
        self._history = [*hist[-1:], x1]
        return FrameResult(q, P, dq, err)


def target_derivatives(X: FloatArray, rate_hz: float) -> tuple[FloatArray, FloatArray]:
    """Target velocity and acceleration at every frame (N, M, 3): central differences
    (one-sided velocity and zero acceleration at the ends or next to a gap)."""
    n = X.shape[0]
    V = np.zeros_like(X)
    A = np.zeros_like(X)
    if n < 2:
        return V, A
    T = 1.0 / rate_hz
    with np.errstate(invalid="ignore"):
        fwd = np.full_like(X, np.nan)
        fwd[:-1] = (X[1:] - X[:-1]) / T
        bwd = np.full_like(X, np.nan)
        bwd[1:] = (X[1:] - X[:-1]) / T
        central = 0.5 * (fwd + bwd)
        acc = (fwd - bwd) / T
    V = np.where(np.isfinite(central), central, np.where(np.isfinite(fwd), fwd, bwd))
    V = np.where(np.isfinite(V), V, 0.0)
    A = np.where(np.isfinite(acc), acc, 0.0)
    return V, A


def reconstruct_offline(
    human: HumanModel,
    names: Sequence[str],
    X: FloatArray,
    rate_hz: float,
    levels: Sequence[Sequence[str]],
    coordinate_tasks: Mapping[str, tuple[float, float]],
    q_init: FloatArray,
    q_posture: FloatArray | None = None,
    params: OSCParams | None = None,
    weights: Mapping[str, float] | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Whole trial X (N, M, 3): returns Q (N, nq), tracked markers (N, M, 3), ΔQ (N, nv)
    and marker errors (N, M). Frame 0 starts at ``q_init`` at rest. The kernel runs in
    blocks of :data:`BLOCK_FRAMES` (the same numbers as one call); ``progress(done,
    total)`` is called after each."""
    p = params or OSCParams()
    X = np.ascontiguousarray(X, dtype=float)
    if X.ndim != 3 or X.shape[1:] != (len(names), 3):
        raise DataError(f"X: expected shape (N, {len(names)}, 3), got {X.shape}")
    q0 = np.asarray(q_init, dtype=float)
    if p.backend == "reference":
        ctrl = DirectMarkerController(
            human, names, levels, coordinate_tasks, q0, rate_hz, q_posture, p, weights
        )
        frames = [ctrl.step(x) for x in X]
        return (
            np.array([f.q for f in frames]),
            np.array([f.tracked for f in frames]),
            np.array([f.dq for f in frames]),
            np.array([f.error for f in frames]),
        )
    tracker = OfflineTracker(
        human, names, levels, coordinate_tasks, q0, rate_hz, q_posture, p, weights
    )
    Xd, Xdd = target_derivatives(X, rate_hz)
    N = X.shape[0]
    parts: list[tuple[FloatArray, FloatArray, FloatArray, FloatArray]] = []
    for a in range(0, N, BLOCK_FRAMES):
        b = min(N, a + BLOCK_FRAMES)
        lo_f = a - 1 if a > 0 else 0  # a block repeats the previous block's last frame
        parts.append(tracker.run(X[lo_f:b], Xd[lo_f:b], Xdd[lo_f:b], continues=a > 0))
        if progress is not None:
            progress(b, N)
    Q, P, DQ, E = (np.concatenate([part[k] for part in parts]) for k in range(4))
    return Q, P, DQ, E


class OfflineTracker:
    """Direct marker control over a trial given piece by piece (:func:`reconstruct_offline`
    and the streamed reconstruction of :mod:`mocapkit.markers.streamed`): the state (q, v)
    is carried from one piece to the next, so any cut gives the numbers of one call. Frame
    0 starts at ``q_init`` at rest."""

    def __init__(
        self,
        human: HumanModel,
        names: Sequence[str],
        levels: Sequence[Sequence[str]],
        coordinate_tasks: Mapping[str, tuple[float, float]],
        q_init: FloatArray,
        rate_hz: float,
        q_posture: FloatArray | None = None,
        params: OSCParams | None = None,
        weights: Mapping[str, float] | None = None,
    ) -> None:
        self.params = params or OSCParams()
        if self.params.backend != "fast":
            raise ConfigError("OfflineTracker runs the fast backend only")
        q0 = np.asarray(q_init, dtype=float)
        self.problem = control_problem(
            human, names, levels, coordinate_tasks, q0 if q_posture is None else q_posture,
            weights,
        )  # fmt: skip
        self.rate_hz = float(rate_hz)
        self.gains = self.params.gains(rate_hz)
        self.q, self.v = q0, np.zeros(human.nv)
        self.frames = 0

    def run(
        self, X: FloatArray, Xd: FloatArray, Xdd: FloatArray, continues: bool
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """The next frames: X, Xd, Xdd (n, M, 3) the markers and their derivatives
        (:func:`target_derivatives` over the whole trial), preceded by the previous piece's
        last frame when ``continues``; returns Q, tracked markers, ΔQ and marker errors of
        the new frames."""
        pb, fm, p = self.problem, self.problem.flat, self.params
        Qb, Pb, DQb, Eb, v = osc_trial(
            fm.parent, fm.R0, fm.p0, fm.axis, fm.mass, fm.com, fm.inertia, fm.gravity,
            fm.marker_joint, fm.marker_offset, self.q, self.v,
            np.ascontiguousarray(X, dtype=float), np.ascontiguousarray(Xd, dtype=float),
            np.ascontiguousarray(Xdd, dtype=float),
            pb.row_weight, pb.level_ptr, pb.level_markers, pb.dof_ptr, pb.dof_markers,
            pb.lock_dof, pb.lock_value, pb.lower, pb.upper, pb.q_posture, self.gains,
            1.0 / self.rate_hz, p.substeps, 1 if continues else 0,
        )  # fmt: skip
        bad = np.flatnonzero(~np.isfinite(Qb).all(axis=1))
        if bad.size:
            raise DataError(
                f"direct marker control diverged at frame {self.frames + int(bad[0])}; lower "
                "kappa or add substeps"
            )
        self.q, self.v = Qb[-1], v
        self.frames += len(Qb)
        return Qb, Pb, DQb, Eb
