"""Robonaut 2 model: agreement with the NASA URDF, Jacobians against finite differences."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.robot import robonaut2_arm
from mocapkit.robot.model import pose_distance, pose_matrix, pose_parts, rotation_angle
from mocapkit.robot.robonaut2 import joint_names


@pytest.mark.parametrize("side", ["right", "left"])
def test_matches_nasa_urdf(shared_data, side):
    """Our table-built model reproduces the R2 URDF's wrist pose in the chest frame."""
    full = pin.buildModelFromUrdf(str(shared_data / "robonaut2" / "r2c6.urdf"))
    names = joint_names(side)
    lock = [j for j in range(1, full.njoints) if full.names[j] not in names]
    ref = pin.buildReducedModel(full, lock, pin.neutral(full))
    data = ref.createData()
    assert tuple(ref.names[1:]) == names
    T_wc_chest = np.eye(4)
    T_wc_chest[:3, 3] = [-0.0240898, 0.0, -0.413899]
    T_wc_chest[:3, :3] = np.diag([1.0, -1.0, -1.0])
    arm = robonaut2_arm(side)
    rng = np.random.default_rng(0)
    for _ in range(30):
        q = rng.uniform(arm.lower, arm.upper)
        pin.framesForwardKinematics(ref, data, q)
        T_world_wc = data.oMf[ref.getFrameId("r2/waist_center")].homogeneous
        T_world_wrist = data.oMf[ref.getFrameId(f"r2/{side}_wrist_yaw")].homogeneous
        expected = np.linalg.inv(T_world_wc @ T_wc_chest) @ T_world_wrist
        # 1e-12: both are the same chain of double-precision products
        np.testing.assert_allclose(arm.frame_pose(q, "palm"), expected, atol=1e-12)
    # the joint limits are the URDF's
    np.testing.assert_allclose(arm.lower, ref.lowerPositionLimit)
    np.testing.assert_allclose(arm.upper, ref.upperPositionLimit)


@pytest.mark.parametrize("side", ["right", "left"])
def test_jacobian_matches_finite_differences(side):
    arm = robonaut2_arm(side)
    rng = np.random.default_rng(1)
    h = 1e-6
    for _ in range(10):
        q = rng.uniform(arm.lower + 0.1, arm.upper - 0.1)
        J = arm.jacobian(q)
        fd = np.zeros((6, arm.n))
        for k in range(arm.n):
            dq = np.zeros(arm.n)
            dq[k] = h
            Tp, Tm = arm.fk(q + dq), arm.fk(q - dq)
            fd[:3, k] = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
            # angular velocity on the manifold: log(R+ R-^T) / 2h, world (chest) frame
            fd[3:, k] = pin.log3(Tp[:3, :3] @ Tm[:3, :3].T) / (2 * h)
        # central differences with h = 1e-6 on O(1 m) arms: error ~ h^2 + eps/h ~ 1e-9
        np.testing.assert_allclose(J, fd, atol=1e-7)


def test_ready_posture_is_in_front_of_the_chest():
    arm = robonaut2_arm("right")
    p = arm.fk(arm.q_ref)[:3, 3]
    assert p[0] > 0.3  # forward
    assert p[1] < 0  # right side
    assert arm.within_limits(arm.q_ref).all()


def test_bad_inputs_name_the_argument():
    arm = robonaut2_arm("right")
    with pytest.raises(ShapeError, match=r"q: expected shape \(7,\), got \(6,\)"):
        arm.check_q(np.zeros(6))
    with pytest.raises(ConfigError, match="no joint 'elbow'"):
        arm.joint_index("elbow")
    with pytest.raises(ConfigError, match="side: expected 'right' or 'left'"):
        robonaut2_arm("middle")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="q_ref: outside the joint limits"):
        robonaut2_arm("right", q_ref=np.zeros(7))
    msg = arm.describe_limit_violation(np.array([0, 0, 0, 0.5, 0, 0, 0.0]))
    assert msg is not None
    assert "r2/right_arm/joint2" in msg
    assert "joint3" in msg


def test_pose_helpers_round_trip():
    rng = np.random.default_rng(2)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    T = pose_matrix([0.1, 0.2, 0.3], q)
    p, quat = pose_parts(T)
    np.testing.assert_allclose(p, [0.1, 0.2, 0.3])
    assert abs(abs(quat @ q) - 1.0) < 1e-12
    assert pose_distance(T, T) == (0.0, 0.0)
    Rz = np.array([[-1.0, 0, 0], [0, -1.0, 0], [0, 0, 1.0]])  # pi about z
    assert abs(rotation_angle(np.eye(3), Rz) - np.pi) < 1e-12
