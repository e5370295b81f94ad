"""Readers used by the body pipeline: qmt full-body .mat, OpenSense quaternion .sto, .mot."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io

from mocapkit.errors import FileFormatError
from mocapkit.io.joint_angles_mot import read_joint_angles_mot, write_joint_angles_mot
from mocapkit.io.opensense import read_orientations_sto, write_orientations_sto
from mocapkit.io.opensim_table import write_table
from mocapkit.io.qmt_mat import read_qmt_mat
from mocapkit.series import JointAngleSeries, OrientationSeries


def test_qmt_full_body_recording(shared_data: Path) -> None:
    rec = read_qmt_mat(shared_data / "full-body-15-imu" / "full_body_example_data.mat")
    assert len(rec.names) == 16
    assert "upper_leg_right" in rec.names
    o = rec.orientation["hip"]
    assert o.n_samples == 10000
    assert o.valid.all()
    assert rec.imu["hip"].rate_hz == pytest.approx(100.0, rel=1e-6)
    # standing still at the start: the accelerometer reads about +g
    assert np.linalg.norm(rec.imu["hip"].acc[100:300].mean(axis=0)) == pytest.approx(9.81, abs=0.3)


def test_qmt_reader_errors(tmp_path: Path) -> None:
    p = tmp_path / "a.mat"
    scipy.io.savemat(p, {"x": np.zeros(3)})
    with pytest.raises(FileFormatError, match="no time vector 't'"):
        read_qmt_mat(p)
    scipy.io.savemat(p, {"t": np.arange(3.0), "hip": np.zeros(3)})
    with pytest.raises(FileFormatError, match="entry 'hip' is not a segment struct"):
        read_qmt_mat(p)
    seg = {"acc": np.zeros((3, 3)), "gyr": np.zeros((3, 3)), "quat": np.zeros((2, 4))}
    scipy.io.savemat(p, {"t": np.arange(3.0), "hip": seg})
    with pytest.raises(FileFormatError, match="hip.quat has shape \\(2, 4\\), expected \\(3, 4\\)"):
        read_qmt_mat(p)
    (tmp_path / "b.mat").write_text("no")
    with pytest.raises(FileFormatError, match="not a readable MATLAB .mat file"):
        read_qmt_mat(tmp_path / "b.mat")


def test_opensense_orientations(shared_data: Path, tmp_path: Path) -> None:
    walk = read_orientations_sto(shared_data / "opensense" / "walking_orientations.sto")
    assert len(walk) == 8
    assert walk["pelvis_imu"].n_samples == 2432
    out = write_orientations_sto(tmp_path / "o.sto", walk)
    again = read_orientations_sto(out)
    # written with 10 significant digits
    np.testing.assert_allclose(again["femur_r_imu"].quat, walk["femur_r_imu"].quat, atol=1e-9)


def test_opensense_reader_errors(tmp_path: Path) -> None:
    t = np.arange(3) / 100.0
    write_table(tmp_path / "n.sto", t, ["a"], np.zeros((3, 1)))
    with pytest.raises(FileFormatError, match="not a quaternion table"):
        read_orientations_sto(tmp_path / "n.sto")
    q = np.tile([[[2.0, 0, 0, 0]]], (3, 1, 1))
    write_table(tmp_path / "q.sto", t, ["imu"], q)
    with pytest.raises(FileFormatError, match="column 'imu', row 0: quaternion norm 2.000000"):
        read_orientations_sto(tmp_path / "q.sto")
    q[1, 0] = 0.0  # an all-zero cell is a missing sample
    q[0, 0] = q[2, 0] = [1.0, 0, 0, 0]
    write_table(tmp_path / "z.sto", t, ["imu"], q)
    assert not read_orientations_sto(tmp_path / "z.sto")["imu"].valid[1]
    with pytest.raises(FileFormatError, match="time base differs"):
        write_orientations_sto(tmp_path / "x.sto", {
            "a": OrientationSeries(t, np.tile([1.0, 0, 0, 0], (3, 1))),
            "b": OrientationSeries(t + 1, np.tile([1.0, 0, 0, 0], (3, 1))),
        })  # fmt: skip


def test_mot_round_trip(tmp_path: Path) -> None:
    t = np.arange(4) / 100.0
    vals = np.array([[0.1, -0.2], [0.3, np.nan], [0.0, 1.0], [2.0, -3.0]])
    a = JointAngleSeries(t, ("knee_angle_r", "hip_flexion_r"), vals)
    p = write_joint_angles_mot(tmp_path / "a.mot", a)
    assert "inDegrees=yes" in p.read_text()
    b = read_joint_angles_mot(p)
    np.testing.assert_allclose(b.values, vals, atol=1e-9)  # 10 significant digits in degrees
    write_table(tmp_path / "t.mot", t, ["pelvis_tx", "knee_angle_r"], np.ones((4, 2)) * 90.0)
    c = read_joint_angles_mot(tmp_path / "t.mot")
    assert c.column("pelvis_tx")[0] == 90.0  # translations stay in metres
    assert c.column("knee_angle_r")[0] == pytest.approx(np.pi / 2)
