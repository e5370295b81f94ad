"""An automatic calibration that disagrees with itself is warned, naming the segment."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.body.calibration import pose_coordinates
from mocapkit.body.calibration_checks import (
    CalibrationWarning,
    check_calibration,
    warn_calibration,
)
from mocapkit.body.functional import calibrate_functional
from mocapkit.body.pipeline import run_body
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.geometry import quat_conj, quat_from_axis_angle, quat_mul, quat_rotate
from mocapkit.series import OrientationSeries
from tests.body.synth import gait_like, random_mountings, sensor_orientations


def _walk(turn_sensor: str | None = None) -> tuple[SensorTree, dict[str, OrientationSeries]]:
    """A gait-like lower body; ``turn_sensor``'s orientation turned by 60 deg about the
    segment's long axis after the held pose (a strap that slipped round the leg)."""
    tree = SensorTree.preset("lower_body")
    t = np.arange(800) / 100.0
    coords = gait_like(tree, t, 1.0, pose_coordinates(tree, "npose"), seed=4)
    mounts = random_mountings(tree, np.random.default_rng(4))
    ori = sensor_orientations(tree, t, coords, mounts, heading_rad=0.3)
    if turn_sensor is not None:
        s = ori[turn_sensor]
        q = s.quat.copy()
        up = quat_rotate(quat_conj(q[0]), np.array([0.0, 0.0, 1.0]))  # in the held pose
        slip = quat_from_axis_angle(up, np.radians(60.0))
        q[t > 1.0] = quat_mul(q[t > 1.0], slip)
        ori[turn_sensor] = OrientationSeries(s.time, q, name=s.name)
    return tree, ori


def test_a_consistent_calibration_has_nothing_to_say() -> None:
    tree, ori = _walk()
    cal = calibrate_functional(tree, ori, (0.0, 0.9))
    assert check_calibration(tree, cal) == []


def test_a_segment_turned_away_from_the_others_is_named() -> None:
    tree, ori = _walk()
    sensor = next(s.sensor for s in tree.segments if s.name == "calcn_r")
    tree, ori = _walk(sensor)
    cal = calibrate_functional(tree, ori, (0.0, 0.9))
    with pytest.warns(CalibrationWarning, match=r"segment calcn_r \(sensor .*\) says the body"):
        found = warn_calibration(tree, cal)
    assert [f.segment for f in found if f.kind == "turned"] == ["calcn_r"]
    # in the pipeline: warned and kept in the result
    with pytest.warns(CalibrationWarning, match="calcn_r"):
        res = run_body(tree, ori, window=(0.0, 0.9))
    assert any(f.segment == "calcn_r" for f in res.calibration_findings)


def test_worlds_aligned_at_the_pose_only_name_the_segments_left_unaligned() -> None:
    """Each sensor's heading its own: the offsets are not faults, but the segments with
    no functional axis (here the pelvis) cannot be aligned, and are named with the fix."""
    tree, ori = _walk()
    cal = calibrate_functional(tree, ori, (0.0, 0.9), heading_alignment="pose")
    found = check_calibration(tree, cal)
    assert [f.kind for f in found] == ["unaligned"]
    pelvis = tree.segment("pelvis").sensor
    assert f"pelvis (sensor {pelvis})" in found[0].message
    assert "--heading-alignment joints" in found[0].message
    assert "femur" not in found[0].message  # the hinged segments were aligned
    with pytest.warns(CalibrationWarning, match="heading_alignment=pose"):
        run_body(tree, ori, window=(0.0, 0.9), heading_alignment="pose")
