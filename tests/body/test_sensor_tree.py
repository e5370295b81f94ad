"""Sensor trees: presets, YAML round trip, and every validation message."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.body.sensor_tree import JointSpec, SegmentSpec, SensorTree
from mocapkit.errors import ConfigError

EXPECTED_SENSORS = {
    "right_arm_2": 2,
    "right_arm_hand_3": 3,
    "right_arm_torso_3": 3,
    "upper_body": 9,
    "lower_body": 7,
    "opensense": 8,
    "full_body_15": 15,
    "full_body_16": 16,
}


def test_presets_load_with_expected_sizes() -> None:
    assert set(SensorTree.preset_names()) == set(EXPECTED_SENSORS)
    for name, n in EXPECTED_SENSORS.items():
        tree = SensorTree.preset(name)
        assert len(tree.segments) == n
        assert len(set(tree.sensor_names)) == n
        assert tree.parent_index[0] == -1


def test_paper_arm_preset_is_the_papers_mapping() -> None:
    tree = SensorTree.preset("right_arm_2")
    # alpha1-3 at the shoulder, alpha4 elbow flexion, alpha5 forearm twist, alpha6 unused
    assert tree.coordinate_names == (
        "arm_flex_r", "arm_add_r", "arm_rot_r", "elbow_flex_r", "pro_sup_r",
    )  # fmt: skip
    assert tree.segment("radius_r").parent == "humerus_r"


def test_left_axes_mirror_right() -> None:
    tree = SensorTree.preset("full_body_15")
    for right, left in [("femur_r", "femur_l"), ("tibia_r", "tibia_l"), ("humerus_r", "humerus_l")]:
        ar = tree.segment(right).joint.axes
        al = tree.segment(left).joint.axes
        # axial vectors mirror through the sagittal plane as (-x, -y, z)
        np.testing.assert_allclose(al, ar * np.array([-1.0, -1.0, 1.0]), atol=0)


def test_dict_round_trip(tmp_path: Path) -> None:
    import yaml

    tree = SensorTree.preset("upper_body")
    path = tmp_path / "tree.yaml"
    path.write_text(yaml.safe_dump(tree.to_dict()))
    again = SensorTree.from_yaml(path)
    assert again.coordinate_names == tree.coordinate_names
    for a, b in zip(again.segments, tree.segments, strict=True):
        np.testing.assert_allclose(a.joint.axes, b.joint.axes)
        assert a.joint.order == b.joint.order
        assert a.sensor == b.sensor


def test_with_sensor_names_and_unknown_segment() -> None:
    tree = SensorTree.preset("right_arm_2").with_sensor_names({"humerus_r": "imu7"})
    assert tree.sensor_names == ("imu7", "forearm_r")
    with pytest.raises(
        ConfigError, match="unknown segment\\(s\\) 'femur_r'; segments are: humerus_r"
    ):
        tree.with_sensor_names({"femur_r": "x"})


def test_check_sensors_names_missing_and_available() -> None:
    tree = SensorTree.preset("right_arm_2")
    with pytest.raises(
        ConfigError, match="no data for sensor\\(s\\) radius_r <- 'forearm_r'.*has: 'a'"
    ):
        tree.check_sensors(["upper_arm_r", "a"])


def test_unknown_preset() -> None:
    with pytest.raises(ConfigError, match="unknown body preset 'nope'; available: full_body_15"):
        SensorTree.preset("nope")


def _joint(**kw: object) -> JointSpec:
    args: dict[str, object] = {
        "name": "j",
        "coordinates": ("a", "b", "c"),
        "axes": [[0, 0, 1], [1, 0, 0], [0, 1, 0]],
    }
    args.update(kw)
    return JointSpec(**args)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"coordinates": ("a", "b")}, "coordinates must list three names"),
        ({"axes": [[0, 0, 1]]}, "axes must be 2 or 3 vectors"),
        ({"axes": [[0, 0, 1], [0, 0, 0]]}, "axes must be finite non-zero vectors"),
        (
            {"axes": [[0, 0, 1], [0, 0.1, 1]]},
            "nearly parallel; give two axes at least 10 deg apart",
        ),
        ({"signs": [1, 2, 1]}, "signs must be three values of \\+1 or -1"),
        ({"offsets": [0, np.nan, 0]}, "offsets must be three finite angles"),
        ({"order": (0, 0, 1)}, "order must be a permutation of 0, 1, 2"),
    ],
)
def test_joint_validation(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        _joint(**kwargs)


def test_tree_validation() -> None:
    j = _joint()
    k = _joint(coordinates=("d", "e", "f"))
    with pytest.raises(ConfigError, match="parent 'nope', which is not an earlier segment"):
        SensorTree("t", (SegmentSpec("a", "nope", "s1", j),))
    with pytest.raises(ConfigError, match="sensor 's1' is on both 'a' and 'b'"):
        SensorTree("t", (SegmentSpec("a", "ground", "s1", j), SegmentSpec("b", "a", "s1", k)))
    with pytest.raises(ConfigError, match="coordinate 'a' in joints 'j' and 'j'"):
        SensorTree("t", (SegmentSpec("a", "ground", "s1", j), SegmentSpec("b", "a", "s2", j)))
    with pytest.raises(ConfigError, match="segment name 'a' used twice"):
        SensorTree("t", (SegmentSpec("a", "ground", "s1", j), SegmentSpec("a", "a", "s2", k)))
    with pytest.raises(ConfigError, match="functional must be one of flexion, twist, none"):
        SegmentSpec("a", "ground", "s1", j, functional="maybe")
    # a twist is the second axis of a two-coordinate joint (j reports three)
    with pytest.raises(ConfigError, match="functional 'twist' needs a joint with two"):
        SegmentSpec("a", "ground", "s1", j, functional="twist")
    with pytest.raises(ConfigError, match="'segments' must be a non-empty list"):
        SensorTree.from_dict({"name": "x"})


def test_bad_yaml(tmp_path: Path) -> None:
    p = tmp_path / "bad.yaml"
    p.write_text("segments: [unclosed")
    with pytest.raises(ConfigError, match="not valid YAML"):
        SensorTree.from_yaml(p)


def test_joint_given_as_an_euler_sequence() -> None:
    seg = {"name": "humerus_r", "parent": "ground", "sensor": "s",
           "joint": {"name": "shoulder", "coordinates": ["a", "b", "c"], "sequence": "ZXY",
                     "signs": [1, -1, 1]}}  # fmt: skip
    tree = SensorTree.from_dict({"name": "t", "segments": [seg]})
    np.testing.assert_array_equal(tree.segments[0].joint.axes, [[0, 0, 1], [1, 0, 0], [0, 1, 0]])
    np.testing.assert_array_equal(tree.segments[0].joint.signs, [1, -1, 1])
    seg["joint"]["sequence"] = "ZXZ"  # type: ignore[index]
    with pytest.raises(ConfigError, match="'ZXZ' repeats an axis"):
        SensorTree.from_dict({"name": "t", "segments": [seg]})
    seg["joint"]["sequence"] = "zxy"  # type: ignore[index]
    with pytest.raises(ConfigError, match="expected three upper-case axis letters"):
        SensorTree.from_dict({"name": "t", "segments": [seg]})
