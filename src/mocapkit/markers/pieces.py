"""A marker trial reconstructed one piece at a time, each piece's solver state carried
from the piece before (:mod:`mocapkit.markers.streamed`): the same numbers as one run
over the whole trial (:func:`mocapkit.markers.reconstruct.reconstruct`)."""

from __future__ import annotations

import time as _time
from collections.abc import Callable

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.scaling import Subject
from mocapkit.markers.osc import OfflineTracker, target_derivatives
from mocapkit.markers.reconstruct import ReconstructionOptions, TrackingPlan

#: one piece's ``(time, targets, q, P or None, dq, seconds)``
Piece = tuple[FloatArray, FloatArray, FloatArray, FloatArray | None, FloatArray, float]


def piece_solver(
    subject: Subject, plan: TrackingPlan, opts: ReconstructionOptions, q_init: FloatArray,
    rate: float, frames: Callable[[int, int], tuple[FloatArray, FloatArray]], n: int,
) -> Callable[[int, int], Piece]:  # fmt: skip
    """The reconstruction of frames ``a .. b``, its state carried from the piece before:
    ``(time, targets, q, P or None, dq, seconds)``. Direct marker control offline (the
    default: the target's derivatives read one frame either side), online (the controller
    stepped on), or IK (each piece warm-started from the last frame's solution)."""
    human, names = subject.human, plan.names
    if opts.method == "ik":
        from mocapkit.markers.bounds import joint_error_bounds
        from mocapkit.markers.determined import dof_determined
        from mocapkit.markers.ik import solve_ik

        last = [q_init]
        tracked_w = np.where([nm in set(plan.tracked) for nm in names], plan.weights, 0.0)

        def ik(a: int, b: int) -> Piece:
            t, X = frames(a, b)
            t0 = _time.perf_counter()
            sol = solve_ik(human, names, X, plan.weights, last[0], plan.tasks,
                           q_posture=human.neutral(), params=opts.ik, continues=a > 0)  # fmt: skip
            elapsed = _time.perf_counter() - t0
            last[0] = sol.q[-1]
            _, det = dof_determined(human, names, plan.tracked, X, held=plan.tasks)
            dq = joint_error_bounds(human, names, sol.q, X, tracked_w, ~det, list(plan.tasks))
            return t, X, sol.q, None, dq, elapsed

        return ik
    wmap = dict(zip(names, plan.weights.tolist(), strict=True))
    if opts.mode == "online":
        from mocapkit.markers.osc import DirectMarkerController

        ctrl = DirectMarkerController(human, names, plan.levels, plan.tasks, q_init, rate,
                                      human.neutral(), opts.osc, wmap)  # fmt: skip

        def online(a: int, b: int) -> Piece:
            t, X = frames(a, b)
            t0 = _time.perf_counter()
            steps = [ctrl.step(x) for x in X]
            elapsed = _time.perf_counter() - t0
            q = np.array([f.q for f in steps])
            return t, X, q, None, np.array([f.dq for f in steps]), elapsed

        return online
    tracker = OfflineTracker(
        human, names, plan.levels, plan.tasks, q_init, rate, human.neutral(), opts.osc, wmap
    )

    def offline(a: int, b: int) -> Piece:
        lo, hi = max(0, a - 2), min(n, b + 1)  # derivatives at a-1 .. b-1
        t_ext, X_ext = frames(lo, hi)
        Xd, Xdd = target_derivatives(X_ext, rate)
        s0 = a - lo
        start, stop = (s0 - 1 if a > 0 else s0), s0 + (b - a)
        t0 = _time.perf_counter()
        Q, P, DQ, _ = tracker.run(
            X_ext[start:stop], Xd[start:stop], Xdd[start:stop], continues=a > 0
        )
        elapsed = _time.perf_counter() - t0
        return t_ext[s0:stop], X_ext[s0:stop], Q, P, DQ, elapsed

    return offline
