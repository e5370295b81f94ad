"""Self-collisions of a humanoid from its URDF's collision meshes (Pinocchio + coal),
counted on the retargeted motion.

Pairs checked: every pair of collision bodies, less those on the same or neighbouring
links (a joint between them), those already touching in the reference posture (the
meshes of many URDFs overlap at rest) and those touching in 90 % of 30 random postures
within the limits (meshes that overlap whatever the joints do). A bounding-sphere test
first, then coal on the pairs whose spheres overlap (0.3 ms a frame for G1's 571 pairs).

Not done: avoidance in the QP. Distance rows on the meshes cost ~2 ms per pair with coal
(20 frames/s); on convex hulls the distances disagreed with the meshes' (a hull came out
farther than its mesh), so the hull route was dropped until understood.
"""

from __future__ import annotations

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.retarget.robot_model import Humanoid

ALWAYS_SAMPLES = 30
ALWAYS_SHARE = 0.9


class SelfCollision:
    def __init__(self, robot: Humanoid) -> None:
        import pinocchio as pin

        self.robot = robot
        urdf = str(robot.spec.urdf)
        dirs = [urdf.split("share/example-robot-data")[0] + "share"] if "share/" in urdf else []
        dirs.append(str(robot.spec.urdf.parent))
        try:
            gm = pin.buildGeomFromUrdf(robot.model, urdf, pin.GeometryType.COLLISION,
                                       package_dirs=dirs)  # fmt: skip
        except ValueError as exc:  # meshes missing: no collision model
            self.available = False
            self.reason = str(exc)
            return
        self.available = True
        self.reason = ""
        self.gm = gm
        model = robot.model
        objs = gm.geometryObjects
        for o in objs:
            o.geometry.computeLocalAABB()
        self.radius = np.array([float(o.geometry.aabb_radius) for o in objs])
        self.centre = np.array([np.asarray(o.geometry.aabb_center) for o in objs])
        parents = [int(o.parentJoint) for o in objs]
        gm.addAllCollisionPairs()
        data = model.createData()
        gd = gm.createData()
        pin.computeCollisions(model, data, gm, gd, robot.q_ref, False)
        keep = []
        for k, cp in enumerate(gm.collisionPairs):
            j1, j2 = parents[cp.first], parents[cp.second]
            if j1 == j2 or model.parents[j1] == j2 or model.parents[j2] == j1:
                continue
            if gd.collisionResults[k].isCollision():
                continue
            keep.append((cp.first, cp.second))
        gm.removeAllCollisionPairs()
        for a, b in keep:
            gm.addCollisionPair(pin.CollisionPair(a, b))
        self.pairs = np.array(keep, dtype=np.int64).reshape(-1, 2)
        self.gd = gm.createData()
        self.data = model.createData()
        self._drop_always_colliding()

    def _drop_always_colliding(self) -> None:
        """Pairs that intersect in nearly every posture (meshes that overlap whatever the
        joints do, as MoveIt's setup assistant finds them) are not self-collisions."""
        import pinocchio as pin

        r = self.robot
        rng = np.random.default_rng(0)
        hits = np.zeros(len(self.pairs), dtype=int)
        lo, hi = r.q_min[r.iq], r.q_max[r.iq]
        for _ in range(ALWAYS_SAMPLES):
            q = r.q_ref.copy()
            q[r.iq] = rng.uniform(lo, hi)
            pin.forwardKinematics(r.model, self.data, q)
            for k in self._candidates(0.0):
                hits[k] += bool(pin.computeCollision(self.gm, self.gd, int(k)))
        keep = hits < ALWAYS_SHARE * ALWAYS_SAMPLES
        self.always = [(self.gm.geometryObjects[int(a)].name, self.gm.geometryObjects[int(b)].name)
                       for a, b in self.pairs[~keep]]  # fmt: skip
        self.gm.removeAllCollisionPairs()
        for a, b in self.pairs[keep]:
            self.gm.addCollisionPair(pin.CollisionPair(int(a), int(b)))
        self.pairs = self.pairs[keep]
        self.gd = self.gm.createData()

    def _candidates(self, margin: float) -> np.ndarray:
        import pinocchio as pin

        pin.updateGeometryPlacements(self.robot.model, self.data, self.gm, self.gd)
        pl = self.gd.oMg
        c = np.array([pl[i].act(self.centre[i]) for i in range(len(self.radius))])
        a, b = self.pairs[:, 0], self.pairs[:, 1]
        gap = np.linalg.norm(c[a] - c[b], axis=1) - self.radius[a] - self.radius[b]
        close = np.flatnonzero(gap < margin)
        return close[np.argsort(gap[close])]  # the closest first

    def colliding(self, q: FloatArray) -> list[tuple[str, str]]:
        """Pairs of collision bodies that intersect in configuration ``q``."""
        import pinocchio as pin

        if not self.available or not len(self.pairs):
            return []
        pin.forwardKinematics(self.robot.model, self.data, q)
        out = []
        for k in self._candidates(0.0):
            if pin.computeCollision(self.gm, self.gd, int(k)):
                a, b = (int(x) for x in self.pairs[k])
                out.append((self.gm.geometryObjects[a].name, self.gm.geometryObjects[b].name))
        return out
