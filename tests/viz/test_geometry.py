"""Drawing geometry: skeleton points from the tree's offsets, arm polylines from FK."""

from __future__ import annotations

import numpy as np

from mocapkit.body.calibration import q_world_ground
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.geometry import quat_from_axis_angle, quat_mul
from mocapkit.robot.robonaut2 import robonaut2_arm
from mocapkit.viz.geometry import (
    arm_frames,
    arm_points,
    polyline_segments,
    skeleton_segments,
    transform_points,
)


def test_skeleton_in_the_reference_pose_stacks_the_offsets() -> None:
    tree = SensorTree.preset("right_arm_torso_3")
    qg = q_world_ground(0.0)  # OpenSim y-up ground in the z-up world
    q = np.tile(qg, (3, 1))  # every segment aligned with the ground: the zero pose
    segs = skeleton_segments(tree, q, qg)
    torso, humerus, radius = segs
    # ground y (up) is world z; ground z (right) is world -y
    np.testing.assert_allclose(torso.start, [0.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(torso.end, [0.0, 0.0, 1.45], atol=1e-12)
    np.testing.assert_allclose(humerus.start, [0.0, -0.19, 1.39], atol=1e-12)
    np.testing.assert_allclose(humerus.end, [0.0, -0.19, 1.10], atol=1e-12)
    np.testing.assert_allclose(radius.start, humerus.end, atol=1e-12)
    np.testing.assert_allclose(radius.end, [0.0, -0.19, 0.86], atol=1e-12)


def test_skeleton_follows_a_rotated_parent_and_drops_lost_segments() -> None:
    tree = SensorTree.preset("right_arm_torso_3")
    qg = q_world_ground(0.0)
    # the humerus raised forward by 90 deg (flexion about the segment's z = world -y)
    q_h = quat_from_axis_angle(np.array([0.0, -1.0, 0.0]), np.pi / 2)
    q = np.stack([qg, quat_mul(q_h, qg), quat_mul(q_h, qg)])
    segs = skeleton_segments(tree, q, qg)
    # the arm now points forward (+x, the way the body faces) from the shoulder
    np.testing.assert_allclose(segs[1].end - segs[1].start, [0.29, 0.0, 0.0], atol=1e-12)
    q[1] = np.nan  # the upper-arm sensor is lost: it and the forearm are not drawn
    names = [s.name for s in skeleton_segments(tree, q, qg)]
    assert names == ["torso"]


def test_arm_points_end_at_the_end_effector_and_make_a_polyline() -> None:
    arm = robonaut2_arm("right")
    pts = arm_points(arm, arm.q_ref)
    assert pts.shape == (len(arm_frames(arm)), 3)
    np.testing.assert_allclose(pts[0], 0.0)
    np.testing.assert_allclose(pts[-1], arm.fk(arm.q_ref)[:3, 3], atol=1e-12)
    segs = polyline_segments(pts)
    assert segs.shape == (len(pts) - 1, 2, 3)
    np.testing.assert_array_equal(segs[1:, 0], segs[:-1, 1])
    T = np.eye(4)
    T[:3, 3] = [1.0, 2.0, 3.0]
    np.testing.assert_allclose(transform_points(T, pts), pts + np.array([1.0, 2.0, 3.0]))
