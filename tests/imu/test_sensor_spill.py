"""Several sensors on their own clocks streamed (mocapkit.imu.sensor_spill, the x-IMU3
path of ``imu run``): the same table as the whole-recording path, cut anywhere."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import ConfigError, FileFormatError
from mocapkit.imu.filters import make_filter
from mocapkit.imu.resample import common_time_base, resample_orientation
from mocapkit.imu.sensor_streams import run_sensors_streaming
from mocapkit.io.opensim_table import read_table, write_table
from mocapkit.io.ximu3 import (
    INERTIAL_COLUMNS,
    MAG_COLUMNS,
    iter_ximu3_sensor,
    read_ximu3_directory,
    read_ximu3_sensor,
)


def _export(root: Path, n: int = 700, rest: int = 0) -> Path:
    """Two x-IMU3 sensors on their own clocks (100 Hz, offset and slightly fast), each
    with a 40 Hz magnetometer that has a dropout; ``rest``: still for that many samples
    first (a gyroscope bias of a few tenths of a deg/s)."""
    rng = np.random.default_rng(4)
    for k, (name, t0, scale) in enumerate((("Thigh", 5.000, 1.0), ("Shank", 5.013, 1.0002))):
        d = root / f"{name} 64F0EB{k:02d} (UDP)"
        d.mkdir(parents=True)
        (d / "Command.json").write_text(json.dumps([{"ping": {"name": name}}]))
        t = t0 + scale * np.arange(n) / 100.0
        gyr = 40.0 * np.sin(np.outer(t, [1.1, 0.7, 0.3]) + k)  # deg/s
        acc = np.array([0.0, 0.0, 1.0]) + 0.05 * rng.standard_normal((n, 3))  # g
        gyr[:rest] = [0.5 - k, -0.3, 0.2] + 0.05 * rng.standard_normal((rest, 3))
        acc[:rest] = [0.0, 0.0, 1.0] + 0.001 * rng.standard_normal((rest, 3))
        rows = np.column_stack([np.round(t * 1e6), gyr, acc])
        np.savetxt(d / "Inertial.csv", rows, delimiter=",", fmt=["%d"] + ["%.6f"] * 6,
                   header=",".join(INERTIAL_COLUMNS), comments="")  # fmt: skip
        tm = t0 + 0.003 + np.arange(int(n * 0.4)) / 40.0
        tm = np.delete(tm, np.arange(100, 110))  # a dropout of 0.275 s: gaps
        mag = np.column_stack([np.cos(tm), np.sin(tm), np.full(tm.size, -0.8)]) * 0.5
        np.savetxt(d / "Magnetometer.csv", np.column_stack([np.round(tm * 1e6), mag]),
                   delimiter=",", fmt=["%d"] + ["%.6f"] * 3,
                   header=",".join(MAG_COLUMNS), comments="")  # fmt: skip
    return root


def _whole(root: Path, out: Path, remove_gyr_bias: bool = False) -> Path:
    """What ``imu run DIR --filter polaris [--remove-gyr-bias]`` wrote before it streamed."""
    from mocapkit.imu.calibration import calibrate_from_rest, remove_gyro_bias

    recs = read_ximu3_directory(root)
    if remove_gyr_bias:
        recs = {k: remove_gyro_bias(r, calibrate_from_rest(r, use_mag=False).gyr_bias)
                for k, r in recs.items()}  # fmt: skip
    series = [make_filter("polaris", r.rate_hz).run_recording(r, use_mag=True)
              for r in recs.values()]  # fmt: skip
    t = common_time_base(series)
    q = np.stack([resample_orientation(s, t) for s in series], axis=1)
    return write_table(out, t - t[0], [n for n in recs], q, name=root.stem)


def test_pieces_of_a_sensor_equal_the_whole_reader(tmp_path: Path) -> None:
    root = _export(tmp_path / "export")
    for d in sorted(p for p in root.iterdir()):
        whole = read_ximu3_sensor(d)
        parts = list(iter_ximu3_sensor(d, rows=37))
        assert len(parts) > 10
        for field in ("time", "gyr", "acc", "mag"):
            a, b = getattr(whole, field), np.concatenate([getattr(p, field) for p in parts])
            np.testing.assert_array_equal(a, b)
        assert np.isnan(whole.mag).any()  # the dropout is a gap in both


@pytest.mark.parametrize("rows", [53, 20_000])
def test_streamed_table_is_the_whole_paths(tmp_path: Path, rows: int) -> None:
    root = _export(tmp_path / "export")
    whole = _whole(root, tmp_path / "whole.sto")
    rep = run_sensors_streaming(root, "polaris", tmp_path / "st.sto", chunk_rows=rows)
    assert (tmp_path / "st.sto").read_text() == whole.read_text()
    assert rep.sensors == ["Shank", "Thigh"]
    assert rep.rows == len(whole.read_text().splitlines()) - 7


@pytest.mark.parametrize("rows", [53, 20_000])
def test_the_rest_bias_removed_in_pieces_as_from_the_whole(tmp_path: Path, rows: int) -> None:
    """``imu run --remove-gyr-bias``: each sensor's first rest period found reading ahead
    (mocapkit.imu.rest_streaming), its bias taken out of every piece."""
    root = _export(tmp_path / "export", rest=200)
    whole = _whole(root, tmp_path / "whole.sto", remove_gyr_bias=True)
    plain = _whole(root, tmp_path / "plain.sto")
    run_sensors_streaming(root, "polaris", tmp_path / "st.sto", chunk_rows=rows,
                        remove_gyr_bias=True)  # fmt: skip
    # the bias summed piece by piece: the whole mean's rounding, to a unit in its last digit
    a, b = read_table(tmp_path / "st.sto"), read_table(whole)
    np.testing.assert_array_equal(a.time, b.time)
    np.testing.assert_allclose(a.data, b.data, rtol=0, atol=1e-12)
    assert np.abs(read_table(plain).data - b.data).max() > 1e-3


def test_one_sensor_selected_keeps_its_own_clock(tmp_path: Path) -> None:
    root = _export(tmp_path / "export")
    rep = run_sensors_streaming(root, "polaris", tmp_path / "st.csv", sensors=["Thigh"],
                              chunk_rows=50)  # fmt: skip
    rec = read_ximu3_sensor(next(root.glob("Thigh*")))
    q = make_filter("polaris", rec.rate_hz).run_recording(rec, use_mag=True)
    table = np.loadtxt(tmp_path / "st.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(table[:, 0], rec.time - rec.time[0], atol=1e-9)
    np.testing.assert_allclose(table[:, 1:], q.quat, atol=1e-9)
    assert rep.rows == rec.n_samples
    with pytest.raises(ConfigError, match="--sensor Knee: not in .*sensors: Shank, Thigh"):
        run_sensors_streaming(root, "polaris", tmp_path / "x.sto", sensors=["Knee"])


def test_time_going_back_in_a_later_block_names_the_row(tmp_path: Path) -> None:
    root = _export(tmp_path / "export")
    f = next(root.glob("Shank*")) / "Inertial.csv"
    lines = f.read_text().splitlines()
    cells = lines[1 + 120].split(",")
    cells[0] = str(int(cells[0]) - 50_000)  # row 120 before row 119
    lines[1 + 120] = ",".join(cells)
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(FileFormatError, match="not increasing at data row 120 \\(line 122"):
        run_sensors_streaming(root, "polaris", tmp_path / "x.sto", chunk_rows=50)


def test_cli_streams_an_export(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from mocapkit.cli.main import main

    root = _export(tmp_path / "export")
    whole = _whole(root, tmp_path / "whole.sto")
    rc = main(["imu", "run", str(root), "--filter", "polaris", "-o", str(tmp_path / "c.sto"),
               "--json"])  # fmt: skip
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["streamed"] is True
    assert out["sensors"] == ["Shank", "Thigh"]
    assert (tmp_path / "c.sto").read_text() == whole.read_text()


def test_offline_smoothing_of_an_export_in_pieces(tmp_path: Path) -> None:
    """``imu run DIR --offline``: each sensor smoothed through files on disk, then
    resampled as the whole path does."""
    from mocapkit.imu.filters.base import recording_steps
    from mocapkit.series import OrientationSeries

    root = _export(tmp_path / "export")
    recs = read_ximu3_directory(root)
    series = []
    for r in recs.values():
        rate = next(iter_ximu3_sensor(next(root.glob(f"{r.name}*")), rows=53)).rate_hz
        f = make_filter("polaris", rate)
        q = f.run_offline(r.gyr, r.acc, r.mag, dt=recording_steps(r, f.params.dt))
        series.append(OrientationSeries(r.time, q, name=r.name))
    t = common_time_base(series)
    want = np.stack([resample_orientation(s, t) for s in series], axis=1)
    rep = run_sensors_streaming(root, "polaris", tmp_path / "st.sto", chunk_rows=53,
                              offline=True, workdir=tmp_path)  # fmt: skip
    got = read_table(tmp_path / "st.sto")
    np.testing.assert_allclose(got.time, t - t[0], atol=1e-9)
    np.testing.assert_allclose(got.data, want, rtol=0, atol=1e-9)
    assert rep.rows == len(t)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["export", "st.sto"]
    with pytest.raises(ConfigError, match="has no offline mode"):
        run_sensors_streaming(root, "bachmann", tmp_path / "b.sto", offline=True)
