"""Retargeting: the paper's segment decomposition (eq. 16) and the YAML joint map."""

from __future__ import annotations

from importlib import metadata

import numpy as np
import pytest
import yaml

from mocapkit.errors import ConfigError, DataError
from mocapkit.geometry import quat_normalize, quat_to_matrix
from mocapkit.robot import RetargetMap, SegmentRetargeter, packaged_map, robonaut2_arm, robot_arm
from mocapkit.robot.segment_retarget import (
    JointGroup,
    robonaut2_groups,
    robonaut2_init_posture,
)
from mocapkit.series import JointAngleSeries

_FRAMES = {
    "humerus_r": "r2/right_arm/joint2",
    "radius_r": "r2/right_arm/joint4",
    "hand_r": "r2/right_arm/wrist/yaw",
}


def _segments(arm, q, mounting):
    return {s: arm.frame_pose(q, f)[:3, :3] @ mounting[s] for s, f in _FRAMES.items()}


def test_segment_retarget_recovers_the_robot_posture():
    """Human segments moving exactly like the robot's (with arbitrary mountings) give back
    the robot's joint angles: eq. 16 + the decomposition along R2's own axes."""
    arm = robonaut2_arm("right")
    q0 = robonaut2_init_posture("right")
    rt = SegmentRetargeter(arm, robonaut2_groups("right"), q0)
    rng = np.random.default_rng(0)
    mounting = {s: quat_to_matrix(quat_normalize(rng.normal(size=4))) for s in _FRAMES}
    rt.calibrate(_segments(arm, q0, mounting))
    q = q0.copy()
    for _ in range(150):
        q = np.clip(q + rng.normal(0, 0.05, arm.n), arm.lower + 0.05, arm.upper - 0.05)
        res = rt.joint_angles(_segments(arm, q, mounting))
        # 1e-5 rad: the URDF's 1.5708 (for pi/2) leaves R2's axes 4e-6 from perpendicular
        np.testing.assert_allclose(res.q, q, atol=1e-5)
        assert res.clipped == ()
        assert abs(res.dropped_rad["radius_r"]) < 1e-5


def test_segment_retarget_clips_and_reports_limits():
    arm = robonaut2_arm("right")
    q0 = robonaut2_init_posture("right")
    rt = SegmentRetargeter(arm, robonaut2_groups("right"), q0)
    eye = {s: np.eye(3) for s in _FRAMES}
    rt.calibrate(eye)
    # forearm hyper-extended 40 degrees about the elbow axis: beyond joint3's upper limit 0
    axis = arm.jacobian(q0)[3:, 3]
    from mocapkit.geometry import quat_from_axis_angle

    bend = quat_to_matrix(quat_from_axis_angle(axis, np.radians(40)))
    res = rt.joint_angles({"humerus_r": np.eye(3), "radius_r": bend, "hand_r": bend})
    assert "r2/right_arm/joint3" in res.clipped
    assert arm.within_limits(res.q).all()


def test_segment_retarget_validation_messages():
    arm = robonaut2_arm("right")
    q0 = robonaut2_init_posture("right")
    with pytest.raises(ConfigError, match="expected 2 or 3 joints"):
        SegmentRetargeter(arm, [JointGroup("humerus_r", None, ("r2/right_arm/joint0",))], q0)
    with pytest.raises(ConfigError, match="must drive an earlier group"):
        SegmentRetargeter(
            arm,
            [JointGroup("radius_r", "humerus_r", ("r2/right_arm/joint3", "r2/right_arm/joint4"))],
            q0,
        )
    rt = SegmentRetargeter(arm, robonaut2_groups("right"), q0)
    with pytest.raises(DataError, match="call calibrate"):
        rt.joint_angles({s: np.eye(3) for s in _FRAMES})
    with pytest.raises(DataError, match="missing 'hand_r'"):
        rt.calibrate({"humerus_r": np.eye(3), "radius_r": np.eye(3)})
    rt.calibrate({s: np.eye(3) for s in _FRAMES})
    with pytest.raises(DataError, match="hand_r is not finite"):
        rt.joint_angles({"humerus_r": np.eye(3), "radius_r": np.eye(3), "hand_r": [np.nan] * 4})


_OBLIQUE_URDF = """<robot name="oblique">
  <link name="base"/><link name="l1"/><link name="l2"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0 0.3" rpy="0 0 0"/><axis xyz="0 0.6 0.8"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
</robot>"""


