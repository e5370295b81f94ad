"""How faithful and how physical a retargeted motion is (issue 14's figures).

- ``keypoint_rmse_mm``: per keypoint (pelvis, head, hands, feet when the robot maps
  them), RMS distance of the robot frame to its scaled target; ``mean`` over them.
- ``foot_skate_mm``: mean horizontal travel of a sole per frame while its human foot is
  in contact (both frames in contact).
- ``ground_penetration``: frames with a sole more than 1 mm below the ground, and the
  deepest [mm].
- ``limit_violations``: joint samples outside the URDF's position limits, and joint
  steps faster than its velocity limits (more than 1 % over).
- ``collisions``: frames with at least one pair of the robot's bodies intersecting, and
  the pairs seen most.
"""

from __future__ import annotations

from collections import Counter
from itertools import pairwise
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.retarget.collisions import SelfCollision
from mocapkit.retarget.robot_model import Humanoid
from mocapkit.retarget.solver import Solution
from mocapkit.retarget.targets import Targets

REPORTED = ("pelvis", "head", "hand_r", "hand_l", "foot_r", "foot_l")


def evaluate(
    robot: Humanoid, targets: Targets, sol: Solution, collisions: SelfCollision | None = None
) -> dict[str, Any]:
    """The figures (module docstring) of a whole retargeted recording."""
    tally = FigureTally(robot, collisions)
    tally.add(targets, sol)
    return tally.figures(len(sol.held_frames))


class FigureTally:
    """The figures summed piece by piece over a recording (pieces in order; the same
    figures as :func:`evaluate` on the whole, to the last digit but for the sums' order)."""

    def __init__(self, robot: Humanoid, collisions: SelfCollision | None = None) -> None:
        self.robot = robot
        self.collisions = collisions if collisions is not None and collisions.available else None
        self.kp_sq: dict[str, float] = {}
        self.frames = 0
        self.skate_sum, self.skate_n = 0.0, 0
        self.depth, self.below = 0.0, 0
        self.contact_frames: dict[str, int] = {}
        self.pos_viol = self.vel_viol = self.coll_frames = 0
        self.pairs: Counter[tuple[str, str]] = Counter()
        self.last: tuple[float, FloatArray, dict[str, tuple[bool, FloatArray]]] | None = None

    def add(self, targets: Targets, sol: Solution) -> None:
        """The next piece of frames."""
        import pinocchio as pin

        robot, n = self.robot, sol.time.size
        if n == 0:
            return
        for seg in REPORTED:
            if seg in sol.keypoint_pos:
                e = np.linalg.norm(sol.keypoint_pos[seg] - targets.pos[seg], axis=1)
                self.kp_sq[seg] = self.kp_sq.get(seg, 0.0) + float(np.sum(e**2))
        self.frames += n
        last_feet = self.last[2] if self.last is not None else {}
        for foot, sole in sol.sole_pos.items():
            c = targets.contact[foot]
            if foot in last_feet:  # the step across the seam with the last piece
                c = np.concatenate([[last_feet[foot][0]], c])
                sole = np.vstack([last_feet[foot][1], sole])
            both = c[1:] & c[:-1]
            step = np.linalg.norm(np.diff(sole[:, :2], axis=0), axis=1)
            self.skate_sum += float(np.sum(1000.0 * step[both]))
            self.skate_n += int(both.sum())
            self.depth = max(self.depth, float(-1000.0 * sol.sole_pos[foot][:, 2].min()))
        if sol.sole_pos:
            lowest = np.min(np.stack([s[:, 2] for s in sol.sole_pos.values()]), axis=0)
            self.below += int(np.sum(lowest < -1e-3))
        for f, c in targets.contact.items():
            self.contact_frames[f] = self.contact_frames.get(f, 0) + int(c.sum())
        q = sol.q[:, robot.iq]
        lo, hi = robot.q_min[robot.iq], robot.q_max[robot.iq]
        self.pos_viol += int(np.sum((q < lo - 1e-6) | (q > hi + 1e-6)))
        qs, ts = sol.q, sol.time
        if self.last is not None:
            qs = np.vstack([self.last[1], qs])
            ts = np.concatenate([[self.last[0]], ts])
        if len(ts) > 1:
            dt = np.diff(ts)[:, None]
            v = np.array([pin.difference(robot.model, a, b) for a, b in pairwise(qs)])
            v = np.abs(v[:, robot.iv]) / dt
            self.vel_viol += int(np.sum(v > robot.v_max[robot.iv] * 1.01))
        if self.collisions is not None:
            for qk in sol.q:
                hit = self.collisions.colliding(qk)
                self.coll_frames += bool(hit)
                self.pairs.update(hit)
        feet = {f: (bool(targets.contact[f][-1]), s[-1]) for f, s in sol.sole_pos.items()}
        self.last = (float(sol.time[-1]), sol.q[-1].copy(), feet)

    def figures(self, held_frames: int) -> dict[str, Any]:
        """The figures so far (``held_frames``: the solver's count)."""
        kp = {s: round(float(1000.0 * np.sqrt(v / self.frames)), 1) for s, v in self.kp_sq.items()}
        return {
            "keypoint_rmse_mm": {**kp, "mean": round(float(np.mean(list(kp.values()))), 1)}
            if kp
            else {},
            "foot_skate_mm": round(self.skate_sum / self.skate_n, 3) if self.skate_n else 0.0,
            "contact_frames": dict(self.contact_frames),
            "ground_penetration": {
                "frames": self.below,
                "deepest_mm": round(max(self.depth, 0.0), 1),
            },
            "limit_violations": {"position": self.pos_viol, "velocity": self.vel_viol},
            "collisions": {
                "frames": self.coll_frames,
                "checked": self.collisions is not None,
                "pairs": [f"{a} / {b}: {n}" for (a, b), n in self.pairs.most_common(3)],
            },
            "held_frames": held_frames,
        }
