"""Automatic (functional) calibration: unknown mountings and heading from the motion."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mocapkit.body import functional
from mocapkit.body.calibration import CalibrationError, HeadingFixed, pose_coordinates
from mocapkit.body.functional import calibrate_functional
from mocapkit.body.hinge_fit import dominant_axis
from mocapkit.body.kinematics import body_angles
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_angle_between, quat_rotate
from tests.body.synth import gait_like, random_mountings, sensor_orientations


def _sagittal_leg() -> SensorTree:
    """Pelvis, thigh, shank, foot with every flexion axis exactly the ground's z: pure
    flexion makes each segment turn exactly about its joint's first axis."""
    zxy = [[0, 0, 1], [1, 0, 0], [0, 1, 0]]

    def seg(name: str, parent: str, sensor: str, joint: str, coords: list, axes: list) -> dict:
        return {"name": name, "parent": parent, "sensor": sensor, "functional": "flexion",
                "joint": {"name": joint, "coordinates": coords, "axes": axes}}  # fmt: skip

    segs = [
        seg("pelvis", "ground", "p", "gp", ["pelvis_tilt", "pelvis_list", "pelvis_rotation"], zxy),
        seg(
            "femur_r",
            "pelvis",
            "f",
            "hip_r",
            ["hip_flexion_r", "hip_adduction_r", "hip_rotation_r"],
            zxy,
        ),
        seg(
            "tibia_r",
            "femur_r",
            "t",
            "knee_r",
            ["knee_angle_r", None, None],
            [[0, 0, -1], [1, 0, 0]],
        ),
        seg(
            "calcn_r",
            "tibia_r",
            "c",
            "ankle_r",
            ["ankle_angle_r", None, None],
            [[0, 0, 1], [1, 0, 0]],
        ),
    ]
    segs[0]["functional"] = "none"
    return SensorTree.from_dict({"name": "leg", "segments": segs})


def _flexion_only(tree: SensorTree, t: np.ndarray) -> dict[str, np.ndarray]:
    coords = gait_like(tree, t, 1.0, {})
    for c in coords:
        if not c.startswith(("hip_flexion", "knee_angle", "ankle_angle")):
            coords[c] = np.zeros_like(t)
    return coords


# Exact data give the mountings back to a few ulps of the eigen-decomposition and TRIAD.
EXACT_RAD = 1e-7


def test_exact_mountings_and_heading_with_a_shared_world() -> None:
    tree = _sagittal_leg()
    t = np.arange(500) / 100.0
    coords = _flexion_only(tree, t)
    mounts = random_mountings(tree, np.random.default_rng(5))
    ori = sensor_orientations(tree, t, coords, mounts, heading_rad=2.1)
    cal = calibrate_functional(tree, ori, (0.0, 0.9))
    assert abs(np.angle(np.exp(1j * (cal.heading_rad - 2.1)))) < EXACT_RAD
    for i, s in enumerate(tree.segments):
        assert quat_angle_between(cal.segments[s.name].q_sensor_segment, mounts[i]) < EXACT_RAD, (
            s.name
        )
    res, _ = body_angles(tree, cal, ori)
    for c in tree.coordinate_names:
        np.testing.assert_allclose(res.angles.column(c), coords[c], atol=1e-6, err_msg=c)
    assert cal.diagnostics["forward_score_deg"] > 0 > cal.diagnostics["backward_score_deg"]


def test_unrelated_sensor_headings_are_aligned_with_pose_alignment() -> None:
    """6D filters: every sensor has its own heading reference (here the pelvis sensor's is
    the true world). heading_alignment='pose' finds each offset (up to +-90 deg from the
    consensus: beyond, an offset looks like a mounting turned the other way round)."""
    tree = _sagittal_leg()
    t = np.arange(500) / 100.0
    coords = _flexion_only(tree, t)
    mounts = random_mountings(tree, np.random.default_rng(6))
    yaw = np.array([0.0, 1.0, -0.6, 0.4])
    ori = sensor_orientations(tree, t, coords, mounts, heading_rad=-0.5, sensor_yaw=yaw)
    cal = calibrate_functional(tree, ori, (0.0, 0.9), heading_alignment="pose")
    res, _ = body_angles(tree, cal, ori)
    for c in tree.coordinate_names:
        np.testing.assert_allclose(res.angles.column(c), coords[c], atol=1e-6, err_msg=c)
    # without alignment the sensors' unrelated headings corrupt the joints
    shared = calibrate_functional(tree, ori, (0.0, 0.9), heading_alignment="shared")
    bad, _ = body_angles(tree, shared, ori)
    assert np.abs(bad.angles.column("hip_rotation_r") - coords["hip_rotation_r"]).max() > 0.5


