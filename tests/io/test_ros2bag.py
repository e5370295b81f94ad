"""ROS 2 bags: written by mocapkit, read back whole by a rosbag2 reader (``rosbags``'s
Reader and CDR deserialiser, the same format ``ros2 bag`` reads) with the same numbers."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mocapkit.cli.main import main
from mocapkit.io.imu_csv import write_imu_csv
from mocapkit.io.joint_angles_mot import write_joint_angles_mot
from mocapkit.series import ImuRecording, JointAngleSeries, OrientationSeries
from tests.conftest import require_peer


def _read(bag: Path) -> dict[str, list[tuple[int, object]]]:
    require_peer("rosbags", extra="ros")
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    out: dict[str, list[tuple[int, object]]] = {}
    with Reader(bag) as reader:
        for conn, t_ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append((t_ns, ts.deserialize_cdr(raw, conn.msgtype)))
    return out


def _recording(n: int = 50) -> ImuRecording:
    rng = np.random.default_rng(1)
    t = np.arange(n) / 100.0
    acc = np.tile([0.0, 0.0, 9.81], (n, 1)) + 0.01 * rng.normal(size=(n, 3))
    return ImuRecording(t, 0.1 * rng.normal(size=(n, 3)), acc, np.tile([20.0, 5, -40], (n, 1)))


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_imu_bag_round_trip(tmp_path: Path, storage: str) -> None:
    require_peer("rosbags", extra="ros")
    from mocapkit.io.ros2bag import write_imu_bag

    rec = _recording()
    q = np.tile([0.5, 0.5, -0.5, 0.5], (rec.n_samples, 1))
    bag = write_imu_bag(
        tmp_path / "bag", {"left shank": rec}, {"left shank": OrientationSeries(rec.time, q)},
        t0_ns=1_700_000_000_000_000_000, storage=storage,
    )  # fmt: skip
    topics = _read(bag)
    imu = topics["/imu/left_shank"]
    assert len(imu) == rec.n_samples
    t_ns, msg = imu[7]
    assert t_ns == 1_700_000_000_000_000_000 + 70_000_000
    assert msg.header.frame_id == "left_shank"  # type: ignore[attr-defined]
    gyr = np.array([[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z]
                    for _, m in imu])  # type: ignore[attr-defined]  # fmt: skip
    np.testing.assert_array_equal(gyr, rec.gyr)
    o = msg.orientation  # type: ignore[attr-defined]
    assert (o.w, o.x, o.y, o.z) == (0.5, 0.5, -0.5, 0.5)  # ours w,x,y,z -> ROS x,y,z,w
    mag = topics["/imu/left_shank/mag"]
    assert mag[0][1].magnetic_field.x == pytest.approx(20e-6)  # type: ignore[attr-defined]


def test_no_orientation_is_marked_as_rep_145_asks(tmp_path: Path) -> None:
    require_peer("rosbags", extra="ros")
    from mocapkit.io.ros2bag import write_imu_bag

    bag = write_imu_bag(tmp_path / "bag", {"s": _recording(5)})
    _, msg = _read(bag)["/imu/s"][0]
    assert msg.orientation_covariance[0] == -1.0  # type: ignore[attr-defined]


def test_joint_states_and_tf(tmp_path: Path) -> None:
    require_peer("rosbags", extra="ros")
    from mocapkit.io.ros2bag import write_joint_state_bag

    t = np.arange(10) / 50.0
    values = np.column_stack([np.linspace(0, 1, 10), np.linspace(0, -0.5, 10)])
    angles = JointAngleSeries(t, ["knee_angle_r", "hip_flexion_r"], values)
    seg = {"femur_r": OrientationSeries(t, np.tile([1.0, 0, 0, 0], (10, 1)))}
    bag = write_joint_state_bag(tmp_path / "bag", angles, seg, t0_ns=0)
    topics = _read(bag)
    js = topics["/joint_states"]
    assert list(js[3][1].name) == ["knee_angle_r", "hip_flexion_r"]  # type: ignore[attr-defined]
    np.testing.assert_array_equal(
        np.array([m.position for _, m in js]),
        values,  # type: ignore[attr-defined]
    )
    tf = topics["/tf"][0][1].transforms[0]  # type: ignore[attr-defined]
    assert (tf.header.frame_id, tf.child_frame_id) == ("world", "femur_r")


def test_cli_export_ros2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    require_peer("rosbags", extra="ros")
    src = write_imu_csv(tmp_path / "thigh.csv", _recording())
    assert main(["export", "ros2", str(src), "-o", str(tmp_path / "b1"), "--filter", "bachmann",
                 "--json"]) == 0  # fmt: skip
    summary = json.loads(capsys.readouterr().out)
    assert summary["messages"] == 50
    (topic,) = summary["topics"]
    assert len(_read(tmp_path / "b1")[topic]) == 50
    mot = write_joint_angles_mot(
        tmp_path / "a.mot",
        JointAngleSeries(np.arange(4) / 10.0, ["knee_angle_r"], np.zeros((4, 1))),
    )
    assert main(["export", "ros2", str(mot), "-o", str(tmp_path / "b2")]) == 0
    assert len(_read(tmp_path / "b2")["/joint_states"]) == 4
    assert main(["export", "ros2", str(mot), "-o", str(tmp_path / "b2")]) == 1  # exists
    assert "already exists" in capsys.readouterr().err
