"""imu run on a mocapkit CSV streams it piece by piece: the same orientations as one run
over the whole recording, in bounded memory."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mocapkit.cli.main import main
from mocapkit.errors import ConfigError
from mocapkit.imu.filters import make_filter
from mocapkit.imu.filters.base import recording_steps
from mocapkit.imu.streaming import run_file_offline, run_file_streaming
from mocapkit.io.imu_csv import iter_imu_csv, read_imu_csv, write_imu_csv
from mocapkit.io.opensim_table import read_table
from mocapkit.series import ImuRecording


def _recording(path: Path, n: int = 5000, lost: bool = True) -> ImuRecording:
    t = np.arange(n) / 100.0
    rng = np.random.default_rng(3)
    gyr = np.column_stack([np.sin(0.7 * t), np.sin(1.1 * t), np.sin(0.3 * t)])
    gyr = gyr + 0.01 * rng.normal(size=(n, 3))
    acc = np.tile([0.0, 0.0, 9.81], (n, 1)) + 0.05 * rng.normal(size=(n, 3))
    mag = np.tile([0.0, 20.0, -40.0], (n, 1)) + 0.3 * rng.normal(size=(n, 3))
    keep = np.ones(n, dtype=bool)
    if lost:
        keep[2003:2007] = False  # lost packets inside a piece
        keep[2104:2106] = False  # and before the first row of a piece of 700 (row 2100)
    rec = ImuRecording(t[keep], gyr[keep], acc[keep], mag[keep], name="left shank")
    write_imu_csv(path, rec)
    return read_imu_csv(path)  # as written (the CSV's precision)


@pytest.mark.parametrize("mode", ["9d", "6d"])
def test_pieces_give_the_whole_run(tmp_path: Path, mode: str) -> None:
    src = tmp_path / "s.csv"
    rec = _recording(src)
    # the stream takes the rate from its first piece (the whole file's median interval
    # differs in the 14th digit, enough to flip a rest decision somewhere in 5,000 samples)
    rate = next(iter_imu_csv(src, chunk_rows=700)).rate_hz
    whole = make_filter("polaris", rate).run_recording(rec, use_mag=mode == "9d")
    out = tmp_path / "o.sto"
    rep = run_file_streaming(src, "polaris", out, mode=mode, chunk_rows=700)
    assert rep.chunks == 8
    assert rep.rows == rec.n_samples
    table = read_table(out)
    np.testing.assert_allclose(table.time, rec.time - rec.time[0], atol=1e-9)
    q = table.data[:, 0, :]
    # 1e-9: the table's 10 significant digits; the pieces themselves are exact
    np.testing.assert_allclose(q, whole.quat, atol=1e-9)


def test_the_csv_reader_in_pieces_equals_the_whole(tmp_path: Path) -> None:
    src = tmp_path / "s.csv"
    rec = _recording(src, n=1234, lost=False)
    pieces = list(iter_imu_csv(src, chunk_rows=100))
    assert [p.n_samples for p in pieces] == [100] * 12 + [34]
    np.testing.assert_array_equal(np.concatenate([p.gyr for p in pieces]), rec.gyr)
    assert {p.name for p in pieces} == {"left shank"}


def test_a_bad_cell_in_a_later_piece_is_named_with_its_line(tmp_path: Path) -> None:
    src = tmp_path / "s.csv"
    _recording(src, n=300, lost=False)
    lines = src.read_text().splitlines()
    header_lines = next(i for i, line in enumerate(lines) if line.startswith("time"))
    row = 250
    cells = lines[header_lines + 1 + row].split(",")
    cells[2] = "oops"
    lines[header_lines + 1 + row] = ",".join(cells)
    src.write_text("\n".join(lines) + "\n")
    with pytest.raises(Exception, match=rf"line {header_lines + 2 + row}, column 'gyr_y'"):
        list(iter_imu_csv(src, chunk_rows=100))


def test_imu_run_streams_a_csv(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = tmp_path / "s.csv"
    rec = _recording(src)
    out = tmp_path / "o.csv"
    assert main(["imu", "run", str(src), "--filter", "polaris", "-o", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["streamed"] is True
    assert report["rows"] == rec.n_samples
    assert report["sensors"] == ["left_shank"]
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    rate = next(iter_imu_csv(src)).rate_hz
    whole = make_filter("polaris", rate).run_recording(rec)
    np.testing.assert_allclose(data[:, 1:5], whole.quat, atol=1e-9)
    # offline: smoothed piece by piece through files on disk
    assert main(["imu", "run", str(src), "--filter", "polaris", "--offline", "-o",
                 str(tmp_path / "f.sto"), "--json"]) == 0  # fmt: skip
    report = json.loads(capsys.readouterr().out)
    assert report["streamed"] is True
    assert report["offline"] is True
    filt = make_filter("polaris", rate)
    smoothed = filt.run_offline(rec.gyr, rec.acc, rec.mag, dt=recording_steps(rec, filt.params.dt))
    np.testing.assert_allclose(read_table(tmp_path / "f.sto").data[:, 0], smoothed, atol=1e-9)


@pytest.mark.parametrize("mode", ["9d", "6d"])
def test_offline_pieces_on_disk_give_the_whole_smoother(tmp_path: Path, mode: str) -> None:
    src = tmp_path / "s.csv"
    rec = _recording(src)
    rate = next(iter_imu_csv(src, chunk_rows=700)).rate_hz
    filt = make_filter("polaris", rate)
    whole = filt.run_offline(rec.gyr, rec.acc, rec.mag if mode == "9d" else None,
                             dt=recording_steps(rec, filt.params.dt))  # fmt: skip
    out = tmp_path / "o.sto"
    work = tmp_path / "work"
    work.mkdir()
    rep = run_file_offline(src, "polaris", out, mode=mode, chunk_rows=700, workdir=work)
    assert (rep.chunks, rep.rows) == (8, rec.n_samples)
    assert not list(work.iterdir())  # the temporary files are gone
    table = read_table(out)
    np.testing.assert_allclose(table.time, rec.time - rec.time[0], atol=1e-9)
    # 1e-9: the table's 10 significant digits; the pieces themselves are exact
    np.testing.assert_allclose(table.data[:, 0, :], whole, atol=1e-9)


def test_offline_needs_a_filter_with_an_offline_mode(tmp_path: Path) -> None:
    src = tmp_path / "s.csv"
    _recording(src, n=300, lost=False)
    with pytest.raises(ConfigError, match="has no offline mode"):
        run_file_offline(src, "bachmann", tmp_path / "o.sto", workdir=tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == ["s.csv"]


def test_lost_samples_at_a_batch_start_are_integrated_as_in_one_run(tmp_path: Path) -> None:
    # live, samples come one by one: a step over lost packets is then always the first
    # of its batch, and takes the previous batch's last reading (the trapezoidal rule)
    rec = _recording(tmp_path / "s.csv", n=2400)
    steps = recording_steps(rec, 0.01)
    assert steps is not None
    assert (steps[2090:2110] > 0.015).any()  # lost packets in the one-by-one part
    whole = make_filter("polaris", 100.0).run(rec.gyr, rec.acc, rec.mag, dt=steps)
    f = make_filter("polaris", 100.0)
    parts = [f.run(rec.gyr[:2090], rec.acc[:2090], rec.mag[:2090], dt=steps[:2090])]
    for i in range(2090, 2110):
        parts.append(f.run(rec.gyr[i : i + 1], rec.acc[i : i + 1], rec.mag[i : i + 1],
                           dt=steps[i : i + 1]))  # fmt: skip
    parts.append(f.run(rec.gyr[2110:], rec.acc[2110:], rec.mag[2110:], dt=steps[2110:]))
    np.testing.assert_allclose(np.concatenate(parts), whole, atol=1e-12)


def _broad(path: Path, n: int = 3000) -> Path:
    """A BROAD-like .hdf5 trial (the datasets and attribute its reader needs)."""
    import h5py

    rec = _recording(path.with_suffix(".csv"), n=n, lost=False)
    with h5py.File(path, "w") as f:
        f.attrs["sampling_rate"] = 100.0
        f["imu_gyr"], f["imu_acc"], f["imu_mag"] = rec.gyr, rec.acc, rec.mag
        f["opt_quat"] = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        f["movement"] = np.ones(n, dtype=bool)
    return path


def test_a_broad_trial_streams_as_the_whole_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from mocapkit.io.broad import iter_broad_imu, read_broad_trial

    src = _broad(tmp_path / "trial.hdf5")
    rec = read_broad_trial(src).imu
    pieces = list(iter_broad_imu(src, chunk_rows=700))
    assert [p.n_samples for p in pieces] == [700, 700, 700, 700, 200]
    np.testing.assert_array_equal(np.concatenate([p.time for p in pieces]), rec.time)
    np.testing.assert_array_equal(np.concatenate([p.gyr for p in pieces]), rec.gyr)
    # the rate from the first piece's steps, as the stream takes it (test above)
    rate = pieces[0].rate_hz
    whole = make_filter("polaris", rate).run_recording(rec)
    rep = run_file_streaming(src, "polaris", tmp_path / "o.sto", chunk_rows=700)
    assert (rep.chunks, rep.rows, rep.sensor) == (5, 3000, "trial")
    np.testing.assert_allclose(read_table(tmp_path / "o.sto").data[:, 0], whole.quat, atol=1e-9)
    filt = make_filter("polaris", rate)
    smoothed = filt.run_offline(rec.gyr, rec.acc, rec.mag, dt=recording_steps(rec, filt.params.dt))
    run_file_offline(src, "polaris", tmp_path / "s.sto", chunk_rows=700, workdir=tmp_path)
    np.testing.assert_allclose(read_table(tmp_path / "s.sto").data[:, 0], smoothed, atol=1e-9)
    rc = main(
        ["imu", "run", str(src), "--filter", "polaris", "-o", str(tmp_path / "c.sto"), "--json"]
    )
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["streamed"] is True
    assert out["rows"] == 3000


def test_a_broad_trial_with_rows_missing_is_named(tmp_path: Path) -> None:
    import h5py

    from mocapkit.errors import FileFormatError
    from mocapkit.io.broad import iter_broad_imu

    src = _broad(tmp_path / "trial.hdf5", n=500)
    with h5py.File(src, "a") as f:
        del f["imu_mag"]
        f["imu_mag"] = np.zeros((400, 3))
    with pytest.raises(FileFormatError, match="imu_gyr has 500 rows, imu_acc 500, imu_mag 400"):
        list(iter_broad_imu(src))


def test_the_rest_bias_is_removed_piece_by_piece(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``imu run FILE.csv --remove-gyr-bias`` streams: the first rest period's bias found
    reading ahead, then taken out of every piece, as from the whole recording."""
    from mocapkit.imu.calibration import calibrate_from_rest, remove_gyro_bias

    n = 3000
    t = np.arange(n) / 100.0
    rng = np.random.default_rng(8)
    gyr = np.column_stack([np.sin(0.7 * t), np.sin(1.1 * t), np.sin(0.3 * t)])
    gyr[:300] = [0.01, -0.02, 0.005] + 0.001 * rng.normal(size=(300, 3))
    acc = np.tile([0.0, 0.0, 9.81], (n, 1)) + 0.01 * rng.normal(size=(n, 3))
    mag = np.tile([0.0, 20.0, -40.0], (n, 1))
    write_imu_csv(tmp_path / "s.csv", ImuRecording(t, gyr, acc, mag, name="wrist"))
    rec = read_imu_csv(tmp_path / "s.csv")
    rate = next(iter_imu_csv(tmp_path / "s.csv", chunk_rows=700)).rate_hz
    fixed = remove_gyro_bias(rec, calibrate_from_rest(rec, use_mag=False).gyr_bias)
    whole = make_filter("polaris", rate).run_recording(fixed)
    run_file_streaming(tmp_path / "s.csv", "polaris", tmp_path / "o.sto", chunk_rows=700,
                       remove_gyr_bias=True)  # fmt: skip
    np.testing.assert_allclose(read_table(tmp_path / "o.sto").data[:, 0], whole.quat, atol=1e-9)
    rc = main(["imu", "run", str(tmp_path / "s.csv"), "--filter", "polaris", "--remove-gyr-bias",
               "-o", str(tmp_path / "c.sto"), "--json"])  # fmt: skip
    assert rc == 0
    assert json.loads(capsys.readouterr().out)["streamed"] is True