def test_oblique_axes_are_rejected(tmp_path):
    from mocapkit.robot.urdf import load_urdf_arm

    path = tmp_path / "oblique.urdf"
    path.write_text(_OBLIQUE_URDF)
    arm = load_urdf_arm(path, ["j1", "j2"], "base", "l2", q_ref=np.zeros(2))
    np.testing.assert_allclose(arm.velocity_limit, [1.0, 1.0])  # the URDF's
    with pytest.raises(ConfigError, match="j1 and j2 are not perpendicular"):
        SegmentRetargeter(arm, [JointGroup("humerus_r", None, ("j1", "j2"))], np.zeros(2))
    with pytest.raises(ConfigError, match=r"joint\(s\) j3 not in the URDF"):
        load_urdf_arm(path, ["j1", "j3"], "base", "l2")
    with pytest.raises(ConfigError, match="chain order: j1, j2"):
        load_urdf_arm(path, ["j2", "j1"], "base", "l2")
    with pytest.raises(ConfigError, match="no frame 'hand'"):
        load_urdf_arm(path, ["j1", "j2"], "base", "hand")
    with pytest.raises(FileNotFoundError, match="no such file"):
        load_urdf_arm(tmp_path / "none.urdf", ["j1"], "base", "l2")


def _series(values, names):
    values = np.atleast_2d(values)
    return JointAngleSeries(np.arange(len(values)) * 0.01, names, values)


HUMAN = (
    "arm_flex_r",
    "arm_add_r",
    "arm_rot_r",
    "elbow_flex_r",
    "pro_sup_r",
    "wrist_flex_r",
    "wrist_dev_r",
)


def test_packaged_r2_map_gives_the_initialisation_posture():
    rmap = packaged_map("robonaut2-right")
    arm = rmap.build_arm()
    init = np.radians([0, 0, 0, 0, 90, 0, 0])
    out, clipped = rmap.apply(_series(init, HUMAN), arm)
    np.testing.assert_allclose(out.values[0], robonaut2_init_posture("right"), atol=1e-12)
    assert not clipped.any()
    assert out.names == arm.joint_names


def test_map_clips_nan_passes_and_reports():
    rmap = packaged_map("robonaut2-right")
    arm = rmap.build_arm()
    vals = np.radians([[0, 0, 0, -30, 90, 0, 0], [np.nan] * 7])  # elbow hyper-extended
    out, clipped = rmap.apply(_series(vals, HUMAN), arm)
    assert clipped[0, 3]
    assert out.values[0, 3] == 0.0
    assert np.isnan(out.values[1]).all()


def _map(**joint3):
    base = {
        "robot": "robonaut2-right",
        "joints": {f"r2/right_arm/joint{k}": {"human": "arm_flex_r"} for k in range(5)}
        | {
            "r2/right_arm/wrist/pitch": {"fixed_deg": 0},
            "r2/right_arm/wrist/yaw": {"fixed_deg": 0},
        },
    }
    base["joints"]["r2/right_arm/joint3"] = joint3
    return base


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ({"human": "elbow_flex_r", "sign": 2}, r"joint3.sign: expected 1 or -1"),
        ({"human": "elbow_flex_r", "scale": -1}, r"joint3.scale: expected a positive factor"),
        ({"human": "elbow_flex_r", "limits_deg": [10, -10]}, r"lower 10 must be below upper -10"),
        ({"human": "elbow_flex_r", "gain": 1}, r"unknown key\(s\) gain"),
        ({"sign": 1}, r"needs 'human'"),
        ({"human": "elbow_flex_r", "fixed_deg": 0}, r"either 'human' or 'fixed_deg'"),
        ({"human": "elbow_flex_r", "offset_deg": "x"}, r"offset_deg: expected a finite number"),
    ],
)
def test_map_entry_validation(entry, message):
    with pytest.raises(ConfigError, match=message):
        RetargetMap.from_dict(_map(**entry), source="m.yaml")


def test_map_checks_against_the_robot(tmp_path):
    arm = robonaut2_arm("right")
    bad_limits = RetargetMap.from_dict(_map(human="elbow_flex_r", limits_deg=[-200, 0]), "m.yaml")
    with pytest.raises(ConfigError, match=r"exceeds the robot's \[-160.0, 0.0\] deg"):
        bad_limits.check_arm(arm)
    data = _map(human="elbow_flex_r")
    del data["joints"]["r2/right_arm/wrist/yaw"]
    with pytest.raises(ConfigError, match=r"not mapped: r2/right_arm/wrist/yaw; map each"):
        RetargetMap.from_dict(data, "m.yaml").check_arm(arm)
    data = _map(human="elbow_flex_r")
    data["joints"]["r2/right_arm/joint9"] = {"fixed_deg": 0}
    with pytest.raises(ConfigError, match=r"joint9 not joint\(s\) of robonaut2-right"):
        RetargetMap.from_dict(data, "m.yaml").check_arm(arm)
    ok = RetargetMap.from_dict(_map(human="elbow_flex_r"), "m.yaml")
    with pytest.raises(DataError, match=r"elbow_flex_r not in the joint angles; available"):
        ok.apply(_series([0.0], ["arm_flex_r"]), arm)
    path = tmp_path / "bad.yaml"
    path.write_text("robot: [unclosed")
    from mocapkit.errors import FileFormatError

    with pytest.raises(FileFormatError, match="not valid YAML"):
        RetargetMap.from_yaml(path)
    path.write_text(yaml.safe_dump(_map(human="elbow_flex_r")))
    assert RetargetMap.from_yaml(path).robot == "robonaut2-right"


