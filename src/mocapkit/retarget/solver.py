"""One QP per frame (proxsuite): track the keypoint targets with the robot's joints.

Variables: the step ``dq`` (nv). Cost: weighted position and orientation errors of the
keypoints, linearised (``J dq ~ e``); feet in contact held where they touched down
(weight ``CONTACT_WEIGHT``, flat); a smoothness term ``SMOOTH * |dq - dq_pred|^2`` that
pulls towards the constant-velocity prediction of the frame (the last frame plus the last
frame's step), instead of a post-filter; a small pull to the reference posture.
Constraints: joint position limits and velocity limits as box bounds on ``dq``
(``v_max * dt``), and every sole point at or above the ground (``z + J_z dq >= 0``).
With ``avoid`` (``collisions.HullAvoidance``), soft rows keep the bodies' convex hulls apart
(one slack per row, cost ``AVOID_WEIGHT``). Self-collisions are counted afterwards. Two
iterations per frame from the previous frame's solution; the first frame is solved from
the reference posture without the velocity limits (30 iterations, 0.1 rad trust region).
A frame whose QP has no solution is held, and reported.

The collision guard (``guard``, :class:`collisions.SelfCollision`, on by default in
``retarget``): every frame's result is checked on the meshes (~0.3 ms for G1); a step
that makes two bodies intersect is cut back to where they are still apart (bisection from
the last collision-free configuration, so the limits still hold), then one more QP step
with the avoidance rows is tried from there and kept only if it is collision-free.
Frames stopped short are reported. No frame leaves the guard colliding.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.retarget.collisions import HullAvoidance, SelfCollision
from mocapkit.retarget.robot_model import Humanoid
from mocapkit.retarget.targets import Targets, yaw_matrix

CONTACT_WEIGHT = 50.0
SMOOTH = 0.05
POSTURE = 1e-3
DAMPING = 1e-6
ITERATIONS = 2
FIRST_ITERATIONS = 30  # the first frame starts from the reference posture
FIRST_STEP_RAD = 0.1  # per iteration on the first frame
VELOCITY_SHARE = 0.99
AVOID_WEIGHT = 1e4  # cost of a metre of slack on an avoidance row, squared
GIVE_WAY_M = 0.005  # m: slack beyond this on an avoidance row is reported
GUARD_BISECTIONS = 6  # halvings of a colliding step (1/64 of it)
# The first frame's iterations stop once one moves no joint further than this [rad], or
# once the guard has parted bodies FIRST_PARTED times on it: pressed against a body, every
# further iteration collides again and is bisected back on the meshes (G1's start on the
# gait2392 TRC: 29 times, 168 ms of its 0.3 s). (Giving the parted pair avoidance rows from
# the next iteration on was tried: 20 ms there, but Talos then started walking2 in a pose
# that stopped 249 of its frames short.)
FIRST_SETTLED_RAD = 1e-3
# A later frame's second iteration only when its first moved a joint further than this
# [rad]: a frame starts from the last one's solution, and a small step is already there.
# Set while looking at G1 and Talos on the 15-IMU recording and walking2 (0.005 / 0.02
# / always one iteration), which retarget_humanoids also reports: no held-out trials.
SETTLED_RAD = 0.02
FIRST_PARTED = 3
GUARD_ROWS_STEPS = 50


@dataclass
class Solution:
    time: FloatArray
    q: FloatArray  # (N, nq)
    keypoint_pos: dict[str, FloatArray]  # achieved (N, 3)
    sole_pos: dict[str, FloatArray]  # achieved sole point (N, 3)
    solve_seconds: float = 0.0
    warnings: list[str] = field(default_factory=list)
    held_frames: list[int] = field(default_factory=list)
    kept_apart: list[int] = field(default_factory=list)  # steered round a collision
    stopped: list[int] = field(default_factory=list)  # stopped short to keep bodies apart


def _moved(model: Any, q0: FloatArray, q1: FloatArray) -> float:
    """The largest joint (or base coordinate) motion from ``q0`` to ``q1``."""
    import pinocchio as pin

    return float(np.max(np.abs(pin.difference(model, q0, q1)), initial=0.0))


def _log3(r: FloatArray) -> FloatArray:
    import pinocchio as pin

    return np.asarray(pin.log3(r))


class FrameSolver:
    """The per-frame QP (module docstring); ``step(k, targets)`` solves frame k."""

    def __init__(
        self, robot: Humanoid, targets: Targets, avoid: HullAvoidance | None = None,
        guard: SelfCollision | None = None,
    ) -> None:  # fmt: skip
        self.robot = robot
        self.targets = targets
        m = robot.model
        self.nv = int(m.nv)
        self.n_feet = len(robot.spec.feet)
        self.held: list[int] = []  # frames whose QP had no solution (held)
        self.avoid = avoid if avoid is not None and avoid.available else None
        self.relaxed: list[int] = []  # frames where an avoidance row gave way (slack)
        self.guard = guard if guard is not None and guard.available and len(guard.pairs) else None
        self._rows = self.avoid  # avoidance rows for the guard's second try (built lazily)
        self.kept_apart: list[int] = []  # frames the guard steered round a collision
        self._qps: dict[tuple[int, int], Any] = {}  # proxsuite dense QPs by size
        self.n_steps = 0  # frames solved so far
        self.bisections = GUARD_BISECTIONS  # fewer live (each halving is a mesh check)
        self.watched: dict[int, int] = {}  # pair the guard parted -> rows in the QP until
        self.stopped: list[int] = []  # frames the guard stopped short of the targets
        self.q = robot.q_ref.copy()
        self.q_last: FloatArray | None = None
        self.anchors: dict[str, tuple[FloatArray, FloatArray]] = {}
        self.kp = [(k, robot.frame_ids[k.frame]) for k in robot.spec.keypoints]
        self._kp_weights = [(k, fid, np.sqrt(k.position), np.sqrt(k.orientation))
                            for k, fid in self.kp]  # fmt: skip
        self._kp_rows = sum(3 * (k.position > 0) + 3 * (k.orientation > 0) for k, _ in self.kp)
        self.q_pred = self.q.copy()  # constant-velocity prediction of this frame
        self.foot_ref = {f.segment: robot.ref_pose[f.frame][1] for f in robot.spec.feet}
        self.feet = [(f, robot.frame_ids[f.frame]) for f in robot.spec.feet]
        dt = np.diff(targets.time)
        self.dt = float(np.median(dt)) if dt.size else 0.01
        self.offset = 0  # frames before ``targets`` (a piece of a longer recording)
        self.t_last: float | None = None  # the time of the frame solved last
        self.first_time: dict[str, float] = {}  # held / stopped -> time of the first such

    def next_piece(self, targets: Targets, offset: int) -> None:
        """Go on with ``targets``, the frames from ``offset`` on of a longer recording: the
        same steps as on the whole (the frame time across the seam included)."""
        self.targets = targets
        self.offset = offset
        if self.t_last is not None and targets.time.size:
            self.dt = float(targets.time[0]) - self.t_last

    def _record(self, kind: list[int], name: str) -> None:
        """This frame (its index in the whole recording) in ``kind``."""
        kind.append(self.k_now)
        self.first_time.setdefault(name, self.t_now)

    def _tasks(self, k: int) -> tuple[FloatArray, FloatArray]:
        """Stacked weighted rows (A, b) with cost |A dq - b|^2 (written into one array:
        this runs twice a frame and its small allocations were a tenth of the frame)."""
        import pinocchio as pin

        m, d = self.robot.model, self.robot.data
        lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        t = self.targets
        contact = [(f, fid) for f, fid in self.feet if t.contact[f.segment][k]]
        for foot, _ in self.feet:
            if not t.contact[foot.segment][k]:
                self.anchors.pop(foot.segment, None)
        n_rows = self._kp_rows + 6 * len(contact)
        a = np.empty((n_rows, self.nv))
        b = np.empty(n_rows)
        r = 0
        for kp, fid, w_pos, w_rot in self._kp_weights:
            oMf = d.oMf[fid]
            jac = pin.getFrameJacobian(m, d, fid, lwa)
            if w_pos > 0:
                a[r : r + 3] = w_pos * jac[:3]
                b[r : r + 3] = w_pos * (t.pos[kp.segment][k] - oMf.translation)
                r += 3
            if w_rot > 0:
                a[r : r + 3] = w_rot * jac[3:]
                b[r : r + 3] = w_rot * _log3(t.rot[kp.segment][k] @ oMf.rotation.T)
                r += 3
        w = np.sqrt(CONTACT_WEIGHT)
        for foot, fid in contact:
            oMf = d.oMf[fid]
            if foot.segment not in self.anchors:  # touch-down: hold here, flat
                p = np.array(oMf.translation)
                rot = np.array(oMf.rotation)
                self.anchors[foot.segment] = (p, self._flat(rot, foot.segment))
            p_a, r_a = self.anchors[foot.segment]
            a[r : r + 6] = w * pin.getFrameJacobian(m, d, fid, lwa)
            b[r : r + 3] = w * (p_a - oMf.translation)
            b[r + 3 : r + 6] = w * _log3(r_a @ oMf.rotation.T)
            r += 6
        return a, b

    def step(self, k: int) -> FloatArray:
        import pinocchio as pin

        m = self.robot.model
        first = self.q_last is None  # the start pose: no velocity limit, solved to rest
        self.k_now = self.offset + k
        self.t_now = float(self.targets.time[k])
        q_start = self.q.copy()
        self.n_steps += 1
        # pairs the guard had to part lately keep rows in the QP (hard) for a while
        self.watched = {p: t for p, t in self.watched.items() if t >= self.n_steps}
        watched = sorted(self.watched) if self.watched and self.avoid is None else None
        avoid = self._rows if watched else self.avoid
        parted = 0  # the guard's steps on the first frame
        for _ in range(FIRST_ITERATIONS if first else ITERATIONS):
            q_before = self.q.copy()
            dq = self._iteration(k, first, q_start, avoid, hard=bool(watched), pairs=watched)
            if dq is None:  # not even the joints' bounds and the ground together: hold
                self._record(self.held, "held")
                break
            self._advance(dq)
            hit = self._collisions() if first else []
            if hit:  # the start pose is reached through free space
                self._keep_apart(k, first, q_before, q_start, hit)
                parted += 1
            settled = _moved(m, q_before, self.q) < (FIRST_SETTLED_RAD if first else SETTLED_RAD)
            if settled or parted >= FIRST_PARTED:
                break  # at rest, or pressed against a body the guard keeps it from
        hit = [] if first else self._collisions()
        if hit:
            self._keep_apart(k, first, q_start, q_start, hit)
        step = (
            np.asarray(pin.difference(m, self.q_last, self.q))
            if self.q_last is not None
            else (np.zeros(self.nv))
        )
        self.q_last = self.q.copy()
        self.t_last = self.t_now
        self.q_pred = np.asarray(pin.integrate(m, self.q, step))
        return self.q

    def _iteration(
        self, k: int, first: bool, q_start: FloatArray, avoid: HullAvoidance | None,
        hard: bool = False, pairs: list[int] | None = None,
    ) -> FloatArray | None:  # fmt: skip
        """One linearised QP step from ``self.q`` (None: no step meets the constraints);
        ``hard``: the avoidance rows as constraints (soft only if no step meets them);
        ``pairs``: rows for these pairs only."""
        import pinocchio as pin

        m, d = self.robot.model, self.robot.data
        pin.computeJointJacobians(m, d, self.q)
        pin.updateFramePlacements(m, d)
        a, b = self._tasks(k)
        h = a.T @ a
        g = -a.T @ b
        h[np.diag_indices(self.nv)] += (0.0 if first else SMOOTH) + POSTURE + DAMPING
        if not first:
            g -= SMOOTH * np.asarray(pin.difference(m, self.q, self.q_pred))
        g -= POSTURE * np.asarray(pin.difference(m, self.q, self.robot.q_ref))
        dt = float(self.targets.time[k] - self.targets.time[k - 1]) if k > 0 else self.dt
        lo, hi = self._bounds(self.robot.n_base_v, None if first else q_start, dt)
        if first:  # a trust region: the linearisation holds only near the current pose
            iv = self.robot.iv
            lo[iv] = np.maximum(lo[iv], -FIRST_STEP_RAD)
            hi[iv] = np.minimum(hi[iv], FIRST_STEP_RAD)
        c, u = self._ground()
        if avoid is not None:
            ca, ua = avoid.rows(self.q, pairs, d)  # d: this q's placements and Jacobians
            if not len(ua):  # no pair within reach
                return self._solve_qp(h, g, c, u, lo, hi)
            if hard:  # the rows as constraints; soft when no step meets them all
                x = self._solve_qp(h, g, np.vstack([c, ca]), np.concatenate([u, ua]), lo, hi)
                if x is not None:
                    return x
            return self._solve_with_slack(h, g, c, u, ca, ua, lo, hi)
        return self._solve_qp(h, g, c, u, lo, hi)

    def _advance(self, dq: FloatArray) -> None:
        import pinocchio as pin

        self.q = np.asarray(pin.integrate(self.robot.model, self.q, dq))
        iq = self.robot.iq  # the QP meets the box to its tolerance: clip exactly
        self.q[iq] = np.clip(self.q[iq], self.robot.q_min[iq], self.robot.q_max[iq])

    def _collisions(self) -> list[int]:
        """The pairs intersecting in ``self.q`` (all of them: a colliding frame needs the
        list, and a free one tests every candidate either way)."""
        return [] if self.guard is None else self.guard.colliding_pairs(self.q)

    def _keep_apart(
        self, k: int, first: bool, q_free: FloatArray, q_start: FloatArray, hit: list[int]
    ) -> None:
        """``self.q`` collides (pairs ``hit``) and ``q_free`` does not: go as far towards
        ``self.q`` as the bodies allow, then one more step from there with hard avoidance
        rows (pairs in touch move apart: the step slides along the contact), as far as it
        stays apart. A frame that ends short of its step is reported (``stopped``)."""
        assert self.guard is not None
        q_bad = self.q
        self.watched.update({p: self.n_steps + GUARD_ROWS_STEPS for p in hit})
        q_safe = self._last_free(q_free, q_bad)
        self.q = q_safe
        if self._rows is None:
            self._rows = self.avoid or HullAvoidance(self.guard)
        dq = self._iteration(k, first, q_start, self._rows, hard=True)
        if dq is not None:
            self._advance(dq)
            if not self.guard.any_colliding(self.q):
                self.kept_apart.append(self.k_now)
                return
            q_bad = self.q
            hit = self.guard.colliding_pairs(q_bad)
        self._record(self.stopped, "stopped")
        # stop only the limbs between the bodies in touch; the rest (the base, the other
        # limbs) goes on, so the robot is not left behind by the human
        q_limbs = self._limbs_stopped(q_free, q_bad, hit)
        self.q = q_safe if q_limbs is None else q_limbs

    def _limbs_stopped(
        self, q_free: FloatArray, q_bad: FloatArray, hit: list[int]
    ) -> FloatArray | None:
        """The step ``q_free -> q_bad`` made in full except on the joints between the
        colliding bodies (cut by bisection); None when that is not collision-free either."""
        import pinocchio as pin

        assert self.guard is not None
        m = self.robot.model
        mask = np.zeros(self.nv, dtype=bool)
        for j in self.guard.joints_between(hit):
            mask[m.joints[j].idx_v : m.joints[j].idx_v + m.joints[j].nv] = True
        if not mask.any():
            return None
        step = np.asarray(pin.difference(m, q_free, q_bad))
        rest = np.where(mask, 0.0, step)
        q0 = np.asarray(pin.integrate(m, q_free, rest))
        if self.guard.any_colliding(q0):
            return None
        lo, hi = 0.0, 1.0
        for _ in range(self.bisections):
            mid = 0.5 * (lo + hi)
            q_mid = np.asarray(pin.integrate(m, q_free, rest + mid * np.where(mask, step, 0.0)))
            if self.guard.any_colliding(q_mid):
                hi = mid
            else:
                lo = mid
        return np.asarray(pin.integrate(m, q_free, rest + lo * np.where(mask, step, 0.0)))

    def _last_free(self, q_free: FloatArray, q_bad: FloatArray) -> FloatArray:
        """The configuration furthest along ``q_free -> q_bad`` known collision-free
        (bisection, ``self.bisections`` halvings; the limits hold on the way)."""
        import pinocchio as pin

        assert self.guard is not None
        m = self.robot.model
        step = np.asarray(pin.difference(m, q_free, q_bad))
        lo, hi = 0.0, 1.0
        for _ in range(self.bisections):
            mid = 0.5 * (lo + hi)
            if self.guard.any_colliding(np.asarray(pin.integrate(m, q_free, mid * step))):
                hi = mid
            else:
                lo = mid
        return np.asarray(pin.integrate(m, q_free, lo * step))

    def _solve_with_slack(
        self, h: FloatArray, g: FloatArray, c: FloatArray, u: FloatArray, ca: FloatArray,
        ua: FloatArray, lo: FloatArray, hi: FloatArray,
    ) -> FloatArray | None:  # fmt: skip
        """The step with the avoidance rows ``ca dq <= ua`` made soft: one slack per row,
        ``ca dq - s <= ua``, ``s >= 0`` at cost ``AVOID_WEIGHT * s^2`` (always feasible;
        a row that cannot hold with the limits gives way as little as it must)."""
        n, m = self.nv, len(ua)
        h2 = np.zeros((n + m, n + m))
        h2[:n, :n] = h
        h2[n:, n:] = AVOID_WEIGHT * np.eye(m)
        g2 = np.concatenate([g, np.zeros(m)])
        c2 = np.zeros((len(u) + m, n + m))
        c2[: len(u), :n] = c
        c2[len(u) :, :n] = ca
        c2[len(u) :, n:] = -np.eye(m)
        u2 = np.concatenate([u, ua])
        lo2 = np.concatenate([lo, np.zeros(m)])
        hi2 = np.concatenate([hi, np.full(m, 1e20)])
        x = self._solve_qp(h2, g2, c2, u2, lo2, hi2)
        if x is None:
            return None
        if float(np.max(x[n:], initial=0.0)) > GIVE_WAY_M:
            self.relaxed.append(self.k_now)
        return x[:n]

    def _solve_qp(
        self, h: FloatArray, g: FloatArray, c: FloatArray, u: FloatArray, lo: FloatArray,
        hi: FloatArray,
    ) -> FloatArray | None:  # fmt: skip
        """The step, or None when the QP has no solution (the frame is then held)."""
        import proxsuite

        key = (len(g), len(u))
        qp = self._qps.get(key)
        if qp is None:  # one solver per problem size, set up once and updated per step
            qp = proxsuite.proxqp.dense.QP(len(g), 0, len(u), True)
            qp.settings.eps_abs = 1e-6
            qp.settings.verbose = False
            qp.init(h, g, None, None, c, np.full(len(u), -1e20), u, lo, hi)
            self._qps[key] = qp
        else:
            qp.update(h, g, None, None, c, np.full(len(u), -1e20), u, lo, hi)
        qp.solve()
        x = np.asarray(qp.results.x)
        if qp.results.info.status == proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED and (
            np.isfinite(x).all()
        ):
            return x
        return None

    def _flat(self, r: FloatArray, foot: str) -> FloatArray:
        """The foot's reference orientation (flat) turned to the heading of ``r``."""
        r_ref = self.foot_ref[foot]
        yaw = np.arctan2(r[1, 0], r[0, 0]) - np.arctan2(r_ref[1, 0], r_ref[0, 0])
        return yaw_matrix(float(yaw)) @ r_ref

    def _bounds(
        self, nb: int, q_start: FloatArray | None, dt: float
    ) -> tuple[FloatArray, FloatArray]:
        """Box on dq: joint limits, and the velocity limits over the frame time counted from
        the frame's start (``q_start``; None: no velocity limit) over this frame's ``dt``.
        One-DOF joints only (continuous joints have neither)."""
        r = self.robot
        iq, iv = r.iq, r.iv
        q = self.q[iq]
        lo = np.full(self.nv, -1e20)
        hi = np.full(self.nv, 1e20)
        lo[iv] = r.q_min[iq] - q
        hi[iv] = r.q_max[iq] - q
        if q_start is not None:
            vmax = r.v_max[iv] * max(dt, 0.0) * VELOCITY_SHARE
            lo[iv] = np.maximum(lo[iv], q_start[iq] - vmax - q)
            hi[iv] = np.minimum(hi[iv], q_start[iq] + vmax - q)
        lo[iv] = np.minimum(lo[iv], 0.0)  # outside a bound: allowed back, not further
        hi[iv] = np.maximum(hi[iv], 0.0)
        return lo, hi

    def _ground(self) -> tuple[FloatArray, FloatArray]:
        """C dq <= u: -(z + J_z dq) <= 0 for each sole point."""
        import pinocchio as pin

        m, d = self.robot.model, self.robot.data
        c = np.zeros((self.n_feet, self.nv))
        u = np.zeros(self.n_feet)
        for i, (foot, fid) in enumerate(self.feet):
            oMf = d.oMf[fid]
            sole = oMf.translation + oMf.rotation @ foot.sole
            jac = pin.getFrameJacobian(m, d, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            # sole point velocity: v + w x (R s)
            arm = oMf.rotation @ foot.sole
            jz = jac[2] + arm[1] * jac[3] - arm[0] * jac[4]  # + (arm x e_z) . w
            c[i] = -jz
            u[i] = sole[2]
        return c, u


def solve(
    robot: Humanoid, targets: Targets, avoid: HullAvoidance | None = None,
    guard: SelfCollision | None = None,
) -> Solution:  # fmt: skip
    """Every frame in order (module docstring); with ``avoid``, bodies are kept apart by
    rows in every frame's QP; with ``guard``, every frame is checked on the meshes and a
    colliding step is steered round or stopped short (:meth:`FrameSolver._keep_apart`)."""
    solver = FrameSolver(robot, targets, avoid, guard)
    sol = solve_piece(solver)
    finish(solver, sol)
    return sol


def solve_piece(solver: FrameSolver) -> Solution:
    """The frames of ``solver.targets`` in order (a whole recording, or the next piece
    of one after :meth:`FrameSolver.next_piece`): configurations, keypoints and soles."""
    import time

    import pinocchio as pin

    robot, targets = solver.robot, solver.targets
    n = targets.time.size
    q_out = np.empty((n, robot.model.nq))
    kp_pos = {k.segment: np.empty((n, 3)) for k in robot.spec.keypoints}
    sole_pos = {f.segment: np.empty((n, 3)) for f in robot.spec.feet}
    t0 = time.perf_counter()
    for k in range(n):
        q = solver.step(k)
        q_out[k] = q
        pin.framesForwardKinematics(robot.model, robot.data, q)
        for kp in robot.spec.keypoints:
            kp_pos[kp.segment][k] = robot.data.oMf[robot.frame_ids[kp.frame]].translation
        for f in robot.spec.feet:
            m = robot.data.oMf[robot.frame_ids[f.frame]]
            sole_pos[f.segment][k] = m.translation + m.rotation @ f.sole
    return Solution(targets.time, q_out, kp_pos, sole_pos, time.perf_counter() - t0)


def finish(solver: FrameSolver, sol: Solution) -> None:
    """The solver's frame lists and warnings (the whole recording's) into ``sol``."""
    sol.held_frames = list(solver.held)
    sol.kept_apart = sorted(set(solver.kept_apart))
    sol.stopped = sorted(set(solver.stopped))
    if solver.relaxed:
        sol.warnings.append(
            f"{len(set(solver.relaxed))} frame(s) where collision avoidance gave way (no step "
            f"met it with the limits), first at frame {solver.relaxed[0]}"
        )
    if sol.stopped:
        sol.warnings.append(
            f"{len(sol.stopped)} frame(s) where the robot stopped short of the human's pose "
            f"to keep its bodies apart, first at frame {sol.stopped[0]} (t = "
            f"{solver.first_time['stopped']:.3f} s): the keypoint errors there are larger"
        )
    if solver.held:
        sol.warnings.append(
            f"{len(solver.held)} frame(s) held (no joint step met the limits and the ground), "
            f"first at frame {solver.held[0]} (t = {solver.first_time['held']:.3f} s)"
        )
