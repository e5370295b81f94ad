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
    with pytest.raises(FileFormatError, match="not a readable C3D file"):
        read_c3d(p)
