"""The R2 joint maps against the body model's coordinates (OpenSim senses), and the
15 deg between the map and the segment (eq. 16) retargeting at the shoulder."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.body.joint_angles import compose_pose
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.geometry import quat_from_matrix, quat_log, quat_to_matrix
from mocapkit.robot import SegmentRetargeter, packaged_map, robonaut2_arm
from mocapkit.robot.segment_retarget import robonaut2_groups, robonaut2_init_posture

_TREE = SensorTree.preset("upper_body")
_NPOSE = {"pro_sup_r": np.pi / 2, "pro_sup_l": np.pi / 2}
# chest frame (x forward, y left, z up) -> OpenSim ground (x forward, y up, z right)
_CHEST_TO_GROUND = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])


def _frames(side: str) -> dict[str, str]:
    s = side[0]
    pre = f"r2/{side}_arm/"
    return {
        f"humerus_{s}": pre + "joint2",
        f"radius_{s}": pre + "joint4",
        f"hand_{s}": pre + "wrist/yaw",
    }


def _segments(coords: dict[str, float]) -> dict[str, np.ndarray]:
    q = compose_pose(_TREE, coords)
    return {seg.name: quat_to_matrix(q[i]) for i, seg in enumerate(_TREE.segments)}


def _rotvec(R: np.ndarray) -> np.ndarray:
    return 2.0 * quat_log(quat_from_matrix(R))


@pytest.mark.parametrize("side", ["right", "left"])
def test_every_mapped_coordinate_turns_the_robot_the_human_way(side):
    """Each human coordinate alone, 10 deg from the N-pose: the robot segment it drives
    turns about (nearly) the same axis in the same sense as the human segment."""
    arm = robonaut2_arm(side)
    cm = packaged_map(f"robonaut2-{side}").compile(arm, _TREE.coordinate_names)
    frames = _frames(side)

    def robot_q(coords: dict[str, float]) -> tuple[np.ndarray, bool]:
        v = np.array([coords.get(c, 0.0) for c in _TREE.coordinate_names])
        q, clipped = cm.apply(v)
        return q, bool(clipped.any())

    q0, _ = robot_q(_NPOSE)
    np.testing.assert_allclose(q0, robonaut2_init_posture(side), atol=1e-12)
    S0 = _segments(_NPOSE)
    checked = 0
    for seg in _TREE.segments:
        if seg.name not in frames:
            continue
        for c in seg.joint.coordinates:
            if c is None:
                continue
            for step in (10.0, -10.0):  # the direction that stays inside R2's limits
                coords = dict(_NPOSE)
                coords[c] = coords.get(c, 0.0) + np.radians(step)
                q, clipped = robot_q(coords)
                if not clipped:
                    break
            w_human = _rotvec(_segments(coords)[seg.name] @ S0[seg.name].T)
            R1 = arm.frame_pose(q, frames[seg.name])[:3, :3]
            R0 = arm.frame_pose(q0, frames[seg.name])[:3, :3]
            w_robot = _CHEST_TO_GROUND @ _rotvec(R1 @ R0.T)
            cos = float(w_human @ w_robot / np.linalg.norm(w_human) / np.linalg.norm(w_robot))
            # same sense; R2's axes are up to 15 deg (cos 0.966) from the human's
            assert cos > 0.95, f"{side}: {c} turns the robot the other way (cos {cos:.3f})"
            checked += 1
    assert checked == 7


def test_the_15_degree_shoulder_yaw_between_map_and_segment_retargeting():
    """R2's shoulder-roll axis is turned 15 deg about the vertical from the lateral axis:
    the map (joint space) flexes R2's arm in that turned plane, the segment retargeting
    (eq. 16, R2's own axes) reproduces the human upper arm's orientation exactly."""
    arm = robonaut2_arm("right")
    q0 = robonaut2_init_posture("right")
    axis = arm.jacobian(q0)[3:, 0]  # joint0's axis in the chest frame
    yaw = np.degrees(np.arctan2(axis[0], -axis[1]))  # from the right-pointing lateral axis
    assert yaw == pytest.approx(15.0, abs=0.01)  # 1.83259 - pi/2 rad in the URDF
    flexed = dict(_NPOSE, arm_flex_r=np.radians(40.0))
    S0, S1 = _segments(_NPOSE), _segments(flexed)
    cm = packaged_map("robonaut2-right").compile(arm, _TREE.coordinate_names)
    q_map, _ = cm.apply(np.array([flexed.get(c, 0.0) for c in _TREE.coordinate_names]))
    rt = SegmentRetargeter(arm, robonaut2_groups("right")[:1], q0)
    ground = {s: _CHEST_TO_GROUND.T @ R @ _CHEST_TO_GROUND for s, R in S0.items()}
    rt.calibrate({"humerus_r": ground["humerus_r"]})
    R1 = _CHEST_TO_GROUND.T @ S1["humerus_r"] @ _CHEST_TO_GROUND
    q_seg = rt.joint_angles({"humerus_r": R1}).q
    human = R1 @ ground["humerus_r"].T  # the upper arm's rotation in the chest frame

    def robot_rotation(q: np.ndarray) -> np.ndarray:
        f = "r2/right_arm/joint2"
        return arm.frame_pose(q, f)[:3, :3] @ arm.frame_pose(q0, f)[:3, :3].T

    off_map = np.degrees(np.linalg.norm(_rotvec(robot_rotation(q_map).T @ human)))
    off_seg = np.degrees(np.linalg.norm(_rotvec(robot_rotation(q_seg).T @ human)))
    # a 40 deg rotation about an axis 15 deg away: 2 asin(sin 20 sin 15) = 10.2 deg
    assert off_map == pytest.approx(10.2, abs=0.1)
    assert off_seg < 1e-3  # 1e-3 deg: R2's URDF axes are 4e-6 rad from perpendicular
