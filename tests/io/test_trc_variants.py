"""Every TRC layout of OpenSim's own example files reads (tests/data/trc/SOURCE.md), and what
we write is what OpenSim 4's TRC reader accepts, gaps included."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from mocapkit.io.trc import read_trc, write_trc
from mocapkit.markers.trajectories import MarkerTrajectories
from tests.conftest import TEST_DATA, require_peer

TRC = TEST_DATA / "trc"

# file -> (frames, markers, rate Hz, first value of the first marker seen in the file [m])
VARIANTS = {
    "exampleFormat.trc": (5, 3, 100.0, ("marker2", 0, -0.152)),
    "dataWithEformat.trc": (5, 14, 119.88012, ("RFAsuperior", 0, -0.273)),
    "dataWithNaNsOfDifferentCases.trc": (5, 14, 250.0, ("toe", 0, 0.175798014)),
    "gait10dof18musc_walk_CRLF_line_ending.trc": (10, 41, 60.0, ("R.ASIS", 0, 0.61724762)),
    "markers_walk_excerpt.trc": (20, 41, 100.0, ("R.Shoulder", 0, -0.65263)),
    "dataWithNaNsWithSpaces_excerpt.trc": (20, 42, 100.0, ("RASI", 0, 1.009526917)),
    "dataWithBlanksForMissingMarkers_excerpt.trc": (20, 40, 250.0, ("LTH3", 0, 3.65697339)),
    "std_walking2_markers_excerpt.trc": (20, 44, 25.0, None),
}


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_reads_every_variant(name: str) -> None:
    frames, markers, rate, probe = VARIANTS[name]
    traj = read_trc(TRC / name)
    assert traj.n_frames == frames
    assert traj.n_markers == markers
    assert traj.rate_hz == pytest.approx(rate, rel=1e-9)
    assert len(set(traj.names)) == markers
    assert all(n.strip() == n and n for n in traj.names)
    if probe is not None:
        marker, frame, x = probe
        # the file's first X value, converted to metres; 1e-12: text precision
        assert traj.marker(marker)[frame, 0] == pytest.approx(x, abs=1e-12)


def test_gaps_of_every_spelling_are_nan() -> None:
    ex = read_trc(TRC / "exampleFormat.trc")
    assert not ex.visible[0, 0]  # empty cells
    assert not ex.visible[2, 1]  # Nan, nan, NAN
    assert ex.visible.sum() == 13
    spaces = read_trc(TRC / "dataWithNaNsWithSpaces_excerpt.trc")
    assert not spaces.visible[0, spaces.index("LASI")]  # "       NaN"
    blanks = read_trc(TRC / "dataWithBlanksForMissingMarkers_excerpt.trc")
    assert 0.0 < blanks.visible.mean() < 0.5


def test_rounded_time_column_keeps_the_declared_rate(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING):
        traj = read_trc(TRC / "gait10dof18musc_walk_CRLF_line_ending.trc")
    assert traj.rate_hz == 60.0  # the time column says 0.017 s: rounding, not 58.8 Hz
    assert "DataRate" not in caplog.text
    with caplog.at_level(logging.WARNING):
        resampled = read_trc(TRC / "std_walking2_markers_excerpt.trc")
    assert "DataRate says 250 Hz but the time column advances 0.04 s" in caplog.text
    assert resampled.meta["declared_rate_hz"] == 250.0


def test_truncated_file_is_reported(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    text = (TRC / "markers_walk_excerpt.trc").read_text().splitlines()
    cut = [*text[:-8], text[-8][: len(text[-8]) // 2]]  # 7 rows gone, the last one cut
    p = tmp_path / "cut.trc"
    p.write_text("\n".join(cut) + "\n")
    with caplog.at_level(logging.WARNING):
        traj = read_trc(p)
    assert traj.n_frames == 13
    assert "announces 20 frames (NumFrames) but the file holds 13" in caplog.text
    assert "fewer than 125 cells" in caplog.text
    assert traj.meta["truncated"] == {"frames": 13, "declared": 20}


def _traj(n: int = 7) -> MarkerTrajectories:
    rng = np.random.default_rng(4)
    pos = rng.normal(size=(n, 3, 3))
    pos[2, 1] = np.nan
    pos[:, 2][[0, 4]] = np.nan  # the last marker missing: trailing cells of a row
    return MarkerTrajectories(
        1.5 + np.arange(n) / 60.0, pos, ("A", "B", "C"), meta={"rate_hz": 60.0}
    )


def test_written_rows_are_full_and_the_rate_exact(tmp_path: Path) -> None:
    traj = _traj()
    p = write_trc(tmp_path / "w.trc", traj)
    rows = p.read_text().splitlines()[6:]
    assert all(r.count("\t") == 2 + 3 * 3 - 1 for r in rows)  # no dropped trailing cells
    assert rows[0].split("\t")[-1] == "NaN"
    back = read_trc(p)
    assert back.rate_hz == 60.0
    np.testing.assert_allclose(back.time, traj.time, atol=1e-9)
    np.testing.assert_array_equal(back.visible, traj.visible)


def test_opensim_reads_what_we_write_with_gaps(tmp_path: Path) -> None:
    """OpenSim 4's TRCFileAdapter (which ends a row at its last non-empty cell and then
    refuses it) and its MarkerData read our file whole: every row, the gaps as NaN."""
    osim = require_peer("opensim")
    traj = _traj()
    p = write_trc(tmp_path / "w.trc", traj)
    table = osim.TimeSeriesTableVec3(str(p))
    assert table.getNumRows() == traj.n_frames
    assert list(table.getColumnLabels()) == list(traj.names)
    times = np.array(table.getIndependentColumn())
    np.testing.assert_allclose(times, traj.time, atol=1e-9)
    for m, name in enumerate(traj.names):
        col = table.getDependentColumn(name)
        got = np.array([[col[i][k] for k in range(3)] for i in range(traj.n_frames)])
        # millimetres with 6 decimals in the file: 1e-9 m
        np.testing.assert_allclose(got / 1000.0, traj.positions[:, m], atol=1e-9)
    md = osim.MarkerData(str(p))
    assert md.getNumFrames() == traj.n_frames
    assert md.getDataRate() == pytest.approx(60.0)


def test_numba_parser_equals_numpy_on_text_numbers() -> None:
    from mocapkit.io._parse_kernels import parse_floats

    rng = np.random.default_rng(5)
    vals = rng.normal(scale=10.0 ** rng.integers(-6, 6, 3000), size=3000)
    cells = [f"{v:.6f}" for v in vals[:1000]] + [f"{v:.9g}" for v in vals[1000:2000]]
    cells += [f"{v:.4E}" for v in vals[2000:]] + ["NaN", "nan", "-nan", "+1.5", "7"]
    text = "\t".join(cells) + "\n"
    out = np.empty(len(cells))
    n = parse_floats(np.frombuffer(text.encode(), dtype=np.uint8), out)
    ref = np.array([float(c) for c in cells])
    assert n == len(cells)
    # up to 15 significant digits the parse is exact (integer mantissa, exact powers of 10)
    np.testing.assert_array_equal(out, ref)
    bad = b"1.0\t2x\t3\n"
    assert parse_floats(np.frombuffer(bad, dtype=np.uint8), np.empty(3)) == -1 - 4
    assert parse_floats(np.frombuffer(b"1 2 3", dtype=np.uint8), np.empty(2)) < 0  # no room
