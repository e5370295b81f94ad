"""File formats: write what we read from the real files in ../shared/data, read it back.

Tolerances are the files' own text precision: a round trip may only lose what the
writer's number format drops, never a sample, a column or a unit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.geometry import quat_angle_between
from mocapkit.io.foxglove_mcap import FoxgloveMcapWriter, read_foxglove_mcap
from mocapkit.io.imu_csv import read_imu_csv, write_imu_csv
from mocapkit.io.joint_angles_mot import read_joint_angles_mot, write_joint_angles_mot
from mocapkit.io.opensense import read_orientations_sto, write_orientations_sto

GAIT = Path("opensim/gait2392")


def test_opensim_ik_mot_round_trip(shared_data: Path, tmp_path: Path) -> None:
    src = shared_data / GAIT / "reference" / "subject01_walk1_ik.mot"
    a = read_joint_angles_mot(src)
    b = read_joint_angles_mot(write_joint_angles_mot(tmp_path / "ik.mot", a))
    assert b.names == a.names
    assert "knee_angle_r" in a.names
    assert "pelvis_tx" in a.names  # a translation: metres, not converted
    np.testing.assert_allclose(b.time, a.time, atol=1e-9)
    # 1e-8 deg: the writer's %.10g of values within +-360 deg
    np.testing.assert_allclose(np.degrees(b.values), np.degrees(a.values), atol=1e-8)


def test_opensim_table_with_repeated_force_columns_round_trip(
    shared_data: Path, tmp_path: Path
) -> None:
    from mocapkit.io.opensim_table import read_table, write_table

    # OpenSim's reference output carries coordinates and two sets of ground reactions
    # with the same labels: a generic table keeps every column, in order
    a = read_table(shared_data / GAIT / "reference" / "OutputReference_subject01_walk1_ik.mot")
    path = write_table(
        tmp_path / "ref.mot", a.time, list(a.labels), a.data, name="ref", in_degrees=a.in_degrees
    )
    b = read_table(path)
    assert list(b.labels) == list(a.labels)
    assert b.in_degrees == a.in_degrees
    np.testing.assert_allclose(b.time, a.time, atol=1e-9)
    np.testing.assert_allclose(b.data, a.data, rtol=1e-9, atol=1e-9)  # %.10g text


def test_opensense_quaternion_sto_round_trip(shared_data: Path, tmp_path: Path) -> None:
    a = read_orientations_sto(shared_data / "opensense" / "walking_orientations.sto")
    path = write_orientations_sto(tmp_path / "orientations.sto", a)
    assert "DataType=Quaternion" in path.read_text()[:500]
    b = read_orientations_sto(path)
    assert list(b) == list(a)
    for name in a:
        np.testing.assert_allclose(b[name].time, a[name].time, atol=1e-9)
        # 1e-7 rad: text precision of the written components
        assert np.nanmax(quat_angle_between(a[name].quat, b[name].quat)) < 1e-7, name


def test_imu_csv_round_trip_of_a_real_xsens_free_recording(
    shared_data: Path, tmp_path: Path
) -> None:
    from mocapkit.io.imu_files import read_imu_recordings

    recs = read_imu_recordings(shared_data / "ximu3-lower-body")
    name, a = next(iter(recs.items()))
    b = read_imu_csv(write_imu_csv(tmp_path / "sensor.csv", a))
    np.testing.assert_allclose(b.time, a.time, atol=1e-9)
    for field in ("gyr", "acc", "mag"):
        x, y = getattr(a, field), getattr(b, field)
        assert (x is None) == (y is None), field
        if x is not None:
            # relative 1e-9: %.10g text precision; NaN gaps (magnetometer) kept in place
            np.testing.assert_allclose(y, x, rtol=1e-9, atol=1e-12, err_msg=f"{name} {field}")


def test_bvh_with_configurable_bone_names_round_trip(shared_data: Path, tmp_path: Path) -> None:
    from mocapkit.body.pipeline import run_body
    from mocapkit.body.sensor_tree import SensorTree
    from mocapkit.body.skeleton import bvh_from_segments, local_rotations
    from mocapkit.io.bvh import read_bvh, write_bvh

    orientations = read_orientations_sto(shared_data / "opensense" / "walking_orientations.sto")
    tree = SensorTree.preset("opensense")
    result = run_body(tree, orientations, calibration="auto")
    bones = {
        "pelvis": "Hips",
        "femur_r": "RightUpLeg",
        "tibia_r": "RightLeg",
        "femur_l": "LeftUpLeg",
    }
    motion = bvh_from_segments(tree, result.segments, result.calibration.q_world_ground,
                               bone_names=bones)  # fmt: skip
    back = read_bvh(write_bvh(tmp_path / "walk.bvh", motion))
    names = [j.name for j in back.joints]
    for bone in bones.values():
        assert bone in names
    assert "pelvis" not in names  # renamed
    assert back.frame_time == pytest.approx(motion.frame_time, rel=1e-6)
    assert back.values.shape == motion.values.shape
    ra, rb = local_rotations(motion), local_rotations(back)
    for joint in ra:
        # 1e-5 rad: the BVH text has 6 decimals of degrees
        assert np.max(quat_angle_between(ra[joint], rb[joint])) < 1e-5, joint


def test_foxglove_mcap_round_trip_of_real_orientations(shared_data: Path, tmp_path: Path) -> None:
    series = read_orientations_sto(shared_data / "opensense" / "walking_orientations.sto")
    names = list(series)
    time = series[names[0]].time[:200]
    path = tmp_path / "walk.mcap"
    with FoxgloveMcapWriter(path) as w:
        for k, t in enumerate(time):
            t_ns = round(float(t) * 1e9)
            w.frame_transforms(
                "/imu", t_ns, [("world", n, [0.1 * i, 0, 0], series[n].quat[k])
                               for i, n in enumerate(names)],
            )  # fmt: skip
            w.pose_in_frame("/pelvis", t_ns, "world", [0.0, 0.0, 1.0], series[names[0]].quat[k])
    msgs = read_foxglove_mcap(path)
    assert [m[1] for m in msgs["/imu"][:1]] == ["foxglove.FrameTransforms"]
    assert msgs["/pelvis"][0][1] == "foxglove.PoseInFrame"
    assert len(msgs["/imu"]) == len(time)
    for k, (t_ns, _schema, msg) in enumerate(msgs["/imu"]):
        assert t_ns == round(float(time[k]) * 1e9)
        assert msg["transforms"][0]["timestamp"] == {"sec": t_ns // 10**9, "nsec": t_ns % 10**9}
        for i, tf in enumerate(msg["transforms"]):
            r = tf["rotation"]  # Foxglove's x, y, z, w order
            q = np.array([r["w"], r["x"], r["y"], r["z"]])
            np.testing.assert_allclose(q, series[names[i]].quat[k], atol=1e-15)
            assert tf["parent_frame_id"] == "world"
            assert tf["child_frame_id"] == names[i]


def test_foxglove_mcap_schemas_are_what_foxglove_decodes(tmp_path: Path) -> None:
    from mcap.reader import make_reader

    path = tmp_path / "one.mcap"
    with FoxgloveMcapWriter(path) as w:
        w.pose_in_frame("/ee", 5, "chest", [1, 2, 3], [1, 0, 0, 0])
        w.frame_transforms("/tf", 5, [("world", "lost", [0, 0, 0], [np.nan] * 4)])
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    schemas = {s.name: s for s in summary.schemas.values()}
    assert set(schemas) == {"foxglove.PoseInFrame", "foxglove.FrameTransforms"}
    assert {s.encoding for s in schemas.values()} == {"jsonschema"}
    assert {c.message_encoding for c in summary.channels.values()} == {"json"}
    msgs = read_foxglove_mcap(path)
    assert msgs["/tf"][0][2] == {"transforms": []}  # a lost segment is left out, not NaN
    pose = msgs["/ee"][0][2]["pose"]
    assert pose["position"] == {"x": 1.0, "y": 2.0, "z": 3.0}
    assert pose["orientation"] == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}


def test_foxglove_reader_names_a_bad_file(tmp_path: Path) -> None:
    from mocapkit.errors import FileFormatError

    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file at all")
    with pytest.raises(FileFormatError, match="bad.mcap: not a readable MCAP file"):
        read_foxglove_mcap(bad)


# -- marker files (the marker package's readers and writers) ---------------------------------


def test_bundled_marker_trial_is_the_shared_one(shared_data: Path) -> None:
    from contextlib import ExitStack

    from mocapkit.demo.markers_section import bundled_marker_files

    with ExitStack() as stack:
        walk, static = bundled_marker_files(stack)
        assert walk.read_bytes() == (shared_data / GAIT / "subject01_walk1.trc").read_bytes()
        full = (shared_data / GAIT / "subject01_static.trc").read_text().splitlines()
        crop = static.read_text().splitlines()
    assert crop[0] == full[0]
    assert crop[2].split("\t")[2] == "60"  # NumFrames
    assert crop[5:] == [ln for ln in full[5:] if ln.strip()][:60] or crop[6:] == full[6:66]


@pytest.mark.parametrize("name", ["subject01_walk1.trc", "subject01_static.trc"])
def test_trc_round_trip(shared_data: Path, tmp_path: Path, name: str) -> None:
    trc = pytest.importorskip(
        "mocapkit.io.trc", reason="the TRC reader comes with mocapkit.markers"
    )
    a = trc.read_trc(shared_data / GAIT / name)
    b = trc.read_trc(trc.write_trc(tmp_path / name, a))
    assert b.names == a.names
    np.testing.assert_allclose(b.time, a.time, atol=1e-6)
    np.testing.assert_array_equal(np.isnan(b.positions), np.isnan(a.positions))
    # 1e-8 m: the writer's millimetres with 5 decimals
    np.testing.assert_allclose(b.positions, a.positions, atol=1e-8)


@pytest.mark.parametrize("name", ["cmu_85_02.c3d", "walking2.c3d"])
def test_c3d_round_trip(shared_data: Path, tmp_path: Path, name: str) -> None:
    c3d = pytest.importorskip(
        "mocapkit.io.c3d", reason="the C3D reader comes with mocapkit.markers"
    )
    a = c3d.read_c3d(shared_data / "c3d" / name)
    b = c3d.read_c3d(c3d.write_c3d(tmp_path / name, a))
    assert b.names == a.names
    assert b.rate_hz == pytest.approx(a.rate_hz)
    np.testing.assert_array_equal(np.isnan(b.positions), np.isnan(a.positions))
    # float32 in the file: 1e-6 relative of positions up to a few metres
    np.testing.assert_allclose(b.positions, a.positions, atol=5e-6)
