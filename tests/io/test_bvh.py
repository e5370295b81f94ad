"""BVH: write/read round trip, segment rotations through BVH, and malformed files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.body.calibration import q_world_ground
from mocapkit.body.joint_angles import compose_pose
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.body.skeleton import bvh_from_segments, local_rotations
from mocapkit.errors import ConfigError, FileFormatError, ShapeError
from mocapkit.geometry import quat_angle_between, quat_conj, quat_mul
from mocapkit.io.bvh import BvhJoint, BvhMotion, read_bvh, write_bvh
from mocapkit.series import OrientationSeries


def _segments(tree: SensorTree, n: int = 30, heading: float = 0.4) -> dict[str, OrientationSeries]:
    rng = np.random.default_rng(0)
    coords = {c: np.cumsum(rng.normal(0, 0.05, n)) for c in tree.coordinate_names}
    q = quat_mul(q_world_ground(heading), compose_pose(tree, coords))
    t = np.arange(n) / 60.0
    return {s.name: OrientationSeries(t, q[:, i], name=s.name) for i, s in enumerate(tree.segments)}


def test_segments_through_bvh_file_and_back(tmp_path: Path) -> None:
    tree = SensorTree.preset("full_body_15")
    segs = _segments(tree)
    names = {"pelvis": "Hips", "femur_r": "RightUpLeg", "tibia_r": "RightLeg"}
    motion = bvh_from_segments(tree, segs, q_world_ground(0.4), bone_names=names)
    path = write_bvh(tmp_path / "body.bvh", motion)
    back = read_bvh(path)
    assert [j.name for j in back.joints][:3] == ["Hips", "torso", "head"]
    assert back.frame_time == pytest.approx(1 / 60.0, abs=1e-8)
    # 6 decimals of degrees in the file: 1e-6 deg is ~2e-8 rad per angle
    np.testing.assert_allclose(back.values, motion.values, atol=1e-6)
    local = local_rotations(back)
    q_g = {k: quat_mul(quat_conj(q_world_ground(0.4)), v.quat) for k, v in segs.items()}
    rel = quat_mul(quat_conj(q_g["femur_r"]), q_g["tibia_r"])
    assert quat_angle_between(local["RightLeg"], rel).max() < 1e-7
    assert quat_angle_between(local["Hips"], q_g["pelvis"]).max() < 1e-7
    hips = back.joints[0]
    assert hips.channels[:3] == ("Xposition", "Yposition", "Zposition")
    np.testing.assert_allclose(hips.offset, [0.0, 93.0, 0.0])  # metres -> centimetres
    leaves = [j for j in back.joints if j.end_site is not None]
    assert len(leaves) == 5  # head, two hands, two feet


def test_several_roots_get_a_ground_joint_and_gaps_are_held(tmp_path: Path) -> None:
    tree = SensorTree.preset("right_arm_2")
    two = SensorTree(
        "two", (tree.segments[0], *SensorTree.preset("right_arm_torso_3").segments[:1])
    )
    segs = _segments(two, n=10)
    q = segs["torso"].quat.copy()
    q[3:5] = np.nan
    segs["torso"] = OrientationSeries(segs["torso"].time, q)
    motion = bvh_from_segments(two, segs, q_world_ground(0.4))
    assert motion.joints[0].name == "Ground"
    assert motion.meta["held_frames"] == 2
    np.testing.assert_array_equal(
        motion.joint_channels("torso")[3], motion.joint_channels("torso")[2]
    )
    write_bvh(tmp_path / "x.bvh", motion)
    with pytest.raises(ConfigError, match="bone_names: unknown segment\\(s\\) femur_r"):
        bvh_from_segments(two, segs, q_world_ground(0.0), bone_names={"femur_r": "x"})


def test_writer_refuses_bad_motion(tmp_path: Path) -> None:
    j = (BvhJoint("Hips", -1, np.zeros(3), ("Xrotation", "Yrotation", "Zrotation")),)
    with pytest.raises(ShapeError, match="values: expected shape \\(N, 3\\)"):
        write_bvh(tmp_path / "a.bvh", BvhMotion(j, 0.01, np.zeros((2, 4))))
    with pytest.raises(ShapeError, match="non-finite channel value at frame 1"):
        write_bvh(tmp_path / "a.bvh", BvhMotion(j, 0.01, np.array([[0, 0, 0], [0, np.nan, 0.0]])))
    bad = (BvhJoint("My Hips", -1, np.zeros(3), ("Xrotation",)),)
    with pytest.raises(ShapeError, match="cannot be empty or contain spaces"):
        write_bvh(tmp_path / "a.bvh", BvhMotion(bad, 0.01, np.zeros((1, 1))))
    bad = (BvhJoint("Hips", -1, np.zeros(3), ("Wrotation",)),)
    with pytest.raises(ShapeError, match="unknown channel\\(s\\) \\['Wrotation'\\]"):
        write_bvh(tmp_path / "a.bvh", BvhMotion(bad, 0.01, np.zeros((1, 1))))


def test_reader_refuses_malformed_files(tmp_path: Path) -> None:
    p = tmp_path / "x.bvh"
    p.write_text("hello\n")
    with pytest.raises(FileFormatError, match="does not start with HIERARCHY"):
        read_bvh(p)
    p.write_text(
        "HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 3 Xrotation Yrotation Zrotation\n}\n"
    )
    with pytest.raises(FileFormatError, match="no MOTION section"):
        read_bvh(p)
    p.write_text(
        "HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 3 Xrotation Yrotation Zrotation\n}\n"
        "MOTION\nFrames: 2\nFrame Time: 0.01\n1 2 3\n"
    )
    with pytest.raises(FileFormatError, match="header says 2 frames, file has 1"):
        read_bvh(p)
    p.write_text(
        "HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 3 Xrotation Yrotation Zrotation\n}\n"
        "MOTION\nFrames: 1\nFrame Time: 0.01\n1 2\n"
    )
    with pytest.raises(FileFormatError, match="2 values per frame, hierarchy has 3 channels"):
        read_bvh(p)
