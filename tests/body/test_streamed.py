"""The streamed body pipeline (``body angles`` on an orientation table, in pieces) equals
the whole-recording pipeline: calibration, joint angles, segment orientations, summary."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import mocapkit.body.functional as functional
import mocapkit.body.streamed as streamed
from mocapkit.body.calibration import pose_coordinates
from mocapkit.body.pipeline import run_body, summary
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import DataError
from mocapkit.io.joint_angles_mot import read_joint_angles_mot, write_joint_angles_mot
from mocapkit.io.opensense import read_orientations_sto, write_orientations_sto
from mocapkit.series import OrientationSeries
from tests.body.synth import gait_like, random_mountings, sensor_orientations


def _recording(tmp_path: Path, seconds: float = 20.0) -> tuple[SensorTree, Path]:
    """A full-body gait-like recording (still for 1 s) with a short and a long dropout
    of one sensor (the long one outlasts --max-hold-s) written as OpenSense's .sto."""
    tree = SensorTree.preset("full_body_15")
    t = np.arange(int(seconds * 100)) / 100.0
    coords = gait_like(tree, t, 1.0, pose_coordinates(tree, "npose"), seed=4)
    mounts = random_mountings(tree, np.random.default_rng(4))
    ori = sensor_orientations(tree, t, coords, mounts, heading_rad=0.4)
    name = tree.segments[5].sensor
    q = ori[name].quat.copy()
    q[1210:1240] = np.nan  # 0.3 s: held
    q[1500:1590] = np.nan  # 0.9 s: held 0.5 s, then unknown
    ori[name] = OrientationSeries(t, q, name=name)
    path = write_orientations_sto(tmp_path / "walk.sto", ori)
    return tree, path


