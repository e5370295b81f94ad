"""Gap filling and low-pass filtering on a trial kept on disk (mocapkit.markers.
streamed_cleaning) against the whole-trial cleaning: the same positions and the same
report, whatever the pieces, and through ``reconstruct_streamed`` the same files."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from mocapkit._spill import RowFile
from mocapkit.io.opensim_table import read_table
from mocapkit.markers.cleaning import fill_gaps, lowpass
from mocapkit.markers.reconstruct import ReconstructionOptions, run
from mocapkit.markers.streamed import reconstruct_streamed
from mocapkit.markers.streamed_cleaning import (
    fill_gaps_spilled,
    find_gaps_spilled,
    lowpass_spilled,
)
from mocapkit.markers.trajectories import MarkerTrajectories
from tests.markers.test_streamed import _figures, _synthetic_trc

NAMES = ("a", "b", "c", "d", "e")
CLUSTERS = {"a": ["b", "c", "d"], "b": ["a", "c", "d"], "c": ["a", "b", "d"], "d": ["a", "b", "c"]}


def _trial(n: int = 900, seed: int = 0) -> MarkerTrajectories:
    """Five markers on one rigid body turning and moving (a-d a cluster, e alone), with
    gaps of every kind: short interior ones (rigid and spline), one across a piece's
    edge, a long one left open, edge gaps, a marker never seen, short visible runs."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 100.0
    local = rng.normal(scale=0.1, size=(len(NAMES), 3))
    ang = 0.8 * np.sin(2 * np.pi * 0.7 * t)
    c, s = np.cos(ang), np.sin(ang)
    R = np.zeros((n, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    centre = np.column_stack([0.5 * t, 0.1 * np.sin(3 * t), 1.0 + 0.02 * np.cos(5 * t)])
    X = np.einsum("nij,mj->nmi", R, local) + centre[:, None]
    X += rng.normal(scale=0.002, size=X.shape)
    X[100:112, 0] = np.nan  # rigid (b, c, d visible)
    X[195:205, 4] = np.nan  # spline, across a piece's edge at 200
    X[300:310, 1] = np.nan
    X[303:306, 2] = np.nan  # b's donors c missing in part: rigid fails there, spline
    X[400:500, 3] = np.nan  # too long: left open
    X[:20, 2] = np.nan  # edge gaps
    X[880:, 1] = np.nan
    X[570:606, 4] = np.nan  # too long: left open
    X[606:610, 4] = 0.0  # a visible run of 4 frames (too short to low-pass)
    X[610:640, 4] = np.nan
    X[:, 4][X[:, 4, 0] == 0.0] = X[606:610, 4] + 1.0
    return MarkerTrajectories(t, X, NAMES, {"rate_hz": 100.0})


@pytest.fixture
def opened() -> Iterator[list[RowFile]]:
    """Row files a test opens, closed after it."""
    files: list[RowFile] = []
    yield files
    for f in files:
        f.close()


def _spill(
    tmp_path: Path, traj: MarkerTrajectories, opened: list[RowFile]
) -> tuple[RowFile, RowFile]:
    times = RowFile(tmp_path / "t.f64")
    pos = RowFile(tmp_path / "p.f64", (traj.n_markers, 3))
    opened += [times, pos]
    times.append(traj.time)
    for a in range(0, traj.n_frames, 77):
        pos.append(traj.positions[a : a + 77])
    return times, pos


@pytest.mark.parametrize("method", ["both", "rigid", "spline", "none"])
def test_fill_equals_the_whole_trial(tmp_path: Path, method: str, opened: list[RowFile]) -> None:
    traj = _trial()
    want, report = fill_gaps(traj, method, 0.25, CLUSTERS)
    times, pos = _spill(tmp_path, traj, opened)
    got = fill_gaps_spilled(times, pos, traj.n_frames, NAMES, 100.0, method, 0.25, CLUSTERS, 50)
    for field in ("gaps_found", "filled_rigid", "filled_spline", "left_open", "never_visible"):
        assert getattr(got, field) == getattr(report, field), field
    if method in ("both", "rigid"):
        assert got.filled_rigid
    if method in ("both", "spline"):
        assert got.filled_spline
    # the rigid fill reads the same numbers; the spline sees 64 samples either side
    np.testing.assert_allclose(pos.read(0, traj.n_frames), want.positions, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(np.isnan(pos.read(0, traj.n_frames)), np.isnan(want.positions))


def test_gaps_found_across_pieces_of_any_size(tmp_path: Path, opened: list[RowFile]) -> None:
    traj = _trial(n=400, seed=3)
    whole = fill_gaps(traj, "none")[1]
    _, pos = _spill(tmp_path, traj, opened)
    for chunk in (1, 7, 100, 400, 1000):
        gaps, never = find_gaps_spilled(
            lambda a, b: np.isfinite(pos.read(a, b)[..., 0]), traj.n_frames, NAMES, chunk
        )
        assert gaps == whole.gaps_found, chunk
        assert never == whole.never_visible


@pytest.mark.parametrize(("cutoff", "chunk"), [(6.0, 50), (6.0, 1000), (1.0, 120)])
def test_lowpass_equals_the_whole_trial(
    tmp_path: Path, cutoff: float, chunk: int, opened: list[RowFile]
) -> None:
    traj = fill_gaps(_trial(), "both", 0.25, CLUSTERS)[0]
    want, report = lowpass(traj, cutoff)
    _, pos = _spill(tmp_path, traj, opened)
    out = RowFile(tmp_path / "o.f64", (traj.n_markers, 3))
    opened.append(out)
    got = type(report)()
    lowpass_spilled(pos, out, traj.n_frames, NAMES, 100.0, cutoff, got, chunk)
    assert got.unfiltered_runs == report.unfiltered_runs
    assert ("e", 606, 610) in got.unfiltered_runs
    assert got.lowpass_hz == cutoff
    np.testing.assert_allclose(out.read(0, traj.n_frames), want.positions, rtol=0, atol=1e-11)


def test_reconstruct_streamed_fills_and_filters_as_the_whole_trial(tmp_path: Path) -> None:
    trial = _synthetic_trc(tmp_path / "walk.trc")
    opts = ReconstructionOptions(fill_gaps="both", lowpass_hz=6.0)
    result, _, _ = run(trial, None, "gait2392", 1.8, 72.0, opts)
    result.write_mot(tmp_path / "whole.mot")
    s = reconstruct_streamed(trial, None, "gait2392", 1.8, 72.0, opts, tmp_path / "st.mot",
                             chunk_frames=37)  # fmt: skip
    # the filtered positions agree to ~1e-12; the .mot prints 9 significant digits, so
    # a value on a rounding edge may print one unit apart
    ta, tb = read_table(tmp_path / "whole.mot"), read_table(tmp_path / "st.mot")
    assert ta.labels == tb.labels
    np.testing.assert_array_equal(ta.time, tb.time)
    np.testing.assert_allclose(ta.data, tb.data, rtol=1e-9, atol=1e-8)
    assert _figures(s.metrics) == pytest.approx(_figures(result.metrics()), rel=1e-6)
    poorly = "poorly determined"
    assert [w for w in s.warnings if poorly not in w] == [
        w for w in result.warnings if poorly not in w
    ]
    # the knee's 15-frame gap is filled: no "gaps are not filled" warning
    assert not any("gaps are not filled" in w for w in s.warnings)
