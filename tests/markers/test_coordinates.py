"""The marker model reports OpenSim's coordinates with the body (IMU) side's meaning: the same
posture gives the same angles through both, and other OpenSim conventions are converted."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from mocapkit.body.human_model import HumanModel, build_human_model
from mocapkit.body.joint_angles import joint_angles_reference
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_from_euler, quat_from_matrix, quat_to_xyzw
from mocapkit.markers.coordinates import (
    coordinate_map,
    coordinates_and_gimbal,
    coordinates_from_q,
    resolve_coordinate_tasks,
    to_rajagopal,
)
from mocapkit.series import OrientationSeries

# full_body_15 segment (OpenSim body names) -> marker-model segment
SEGMENTS = {
    "pelvis": "pelvis", "torso": "thorax", "head": "head",
    "humerus_r": "upper_arm_r", "radius_r": "forearm_r", "hand_r": "hand_r",
    "humerus_l": "upper_arm_l", "radius_l": "forearm_l", "hand_l": "hand_l",
    "femur_r": "thigh_r", "tibia_r": "shank_r", "calcn_r": "foot_r",
    "femur_l": "thigh_l", "tibia_l": "shank_l", "calcn_l": "foot_l",
}  # fmt: skip
# OpenSim's body axes (x fwd, y up, z right) in the marker model's (x fwd, y left, z up)
OPENSIM_IN_OURS = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def _postures(h: HumanModel, n: int = 6) -> np.ndarray:
    """Random postures within the limits, every DOF moving (subtalar and mtp at 0: the body
    side folds the subtalar into the ankle joint), the pelvis turned and tilted."""
    rng = np.random.default_rng(7)
    Q = np.tile(h.neutral(), (n, 1))
    lo, hi = h.dof_limits()
    span = np.minimum(hi - lo, np.radians(90.0))
    mid = np.clip(0.0, lo + 0.3 * span, hi - 0.3 * span)
    Q[:, 7:] = mid + rng.uniform(-0.3, 0.3, (n, len(lo))) * span
    for name in ("subtalar_angle_r", "subtalar_angle_l", "mtp_angle_r", "mtp_angle_l"):
        Q[:, h.dof_index(name) + 1] = 0.0
    Q[:, h.dof_index("elbow_flex_r") + 1] = np.linspace(0.1, 2.2, n)
    Q[:, h.dof_index("pro_sup_r") + 1] = np.linspace(-1.2, 1.5, n)
    Q[:, h.dof_index("knee_angle_l") + 1] = np.linspace(0.0, 1.9, n)
    Q[:, 3:7] = quat_to_xyzw(quat_from_euler(rng.uniform(-0.4, 0.4, (n, 3)), "ZXY"))
    return Q


def _body_side_angles(h: HumanModel, Q: np.ndarray) -> tuple[tuple[str, ...], np.ndarray]:
    """The body (IMU) pipeline's joint angles (preset full_body_15, Rajagopal's joints) from
    the marker model's segment orientations."""
    tree = SensorTree.preset("full_body_15")
    data = h.model.createData()
    quats: dict[str, list[np.ndarray]] = {s.name: [] for s in tree.segments}
    for q in Q:
        pin.framesForwardKinematics(h.model, data, q)
        for s in tree.segments:
            R = data.oMf[h.model.getFrameId(SEGMENTS[s.name])].rotation @ OPENSIM_IN_OURS
            quats[s.name].append(quat_from_matrix(R))
    t = np.arange(len(Q)) * 0.01
    series = {k: OrientationSeries(t, np.array(v)) for k, v in quats.items()}
    body = joint_angles_reference(tree, series, quat_from_matrix(OPENSIM_IN_OURS))
    return body.angles.names, body.angles.values


def test_same_posture_same_angles_as_the_body_side() -> None:
    h = build_human_model(1.75, 70.0)
    Q = _postures(h)
    names, body = _body_side_angles(h, Q)
    cmap = coordinate_map(h)
    ours = coordinates_from_q(h, Q, cmap)
    assert {"arm_flex_r", "elbow_flex_r", "pro_sup_r", "lumbar_extension"} <= set(names)
    compared = 0
    for k, c in enumerate(names):
        col = ours[:, cmap.names.index(c)]
        # same axes, order and frames: equal to rounding; the subtalar axis is rounded to
        # 4 digits in the preset (and made orthogonal to the ankle's there): 0.01 deg
        tol = np.radians(0.01) if c.startswith("subtalar") else 1e-9
        np.testing.assert_allclose(col, body[:, k], atol=tol, err_msg=c)
        compared += 1
    assert compared == len(names) == 35
    # the shoulder girdle moved, so arm_* (upper arm on thorax, as OpenSim) differs from the
    # model's own shoulder DOFs (upper arm on clavicle)
    sc = Q[:, h.dof_index("sc_elevation_r") + 1]
    assert np.abs(sc).max() > 0.1
    arm = ours[:, cmap.names.index("arm_add_r")]
    shoulder = Q[:, h.dof_index("shoulder_adduction_r") + 1]
    assert np.abs(arm - shoulder).max() > 0.05