def _assert_close(a: object, b: object, path: str = "", tol: float = 1e-9) -> None:
    """Nested dicts and lists equal, numbers to ``tol`` (relative or absolute)."""
    if isinstance(a, dict) and isinstance(b, dict):
        assert set(a) == set(b), path
        for k in a:
            _assert_close(a[k], b[k], f"{path}.{k}", tol)
    elif isinstance(a, list) and isinstance(b, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _assert_close(x, y, f"{path}[{i}]", tol)
    elif isinstance(a, float) and isinstance(b, float):
        assert a == pytest.approx(b, rel=tol, abs=tol), path
    else:
        assert a == b, path


@pytest.fixture
def short_windows(monkeypatch: pytest.MonkeyPatch) -> None:
    """Calibrate from 5 s of motion after a pose looked for in the first 3 s, so that a
    20 s recording has pieces past the calibration head (the defaults: 300 and 600 s)."""
    monkeypatch.setattr(functional, "MAX_MOTION_S", 5.0)
    monkeypatch.setattr(streamed, "MAX_MOTION_S", 5.0)
    monkeypatch.setattr(streamed, "HEAD_S", 3.0)


@pytest.mark.usefixtures("short_windows")
@pytest.mark.parametrize("dropout", ["nan", "hold"])
def test_streamed_equals_the_whole_recording(tmp_path: Path, dropout: str) -> None:
    tree, path = _recording(tmp_path)
    whole = run_body(tree, read_orientations_sto(path), dropout=dropout)
    write_joint_angles_mot(tmp_path / "whole.mot", whole.body.angles)
    done = streamed.stream_body(
        tree, path, output=tmp_path / "piece.mot", segments_output=tmp_path / "seg.sto",
        dropout=dropout, rows=97,
    )  # fmt: skip
    # the same samples, in arrays of another length: equal to the last bits or so; the
    # forearms' twist axis (the two-axis fit's second axis, in a flat valley of its least
    # squares) settles to ~1e-8 (its correction to ~1e-6 deg)
    _assert_close(done.calibration.to_dict(), whole.calibration.to_dict(), tol=1e-6)
    a = read_joint_angles_mot(tmp_path / "piece.mot")
    b = read_joint_angles_mot(tmp_path / "whole.mot")
    assert a.names == b.names
    assert a.n_samples == b.n_samples == 2000
    np.testing.assert_array_equal(a.time, b.time)
    np.testing.assert_allclose(a.values, b.values, atol=1e-8, equal_nan=True)  # NaN alike
    assert np.isnan(a.values).any()
    # the header's row count, filled in at the end, is the rows written
    assert "nRows=2000 " in (tmp_path / "piece.mot").read_text()[:200]
    seg = read_orientations_sto(tmp_path / "seg.sto")
    for name in tree.segment_names:
        np.testing.assert_allclose(seg[name].quat, whole.segments[name].quat, atol=1e-9,
                                   equal_nan=True)  # fmt: skip
    want = summary(whole)
    got = done.summary
    assert got["rate_hz"] == pytest.approx(want.pop("rate_hz"))
    got.pop("rate_hz")
    # degrees, to 1e-6 (the twist axis above)
    _assert_close(json.loads(json.dumps(got)), json.loads(json.dumps(want)), tol=1e-6)
    if dropout == "hold":
        assert got["held"] == {tree.segments[5].sensor: 80}


@pytest.mark.usefixtures("short_windows")
def test_crop_and_a_given_window(tmp_path: Path) -> None:
    tree, path = _recording(tmp_path)
    opts = {"start": 0.5, "stop": 17.0, "window": (0.5, 0.95)}
    whole = run_body(tree, read_orientations_sto(path), **opts)  # type: ignore[arg-type]
    done = streamed.stream_body(tree, path, output=tmp_path / "a.mot", rows=64, **opts)  # type: ignore[arg-type]
    a = read_joint_angles_mot(tmp_path / "a.mot")
    np.testing.assert_array_equal(a.time, whole.body.angles.time)
    np.testing.assert_allclose(a.values, whole.body.angles.values, atol=1e-9,
                               equal_nan=True)  # fmt: skip
    assert done.summary["n_frames"] == whole.body.angles.n_samples


def test_time_going_back_across_pieces_names_the_row(tmp_path: Path) -> None:
    tree, path = _recording(tmp_path, seconds=4.0)
    lines = path.read_text().splitlines()
    start = lines.index("endheader") + 2
    lines[start + 150], lines[start + 149] = lines[start + 149], lines[start + 150]
    path.write_text("\n".join(lines) + "\n")
    out = tmp_path / "angles.mot"
    with pytest.raises(DataError, match="row 150"):
        streamed.stream_body(tree, path, output=out, rows=150)
    assert not out.exists()  # the rows before the bad one are not left as a result


def test_no_still_pose_at_the_start_names_the_fix(tmp_path: Path) -> None:
    tree = SensorTree.preset("full_body_15")
    t = np.arange(800) / 100.0
    coords = gait_like(tree, t, 0.0, pose_coordinates(tree, "npose"), seed=1)
    ori = sensor_orientations(tree, t, coords, random_mountings(tree, np.random.default_rng(1)), 0)
    path = write_orientations_sto(tmp_path / "moving.sto", ori)
    with pytest.raises(Exception, match="--calib-window"):
        streamed.stream_body(tree, path)


def test_cli_streams_an_orientation_table(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from mocapkit.cli.main import main

    _, path = _recording(tmp_path, seconds=12.0)
    out = tmp_path / "angles.mot"
    assert main(["body", "angles", str(path), "--preset", "full_body_15", "-o", str(out),
                 "--json"]) == 0  # fmt: skip
    report = json.loads(capsys.readouterr().out)
    assert report["streamed"] is True
    assert report["n_frames"] == 1200
    assert read_joint_angles_mot(out).n_samples == 1200
    # the BVH needs the whole recording: the whole-recording path, same angles
    b_mot, bvh = str(tmp_path / "b.mot"), str(tmp_path / "b.bvh")
    assert main(["body", "angles", str(path), "--preset", "full_body_15", "-o", b_mot,
                 "--bvh", bvh, "--json"]) == 0  # fmt: skip
    report = json.loads(capsys.readouterr().out)
    assert report["streamed"] is False
    np.testing.assert_allclose(
        read_joint_angles_mot(out).values,
        read_joint_angles_mot(tmp_path / "b.mot").values,
        atol=1e-9,
    )


def _ximu3_export(tmp_path: Path) -> tuple[SensorTree, Path]:
    """A lower-body suit's raw samples (simulated, consumer grade, still for 2.5 s then
    gait-like) written as an x-IMU3 export, each sensor on a clock of its own."""
    from mocapkit.body.simulate import segment_poses, virtual_suit
    from mocapkit.io.ximu3 import INERTIAL_COLUMNS, MAG_COLUMNS, STANDARD_GRAVITY

    tree = SensorTree.preset("lower_body")
    t = np.arange(1500) / 100.0
    coords = gait_like(tree, t, 2.5, pose_coordinates(tree, "npose"), amplitude=0.3, seed=2)
    segs = segment_poses(tree, t, coords, heading_rad=0.4, speed=0.0)
    recs, _ = virtual_suit(tree, segs, np.random.default_rng(2), max_mount_deg=30.0)
    root = tmp_path / "export"
    for k, s in enumerate(tree.segments):
        rec = recs[s.sensor]
        d = root / f"{s.sensor} 64F0EB{k:02d} (UDP)"
        d.mkdir(parents=True)
        (d / "Command.json").write_text(json.dumps([{"ping": {"name": s.sensor}}]))
        us = np.round((rec.time + 100.0 + 0.0031 * k) * 1e6)  # its own clock
        np.savetxt(d / "Inertial.csv",
                   np.column_stack([us, np.degrees(rec.gyr), rec.acc / STANDARD_GRAVITY]),
                   delimiter=",", fmt=["%d"] + ["%.7f"] * 6,
                   header=",".join(INERTIAL_COLUMNS), comments="")  # fmt: skip
        np.savetxt(d / "Magnetometer.csv", np.column_stack([us, rec.mag]), delimiter=",",
                   fmt=["%d"] + ["%.5f"] * 3, header=",".join(MAG_COLUMNS),
                   comments="")  # fmt: skip
    return tree, root


@pytest.mark.usefixtures("short_windows")
def test_raw_samples_streamed_equal_the_whole_recording(tmp_path: Path) -> None:
    """An x-IMU3 export through polaris-body 9D: filtered, aligned onto one time base and
    turned into angles piece by piece, against the whole path (run_filter, run_body)."""
    from mocapkit.body.recordings import read_raw, run_filter
    from mocapkit.imu.sensor_spill import body_pieces
    from mocapkit.imu.sensor_streams import spill_filtered

    tree, root = _ximu3_export(tmp_path)
    whole = run_body(tree, run_filter(read_raw(root, "device"), "polaris-body", "9d"))
    write_joint_angles_mot(tmp_path / "whole.mot", whole.body.angles)
    spills = spill_filtered(root, "polaris-body", "9d", tmp_path, chunk_rows=211,
                         sensors=[s.sensor for s in tree.segments])  # fmt: skip
    try:
        done = streamed.stream_body(tree, root, output=tmp_path / "piece.mot",
                                    pieces=body_pieces(spills, rows=97))  # fmt: skip
    finally:
        for s in spills:
            s.close()
    _assert_close(done.calibration.to_dict(), whole.calibration.to_dict())
    a = read_joint_angles_mot(tmp_path / "piece.mot")
    b = read_joint_angles_mot(tmp_path / "whole.mot")
    assert a.names == b.names
    assert a.n_samples == b.n_samples > 1400
    np.testing.assert_array_equal(a.time, b.time)
    np.testing.assert_allclose(a.values, b.values, atol=1e-8)


def test_cli_streams_raw_samples_of_an_export(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from mocapkit.cli.main import main

    _, root = _ximu3_export(tmp_path)
    base = ["body", "angles", str(root), "--preset", "lower_body", "--filter", "polaris-body",
            "--json"]  # fmt: skip
    assert main([*base, "-o", str(tmp_path / "st.mot")]) == 0
    streamed_run = json.loads(capsys.readouterr().out)
    assert streamed_run["streamed"] is True
    # --start/--stop stream too: the filters run over the whole recording, then each
    # sensor is cropped before the sensors are aligned, as the whole path does
    assert main([*base, "--start", "100.4", "--stop", "111", "-o", str(tmp_path / "cr.mot")]) == 0
    assert json.loads(capsys.readouterr().out)["streamed"] is True
    from mocapkit.body.recordings import read_raw, run_filter

    tree = SensorTree.preset("lower_body")
    oris = run_filter(read_raw(root, "device"), "polaris-body", "9d")
    whole = run_body(tree, oris, start=100.4, stop=111.0, heading_alignment="hinges")
    a = read_joint_angles_mot(tmp_path / "cr.mot")
    assert a.time[0] >= 100.4
    assert a.time[-1] <= 111.0
    np.testing.assert_array_equal(a.time, np.round(whole.body.angles.time, 6))
    np.testing.assert_allclose(a.values, whole.body.angles.values, atol=1e-8)
    assert main([*base, "--start", "500", "-o", str(tmp_path / "none.mot")]) != 0
    assert "fewer than 2 samples between 500.0 and None s" in capsys.readouterr().err
    # a tree sensor the export lacks: the whole path's message, nothing written
    assert main([*base, "--map", "pelvis=Hips", "-o", str(tmp_path / "x.mot")]) != 0
    assert "no data for sensor(s) pelvis <- 'Hips'" in capsys.readouterr().err
    assert not (tmp_path / "x.mot").exists()


def test_cli_streams_an_exports_device_orientations(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Without --filter, an x-IMU3 export's own orientations (Quaternion.csv) go through
    in pieces too, cropped per sensor before they are aligned, as the whole path does."""
    from mocapkit.body.recordings import load_orientations
    from mocapkit.cli.main import main
    from tests.retarget.test_streamed import _ximu3_export as device_export

    root = device_export(tmp_path, seconds=12.0)
    tree = SensorTree.preset("lower_body")
    argv = ["body", "angles", str(root), "--preset", "lower_body", "--start", "0",
            "--stop", "10", "-o", str(tmp_path / "st.mot"), "--json"]  # fmt: skip
    assert main(argv) == 0
    assert json.loads(capsys.readouterr().out)["streamed"] is True
    whole = run_body(tree, load_orientations(root), start=0.0, stop=10.0)
    a = read_joint_angles_mot(tmp_path / "st.mot")
    assert a.names == whole.body.angles.names
    np.testing.assert_allclose(a.values, whole.body.angles.values, atol=1e-8)