def test_full_body_gait_like_motion_within_degrees() -> None:
    """The presets' oblique knee/ankle axes and the off-axis motion of every joint (a
    shoulder swinging with abduction and rotation beside its flexion) put a segment's own
    dominant axis degrees off its joint's axis; the hinges (knees, elbows, ankles), seen
    from both sides, give the thighs, shanks, feet and upper arms their axes exactly."""
    tree = SensorTree.preset("full_body_15")
    t = np.arange(600) / 100.0
    coords = gait_like(tree, t, 1.0, pose_coordinates(tree, "npose"), seed=2)
    mounts = random_mountings(tree, np.random.default_rng(2))
    ori = sensor_orientations(tree, t, coords, mounts, heading_rad=0.9)
    cal = calibrate_functional(tree, ori, (0.0, 0.9))
    assert abs(np.rad2deg(np.angle(np.exp(1j * (cal.heading_rad - 0.9))))) < 0.1
    for name in ("humerus_r", "humerus_l", "femur_r", "tibia_r", "calcn_r", "calcn_l"):
        assert cal.segments[name].diagnostics["hinge"] == 1.0, name
    res, _ = body_angles(tree, cal, ori)
    # 0.25 deg: the foot's ankle axis seen from the foot moves with the subtalar joint
    for c in tree.coordinate_names:
        rms = float(np.sqrt(np.mean((res.angles.column(c) - coords[c]) ** 2)))
        assert rms < np.deg2rad(0.25), (c, np.rad2deg(rms))


def test_forearm_twist_axis_takes_the_held_pose_tilt_out(monkeypatch: pytest.MonkeyPatch) -> None:
    """A pose held off (the upper arm 6 deg forward, the elbow 4 deg bent) tilts every
    pose-calibrated mounting of the arm. The forearm turns far about its own long axis
    afterwards (pronation), so a tilt fixed in it crosses into the elbow's flexion by as
    much as it turned: the elbow's error swings with the pronation. Its twist axis (the
    elbow's second axis, from the two-axis fit) lays the tilt exactly: the elbow then
    reads a constant offset (the upper arm's, which only the pose defines), and the hand,
    held as the forearm was, is turned with it (the wrist stays exact)."""
    tree = SensorTree.preset("full_body_15")
    t = np.arange(1000) / 100.0
    coords = gait_like(tree, t, 1.0, pose_coordinates(tree, "npose"), seed=2)
    coords["pro_sup_r"] = coords["pro_sup_r"] - 0.8 * (
        1.0 - np.cos(1.4 * np.pi * np.maximum(t - 1.0, 0.0))
    )
    held = np.clip((1.5 - t) / 0.5, 0.0, 1.0)
    coords["arm_flex_r"] = coords["arm_flex_r"] + np.deg2rad(6.0) * held
    coords["elbow_flex_r"] = coords["elbow_flex_r"] + np.deg2rad(4.0) * held
    mounts = random_mountings(tree, np.random.default_rng(3))
    ori = sensor_orientations(tree, t, coords, mounts, heading_rad=0.7)
    plain = SensorTree(tree.name, tuple(replace(s, functional="none") if s.functional == "twist"
                                        else s for s in tree.segments))  # fmt: skip
    i = tree.segment_names.index("radius_r")
    axis = tree.segments[i].joint.second_axis_in_child()
    assert axis is not None
    moving = t > 2.0
    found = {}
    for which, tr in (("twist", tree), ("pose", plain)):
        cal = calibrate_functional(tr, ori, (0.0, 0.9))
        mount = cal.segments["radius_r"].q_sensor_segment
        tilt = np.rad2deg(np.arccos(min(1.0, abs(float(
            quat_rotate(mount, axis) @ quat_rotate(mounts[i], axis))))))  # fmt: skip
        res, _ = body_angles(tr, cal, ori)
        err = {c: np.rad2deg(res.angles.column(c)[moving] - coords[c][moving])
               for c in ("elbow_flex_r", "wrist_flex_r", "wrist_dev_r")}  # fmt: skip
        found[which] = (tilt, err, cal.segments["radius_r"].diagnostics)
    tilt, err, diag = found["twist"]
    assert tilt < 0.05
    assert diag["functional"] == 1.0
    assert 5.0 < diag["twist_correction_deg"] < 15.0
    assert np.std(err["elbow_flex_r"]) < 0.1  # constant: the upper arm's pose offset
    assert abs(np.mean(err["elbow_flex_r"]) - 6.0) < 0.5
    for c in ("wrist_flex_r", "wrist_dev_r"):
        assert np.sqrt(np.mean(err[c] ** 2)) < 0.1, c
    tilt, err, diag = found["pose"]
    assert tilt > 5.0
    assert np.std(err["elbow_flex_r"]) > 2.0  # swings with the pronation
    # a correction larger than a held pose's error says the fit missed: the pose stays
    monkeypatch.setattr(functional, "MAX_TWIST_CORRECTION_DEG", 5.0)
    kept = calibrate_functional(tree, ori, (0.0, 0.9)).segments["radius_r"]
    assert kept.diagnostics["functional"] == 0.0
    assert kept.diagnostics["twist_correction_deg"] > 5.0


