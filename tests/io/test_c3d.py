"""C3D through ezc3d: round trip with gaps, real files, unlabelled points dropped."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import FileFormatError
from mocapkit.io.c3d import read_c3d, write_c3d
from mocapkit.markers.trajectories import MarkerTrajectories


def _traj(names: tuple[str, ...] = ("A", "B", "C")) -> MarkerTrajectories:
    rng = np.random.default_rng(1)
    pos = rng.normal(size=(5, len(names), 3))
    pos[1, 0] = np.nan
    return MarkerTrajectories(np.arange(5) / 50.0, pos, names, meta={"rate_hz": 50.0})


def test_round_trip(tmp_path: Path) -> None:
    traj = _traj()
    back = read_c3d(write_c3d(tmp_path / "a.c3d", traj))
    assert back.names == traj.names
    assert back.rate_hz == 50.0
    # C3D stores float32 millimetres: ~1e-7 relative
    np.testing.assert_allclose(back.positions, traj.positions, atol=1e-6, rtol=1e-6)
    assert not back.visible[1, 0]


def test_unlabelled_points_are_dropped(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    p = write_c3d(tmp_path / "u.c3d", _traj(("Sub:A", "Sub:B", "*12")))
    with caplog.at_level(logging.WARNING):
        back = read_c3d(p)
    assert back.names == ("A", "B")  # prefix stripped, unlabelled dropped
    assert back.meta["label_prefix"] == "Sub:"
    assert "dropped 1 unlabelled points (*12)" in caplog.text


def test_real_files(shared_data: Path) -> None:
    cmu = read_c3d(shared_data / "c3d" / "cmu_85_02.c3d")
    assert cmu.n_markers == 41
    assert cmu.rate_hz == 120.0
    assert "LFHD" in cmu.names
    walk = read_c3d(shared_data / "c3d" / "walking2.c3d")
    assert walk.rate_hz == 250.0
    assert 0.3 < walk.visible.mean() < 0.7  # the subject walks through the volume


def test_not_a_c3d(tmp_path: Path) -> None:
    p = tmp_path / "bad.c3d"
    p.write_bytes(b"\x00" * 100)
    with pytest.raises(FileFormatError, match=r"damaged C3D \(no C3D signature"):
        read_c3d(p)


def test_analogs_force_plates_and_events_survive_read_and_write(
    shared_data: Path, tmp_path: Path
) -> None:
    import dataclasses

    trial = read_c3d(shared_data / "c3d" / "walking2.c3d")
    ex = trial.meta["c3d"]
    assert ex.analog_rate_hz == 2000.0
    assert ex.analog_labels[:3] == ("Fx1", "Fy1", "Fz1")
    assert ex.analogs.shape == (9992, 12)
    assert int(ex.groups["FORCE_PLATFORM"]["USED"][0]) == 2
    # walking2 has no events: add two, as a lab's gait events
    ev = dict(ex.groups["EVENT"])
    ev.update({"USED": np.array([2]), "LABELS": ["Foot Strike", "Foot Off"],
               "CONTEXTS": ["Right", "Left"], "DESCRIPTIONS": ["", ""],
               "SUBJECTS": ["s", "s"], "ICON_IDS": np.array([0, 0]),
               "GENERIC_FLAGS": np.array([0, 0]),
               "TIMES": np.array([[0.0, 0.0], [1.5, 2.25]])})  # fmt: skip
    ex = dataclasses.replace(ex, groups={**ex.groups, "EVENT": ev})
    back = read_c3d(write_c3d(tmp_path / "w.c3d", trial, ex))
    bx = back.meta["c3d"]
    np.testing.assert_array_equal(bx.analogs, ex.analogs)  # float32 on disk both ways
    assert bx.analog_labels == ex.analog_labels
    assert bx.analog_units == ex.analog_units
    for key in ("USED", "CORNERS", "ORIGIN", "CHANNEL", "TYPE", "CAL_MATRIX"):
        np.testing.assert_allclose(
            np.asarray(bx.groups["FORCE_PLATFORM"][key], dtype=float),
            np.asarray(ex.groups["FORCE_PLATFORM"][key], dtype=float),
            err_msg=key,
        )
    assert [(e.label, e.context, e.time_s) for e in bx.events] == [
        ("Foot Strike", "Right", 1.5),
        ("Foot Off", "Left", 2.25),
    ]
    # a crop keeps its analogs (8 samples a frame) and moves the events with it
    crop = trial.between(1.0, 2.0)
    cut = read_c3d(write_c3d(tmp_path / "c.c3d", crop, ex)).meta["c3d"]
    assert cut.analogs.shape == (crop.n_frames * 8, 12)
    first = round(1.0 * 2000)
    np.testing.assert_array_equal(cut.analogs, ex.analogs[first : first + crop.n_frames * 8])
    assert [(e.label, round(e.time_s, 9)) for e in cut.events] == [("Foot Strike", 0.5)]


def test_a_file_cut_short_is_reported(
    shared_data: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    raw = (shared_data / "c3d" / "cmu_85_02.c3d").read_bytes()
    p = tmp_path / "cut.c3d"
    p.write_bytes(raw[: len(raw) // 2])
    with caplog.at_level(logging.WARNING):
        traj = read_c3d(p)
    # issue 12: "a C3D cut in half reads 397 of 810 frames without a warning"
    assert traj.n_frames == 397
    assert "header announces 810 frames but only 397 are in the file" in caplog.text
    assert traj.meta["truncated"] == {"frames": 397, "declared": 810}


def test_more_frames_than_ezc3d_reads_back_are_refused(tmp_path: Path) -> None:
    from mocapkit.errors import DataError

    n = 65536 + 10
    rng = np.random.default_rng(2)
    traj = MarkerTrajectories(np.arange(n) / 100.0, rng.normal(size=(n, 1, 3)), ("A",),
                              meta={"rate_hz": 100.0})  # fmt: skip
    with pytest.raises(DataError, match="at most 65535 frames that it can read back"):
        write_c3d(tmp_path / "big.c3d", traj)
    # a file that holds them (ezc3d itself writes them, then reads back 65,535): refused
    import ezc3d

    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ("A",)
    c3d["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    pts = np.ones((4, 1, n))
    pts[:3] = rng.normal(size=(3, 1, n)) * 100.0
    c3d["data"]["points"] = pts
    c3d.write(str(tmp_path / "long.c3d"))
    with pytest.raises(DataError, match="holds more frames than the 65535 that C3D readers"):
        read_c3d(tmp_path / "long.c3d")
    ok = MarkerTrajectories(np.arange(65535) / 100.0, rng.normal(size=(65535, 1, 3)), ("A",),
                            meta={"rate_hz": 100.0})  # fmt: skip
    assert read_c3d(write_c3d(tmp_path / "max.c3d", ok)).n_frames == 65535


def test_unknown_unit_names_the_field_and_the_fix(tmp_path: Path) -> None:
    import ezc3d

    p = write_c3d(tmp_path / "u.c3d", _traj())
    c3d = ezc3d.c3d(str(p))
    c3d["parameters"]["POINT"]["UNITS"]["value"] = ["in"]
    c3d.write(str(tmp_path / "inches.c3d"))
    with pytest.raises(FileFormatError, match=r"POINT:UNITS: unknown length unit 'in'.*--units"):
        read_c3d(tmp_path / "inches.c3d")
    assert read_c3d(tmp_path / "inches.c3d", units="mm").n_markers == 3  # the override