def test_arm_angles_pass_gimbal_lock_continuously() -> None:
    """Arm abducted through 90 deg (arm_add = -90: OpenSim's sequence locks there): the
    reported angles stay continuous and still compose the same rotation."""
    h = build_human_model()
    n = 41
    Q = np.tile(h.neutral(), (n, 1))
    Q[:, h.dof_index("shoulder_adduction_r") + 1] = np.radians(np.linspace(-70, -110, n))
    Q[:, h.dof_index("shoulder_flexion_r") + 1] = 0.3
    Q[:, h.dof_index("shoulder_rotation_r") + 1] = -0.4
    cmap = coordinate_map(h)
    C, gimbal = coordinates_and_gimbal(h, Q, cmap)
    arm = C[:, [cmap.names.index(f"arm_{a}_r") for a in ("flex", "add", "rot")]]
    # girdle at zero: arm_* are the shoulder DOFs themselves, across the lock
    dofs = [h.dof_index(f"shoulder_{a}_r") + 1 for a in ("flexion", "adduction", "rotation")]
    shoulder = Q[:, dofs]
    np.testing.assert_allclose(arm, shoulder, atol=1e-6)  # rounding near the lock
    assert gimbal["arm_add_r"].sum() > 0  # reported as near gimbal lock


def test_coordinate_tasks_with_opensim_names() -> None:
    h = build_human_model()
    tasks, notes = resolve_coordinate_tasks(
        h, {"lumbar_extension": (0.2, 100.0), "knee_angle_r": (0.1, 5.0), "arm_flex_l": (0.3, 1.0)}
    )
    assert tasks["abdomen_extension"] == (0.1, 100.0)  # shared by the two spine joints
    assert tasks["thorax_extension"] == (0.1, 100.0)
    assert tasks["knee_angle_r"] == (0.1, 5.0)
    assert tasks["shoulder_flexion_l"] == (0.3, 1.0)  # the girdle stays free
    assert any("lumbar_extension = 11.5 deg held as abdomen_extension" in n for n in notes)
    with pytest.raises(ConfigError, match="'pelvis_tilt' is not a coordinate of this model"):
        resolve_coordinate_tasks(h, {"pelvis_tilt": (0.0, 1.0)}, where="setup.xml")


def test_other_models_conventions() -> None:
    labels = ("hip_flexion_r", "knee_angle_r", "knee_angle_l")
    gait = np.column_stack([np.linspace(-10, 30, 20), -np.linspace(0, 60, 20), -np.full(20, 5.0)])
    out, used = to_rajagopal(labels, gait)
    assert used == "gait2392"  # mostly negative knees: gait2392's sign
    np.testing.assert_array_equal(out[:, 1], np.linspace(0, 60, 20))
    np.testing.assert_array_equal(out[:, 0], gait[:, 0])
    same, used = to_rajagopal(labels, out)
    assert used == "rajagopal"
    np.testing.assert_array_equal(same, out)
    with pytest.raises(ConfigError, match="reference model 'opensim3'"):
        to_rajagopal(labels, gait, "opensim3")


def test_pelvis_rotation_is_continuous_when_the_subject_turns() -> None:
    """A subject turning 1.5 times on the spot: pelvis_rotation runs 0 -> 540 deg in the
    outputs (no jump at +-180), the model's own configuration being the same."""
    from mocapkit.geometry import quat_from_axis_angle, quat_to_xyzw
    from mocapkit.markers.result import ReconstructionResult
    from tests.markers import synthetic

    human, ms = synthetic.subject(1.8)
    names = list(ms.names)
    n = 61
    yaw = np.radians(np.linspace(0.0, 540.0, n))
    Q = np.tile(human.neutral(), (n, 1))
    Q[:, 3:7] = quat_to_xyzw(quat_from_axis_angle([0.0, 0.0, 1.0], yaw))
    X = synthetic.markers(human, names, Q)
    res = ReconstructionResult.build(
        np.arange(n) / 60.0, human, names, names, X, Q, np.zeros((n, human.nv)), 1.0, "ik",
        "offline", [names], {}, [], with_total=False,
    )  # fmt: skip
    rot = np.degrees(res.column("pelvis_rotation"))
    # exact poses: the reported angle is the yaw itself, to rounding
    np.testing.assert_allclose(rot, np.degrees(yaw), atol=1e-6)
