"""Segment joint and end points from orientations and the tree's offsets."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.body.calibration import q_world_ground
from mocapkit.body.segment_points import segment_points
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ShapeError
from mocapkit.geometry import quat_exp, quat_mul


def test_frames_at_once_equal_one_at_a_time_and_nan_reaches_the_children() -> None:
    tree = SensorTree.preset("right_arm_torso_3")
    qg = q_world_ground(0.4)
    rng = np.random.default_rng(0)
    q = quat_mul(qg, quat_exp(0.5 * rng.normal(size=(5, 3, 3))))  # (5 frames, 3 segs, 4)
    start, end = segment_points(tree, q, qg, (1.0, 2.0, 0.0))
    assert start.shape == end.shape == (5, 3, 3)
    for k in range(5):
        s1, e1 = segment_points(tree, q[k], qg, (1.0, 2.0, 0.0))
        np.testing.assert_allclose(s1, start[k], atol=1e-15)
        np.testing.assert_allclose(e1, end[k], atol=1e-15)
    # a child's joint is its parent's offset away; a segment is as long as its end vector
    for i, seg in enumerate(tree.segments):
        np.testing.assert_allclose(
            np.linalg.norm(end[:, i] - start[:, i], axis=1), np.linalg.norm(seg.end), atol=1e-12
        )
    np.testing.assert_allclose(start[:, 2], end[:, 1], atol=1e-12)  # the forearm hangs at the elbow
    q[2, 1] = np.nan  # the upper arm's sensor lost in frame 2
    start, end = segment_points(tree, q, qg)
    assert np.isfinite(start[2, :2]).all()  # its own joint is the torso's
    assert np.isnan(end[2, 1]).all()
    assert np.isnan(start[2, 2]).all()  # the forearm hangs from a lost upper arm
    assert np.isnan(end[2, 2]).all()
    assert np.isfinite(start[[0, 1, 3, 4]]).all()


def test_segment_points_checks_the_shape() -> None:
    tree = SensorTree.preset("right_arm_2")
    with pytest.raises(ShapeError, match="q_world_segment"):
        segment_points(tree, np.zeros((3, 4)), q_world_ground(0.0))
