"""``mocapkit markers`` in process: the JSON contract, the report, inspect, bad arguments."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from mocapkit.cli.main import main


@pytest.fixture
def gait(shared_data: Path) -> Path:
    return shared_data / "opensim" / "gait2392"


def test_reconstruct_json(gait: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "walk.mot"
    code = main([
        "markers", "reconstruct", str(gait / "subject01_walk1.trc"), "--static",
        str(gait / "subject01_static.trc"), "--method", "ik", "--height-m", "1.8034",
        "--mass-kg", "72.6", "--end-s", "0.5", "-o", str(out), "--json",
    ])  # fmt: skip
    assert code == 0
    figures = json.loads(capsys.readouterr().out)
    assert list(figures) == [
        "frames",
        "solve_fps",
        "marker_rms_mm",
        "marker_max_mm",
        "joint_error_bound_deg_max",
        "fps",
        "seconds",
    ]
    assert figures["fps"] < figures["solve_fps"]  # the whole command includes the loop
    assert figures["frames"] == 31
    assert 0 < figures["marker_rms_mm"] < 30
    assert out.read_text().startswith("mocapkit_markers")


def test_report_and_inspect(gait: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main([
        "markers", "report", str(gait / "subject01_walk1.trc"), "--static",
        str(gait / "subject01_static.trc"), "--grouping", "paper", "--end-s", "0.5",
        "--reference", str(gait / "reference" / "OutputReference_subject01_walk1_ik.mot"),
        "-o", str(tmp_path / "rep"), "--json",
    ])  # fmt: skip
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["levels"][:2] == [["R.Acromium", "L.Wrist.Lat"], ["L.Elbow", "R.Wrist.Lat"]]
    assert len(summary["levels"]) == 3  # the paper's two subsets, then every other marker
    # issue 12: the paper's grouping gave all-NaN angles and a bound of 0.0; the held
    # subtalar/mtp (bound 0 by construction) no longer count
    assert summary["metrics"]["joint_error_bound_deg_max"] > 0.0
    assert (tmp_path / "rep" / "fig3_markers.png").is_file()
    assert main([
        "markers", "report", str(gait / "subject01_walk1.trc"), "--static",
        str(gait / "subject01_static.trc"), "--grouping", "paper-only", "--end-s", "0.5",
        "-o", str(tmp_path / "rep2"),
    ]) == 1  # fmt: skip
    assert "determine no joint angle of the model" in capsys.readouterr().err
    assert main(["markers", "inspect", str(gait / "subject01_walk1.trc"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["frames"] == 151
    assert info["declared_units"] == "mm"


def test_bad_arguments(gait: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    trial = str(gait / "subject01_walk1.trc")
    assert main(["markers", "reconstruct", trial, "-o", str(tmp_path / "x.txt")]) == 1
    assert "expected a .mot or .csv file name" in capsys.readouterr().err
    assert (
        main(
            ["markers", "reconstruct", trial, "--markerset", "nope", "-o", str(tmp_path / "x.mot")]
        )
        == 1
    )
    assert "marker set 'nope': not a preset" in capsys.readouterr().err
    assert (
        main(["markers", "reconstruct", str(tmp_path / "none.trc"), "-o", str(tmp_path / "x.mot")])
        == 1
    )
    assert "no such marker file" in capsys.readouterr().err
    assert main(["markers", "reconstruct", trial]) == 2  # -o is required


def test_tracked_c3d_overlays_the_trial_with_its_force_plates(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import numpy as np

    from mocapkit.io.c3d import read_c3d

    trial_path = shared_data / "c3d" / "walking2.c3d"
    out = tmp_path / "tracked.c3d"
    assert main([
        "markers", "reconstruct", str(trial_path), "--markerset", "walking2", "--method",
        "ik", "--start-s", "2.0", "--end-s", "2.4", "-o", str(tmp_path / "w.mot"),
        "--tracked-c3d", str(out), "--json",
    ]) == 0  # fmt: skip
    figures = json.loads(capsys.readouterr().out)
    tracked, trial = read_c3d(out), read_c3d(trial_path).between(2.0, 2.4)
    assert tracked.n_frames == trial.n_frames
    common = [n for n in tracked.names if n in trial.names]
    d = np.linalg.norm(tracked.select(common).positions - trial.select(common).positions, axis=2)
    # the same axes and units as the trial: the model's markers sit on the captured ones
    # (mean distance = the fit's residual, a few mm; a wrong axis would be metres off)
    assert np.nanmean(d) * 1000 < 2.0 * figures["marker_rms_mm"]
    ex = tracked.meta["c3d"]
    assert ex.analogs.shape == (trial.n_frames * 8, 12)
    assert int(ex.groups["FORCE_PLATFORM"]["USED"][0]) == 2
