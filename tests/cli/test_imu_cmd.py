"""``mocapkit imu ...`` in-process through ``main(argv)``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mocapkit.cli.main import main
from mocapkit.imu.filters import TimeGapWarning
from mocapkit.io.imu_csv import write_imu_csv
from mocapkit.io.opensim_table import read_table
from mocapkit.series import ImuRecording

BROAD_TRIALS = ["02_undisturbed_slow_rotation_B.hdf5", "24_disturbed_tapping_A.hdf5"]


@pytest.fixture
def two_trials(shared_data: Path, tmp_path: Path) -> Path:
    d = tmp_path / "broad"
    d.mkdir()
    for name in BROAD_TRIALS:
        (d / name).symlink_to(shared_data / "broad" / name)
    return d


@pytest.mark.shared_data
@pytest.mark.parametrize("mode", ["9d", "6d"])
def test_evaluate_json_has_exactly_the_issue_keys(
    two_trials: Path, capsys: pytest.CaptureFixture[str], mode: str
) -> None:
    code = main(
        ["imu", "evaluate", str(two_trials), "--filter", "miller", "--mode", mode, "--json"]
    )
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {
        "filter",
        "mode",
        "trials",
        "mean_total_deg",
        "mean_inclination_deg",
        "samples_per_s",
    }
    assert out["filter"] == "miller"
    assert out["mode"] == mode
    assert sorted(out["trials"]) == [n.removesuffix(".hdf5") for n in BROAD_TRIALS]
    for errors in out["trials"].values():
        assert set(errors) == {"total_deg", "heading_deg", "inclination_deg"}
        assert 0.0 < errors["inclination_deg"] <= errors["total_deg"] < 10.0
    totals = [t["total_deg"] for t in out["trials"].values()]
    assert out["mean_total_deg"] == pytest.approx(np.mean(totals))
    assert out["samples_per_s"] > 0


@pytest.mark.shared_data
def test_evaluate_text_table(two_trials: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert (
        main(["imu", "evaluate", str(two_trials), "--filter", "bachmann", "--param", "alpha=0.3"])
        == 0
    )
    out = capsys.readouterr().out
    assert "filter bachmann (online), 9d, backend fast" in out
    assert "02_undisturbed_slow_rotation_B" in out
    assert "throughput:" in out


def test_evaluate_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["imu", "evaluate", str(tmp_path), "--filter", "miller"]) == 1
    assert "no .hdf5 or .mat files found" in capsys.readouterr().err
    assert main(["imu", "evaluate", str(tmp_path), "--filter", "nope"]) == 2
    assert main(["imu", "evaluate", str(tmp_path), "--filter", "miller", "--param", "alpha"]) == 2


def _csv_recording(tmp_path: Path) -> Path:
    n = 200
    t = np.arange(n) / 100.0
    gyr = np.tile([0.0, 0.0, 0.5], (n, 1))  # turning about the vertical at 0.5 rad/s
    acc = np.tile([0.0, 0.0, 9.81], (n, 1))
    psi = 0.5 * t
    mag = np.column_stack([20.0 * np.sin(psi), 20.0 * np.cos(psi), np.full(n, -40.0)])
    rec = ImuRecording(t, gyr, acc, mag, name="thigh imu")
    return write_imu_csv(tmp_path / "thigh.csv", rec)


def test_run_writes_an_opensense_quaternion_table(tmp_path: Path) -> None:
    out = tmp_path / "o.sto"
    assert (
        main(["imu", "run", str(_csv_recording(tmp_path)), "--filter", "miller", "-o", str(out)])
        == 0
    )
    table = read_table(out)
    assert table.is_quaternion
    assert table.labels == ["thigh_imu"]
    assert table.data.shape == (200, 1, 4)
    # turning at 0.5 rad/s from heading 0: at 1.99 s the heading is 0.995 rad (to 0.5 deg)
    q = table.data[-1, 0]
    yaw = 2.0 * np.arctan2(q[3], q[0])
    assert yaw == pytest.approx(0.995, abs=np.radians(0.5))


@pytest.mark.shared_data
def test_run_on_a_multi_sensor_export(shared_data: Path, tmp_path: Path) -> None:
    out = tmp_path / "lower.sto"
    code = main(
        [
            "imu",
            "run",
            str(shared_data / "ximu3-lower-body"),
            "--filter",
            "bachmann",
            "-o",
            str(out),
        ]
    )
    assert code == 0
    table = read_table(out)
    assert len(table.labels) == 7
    assert "Left_Foot" in table.labels
    assert table.time[0] == 0.0
    np.testing.assert_allclose(np.linalg.norm(table.data, axis=2), 1.0, atol=1e-6)
    device = tmp_path / "device.sto"
    xsens = shared_data / "opensense" / "xsens" / "IMUData"
    assert main(["imu", "run", str(xsens), "--filter", "device", "-o", str(device)]) == 0
    assert read_table(device).data.shape == (2432, 8, 4)
    # the Xsens exports have no gyroscope: a clear error, exit code 1
    assert main(["imu", "run", str(xsens), "--filter", "miller", "-o", str(device)]) == 1


def test_run_sensor_selection_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _csv_recording(tmp_path)
    code = main(["imu", "run", str(path), "--filter", "miller", "--sensor", "x", "-o", "o.sto"])
    assert code == 1
    assert "--sensor x: not in" in capsys.readouterr().err


@pytest.mark.shared_data
def test_calibrate_mag(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = shared_data / "broad" / "02_undisturbed_slow_rotation_B.hdf5"
    out = tmp_path / "cal.csv"
    assert main(["imu", "calibrate-mag", str(path), "--json", "-o", str(out)]) == 0
    result = json.loads(capsys.readouterr().out)["sensors"]["02_undisturbed_slow_rotation_B"]
    assert result["model"] == "ellipsoid"
    assert result["calibrated_norm_std"] < result["raw_norm_std"]
    assert out.is_file()
    assert main(["imu", "calibrate-mag", str(path)]) == 0
    assert "hard iron" in capsys.readouterr().out


def test_calibrate_mag_needs_a_magnetometer(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    acc = np.tile([0.0, 0.0, 9.81], (20, 1))
    rec = ImuRecording(np.arange(20) / 100.0, np.zeros((20, 3)), acc, name="s")
    path = write_imu_csv(tmp_path / "s.csv", rec)
    assert main(["imu", "calibrate-mag", str(path)]) == 1
    assert "s: this recording has no magnetometer to calibrate" in capsys.readouterr().err


@pytest.mark.shared_data
def test_evaluate_offline(two_trials: Path, capsys: pytest.CaptureFixture[str]) -> None:
    base = ["imu", "evaluate", str(two_trials), "--filter", "polaris", "--json"]
    assert main(base) == 0
    online = json.loads(capsys.readouterr().out)
    assert main([*base, "--offline"]) == 0
    offline = json.loads(capsys.readouterr().out)
    # the forward-backward smoother is more accurate on both (BROAD: 2.02 -> 1.52 deg)
    assert offline["mean_total_deg"] < online["mean_total_deg"]
    assert main([*base[:4], "bachmann", "--offline"]) == 1
    assert "--offline: filter 'bachmann' has no offline mode" in capsys.readouterr().err


def test_run_holds_and_names_a_time_gap(tmp_path: Path) -> None:
    # 100 s missing from the time column: the filter must not integrate the next reading
    # over it (it turned 50 rad "in" the gap); a warning names the sample and the length
    n = 400
    t = np.arange(n) / 100.0
    t[200:] += 100.0
    rec = ImuRecording(t, np.zeros((n, 3)), np.tile([0.0, 0.0, 9.81], (n, 1)), name="s")
    src = write_imu_csv(tmp_path / "gap.csv", rec)
    out = tmp_path / "o.sto"
    with pytest.warns(TimeGapWarning, match=r"time gap of 100 s before sample 200"):
        assert main(["imu", "run", str(src), "--filter", "polaris", "-o", str(out)]) == 0
    q = read_table(out).data[:, 0]
    assert np.degrees(2 * np.arccos(np.clip(np.abs(q[:, 0]), 0, 1))).max() < 1.0
    out2 = tmp_path / "o2.sto"
    with pytest.warns(TimeGapWarning, match=r"time gap"):
        assert (
            main(["imu", "run", str(src), "--filter", "polaris", "--offline", "-o", str(out2)]) == 0
        )


def test_run_output_follows_the_extension(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = _csv_recording(tmp_path)
    out = tmp_path / "q.csv"
    argv = ["imu", "run", str(src), "--filter", "miller", "-o", str(out), "--json"]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert (summary["rows"], summary["sensors"]) == (200, ["thigh_imu"])
    table = np.loadtxt(out, delimiter=",", skiprows=1)
    assert (
        out.read_text().splitlines()[0] == "time_s,thigh_imu_w,thigh_imu_x,thigh_imu_y,thigh_imu_z"
    )
    assert table.shape == (200, 5)
    np.testing.assert_allclose(np.linalg.norm(table[:, 1:], axis=1), 1.0, atol=1e-9)
    assert main(["imu", "run", str(src), "--filter", "miller", "-o", str(tmp_path / "q.txt")]) == 1
    assert "the output format follows the extension" in capsys.readouterr().err
