"""One QP per frame (proxsuite): track the keypoint targets with the robot's joints.

Variables: the step ``dq`` (nv). Cost: weighted position and orientation errors of the
keypoints, linearised (``J dq ~ e``); feet in contact held where they touched down
(weight ``CONTACT_WEIGHT``, flat); a smoothness term ``SMOOTH * |dq - dq_pred|^2`` that
pulls towards the constant-velocity prediction of the frame (the last frame plus the last
frame's step), instead of a post-filter; a small pull to the reference posture.
Constraints: joint position limits and velocity limits as box bounds on ``dq``
(``v_max * dt``), and every sole point at or above the ground (``z + J_z dq >= 0``).
With ``avoid`` (``collisions.SphereAvoidance``), soft rows keep the bodies' spheres apart
(one slack per row, cost ``AVOID_WEIGHT``). Self-collisions are counted afterwards. Two
iterations per frame from the previous frame's solution; the first frame is solved from
the reference posture without the velocity limits (30 iterations, 0.1 rad trust region).
A frame whose QP has no solution is held, and reported.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.retarget.collisions import SphereAvoidance
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
GIVE_WAY_M = (
    0.005  # slack beyond this on a row is reported  # of the velocity limit the steps may use
)


@dataclass
class Solution:
    time: FloatArray
    q: FloatArray  # (N, nq)
    keypoint_pos: dict[str, FloatArray]  # achieved (N, 3)
    sole_pos: dict[str, FloatArray]  # achieved sole point (N, 3)
    solve_seconds: float = 0.0
    warnings: list[str] = field(default_factory=list)
    held_frames: list[int] = field(default_factory=list)


def _log3(r: FloatArray) -> FloatArray:
    import pinocchio as pin

    return np.asarray(pin.log3(r))


class FrameSolver:
    """The per-frame QP (module docstring); ``step(k, targets)`` solves frame k."""

    def __init__(
        self, robot: Humanoid, targets: Targets, avoid: SphereAvoidance | None = None
    ) -> None:
        self.robot = robot
        self.targets = targets
        m = robot.model
        self.nv = int(m.nv)
        self.n_feet = len(robot.spec.feet)
        self.held: list[int] = []  # frames whose QP had no solution (held)
        self.avoid = avoid if avoid is not None and avoid.available else None
        self.relaxed: list[int] = []  # frames where an avoidance row gave way (slack)
        self.q = robot.q_ref.copy()
        self.q_last: FloatArray | None = None
        self.anchors: dict[str, tuple[FloatArray, FloatArray]] = {}
        self.kp = [(k, robot.frame_ids[k.frame]) for k in robot.spec.keypoints]
        self.q_pred = self.q.copy()  # constant-velocity prediction of this frame
        self.foot_ref = {f.segment: robot.ref_pose[f.frame][1] for f in robot.spec.feet}
        self.feet = [(f, robot.frame_ids[f.frame]) for f in robot.spec.feet]
        dt = np.diff(targets.time)
        self.dt = float(np.median(dt)) if dt.size else 0.01

    def _tasks(self, k: int) -> tuple[FloatArray, FloatArray]:
        """Stacked weighted rows (A, b) with cost |A dq - b|^2."""
        import pinocchio as pin

        m, d = self.robot.model, self.robot.data
        lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        rows, rhs = [], []
        t = self.targets
        for kp, fid in self.kp:
            oMf = d.oMf[fid]
            jac = pin.getFrameJacobian(m, d, fid, lwa)
            if kp.position > 0:
                w = np.sqrt(kp.position)
                rows.append(w * jac[:3])
                rhs.append(w * (t.pos[kp.segment][k] - oMf.translation))
            if kp.orientation > 0:
                w = np.sqrt(kp.orientation)
                rows.append(w * jac[3:])
                rhs.append(w * _log3(t.rot[kp.segment][k] @ oMf.rotation.T))
        for foot, fid in self.feet:
            if not t.contact[foot.segment][k]:
                self.anchors.pop(foot.segment, None)
                continue
            oMf = d.oMf[fid]
            if foot.segment not in self.anchors:  # touch-down: hold here, flat
                p = np.array(oMf.translation)
                r = np.array(oMf.rotation)
                self.anchors[foot.segment] = (p, self._flat(r, foot.segment))
            p_a, r_a = self.anchors[foot.segment]
            jac = pin.getFrameJacobian(m, d, fid, lwa)
            w = np.sqrt(CONTACT_WEIGHT)
            rows.append(w * jac)
            rhs.append(w * np.concatenate([p_a - oMf.translation, _log3(r_a @ oMf.rotation.T)]))
        return np.vstack(rows), np.concatenate(rhs)

    def step(self, k: int) -> FloatArray:
        import pinocchio as pin

        m, d = self.robot.model, self.robot.data
        nb = self.robot.n_base_v
        first = self.q_last is None  # the start pose: no velocity limit, solved to rest
        self.k_now = k
        q_start = self.q.copy()
        for _ in range(FIRST_ITERATIONS if first else ITERATIONS):
            pin.computeJointJacobians(m, d, self.q)
            pin.updateFramePlacements(m, d)
            a, b = self._tasks(k)
            h = a.T @ a
            g = -a.T @ b
            h[np.diag_indices(self.nv)] += (0.0 if first else SMOOTH) + POSTURE + DAMPING
            if not first:
                g -= SMOOTH * np.asarray(pin.difference(m, self.q, self.q_pred))
            post = np.asarray(pin.difference(m, self.q, self.robot.q_ref))
            g -= POSTURE * post
            dt = float(self.targets.time[k] - self.targets.time[k - 1]) if k > 0 else self.dt
            lo, hi = self._bounds(nb, None if first else q_start, dt)
            if first:  # a trust region: the linearisation holds only near the current pose
                iv = self.robot.iv
                lo[iv] = np.maximum(lo[iv], -FIRST_STEP_RAD)
                hi[iv] = np.minimum(hi[iv], FIRST_STEP_RAD)
            c, u = self._ground()
            if self.avoid is not None:
                ca, ua = self.avoid.rows(self.q)
                dq = self._solve_with_slack(h, g, c, u, ca, ua, lo, hi)
            else:
                dq = self._solve_qp(h, g, c, u, lo, hi)
            if dq is None:  # not even the joints' bounds and the ground together: hold
                self.held.append(k)
                break
            self.q = np.asarray(pin.integrate(m, self.q, dq))
            iq = self.robot.iq  # the QP meets the box to its tolerance: clip exactly
            self.q[iq] = np.clip(self.q[iq], self.robot.q_min[iq], self.robot.q_max[iq])
        step = (
            np.asarray(pin.difference(m, self.q_last, self.q))
            if self.q_last is not None
            else (np.zeros(self.nv))
        )
        self.q_last = self.q.copy()
        self.q_pred = np.asarray(pin.integrate(m, self.q, step))
        return self.q

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

        qp = proxsuite.proxqp.dense.QP(len(g), 0, len(u), True)
        qp.settings.eps_abs = 1e-6
        qp.settings.verbose = False
        qp.init(h, g, None, None, c, np.full(len(u), -1e20), u, lo, hi)
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
            jz = jac[2] + (np.cross(arm, np.eye(3)[2]) @ jac[3:])
            c[i] = -jz
            u[i] = sole[2]
        return c, u


def solve(robot: Humanoid, targets: Targets, avoid: SphereAvoidance | None = None) -> Solution:
    """Every frame in order (module docstring); with ``avoid``, bodies are kept apart."""
    import time

    import pinocchio as pin

    solver = FrameSolver(robot, targets, avoid)
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
    sol = Solution(targets.time, q_out, kp_pos, sole_pos, time.perf_counter() - t0)
    sol.held_frames = list(solver.held)
    if solver.relaxed:
        sol.warnings.append(
            f"{len(set(solver.relaxed))} frame(s) where collision avoidance gave way (no step "
            f"met it with the limits), first at frame {solver.relaxed[0]}"
        )
    if solver.held:
        sol.warnings.append(
            f"{len(solver.held)} frame(s) held (no joint step met the limits and the ground), "
            f"first at frame {solver.held[0]} (t = {targets.time[solver.held[0]]:.3f} s)"
        )
    return sol
