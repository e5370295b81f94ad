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
from typing import Any

import numpy as np

from mocapkit.retarget.collisions import SelfCollision
from mocapkit.retarget.robot_model import Humanoid
from mocapkit.retarget.solver import Solution
from mocapkit.retarget.targets import Targets

REPORTED = ("pelvis", "head", "hand_r", "hand_l", "foot_r", "foot_l")


def evaluate(
    robot: Humanoid, targets: Targets, sol: Solution, collisions: SelfCollision | None = None
) -> dict[str, Any]:
    import pinocchio as pin

    kp = {}
    for seg in REPORTED:
        if seg in sol.keypoint_pos:
            e = np.linalg.norm(sol.keypoint_pos[seg] - targets.pos[seg], axis=1)
            kp[seg] = round(float(1000.0 * np.sqrt(np.mean(e**2))), 1)
    skate, depth, below = [], 0.0, 0
    for foot, sole in sol.sole_pos.items():
        c = targets.contact[foot]
        both = c[1:] & c[:-1]
        step = np.linalg.norm(np.diff(sole[:, :2], axis=0), axis=1)
        skate.extend((1000.0 * step[both]).tolist())
        depth = max(depth, float(-1000.0 * sole[:, 2].min()))
    lowest = (
        np.min(np.stack([s[:, 2] for s in sol.sole_pos.values()]), axis=0)
        if (sol.sole_pos)
        else np.zeros(0)
    )
    below = int(np.sum(lowest < -1e-3))
    q = sol.q[:, robot.iq]
    lo, hi = robot.q_min[robot.iq], robot.q_max[robot.iq]
    pos_viol = int(np.sum((q < lo - 1e-6) | (q > hi + 1e-6)))
    vel_viol = 0
    if len(sol.time) > 1:
        dt = np.diff(sol.time)[:, None]
        v = np.array([pin.difference(robot.model, a, b) for a, b in zip(sol.q[:-1], sol.q[1:],
                                                                        strict=True)])  # fmt: skip
        v = np.abs(v[:, robot.iv]) / dt
        vel_viol = int(np.sum(v > robot.v_max[robot.iv] * 1.01))
    coll_frames = 0
    pairs: Counter[tuple[str, str]] = Counter()
    if collisions is not None and collisions.available:
        for qk in sol.q:
            hit = collisions.colliding(qk)
            coll_frames += bool(hit)
            pairs.update(hit)
    return {
        "keypoint_rmse_mm": {**kp, "mean": round(float(np.mean(list(kp.values()))), 1)}
        if kp
        else {},
        "foot_skate_mm": round(float(np.mean(skate)), 3) if skate else 0.0,
        "contact_frames": {f: int(c.sum()) for f, c in targets.contact.items()},
        "ground_penetration": {"frames": below, "deepest_mm": round(max(depth, 0.0), 1)},
        "limit_violations": {"position": pos_viol, "velocity": vel_viol},
        "collisions": {
            "frames": coll_frames,
            "checked": bool(collisions is not None and collisions.available),
            "pairs": [f"{a} / {b}: {n}" for (a, b), n in pairs.most_common(3)],
        },
        "held_frames": len(sol.held_frames),
    }
