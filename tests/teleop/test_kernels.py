"""The per-packet numba kernels against the readable geometry functions."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from mocapkit.geometry import (
    quat_angle_between,
    quat_from_matrix,
    quat_normalize,
    quat_slerp,
    quat_to_matrix,
)
from mocapkit.robot.model import pose_distance
from mocapkit.teleop import _kernels

_QUAT = st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(lambda v: np.linalg.norm(v) > 0.1)


def _pose(q, p):
    T = np.eye(4)
    T[:3, :3] = quat_to_matrix(quat_normalize(np.array(q)))
    T[:3, 3] = p
    return T


@given(_QUAT, _QUAT)
def test_mat_to_quat_and_pose_error_match_the_geometry_module(qa, qb):
    A, B = _pose(qa, [0.1, 0.2, 0.3]), _pose(qb, [-0.2, 0.0, 0.5])
    out = np.empty(4)
    _kernels.mat_to_quat(A[:3, :3], out)
    np.testing.assert_allclose(out, quat_from_matrix(A[:3, :3]), atol=1e-12)  # same formula
    dp, dr = _kernels.pose_error(A, B)
    ref_dp, ref_dr = pose_distance(A, B)
    assert abs(dp - ref_dp) < 1e-12
    assert abs(dr - ref_dr) < 1e-9  # both atan2 forms; rounding of the 3x3 products


def test_limit_command_box_speed_and_slerp():
    rng = np.random.default_rng(0)
    lo, hi = np.array([-1.0, -1.0, -1.0]), np.array([0.5, 1.0, 1.0])
    prev = _pose([1, 0, 0, 0], [0.4, 0.0, 0.0])
    q_target = quat_normalize(np.array([0.8, 0.3, -0.4, 0.2]))
    cmd = _pose(q_target, [0.9, 0.05, 0.0])
    flags = _kernels.limit_command(cmd, prev, lo, hi, 0.01, 0.1, True)
    assert flags == 1 | 2 | 4
    assert cmd[0, 3] <= 0.5
    np.testing.assert_allclose(np.linalg.norm(cmd[:3, 3] - prev[:3, 3]), 0.01, atol=1e-12)
    # the rotation: the slerp from prev towards the target by 0.1 rad
    q_prev = quat_from_matrix(prev[:3, :3])
    total = float(quat_angle_between(q_prev, q_target))
    expect = quat_slerp(q_prev, q_target, 0.1 / total)
    got = quat_from_matrix(cmd[:3, :3])
    assert float(quat_angle_between(got, expect)) < 1e-9
    # within every limit: untouched
    ok = _pose(rng.normal(size=4), [0.1, 0.1, 0.1])
    same = ok.copy()
    assert _kernels.limit_command(same, ok, lo, hi, 1.0, 1.0, True) == 0
    np.testing.assert_array_equal(same, ok)
