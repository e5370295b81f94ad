"""Self-collisions of a humanoid from its URDF's collision meshes (Pinocchio + coal),
counted on the retargeted motion.

Pairs checked: every pair of collision bodies, less those on the same link, on
neighbouring links or two joints apart (inside a shoulder, hip, wrist or ankle), those
already touching in the reference posture (the meshes of many URDFs overlap at rest) and
those touching in 90 % of 30 random postures
within the limits (meshes that overlap whatever the joints do). A bounding-sphere test
first, then coal on the pairs whose spheres overlap: their convex hulls (with a 2 mm margin),
and the meshes only where the hulls touch (~0.1 ms a frame for G1's 539 pairs). Where hulls
touch and meshes do not (concave bodies; Romeo's fingers, ~1 mm apart all along), the
meshes' distance is kept with the bodies' relative placement: while one has moved less than
that relative to the other, the meshes are not tested again.

Avoidance (:class:`HullAvoidance`): distance rows between the convex hulls (exact distances
on the meshes cost 0.3-0.9 ms a pair with coal; on the hulls 10-20 us, never farther than
the meshes' on 1,600 random pairs of G1 and Talos).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.retarget.robot_model import Humanoid

ALWAYS_SAMPLES = 30
ALWAYS_SHARE = 0.9
HULL_MARGIN_M = 0.002  # the hull test's margin (numerical slack: a hull contains its mesh)


class SelfCollision:
    def __init__(self, robot: Humanoid) -> None:
        import pinocchio as pin

        self.robot = robot
        # pair -> (B's placement in A's frame, the meshes' distance there less a margin):
        # a pair whose hulls touch and whose meshes were that far apart cannot intersect
        # while B moves less than that relative to A (exact: no collision is missed)
        self._certificates: dict[int, tuple[FloatArray, float]] = {}
        self.certified = 0  # mesh tests a certificate spared
        self._known: dict[bytes, list[int]] = {}  # configuration -> colliding pairs
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
        # each sphere's centre in its joint's frame: the sphere pass reads the joints'
        # placements (one array) instead of every body's (36 Python calls on G1)
        self._centre_in_joint = np.array(
            [np.asarray(o.placement.act(self.centre[i])) for i, o in enumerate(objs)]
        )
        self._parent = np.array(parents, dtype=np.int64)
        gm.addAllCollisionPairs()
        data = model.createData()
        gd = gm.createData()
        pin.computeCollisions(model, data, gm, gd, robot.q_ref, False)
        keep = []
        for k, cp in enumerate(gm.collisionPairs):
            j1, j2 = parents[cp.first], parents[cp.second]
            if _within_two_joints(model, j1, j2):
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
        self._build_hulls()

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
        return self._candidates_placed(margin, self.data)

    def _candidates_placed(self, margin: float, data: Any) -> np.ndarray:
        """Pairs whose bounding spheres come within ``margin`` with the joint placements in
        ``data`` (forward kinematics done), the closest first."""
        return self._close_pairs(self.data, self.pairs, np.arange(len(self.pairs)), margin)

    def _close_pairs(
        self, data: Any, pairs: np.ndarray, index: np.ndarray, margin: float
    ) -> np.ndarray:
        """``index`` (of ``pairs``, rows of ``self.pairs``) whose bounding spheres come within
        ``margin`` with the joint placements in ``data``, the closest first."""
        h = np.array([m.homogeneous for m in data.oMi])[self._parent]
        c = np.einsum("kij,kj->ki", h[:, :3, :3], self._centre_in_joint) + h[:, :3, 3]
        a, b = pairs[:, 0], pairs[:, 1]
        d = c.take(a, 0) - c.take(b, 0)  # (take: ~3x faster than fancy indexing here)
        reach = self.radius.take(a) + self.radius.take(b) + margin
        d2 = np.einsum("ij,ij->i", d, d)
        close = np.flatnonzero(d2 < reach * reach)
        gap = np.sqrt(d2[close]) - reach[close]
        return index[close[np.argsort(gap)]]  # the closest first

    def _build_hulls(self) -> None:
        """The same bodies as convex hulls (Qhull, through coal), tested with a 2 mm margin
        before the meshes: a hull contains its mesh, so hulls apart means meshes apart, at
        ~3.5 us a pair instead of ~25 (G1)."""
        import pinocchio as pin

        hm = self.gm.copy()
        for o in hm.geometryObjects:
            g = o.geometry
            if hasattr(g, "buildConvexHull"):
                g.buildConvexHull(True, "Qt")
                o.geometry = g.convex
        hm.removeAllCollisionPairs()
        for a, b in self.pairs:
            hm.addCollisionPair(pin.CollisionPair(int(a), int(b)))
        self.hm = hm
        self.hd = hm.createData()
        for req in self.hd.collisionRequests:
            req.security_margin = HULL_MARGIN_M

    def _pair_collides(self, k: int, certify: bool = True) -> bool:
        """Pair ``k`` intersects (placements updated): the hulls first, then a distance
        certificate, then the meshes; ``certify``: where the meshes are apart, measure how
        far (a certificate for the next frames; not while bisecting, where each
        configuration is visited once and the distance would cost twice the test)."""
        import pinocchio as pin

        if not pin.computeCollision(self.hm, self.hd, k):
            return False
        a, b = int(self.pairs[k, 0]), int(self.pairs[k, 1])
        rel = self._relative(a, b)
        cert = self._certificates.get(k)
        if cert is not None and _moved_by(cert[0], rel, self.centre[b], self.radius[b]) < cert[1]:
            self.certified += 1
            return False  # B has not moved, relative to A, as far as the meshes were apart
        if pin.computeCollision(self.gm, self.gd, k):
            self._certificates.pop(k, None)
            return True
        if not certify:
            return False
        # hulls touching, meshes apart (concave bodies, a hand's fingers): how far apart,
        # so that the next frames need not test the meshes while the bodies barely move
        d = float(pin.computeDistance(self.gm, self.gd, k).min_distance)
        if d > CERTIFICATE_MIN_M:
            self._certificates[k] = (rel, d - CERTIFICATE_MIN_M)
        return False

    def _relative(self, a: int, b: int) -> FloatArray:
        """Body b's placement in body a's frame (4, 4), mesh placements updated."""
        ma = self.gd.oMg[a]
        return np.asarray((ma.actInv(self.gd.oMg[b])).homogeneous)

    def _hits(self, q: FloatArray, certify: bool = True) -> Iterator[int]:
        """Indices (into ``pairs``) of the pairs that intersect in ``q``, the closest
        first, found one by one (a caller may stop at the first)."""
        import pinocchio as pin

        if not self.available or not len(self.pairs):
            return
        pin.forwardKinematics(self.robot.model, self.data, q)
        cand = self._candidates(0.0)
        pin.updateGeometryPlacements(self.robot.model, self.data, self.hm, self.hd)
        yield from (int(k) for k in cand if self._pair_collides(int(k), certify))

    def any_colliding(self, q: FloatArray) -> bool:
        """Whether any checked pair intersects in ``q`` (stops at the first; the guard's
        bisections: uses the distance certificates, makes none)."""
        key = np.ascontiguousarray(q, dtype=np.float64).tobytes()
        known = self._known.get(key)
        if known is not None:
            return bool(known)
        hit = next(self._hits(q, certify=False), None)
        if hit is None:  # every candidate tested: the complete answer
            self._remember(key, [])
        return hit is not None

    def colliding_pairs(self, q: FloatArray) -> list[int]:
        """Indices (into ``pairs``) of the pairs that intersect in ``q``."""
        key = np.ascontiguousarray(q, dtype=np.float64).tobytes()
        known = self._known.get(key)
        if known is None:
            known = list(self._hits(q))
            self._remember(key, known)
        return list(known)

    def _remember(self, key: bytes, hits: list[int]) -> None:
        """The answer for one configuration (the same bytes, the same answer): the
        solver's checks of each frame's final configuration answer the counting of the
        collisions afterwards (``metrics.evaluate``), which otherwise doubled the cost."""
        if len(self._known) >= KNOWN_MAX:
            self._known.clear()
        self._known[key] = hits

    def joints_between(self, pairs: list[int]) -> set[int]:
        """The joints on the kinematic paths between the bodies of ``pairs`` (not their
        common ancestors: moving those moves both bodies together)."""
        model = self.robot.model
        objs = self.gm.geometryObjects
        out: set[int] = set()
        for k in pairs:
            a, b = (int(objs[int(x)].parentJoint) for x in self.pairs[k])
            out |= set(model.supports[a]) ^ set(model.supports[b])
        return out

    def colliding(self, q: FloatArray) -> list[tuple[str, str]]:
        """Pairs of collision bodies (their names) that intersect in configuration ``q``."""
        objs = self.gm.geometryObjects
        return [(objs[int(self.pairs[k][0])].name, objs[int(self.pairs[k][1])].name)
                for k in self.colliding_pairs(q)]  # fmt: skip


# distance certificates below this are not kept (the meshes nearly touch: test them)
CERTIFICATE_MIN_M = 1e-4
# configurations whose answer is kept (~0.5 KB each) before the memory is cleared
KNOWN_MAX = 100_000


def _moved_by(rel0: FloatArray, rel1: FloatArray, centre: FloatArray, radius: float) -> float:
    """An upper bound [m] on how far any point of body B (within ``radius`` of ``centre``,
    its own frame) moved relative to body A between placements ``rel0`` and ``rel1``
    (B in A's frame, (4, 4)): the centre's displacement plus ``|R1 - R0| radius``, where
    the spectral norm of the rotation difference is ``2 sin(theta / 2)``."""
    r0, r1 = rel0[:3, :3], rel1[:3, :3]
    d = r1 @ centre + rel1[:3, 3] - r0 @ centre - rel0[:3, 3]
    trace = float(np.einsum("ij,ij->", r0, r1))  # tr(R0^T R1)
    return float(np.sqrt(d @ d)) + float(np.sqrt(max(3.0 - trace, 0.0))) * radius


def _within_two_joints(model: object, j1: int, j2: int) -> bool:
    """Bodies on the same link, on neighbouring links, or two joints apart along a chain
    (the small links inside a 2- or 3-DOF shoulder, hip, wrist or ankle): their joint
    limits keep them apart, and their meshes' contact within those limits is the
    mechanism's, not a self-collision."""
    par = model.parents  # type: ignore[attr-defined]
    return j1 == j2 or par[j1] == j2 or par[j2] == j1 or par[par[j1]] == j2 or par[par[j2]] == j1


MIN_DISTANCE = 0.005  # m kept between two bodies' hulls (or their distance at rest)
ACTIVE_DISTANCE = 0.03  # m: pairs closer than this (beyond their floor) get a row
MAX_ROWS = 10


class HullAvoidance:
    """Avoidance rows for the QP from the bodies' convex hulls (:class:`SelfCollision`'s;
    a hull contains its mesh, so hulls apart means meshes apart). For every checked pair
    whose hulls are within ``ACTIVE_DISTANCE`` of their floor, one row on the linearised
    distance between the hulls' nearest points (coal's GJK/EPA, ~10-20 us a pair):
    ``d + n . (v_b - v_a) dt >= floor``, the floor being ``min(MIN_DISTANCE, the hulls'
    distance at rest)``. Hulls of concave bodies side by side may overlap at rest although
    their meshes do not: those pairs are measured on the meshes (0.3-0.9 ms a pair)."""

    def __init__(self, coll: SelfCollision) -> None:
        import pinocchio as pin

        self.coll = coll
        self.available = coll.available and len(coll.pairs) > 0
        if not self.available:
            return
        robot = coll.robot
        self.data = robot.model.createData()
        self.hd = coll.hm.createData()
        pin.forwardKinematics(robot.model, self.data, robot.q_ref)
        pin.updateGeometryPlacements(robot.model, self.data, coll.gm, coll.gd)
        pin.updateGeometryPlacements(robot.model, self.data, coll.hm, self.hd)
        self.floor = np.full(len(coll.pairs), MIN_DISTANCE)
        self.on_mesh = np.zeros(len(coll.pairs), dtype=bool)
        # only these can be nearer than the floor at rest
        for k in coll._candidates_placed(MIN_DISTANCE, self.data):
            d_ref = pin.computeDistance(coll.hm, self.hd, int(k)).min_distance
            if d_ref < 0.0:  # hulls overlapping at rest (concave bodies side by side) say
                self.on_mesh[k] = True  # nothing of the meshes: measure those on the meshes
                d_ref = pin.computeDistance(coll.gm, coll.gd, int(k)).min_distance
            self.floor[k] = min(MIN_DISTANCE, d_ref)
        self.parent = [int(o.parentJoint) for o in coll.hm.geometryObjects]

    def rows(
        self, q: FloatArray, pairs: list[int] | None = None, data: Any = None
    ) -> tuple[FloatArray, FloatArray]:
        """(C (m, nv), u (m,)) with ``C dq <= u``, one row for each of the at most
        ``MAX_ROWS`` nearest pairs within reach (m may be 0). A pair nearer than its floor
        must move apart (by at most ``RECOVER_PER_STEP`` a step). ``pairs``: only these
        (indices into the checked pairs), else every pair near enough. ``data``: the
        caller's Pinocchio data with the joint placements and Jacobians of ``q`` already
        computed (the QP's), else they are computed here."""
        import pinocchio as pin

        coll = self.coll
        robot = coll.robot
        nv = robot.model.nv
        if not self.available:
            return np.zeros((0, nv)), np.zeros(0)
        d = self.data if data is None else data
        if data is None:
            pin.computeJointJacobians(robot.model, d, q)  # and the joint placements
        reach = ACTIVE_DISTANCE + MIN_DISTANCE  # no row beyond: slack >= sphere gap - floor
        cand = (coll._candidates_placed(reach, d) if pairs is None
                else np.asarray(pairs, dtype=np.int64))  # fmt: skip
        if not len(cand):
            return np.zeros((0, nv)), np.zeros(0)
        if self.on_mesh[cand].any():
            pin.updateGeometryPlacements(robot.model, d, coll.gm, coll.gd)
        pin.updateGeometryPlacements(robot.model, d, coll.hm, self.hd)
        near = []
        for k in cand:
            on_mesh = bool(self.on_mesh[k])
            res = pin.computeDistance(coll.gm if on_mesh else coll.hm,
                                      coll.gd if on_mesh else self.hd, int(k))  # fmt: skip
            slack = res.min_distance - self.floor[k]
            if slack < ACTIVE_DISTANCE:
                near.append((slack, int(k), res))
        near.sort(key=lambda x: x[0])
        lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        objs = coll.pairs
        c_out, u_out = [], []
        for slack, k, res in near[:MAX_ROWS]:
            a, b = (int(x) for x in objs[k])
            pa = np.asarray(res.getNearestPoint1())
            pb = np.asarray(res.getNearestPoint2())
            # from body a to body b: the nearest points' direction while apart (coal leaves
            # the normal unset for meshes), the contact normal once hulls overlap
            n = pb - pa if res.min_distance > 1e-6 else np.asarray(res.normal, dtype=float)
            if not np.isfinite(n).all() or float(np.linalg.norm(n)) < 1e-9:
                continue
            n = n / np.linalg.norm(n)
            ja = self._point_jacobian(d, self.parent[a], pa, lwa)
            jb = self._point_jacobian(d, self.parent[b], pb, lwa)
            row = n @ (ja - jb)  # the distance shrinks at n . (v_a - v_b)
            if float(np.linalg.norm(row)) < 1e-2:
                continue
            c_out.append(row)
            u_out.append(max(float(slack), -RECOVER_PER_STEP))
        if not c_out:
            return np.zeros((0, nv)), np.zeros(0)
        return np.array(c_out), np.array(u_out)

    def _point_jacobian(self, d: Any, joint: int, point: FloatArray, frame: object) -> FloatArray:
        import pinocchio as pin

        jac = pin.getJointJacobian(self.coll.robot.model, d, joint, frame)
        r = point - d.oMi[joint].translation
        skew = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
        return jac[:3] - skew @ jac[3:]


RECOVER_PER_STEP = 0.005  # m: an overlap beyond the floor is undone at most this fast
