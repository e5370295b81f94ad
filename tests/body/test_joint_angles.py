"""Joint angles: exact recovery of known coordinates, eq. 16, unwrapping, gimbal lock."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mocapkit.body.calibration import q_world_ground
from mocapkit.body.joint_angles import compose_pose, joint_angles_reference
from mocapkit.body.sensor_tree import JointSpec, SegmentSpec, SensorTree
from mocapkit.geometry import quat_conj, quat_from_axis_angle, quat_from_euler, quat_mul
from mocapkit.series import OrientationSeries

# Recovering coordinates through compose -> decompose is a handful of quaternion products
# and one atan2 chain: exact to a few ulps; 1e-9 rad leaves room for accumulation.
EXACT = 1e-9


def _segments(
    tree: SensorTree, coords: dict[str, np.ndarray], heading: float = 0.3
) -> dict[str, OrientationSeries]:
    n = len(next(iter(coords.values())))
    q_wg = q_world_ground(heading)
    q = np.array([compose_pose(tree, {c: v[k] for c, v in coords.items()}) for k in range(n)])
    t = np.arange(n) / 100.0
    return {
        s.name: OrientationSeries(t, quat_mul(q_wg, q[:, i]), name=s.name)
        for i, s in enumerate(tree.segments)
    }


@pytest.mark.parametrize("preset", SensorTree.preset_names())
def test_compose_then_decompose_recovers_coordinates(preset: str) -> None:
    tree = SensorTree.preset(preset)
    rng = np.random.default_rng(3)
    # within every joint's working range, away from +-90 deg for the middle angles
    coords = {c: rng.uniform(-1.2, 1.2, 40) for c in tree.coordinate_names}
    result = joint_angles_reference(tree, _segments(tree, coords), q_world_ground(0.3))
    for c in tree.coordinate_names:
        np.testing.assert_allclose(result.angles.column(c), coords[c], atol=EXACT, err_msg=c)


def test_eq16_local_orientation_of_the_child() -> None:
    """Paper eq. 16: q2_local = q1^-1 q2; the elbow angle is the rotation about the elbow axis."""
    tree = SensorTree.preset("right_arm_2")
    axis = tree.segment("radius_r").joint.axes[0]
    q1 = quat_from_euler([0.3, -0.4, 0.2], "xyz")  # any upper-arm orientation
    q2_local = quat_from_axis_angle(axis, 1.1)  # 1.1 rad of pure elbow flexion
    q2 = quat_mul(q1, q2_local)
    t = np.array([0.0])
    segs = {"humerus_r": OrientationSeries(t, q1[None]), "radius_r": OrientationSeries(t, q2[None])}
    res = joint_angles_reference(tree, segs, np.array([1.0, 0.0, 0.0, 0.0]))
    assert res.angles.column("elbow_flex_r")[0] == pytest.approx(1.1, abs=EXACT)
    assert res.angles.column("pro_sup_r")[0] == pytest.approx(0.0, abs=EXACT)


def test_signs_and_offsets() -> None:
    axes = [[0, 0, 1], [1, 0, 0], [0, 1, 0]]
    plain = JointSpec("j", ("a", "b", "c"), np.array(axes))
    flipped = JointSpec("j", ("a", "b", "c"), np.array(axes), signs=np.array([-1.0, 1.0, 1.0]),
                        offsets=np.array([0.5, 0.0, 0.0]))  # fmt: skip
    q = quat_from_euler([0.2, 0.1, -0.3], "ZXY")[None]
    t = np.array([0.0])
    out = []
    for joint in (plain, flipped):
        tree = SensorTree("t", (SegmentSpec("s", "ground", "s", joint),))
        res = joint_angles_reference(tree, {"s": OrientationSeries(t, q)}, q_world_ground(0.0))
        out.append(res.angles.values[0])
    # the paper's offsets, some negated: coordinate = sign * angle + offset
    np.testing.assert_allclose(out[1], [-out[0][0] + 0.5, out[0][1], out[0][2]], atol=EXACT)


def test_unwrap_gives_continuous_angles_past_180_deg() -> None:
    tree = SensorTree.preset("right_arm_2")
    n = 400
    coords = {c: np.zeros(n) for c in tree.coordinate_names}
    coords["arm_rot_r"] = np.linspace(0.0, 3.0 * np.pi, n)  # one and a half turns
    res = joint_angles_reference(tree, _segments(tree, coords), q_world_ground(0.3))
    np.testing.assert_allclose(res.angles.column("arm_rot_r"), coords["arm_rot_r"], atol=EXACT)
    assert np.abs(np.diff(res.angles.column("arm_rot_r"))).max() < 0.05


def test_gimbal_lock_is_held_continuous_and_reported(caplog: pytest.LogCaptureFixture) -> None:
    """The shoulder (ZXY) locks at arm_add = -90 deg (T-pose): the output stays continuous,
    the third angle is held, and the warning names joint, sensor, sample and fix."""
    tree = SensorTree.preset("right_arm_2")
    n = 60
    coords = {c: np.zeros(n) for c in tree.coordinate_names}
    coords["arm_add_r"] = np.concatenate(
        [np.linspace(0.0, -np.pi / 2, 30), np.full(30, -np.pi / 2)]
    )
    coords["arm_rot_r"] = np.concatenate([np.linspace(0.0, 0.3, 30), np.full(30, 0.3)])
    coords["arm_flex_r"] = np.concatenate([np.zeros(30), np.linspace(0.0, 0.4, 30)])
    with caplog.at_level(logging.WARNING, logger="mocapkit.body.joint_angles"):
        res = joint_angles_reference(tree, _segments(tree, coords, 0.0), q_world_ground(0.0))
    assert "acromial_r" in res.gimbal
    assert res.gimbal["acromial_r"].size >= 29
    rot = res.angles.column("arm_rot_r")
    flex = res.angles.column("arm_flex_r")
    # held: the third angle keeps its value from before the lock; the first takes the rest,
    # so flex - rot (the only defined combination at arm_add = -90 deg) is right
    assert np.abs(rot[31:] - rot[30]).max() < 1e-6
    np.testing.assert_allclose(
        (flex - rot)[31:], (coords["arm_flex_r"] - coords["arm_rot_r"])[31:], atol=1e-6
    )
    assert np.abs(np.diff(flex)).max() < 0.05
    msg = caplog.text
    assert "joint acromial_r (segment humerus_r, sensor upper_arm_r)" in msg
    assert "gimbal lock" in msg
    assert "first at sample" in msg
    assert "Fix:" in msg


def test_nan_segment_makes_only_its_joints_nan() -> None:
    tree = SensorTree.preset("right_arm_hand_3")
    coords = {c: np.full(10, 0.2) for c in tree.coordinate_names}
    segs = _segments(tree, coords)
    q = segs["radius_r"].quat.copy()
    q[4:6] = np.nan
    segs["radius_r"] = OrientationSeries(segs["radius_r"].time, q)
    res = joint_angles_reference(tree, segs, q_world_ground(0.3))
    for c in ("elbow_flex_r", "pro_sup_r", "wrist_flex_r", "wrist_dev_r"):
        assert np.isnan(res.angles.column(c)[4:6]).all()
        assert res.missing[c] == 2
    assert np.isfinite(res.angles.column("arm_flex_r")).all()
    assert "arm_flex_r" not in res.missing


@settings(max_examples=50)
@given(st.floats(-1.0, 1.0), st.floats(-0.8, 0.3), st.floats(-0.5, 0.5), st.floats(0.0, 1.2))
def test_left_and_right_mirror(flex: float, add: float, rot: float, knee: float) -> None:
    """A mirrored motion gives the same coordinates on both sides (OpenSim's convention)."""
    tree = SensorTree.preset("lower_body")
    coords = {c: np.zeros(1) for c in tree.coordinate_names}
    for side in "rl":
        coords[f"hip_flexion_{side}"][:] = flex
        coords[f"hip_adduction_{side}"][:] = add
        coords[f"hip_rotation_{side}"][:] = rot
        coords[f"knee_angle_{side}"][:] = knee
    q = compose_pose(tree, {c: v[0] for c, v in coords.items()})
    # mirror of a rotation through the sagittal plane (z -> -z): (w, x, y, z) -> (w, -x, -y, z)
    m = np.array([1.0, -1.0, -1.0, 1.0])
    names = tree.segment_names
    np.testing.assert_allclose(q[names.index("tibia_l")] * m, q[names.index("tibia_r")], atol=1e-12)
    rel_r = quat_mul(quat_conj(q[names.index("pelvis")]), q[names.index("femur_r")])
    rel_l = quat_mul(quat_conj(q[names.index("pelvis")]), q[names.index("femur_l")])
    np.testing.assert_allclose(rel_l * m, rel_r, atol=1e-12)
