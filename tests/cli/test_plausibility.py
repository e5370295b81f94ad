"""Plausibility checks that turn silent wrong results into warnings or errors: a
gyroscope in deg/s, an accelerometer in g, a teleoperation recording given to
``suit decode``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.cli.main import main
from mocapkit.io.imu_csv import write_imu_csv
from mocapkit.io.imu_files import UnitWarning, read_imu_recordings
from mocapkit.series import ImuRecording
from mocapkit.teleop.recording import TeleopRecorder


def _recording(tmp_path: Path, gyr_scale: float = 1.0, acc_scale: float = 1.0) -> Path:
    n = 300
    t = np.arange(n) / 100.0
    gyr = np.column_stack([4.0 * np.sin(2 * np.pi * t), 0 * t, 0 * t]) * gyr_scale  # 4 rad/s peak
    acc = np.tile([0.0, 0.0, 9.81], (n, 1)) * acc_scale
    rec = ImuRecording(t, gyr, acc, name="s")
    return write_imu_csv(tmp_path / "s.csv", rec)


def test_plausible_units_pass_silently(tmp_path: Path) -> None:
    read_imu_recordings(_recording(tmp_path))  # warnings are errors in the suite


def test_a_gyroscope_in_deg_per_s_is_named(tmp_path: Path) -> None:
    src = _recording(tmp_path, gyr_scale=180.0 / np.pi)  # 229 "rad/s"
    with pytest.warns(UnitWarning, match=r"gyr column x reaches 229.2 rad/s at sample 25 .*deg/s"):
        read_imu_recordings(src)


def test_an_accelerometer_in_g_is_named(tmp_path: Path) -> None:
    src = _recording(tmp_path, acc_scale=1.0 / 9.81)
    with pytest.warns(UnitWarning, match=r"acc's median norm is 1 .*looks like g"):
        read_imu_recordings(src)


def test_suit_decode_refuses_a_teleop_recording(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "teleop.mcap"
    with TeleopRecorder(path) as rec:
        rec.command(0.0, [0.1, 0.2, 0.3], [1.0, 0.0, 0.0, 0.0])
    assert main(["suit", "decode", str(path)]) == 1
    assert "no suit frames (/suit/packets)" in capsys.readouterr().err