def test_no_motion_is_refused() -> None:
    tree = _sagittal_leg()
    t = np.arange(300) / 100.0
    coords = {c: np.zeros_like(t) for c in tree.coordinate_names}
    ori = sensor_orientations(
        tree, t, coords, random_mountings(tree, np.random.default_rng(0)), 0.0
    )
    with pytest.raises(CalibrationError, match="no segment gave a usable functional axis"):
        calibrate_functional(tree, ori, (0.0, 0.9))
    # with the heading given, segments without a functional axis use the pose
    cal = calibrate_functional(tree, ori, (0.0, 0.9), heading=HeadingFixed(0.0))
    assert cal.segments["femur_r"].diagnostics["functional"] == 0.0


def test_tree_without_knee_or_elbow_needs_a_heading() -> None:
    tree = SensorTree.preset("lower_body").subtree(["pelvis", "femur_r", "femur_l"])
    t = np.arange(400) / 100.0
    coords = gait_like(tree, t, 1.0, {})
    ori = sensor_orientations(
        tree, t, coords, random_mountings(tree, np.random.default_rng(1)), 0.0
    )
    with pytest.raises(
        CalibrationError, match="has no knee or elbow to tell forward from backward"
    ):
        calibrate_functional(tree, ori, (0.0, 0.9))


def test_dominant_axis() -> None:
    rng = np.random.default_rng(0)
    axis = np.array([0.6, 0.0, 0.8])
    rate = np.outer(np.sin(np.linspace(0, 20, 500)) * 3.0, axis) + rng.normal(0, 0.05, (500, 3))
    found, share, n = dominant_axis(rate, smooth=5)
    assert abs(found @ axis) > 0.999  # noise 0.05 rad/s against 3 rad/s: well under 1 deg
    assert share > 0.95
    assert n > 100
    nothing, share0, n0 = dominant_axis(np.zeros((50, 3)))
    assert np.isnan(nothing).all()
    assert share0 == 0.0
    assert n0 == 0


def test_hinges_only_across_worlds_that_agree() -> None:
    """'pose' (6D worlds of their own) never compares two sensors across a joint; 'joints'
    (6D worlds aligned through the joints first) does, as 'shared' does, and aligns each
    segment at the pose as 'pose' does; anything else is refused with the choices."""
    tree = _sagittal_leg()
    t = np.arange(500) / 100.0
    coords = _flexion_only(tree, t)
    mounts = random_mountings(tree, np.random.default_rng(6))
    ori = sensor_orientations(tree, t, coords, mounts, heading_rad=-0.5,
                              sensor_yaw=np.array([0.0, 1.0, -0.6, 0.4]))  # fmt: skip
    pose = calibrate_functional(tree, ori, (0.0, 0.9), heading_alignment="pose")
    assert all(s.diagnostics.get("hinge", 0.0) == 0.0 for s in pose.segments.values())
    same = sensor_orientations(tree, t, coords, mounts, heading_rad=-0.5)
    joints = calibrate_functional(tree, same, (0.0, 0.9), heading_alignment="joints")
    assert joints.segments["tibia_r"].diagnostics["hinge"] == 1.0
    assert joints.diagnostics["heading_alignment"] == "joints"
    res, _ = body_angles(tree, joints, same)
    for c in tree.coordinate_names:
        np.testing.assert_allclose(res.angles.column(c), coords[c], atol=1e-6, err_msg=c)
    # the default on worlds that share a heading (9D): hinges, then the pose's alignment
    hinges = calibrate_functional(tree, same, (0.0, 0.9))
    assert hinges.diagnostics["heading_alignment"] == "hinges"
    assert hinges.segments["tibia_r"].diagnostics["hinge"] == 1.0
    res, _ = body_angles(tree, hinges, same)
    for c in tree.coordinate_names:
        np.testing.assert_allclose(res.angles.column(c), coords[c], atol=1e-6, err_msg=c)
    with pytest.raises(ConfigError, match="expected one of hinges, shared, pose, joints, got 'x'"):
        calibrate_functional(tree, same, (0.0, 0.9), heading_alignment="x")
