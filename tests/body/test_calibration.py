"""Pose calibration: exact recovery of mountings, heading sources, and refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mocapkit.body.calibration import (
    BodyCalibration,
    CalibrationError,
    HeadingFixed,
    HeadingFromSensor,
    calibrate_pose,
    find_still_window,
    pose_coordinates,
)
from mocapkit.body.kinematics import body_angles
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_angle_between, quat_from_axis_angle, quat_mul, quat_rotate
from mocapkit.series import OrientationSeries
from tests.body.synth import gait_like, random_mountings, sensor_orientations

# Mountings and coordinates come back through a few quaternion products: exact to 1e-9.
EXACT = 1e-9


def _recording(preset: str = "full_body_15", heading: float = 0.7, pose: str = "npose",
               seed: int = 0, identity_first: bool = False):  # fmt: skip
    tree = SensorTree.preset(preset)
    t = np.arange(300) / 100.0
    coords = gait_like(tree, t, 1.0, pose_coordinates(tree, pose), seed=seed)
    mounts = random_mountings(tree, np.random.default_rng(seed))
    if identity_first:
        mounts[0] = [1.0, 0.0, 0.0, 0.0]
    return tree, t, coords, mounts, sensor_orientations(tree, t, coords, mounts, heading)


def test_pose_calibration_recovers_mountings_and_angles() -> None:
    tree, _, coords, mounts, ori = _recording()
    cal = calibrate_pose(tree, ori, (0.0, 0.9), pose="npose", heading=HeadingFixed(0.7))
    for i, s in enumerate(tree.segments):
        err = quat_angle_between(cal.segments[s.name].q_sensor_segment, mounts[i])
        assert err < EXACT, s.name
    res, _ = body_angles(tree, cal, ori)
    for c in tree.coordinate_names:
        np.testing.assert_allclose(res.angles.column(c), coords[c], atol=EXACT, err_msg=c)


def test_heading_from_a_sensor_axis_like_opensense() -> None:
    tree, _, _coords, mounts, ori = _recording(heading=-1.2)
    # the pelvis sensor axis that points forward (ground x) in the true mounting
    fwd = quat_rotate(mounts[0], np.array([1.0, 0.0, 0.0]))
    axis = "xyz"[int(np.argmax(np.abs(fwd)))]
    sign = "-" if fwd["xyz".index(axis)] < 0 else ""
    cal = calibrate_pose(tree, ori, (0.0, 0.9), heading=HeadingFromSensor("hip", sign + axis))
    # the axis is not exactly forward (a random mounting), so the heading is approximate:
    # its error is the horizontal angle between that axis and forward
    assert abs(np.angle(np.exp(1j * (cal.heading_rad + 1.2)))) < np.arccos(np.abs(fwd).max()) + 1e-9


def test_motion_during_calibration_is_refused_naming_the_sensor() -> None:
    tree, t, _coords, _mounts, ori = _recording()
    q = ori["forearm_left"].quat.copy()
    turn = quat_from_axis_angle([0.0, 0.0, 1.0], np.deg2rad(np.linspace(0.0, 20.0, 50)))
    q[20:70] = quat_mul(turn, q[20:70])
    ori["forearm_left"] = OrientationSeries(t, q, name="forearm_left")
    with pytest.raises(
        CalibrationError,
        match="sensor 'forearm_left' moved during the calibration pose: it turned 1[0-9].\\d deg",
    ):
        calibrate_pose(tree, ori, (0.0, 0.9))
    with pytest.raises(CalibrationError, match="sensor 'forearm_left' moves the most"):
        find_still_window({"forearm_left": ori["forearm_left"]}, duration_s=2.5, rate_threshold=0.1)


def test_sensor_missing_during_calibration_is_refused() -> None:
    tree, t, _coords, _mounts, ori = _recording()
    q = ori["head"].quat.copy()
    q[:80] = np.nan
    ori["head"] = OrientationSeries(t, q, name="head")
    with pytest.raises(CalibrationError, match="sensor 'head': only 11 of 91 samples are valid"):
        calibrate_pose(tree, ori, (0.0, 0.9))


def test_connectors_up_checks_every_sensor() -> None:
    tree, _, _coords, _mounts, ori = _recording(preset="right_arm_2")
    with pytest.raises(
        CalibrationError, match="connectors-up initialisation needs every connector"
    ):
        calibrate_pose(tree, ori, (0.0, 0.9), pose="connectors_up", connector_axis="x",
                       connector_tolerance_deg=1.0)  # fmt: skip
    # with the axis that is actually up on both sensors it passes
    cal = calibrate_pose(tree, ori, (0.0, 0.9), pose="connectors_up", connector_tolerance_deg=180.0)
    assert cal.diagnostics["pose"] == "connectors_up"


def test_vertical_heading_axis_is_refused() -> None:
    tree, _, _coords, _mounts, ori = _recording(identity_first=True)
    # the pelvis sensor is aligned with the segment: its y axis is the segment's up
    with pytest.raises(CalibrationError, match="its axis -y is 90 deg from horizontal"):
        calibrate_pose(tree, ori, (0.0, 0.9), heading=HeadingFromSensor("hip", "-y"))


def test_config_errors() -> None:
    tree, _, _coords, _mounts, ori = _recording(preset="right_arm_2")
    with pytest.raises(ConfigError, match="unknown pose 'sitting'; known: anatomical"):
        calibrate_pose(tree, ori, (0.0, 0.9), pose="sitting")
    with pytest.raises(ConfigError, match="pose names coordinate\\(s\\) knee_angle_r"):
        calibrate_pose(tree, ori, (0.0, 0.9), pose={"knee_angle_r": 0.1})
    with pytest.raises(ConfigError, match="heading sensor 'torso' is not in tree"):
        calibrate_pose(tree, ori, (0.0, 0.9), heading=HeadingFromSensor("torso", "x"))
    with pytest.raises(CalibrationError, match="calibration window 5.000-6.000 s holds no sample"):
        calibrate_pose(tree, ori, (5.0, 6.0))


def test_calibration_json_round_trip_and_tree_check() -> None:
    tree, _, _coords, _mounts, ori = _recording()
    cal = calibrate_pose(tree, ori, (0.0, 0.9), heading=HeadingFixed(0.7)).with_root_reference(
        "world"
    )
    again = BodyCalibration.from_dict(json.loads(json.dumps(cal.to_dict())))
    assert again.ground_heading_rad == 0.0
    for k in cal.segments:
        np.testing.assert_allclose(
            again.segments[k].q_sensor_segment, cal.segments[k].q_sensor_segment
        )
    other = tree.with_sensor_names({"head": "imu9"})
    with pytest.raises(ConfigError, match="head \\(calibrated with 'head', tree has 'imu9'\\)"):
        again.check_tree(other)
    with pytest.raises(ConfigError, match="has no segment\\(s\\) humerus_r"):
        BodyCalibration("x", {}, 0.0, "pose").check_tree(SensorTree.preset("right_arm_2"))
    with pytest.raises(ConfigError, match="malformed dictionary"):
        BodyCalibration.from_dict({"segments": {}})


def test_find_still_window_on_synthetic() -> None:
    _tree, _, _coords, _mounts, ori = _recording()
    t0, t1 = find_still_window(ori, duration_s=0.8)
    assert t0 == pytest.approx(0.0)
    assert t1 <= 1.0


def test_reset_headings_aligns_any_sensor_heading_offsets() -> None:
    """Sensors with unrelated world headings (6D filters), known mountings: a heading reset
    in the N-pose recovers exact joint angles, for offsets of any size."""
    from mocapkit.body.calibration import SegmentCalibration, reset_headings

    tree = SensorTree.preset("full_body_15")
    t = np.arange(300) / 100.0
    coords = gait_like(tree, t, 1.0, pose_coordinates(tree, "npose"), seed=4)
    mounts = random_mountings(tree, np.random.default_rng(4))
    yaw = np.random.default_rng(5).uniform(-np.pi, np.pi, len(tree.segments))
    ori = sensor_orientations(tree, t, coords, mounts, heading_rad=0.3, sensor_yaw=yaw)
    known = {s.name: SegmentCalibration(s.sensor, mounts[i]) for i, s in enumerate(tree.segments)}
    cal = BodyCalibration(tree.name, known, heading_rad=0.3, method="known")
    before, _ = body_angles(tree, cal, ori)
    assert (
        np.nanmax(np.abs(before.angles.column("hip_rotation_r") - coords["hip_rotation_r"])) > 0.3
    )
    fixed = reset_headings(tree, cal, ori, (0.0, 0.9))
    res, _ = body_angles(tree, fixed, ori)
    for c in tree.coordinate_names:
        np.testing.assert_allclose(res.angles.column(c), coords[c], atol=EXACT, err_msg=c)


def test_root_sensor_on_the_torso_removes_the_skew_of_turning() -> None:
    """Section 6: with only upper-arm and forearm sensors, turning the whole body skews the
    shoulder angles; a third (torso) sensor as root gives them relative to the torso."""
    tree3 = SensorTree.preset("right_arm_torso_3")
    t = np.arange(300) / 100.0
    coords = {c: np.zeros_like(t) for c in tree3.coordinate_names}
    coords["torso_rotation"] = np.where(t > 1.0, np.deg2rad(90.0) * np.minimum(t - 1.0, 1.0), 0.0)
    coords["arm_flex_r"] = np.full_like(t, 0.4)  # arm held forward, body turning
    coords["arm_add_r"] = np.full_like(t, -0.3)
    coords["elbow_flex_r"] = np.full_like(t, 0.8)
    mounts = random_mountings(tree3, np.random.default_rng(8))
    ori = sensor_orientations(tree3, t, coords, mounts, heading_rad=0.2)
    pose = {"arm_flex_r": 0.4, "arm_add_r": -0.3, "elbow_flex_r": 0.8}
    cal3 = calibrate_pose(tree3, ori, (0.0, 0.9), pose=pose, heading=HeadingFixed(0.2))
    res3, _ = body_angles(tree3, cal3, ori)
    np.testing.assert_allclose(res3.angles.column("arm_flex_r"), 0.4, atol=EXACT)
    tree2 = SensorTree.preset("right_arm_2")
    cal2 = calibrate_pose(tree2, ori, (0.0, 0.9), pose=pose, heading=HeadingFixed(0.2))
    res2, _ = body_angles(tree2, cal2, ori)
    skew = max(
        np.abs(res2.angles.column(c) - coords[c]).max()
        for c in ("arm_flex_r", "arm_add_r", "arm_rot_r")
    )
    assert skew > np.deg2rad(45.0)  # the paper's "skewing of the capture data" (90 deg turn)
    # the elbow is relative to the upper arm in both: unaffected
    np.testing.assert_allclose(res2.angles.column("elbow_flex_r"), 0.8, atol=EXACT)
