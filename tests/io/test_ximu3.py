"""x-IMU3 CSV exports: the real lower-body recording, and malformed tiny files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import FileFormatError
from mocapkit.geometry import quat_rotate
from mocapkit.io.ximu3 import (
    STANDARD_GRAVITY,
    align_mag,
    read_ximu3_directory,
    read_ximu3_quaternion,
    read_ximu3_sensor,
    sensor_name,
)

INERTIAL_HEADER = (
    "Timestamp (us),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s),"
    "Accelerometer X (g),Accelerometer Y (g),Accelerometer Z (g)"
)


@pytest.mark.shared_data
def test_real_lower_body_recording(shared_data: Path) -> None:
    recs = read_ximu3_directory(shared_data / "ximu3-lower-body")
    assert sorted(recs) == [
        "Left Foot",
        "Left Lower Leg",
        "Left Upper Leg",
        "Pelvis",
        "Right Foot",
        "Right Lower Leg",
        "Right Upper Leg",
    ]
    pelvis = recs["Pelvis"]
    assert pelvis.n_samples == 900
    assert pelvis.rate_hz == pytest.approx(50.0, rel=0.01)
    # first row of Inertial.csv: 917418209 us, 1.013036 deg/s, ..., 0.903545 g
    assert pelvis.time[0] == pytest.approx(917.418209)
    assert pelvis.gyr[0, 0] == pytest.approx(np.radians(1.013036))
    assert pelvis.acc[0, 0] == pytest.approx(0.903545 * STANDARD_GRAVITY)
    # the magnetometer (about 20 Hz) is interpolated; a few samples at the edges and in
    # dropouts are gaps, and the meta data says so
    assert 0 < (~pelvis.mag_valid).sum() < 20
    assert "linear interpolation" in str(pelvis.meta["mag_alignment"])


@pytest.mark.shared_data
def test_device_quaternion_is_converted_to_enu(shared_data: Path) -> None:
    directory = shared_data / "ximu3-lower-body" / "pelvis 64F0EDBF (UDP)"
    rec = read_ximu3_sensor(directory)
    ori = read_ximu3_quaternion(directory)
    np.testing.assert_array_equal(ori.time, rec.time)
    ok = rec.mag_valid
    acc_world = quat_rotate(ori.quat, rec.acc)
    mag_world = quat_rotate(ori.quat[ok], rec.mag[ok])
    # gravity up, and the horizontal field towards +y (north in ENU): within the
    # device's own accuracy (a few degrees)
    up = acc_world.mean(axis=0) / np.linalg.norm(acc_world.mean(axis=0))
    assert up[2] > 0.999
    heading = np.degrees(np.arctan2(mag_world[:, 0], mag_world[:, 1]))
    assert abs(np.median(heading)) < 5.0


def test_align_mag_interpolates_and_marks_gaps() -> None:
    t_mag = np.array([0.0, 0.1, 0.2, 0.6, 0.7])  # a dropout between 0.2 and 0.6 s
    mag = np.column_stack([t_mag * 10.0, np.ones(5), np.zeros(5)])
    t = np.array([-0.05, 0.05, 0.15, 0.4, 0.65, 0.75])
    out, n_gap = align_mag(t, t_mag, mag)
    assert n_gap == 3  # before the first, in the dropout, after the last
    np.testing.assert_allclose(out[1], [0.5, 1.0, 0.0])
    np.testing.assert_allclose(out[4], [6.5, 1.0, 0.0])
    assert np.isnan(out[[0, 3, 5]]).all()


def _write_sensor(d: Path, inertial: str) -> Path:
    d.mkdir()
    (d / "Inertial.csv").write_text(inertial)
    return d


def test_malformed_exports(tmp_path: Path) -> None:
    d = _write_sensor(tmp_path / "Knee 64F0EBCE (UDP)", INERTIAL_HEADER + "\n1,0,0,0,0,0,1\n")
    assert sensor_name(d) == "Knee"
    rec = read_ximu3_sensor(d)  # no magnetometer file: 6D
    assert rec.mag is None
    bad = _write_sensor(tmp_path / "a", "Timestamp (us),X\n1,2\n")
    with pytest.raises(FileFormatError, match="does not match the x-IMU3 export"):
        read_ximu3_sensor(bad)
    bad = _write_sensor(tmp_path / "b", INERTIAL_HEADER + "\n1,0,0,0,0,0,1\n2,0,x,0,0,0,1\n")
    with pytest.raises(FileFormatError, match=r"line 3, column 'Gyroscope Y \(deg/s\)'"):
        read_ximu3_sensor(bad)
    bad = _write_sensor(tmp_path / "c", INERTIAL_HEADER + "\n5,0,0,0,0,0,1\n5,0,0,0,0,0,1\n")
    with pytest.raises(FileFormatError, match="time stamps not increasing at data row 1"):
        read_ximu3_sensor(bad)
    bad = _write_sensor(tmp_path / "d", INERTIAL_HEADER + "\n5,0,0,0,0,1\n")
    with pytest.raises(FileFormatError, match="line 2 has 6 cells, expected 7"):
        read_ximu3_sensor(bad)
    with pytest.raises(FileFormatError, match="no Inertial.csv"):
        read_ximu3_sensor(tmp_path)
    with pytest.raises(FileFormatError, match="no Quaternion.csv"):
        read_ximu3_quaternion(d)
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(FileFormatError, match="no sensor directory with an Inertial.csv"):
        read_ximu3_directory(empty)
