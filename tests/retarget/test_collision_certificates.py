"""The collision guard's distance certificates never hide a collision: along paths that
end in collisions, the guard's answer equals testing every pair's meshes."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pinocchio", reason="the robots extra (pip install 'mocapkit[robots]')")

from mocapkit.retarget.collisions import SelfCollision, _moved_by
from mocapkit.retarget.robot_model import build_humanoid
from mocapkit.retarget.robot_spec import load_robot_spec


def _brute_force(coll: SelfCollision, q: np.ndarray) -> list[int]:
    import pinocchio as pin

    model = coll.robot.model
    data, gd = model.createData(), coll.gm.createData()
    pin.forwardKinematics(model, data, q)
    pin.updateGeometryPlacements(model, data, coll.gm, gd)
    return [k for k in range(len(coll.pairs)) if pin.computeCollision(coll.gm, gd, k)]


def test_moved_by_bounds_every_point() -> None:
    rng = np.random.default_rng(0)
    for _ in range(200):
        rel = [np.eye(4), np.eye(4)]
        for m in rel:
            axis = rng.normal(size=3)
            angle = rng.uniform(0, 0.3)
            k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
            k /= np.linalg.norm(axis)
            m[:3, :3] = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
            m[:3, 3] = rng.normal(scale=0.02, size=3)
        centre, radius = rng.normal(scale=0.1, size=3), rng.uniform(0.01, 0.2)
        bound = _moved_by(rel[0], rel[1], centre, radius)
        pts = centre + radius * rng.uniform(-1, 1, size=(100, 3)) / np.sqrt(3)
        moved = (pts @ rel[1][:3, :3].T + rel[1][:3, 3]) - (pts @ rel[0][:3, :3].T + rel[0][:3, 3])
        assert np.linalg.norm(moved, axis=1).max() <= bound + 1e-12


@pytest.mark.parametrize("robot", ["romeo", "g1"])
def test_certificates_never_hide_a_collision(robot: str) -> None:
    h = build_humanoid(load_robot_spec(robot))
    coll = SelfCollision(h)
    assert coll.available
    rng = np.random.default_rng(1)
    lo, hi = h.q_min[h.iq], h.q_max[h.iq]
    checked = hits = 0
    for _ in range(4):  # from the reference posture towards random ones, 40 small steps
        goal = h.q_ref.copy()
        goal[h.iq] = rng.uniform(lo, hi)
        for s in np.linspace(0.0, 1.0, 40):
            q = h.q_ref.copy()
            q[h.iq] = (1 - s) * h.q_ref[h.iq] + s * goal[h.iq]
            got = sorted(coll.colliding_pairs(q))
            assert got == _brute_force(coll, q), s
            checked += 1
            hits += bool(got)
    assert hits > 0  # the paths do reach collisions
    if robot == "romeo":  # its fingers' hulls touch all along: certificates spare tests
        assert coll.certified > 0


def test_a_robot_without_meshes_answers_no_collision(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """A URDF whose meshes cannot be found (copied away from its package): the guard is
    not available, says why, and asking it is safe (nothing found, nothing raised)."""
    import yaml

    spec = load_robot_spec("g1")
    urdf = tmp_path / "g1.urdf"
    urdf.write_text(spec.urdf.read_text())  # its meshes stay behind
    from mocapkit.retarget.robot_spec import packaged_robots

    data = yaml.safe_load(packaged_robots()["g1"].read_text())
    data["urdf"] = str(urdf)
    (tmp_path / "g1.yaml").write_text(yaml.safe_dump(data))
    h = build_humanoid(load_robot_spec(tmp_path / "g1.yaml"))
    coll = SelfCollision(h)
    assert not coll.available
    assert coll.reason
    assert not coll.any_colliding(h.q_ref)
    assert coll.colliding_pairs(h.q_ref) == []
