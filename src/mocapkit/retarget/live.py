"""Retargeting frame by frame, as a live suit streams: body joint angles in, robot
configuration out, one QP step per frame (the same targets and QP as offline).

``LiveRetargeter(robot).update(coordinates, t)`` takes one frame of joint angles on
OpenSim's coordinate names (what ``body.kinematics.BodyStream`` gives) and returns the
robot's configuration (nq,). The first frame fixes the heading alignment; an IMU suit has
no positions, so the pelvis stays where it starts. Feet: in contact while the foot is
within 3 cm of the lower foot (heights from the skeleton), so the stance foot is held.
Self-collisions: the offline guard (``solver`` docstring) on every frame, unless
``guard=False``.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.retarget.collisions import SelfCollision
from mocapkit.retarget.human import FrameSkeleton
from mocapkit.retarget.robot_model import Humanoid, build_humanoid
from mocapkit.retarget.robot_spec import load_robot_spec
from mocapkit.retarget.solver import FrameSolver
from mocapkit.retarget.targets import make_targets

CONTACT_HEIGHT_M = 0.03
LIVE_BISECTIONS = 3  # the guard cuts a colliding step to 1/8 steps (offline 1/64): time


class LiveRetargeter:
    def __init__(
        self, robot: str | Path | Humanoid, rate_hz: float = 100.0, *, guard: bool = True
    ) -> None:
        self.robot = (
            robot if isinstance(robot, Humanoid) else build_humanoid(load_robot_spec(robot))
        )
        # every frame checked on the meshes, a colliding step steered round or stopped short
        self.guard = SelfCollision(self.robot) if guard else None
        spec = self.robot.spec
        self.segments = tuple(sorted({k.segment for k in spec.keypoints}
                                     | {f.segment for f in spec.feet} | {"pelvis"}))  # fmt: skip
        self.feet = [f.segment for f in spec.feet]
        self.skeleton = FrameSkeleton(self.segments)  # from_coordinates, one frame, in numba
        self.dt = 1.0 / rate_hz
        self.start: tuple[FloatArray, FloatArray] | None = None
        self.solver: FrameSolver | None = None
        self.t_last: float | None = None
        self.seconds: list[float] = []  # per-frame compute time

    def update(self, coordinates: Mapping[str, float], t: float) -> FloatArray:
        """One frame of joint angles [rad] -> the robot configuration (nq,)."""
        t0 = time.perf_counter()
        motion = self.skeleton(t, coordinates)
        heights = {f: float(motion.pos[f][0, 2]) for f in self.feet}
        low = min(heights.values()) if heights else 0.0
        contact = {f: np.array([h <= low + CONTACT_HEIGHT_M]) for f, h in heights.items()}
        targets = make_targets(motion, self.robot, start=self.start, contact=contact)
        if self.start is None:
            self.start = targets.start
        if self.solver is None:
            self.solver = FrameSolver(self.robot, targets, guard=self.guard)
            self.solver.bisections = LIVE_BISECTIONS
        else:
            self.solver.targets = targets
        if self.t_last is not None and t > self.t_last:
            self.solver.dt = t - self.t_last
        self.t_last = t
        q = self.solver.step(0)
        self.seconds.append(time.perf_counter() - t0)
        return q
