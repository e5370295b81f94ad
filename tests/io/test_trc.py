"""TRC read/write: round trips with gaps, the OpenSim tutorial file, malformed files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import FileFormatError
from mocapkit.io.trc import read_trc, write_trc
from mocapkit.markers.trajectories import MarkerTrajectories


def _traj() -> MarkerTrajectories:
    rng = np.random.default_rng(0)
    pos = rng.normal(size=(6, 3, 3))
    pos[2, 1] = np.nan  # a gap
    return MarkerTrajectories(np.arange(6) / 100.0, pos, ("A", "B.x", "C"), meta={"rate_hz": 100.0})


def test_round_trip_keeps_gaps(tmp_path: Path) -> None:
    traj = _traj()
    back = read_trc(write_trc(tmp_path / "a.trc", traj))
    assert back.names == traj.names
    assert back.rate_hz == 100.0
    # 6 decimals of mm in the file: 1e-9 m
    np.testing.assert_allclose(back.positions, traj.positions, atol=1e-9)
    assert not back.visible[2, 1]
    assert back.meta["up_axis"] == "y"


def test_units_override_and_metres(tmp_path: Path) -> None:
    p = write_trc(tmp_path / "m.trc", _traj(), units="m")
    assert read_trc(p).meta["units"] == "m"
    # 6 decimals of metres in the file (5e-7 m), read as millimetres: 5e-10 m
    expected = _traj().positions * 1e-3
    np.testing.assert_allclose(read_trc(p, units="mm").positions, expected, atol=1e-9)


def test_reads_opensim_walk(shared_data: Path) -> None:
    traj = read_trc(shared_data / "opensim" / "gait2392" / "subject01_walk1.trc")
    assert traj.n_frames == 151
    assert traj.n_markers == 41
    assert traj.rate_hz == 60.0
    assert "R.ASIS" in traj.names
    # the first R.ASIS sample is 617.24762 mm
    assert traj.marker("R.ASIS")[0, 0] == pytest.approx(0.61724762)


def test_bad_files(tmp_path: Path) -> None:
    p = tmp_path / "x.trc"
    p.write_text("hello\nworld\n")
    with pytest.raises(FileFormatError, match="not a TRC file"):
        read_trc(p)
    good = tmp_path / "g.trc"
    write_trc(good, _traj())
    text = good.read_text().splitlines()
    text[2] = text[2].replace("\t3\t", "\t4\t", 1)  # NumMarkers 4 but 3 names
    bad = tmp_path / "b.trc"
    bad.write_text("\n".join(text))
    with pytest.raises(FileFormatError, match="NumMarkers=4 but line 4 names 3"):
        read_trc(bad)
    text = good.read_text().replace("\tmm\t", "\tinches\t")
    bad.write_text(text)
    with pytest.raises(FileFormatError, match="unknown length unit 'inches'"):
        read_trc(bad)