def _has_example_robot_data() -> bool:
    try:
        metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError:
        return False
    return True


@pytest.mark.skipif(not _has_example_robot_data(), reason="pip install 'mocapkit[robots]'")
def test_second_robot_from_a_pypi_urdf():
    """Talos's right arm (URDF shipped by example-robot-data): map, FK, Jacobian, IK."""
    from mocapkit.robot import solve_ik

    rmap = packaged_map("talos-right")
    arm = rmap.build_arm()
    assert arm.n == 7
    assert arm.name == "talos-right"
    out, _ = rmap.apply(_series(np.radians([20, -10, 5, 60, 90, 0, 0]), HUMAN), arm)
    q = out.values[0]
    assert arm.within_limits(q).all()
    h = 1e-6
    J = arm.jacobian(q)
    for k in range(arm.n):
        dq = np.zeros(arm.n)
        dq[k] = h
        fd = (arm.fk(q + dq)[:3, 3] - arm.fk(q - dq)[:3, 3]) / (2 * h)
        np.testing.assert_allclose(J[:3, k], fd, atol=1e-7)  # central-difference error
    res = solve_ik(arm, arm.fk(q), arm.q_ref)
    assert res.reached
    assert robot_arm("talos-right").n == 7


def test_matrix_euler_matches_the_geometry_module():
    """The per-frame XYX decomposition on matrices equals geometry.euler_from_quat."""
    from mocapkit.geometry import euler_from_quat, quat_from_euler
    from mocapkit.robot.segment_retarget import _euler_xyx

    rng = np.random.default_rng(5)
    qs = [quat_normalize(rng.normal(size=4)) for _ in range(200)]
    qs += [quat_from_euler([0.7, b, 0.0], "XYX") for b in (0.0, np.pi)]  # gimbal lock
    for q in qs:
        got = _euler_xyx(quat_to_matrix(q))
        want = euler_from_quat(q, "XYX")
        # angles compared modulo 2 pi; 1e-9 rad: both are closed forms in double precision
        np.testing.assert_allclose(np.angle(np.exp(1j * (got - want))), 0.0, atol=1e-9)


def test_fast_and_reference_retargeting_agree():
    """The numba kernel equals the numpy reference over a random walk that visits joint
    limits and wraps (same continuity state, same clipping), and solve() equals both."""
    arm = robonaut2_arm("right")
    q0 = robonaut2_init_posture("right")
    fast = SegmentRetargeter(arm, robonaut2_groups("right"), q0)
    ref = SegmentRetargeter(arm, robonaut2_groups("right"), q0, backend="reference")
    lean = SegmentRetargeter(arm, robonaut2_groups("right"), q0)
    rng = np.random.default_rng(7)
    mounting = {s: quat_to_matrix(quat_normalize(rng.normal(size=4))) for s in _FRAMES}
    for rt in (fast, ref, lean):
        rt.calibrate(_segments(arm, q0, mounting))
    q = q0.copy()
    n_clipped = 0
    for _ in range(300):
        q = q + rng.normal(0, 0.15, arm.n)  # unclipped: leaves the limits at times
        segs = _segments(arm, q, mounting)
        a, b = fast.joint_angles(segs), ref.joint_angles(segs)
        c = lean.solve(np.stack([segs[s] for s in lean.segments]))
        np.testing.assert_allclose(a.q, b.q, atol=1e-9)  # same arithmetic, other order
        np.testing.assert_allclose(c, b.q, atol=1e-9)
        assert a.clipped == b.clipped
        assert a.dropped_rad == pytest.approx(b.dropped_rad, abs=1e-9)
        n_clipped += bool(b.clipped)
    assert n_clipped > 10  # the walk did exercise the limits
    with pytest.raises(ConfigError, match="backend: expected 'fast' or 'reference'"):
        SegmentRetargeter(arm, robonaut2_groups("right"), q0, backend="gpu")
