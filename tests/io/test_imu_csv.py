"""The plain IMU CSV format: unit conversion, round trip, malformed files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import FileFormatError
from mocapkit.io.imu_csv import STANDARD_GRAVITY, read_imu_csv, write_imu_csv
from mocapkit.io.imu_files import read_device_orientations, read_imu_recordings
from mocapkit.series import ImuRecording

HEAD = "time [s],gyr_x [rad/s],gyr_y [rad/s],gyr_z [rad/s],acc_x [g],acc_y [g],acc_z [g]\n"


def test_units_are_converted_on_read(tmp_path: Path) -> None:
    p = tmp_path / "s.csv"
    p.write_text(
        "# a comment\n# name: shank\n"
        "time [ms],acc_z [g],acc_y [g],acc_x [g],gyr_x [deg/s],gyr_y [deg/s],gyr_z [deg/s],"
        "mag_x [nT],mag_y [nT],mag_z [nT],temp [degC]\n"
        "0,1,0,0,180,0,0,20000,0,-40000,30\n"
        "10,1,0,0,90,0,0,,,,30\n"
    )
    rec = read_imu_csv(p)
    assert rec.name == "shank"
    np.testing.assert_allclose(rec.time, [0.0, 0.01])
    np.testing.assert_allclose(rec.gyr[:, 0], [np.pi, np.pi / 2])
    np.testing.assert_allclose(rec.acc[0], [0.0, 0.0, STANDARD_GRAVITY])
    np.testing.assert_allclose(rec.mag[0], [20.0, 0.0, -40.0])  # nT -> uT
    np.testing.assert_array_equal(rec.mag_valid, [True, False])  # empty cells: a gap
    assert rec.meta["mag_unit"] == "uT"


def test_round_trip(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    mag = rng.normal(size=(5, 3))
    mag[2] = np.nan
    rec = ImuRecording(
        np.arange(5) * 0.01, rng.normal(size=(5, 3)), rng.normal(size=(5, 3)), mag, name="pelvis"
    )
    back = read_imu_csv(write_imu_csv(tmp_path / "r.csv", rec))
    assert back.name == "pelvis"
    for key in ("time", "gyr", "acc", "mag"):
        # 10 significant digits in the file
        np.testing.assert_allclose(getattr(back, key), getattr(rec, key), rtol=1e-9, atol=1e-12)
    six_d = read_imu_csv(write_imu_csv(tmp_path / "r6.csv", rec.without_mag()))
    assert six_d.mag is None


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("time [s],gyr_x [rad/s]\n0,0\n", r"missing column\(s\) gyr_y, gyr_z, acc_x"),
        ("time,gyr_x [rad/s]\n", r"column 'time' has no unit; write it as '<name> \[<unit>\]'"),
        (
            HEAD.replace("gyr_x [rad/s]", "gyr_x [rpm]") + "0,1,1,1,1,1,1\n",
            r"column 'gyr_x' has unit 'rpm'; supported: rad/s, deg/s",
        ),
        (
            HEAD + "0,1,1,1,1,1\n",
            "line 2 has 6 cells, expected 7",
        ),
        (
            HEAD + "0,1,1,1,1,one,1\n",
            r"line 2, column 'acc_y': 'one' is not a number",
        ),
        (
            HEAD + "0,1,,1,1,1,1\n",
            r"column 'gyr_y' is empty or not finite at data row 0 \(line 2\)",
        ),
        (
            HEAD.rstrip("\n") + ",mag_x [uT]\n",
            "give all of mag_x, mag_y, mag_z or none of them",
        ),
        ("# only comments\n", "no column labels"),
        (
            HEAD,
            "no data rows",
        ),
    ],
)
def test_malformed_files(tmp_path: Path, text: str, message: str) -> None:
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(FileFormatError, match=message):
        read_imu_csv(p)


def test_non_increasing_time_is_named(tmp_path: Path) -> None:
    p = tmp_path / "t.csv"
    p.write_text(
        "time [s],gyr_x [rad/s],gyr_y [rad/s],gyr_z [rad/s],acc_x [g],acc_y [g],acc_z [g]\n"
        "0,0,0,0,0,0,1\n0.01,0,0,0,0,0,1\n0.01,0,0,0,0,0,1\n"
    )
    with pytest.raises(ValueError, match=r"t.time: not strictly increasing at sample 2"):
        read_imu_csv(p)


def test_dispatcher_errors(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="no such file or directory"):
        read_imu_recordings(tmp_path / "missing.csv")
    (tmp_path / "x.dat").write_text("1")
    with pytest.raises(FileFormatError, match="unknown file type; expected a BROAD .hdf5"):
        read_imu_recordings(tmp_path / "x.dat")
    with pytest.raises(FileFormatError, match="no recording found"):
        read_imu_recordings(tmp_path)
    with pytest.raises(FileFormatError, match="no device orientations here"):
        read_device_orientations(tmp_path)


@pytest.mark.shared_data
def test_dispatcher_on_real_files(shared_data: Path) -> None:
    broad = read_imu_recordings(shared_data / "broad" / "02_undisturbed_slow_rotation_B.hdf5")
    assert list(broad) == ["02_undisturbed_slow_rotation_B"]
    assert len(read_imu_recordings(shared_data / "ximu3-lower-body")) == 7
    assert len(read_device_orientations(shared_data / "ximu3-lower-body")) == 7
    assert len(read_device_orientations(shared_data / "opensense" / "xsens" / "IMUData")) == 8
