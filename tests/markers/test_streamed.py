"""The streamed marker reconstruction (mocapkit.markers.streamed) against the whole-trial
path: the same files and figures when cut into pieces, the same refusals."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import DataError
from mocapkit.io.opensim_table import read_table
from mocapkit.io.trc import TrcStream, read_trc, write_trc
from mocapkit.markers import streamed
from mocapkit.markers.cleaning import CleaningReport, fill_candidates, find_gaps
from mocapkit.markers.reconstruct import ReconstructionOptions, _Warnings, run, warn_open_gaps
from mocapkit.markers.streamed import reconstruct_streamed
from mocapkit.markers.streamed_cleaning import find_gaps_spilled
from mocapkit.markers.trajectories import MarkerTrajectories
from tests.markers import synthetic

TEST_DATA = Path(__file__).resolve().parents[1] / "data"
POORLY = "poorly determined"  # sampled per visibility pattern: per piece when streamed


def _synthetic_trc(path: Path, n: int = 260) -> Path:
    """A walking-like motion of the gait2392 model's markers (z-up, mm) with a gap, a
    marker that never appears and one that appears late."""
    human, ms = synthetic.subject()
    names = [m for m in ms.names if m in human.markers]
    X = synthetic.markers(human, names, synthetic.motion(human, n=n))
    X[60:75, names.index("R.Knee.Lat")] = np.nan
    X[:, names.index("L.Toe.Tip")] = np.nan
    X[:130, names.index("R.Heel")] = np.nan
    traj = MarkerTrajectories(np.arange(n) / 60.0, X, tuple(names), {"rate_hz": 60.0})
    return write_trc(path, traj, rate_hz=60.0)


def _whole(trial: Path, out: Path, **kw: object) -> tuple[dict, list[str]]:  # type: ignore[type-arg]
    result, _, _ = run(trial, kw.get("static"), kw.get("markerset", "gait2392"), 1.8,  # type: ignore[arg-type]
                       72.0, ReconstructionOptions(), ik_setup=kw.get("ik_setup"))  # type: ignore[arg-type]  # fmt: skip
    result.write_mot(out)
    if "tracked" in kw:
        result.write_tracked_trc(kw["tracked"])  # type: ignore[arg-type]
    return result.metrics(), result.warnings


def _figures(metrics: dict) -> dict:  # type: ignore[type-arg]
    return {k: v for k, v in metrics.items() if k != "solve_fps"}  # a rate, not a result


def _same_tables(a: Path, b: Path) -> None:
    ta, tb = read_table(a), read_table(b)
    assert ta.labels == tb.labels
    np.testing.assert_array_equal(ta.time, tb.time)
    np.testing.assert_array_equal(np.isnan(ta.data), np.isnan(tb.data))
    np.testing.assert_allclose(ta.data, tb.data, rtol=0, atol=1e-9)


def test_pieces_give_the_whole_trials_files_figures_and_warnings(tmp_path: Path) -> None:
    trial = _synthetic_trc(tmp_path / "walk.trc")
    metrics, warnings = _whole(trial, tmp_path / "whole.mot", tracked=tmp_path / "whole.trc")
    s = reconstruct_streamed(
        trial, None, "gait2392", 1.8, 72.0, ReconstructionOptions(), tmp_path / "st.mot",
        tracked_trc=tmp_path / "st.trc", chunk_frames=37,
    )  # fmt: skip
    _same_tables(tmp_path / "whole.mot", tmp_path / "st.mot")
    assert _figures(s.metrics) == _figures(metrics)
    assert [w for w in s.warnings if POORLY not in w] == [w for w in warnings if POORLY not in w]
    assert any("L.Toe.Tip never appear" in w for w in s.warnings)
    assert any("1 gaps are not filled (longest: R.Knee.Lat, frames 60-74" in w for w in s.warnings)
    whole_trc = (tmp_path / "whole.trc").read_text().splitlines()[1:]
    assert (tmp_path / "st.trc").read_text().splitlines()[1:] == whole_trc
    assert not list(tmp_path.glob("*.part"))


def test_csv_output_streamed(tmp_path: Path) -> None:
    trial = _synthetic_trc(tmp_path / "walk.trc", n=90)
    result, _, _ = run(trial, None, "gait2392", 1.8, 72.0, ReconstructionOptions())
    result.write_csv(tmp_path / "whole.csv")
    reconstruct_streamed(trial, None, "gait2392", 1.8, 72.0, ReconstructionOptions(),
                         tmp_path / "st.csv", chunk_frames=25)  # fmt: skip
    assert (tmp_path / "st.csv").read_text() == (tmp_path / "whole.csv").read_text()


def test_gait2392_walk_with_static_and_ik_setup(shared_data: Path, tmp_path: Path) -> None:
    """OpenSim's tutorial: static trial, IK setup (its time range crops the trial)."""
    gait = shared_data / "opensim" / "gait2392"
    kw = {"static": gait / "subject01_static.trc", "ik_setup": gait / "subject01_Setup_IK.xml"}
    metrics, warnings = _whole(gait / "subject01_walk1.trc", tmp_path / "whole.mot", **kw)
    s = reconstruct_streamed(
        gait / "subject01_walk1.trc", kw["static"], "gait2392", 1.8, 72.0,
        ReconstructionOptions(), tmp_path / "st.mot", ik_setup=kw["ik_setup"], chunk_frames=40,
    )  # fmt: skip
    _same_tables(tmp_path / "whole.mot", tmp_path / "st.mot")
    assert _figures(s.metrics) == _figures(metrics)
    assert metrics["frames"] == 121
    assert [w for w in s.warnings if POORLY not in w] == [w for w in warnings if POORLY not in w]


def test_a_marker_first_seen_after_the_head_is_kept(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Decisions come from the trial's start; which markers exist, from all of it."""
    monkeypatch.setattr(streamed, "HEAD_S", 1.0)
    trial = _synthetic_trc(tmp_path / "walk.trc")  # R.Heel appears at 2.17 s
    s = reconstruct_streamed(trial, None, "gait2392", 1.8, 72.0, ReconstructionOptions(),
                             tmp_path / "st.mot", chunk_frames=50)  # fmt: skip
    assert s.metrics["frames"] == 260
    assert not any("R.Heel" in w and "never appear" in w for w in s.warnings)
    assert np.isfinite(read_table(tmp_path / "st.mot").data).any(axis=0).all()


@pytest.mark.parametrize("seed", range(4))
def test_gap_tally_counts_what_the_whole_trial_finds(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n, m = 200, 5
    vis = rng.random((n, m)) > 0.15
    vis[:, 0] = True
    vis[:30, 1] = False  # an edge gap
    vis[-12:, 2] = False  # an edge gap at the end
    pos = np.where(vis[..., None], 1.0, np.nan) * np.ones((n, m, 3))
    names = tuple(f"m{i}" for i in range(m))
    gaps, _ = find_gaps(MarkerTrajectories(np.arange(n) / 100.0, pos, names))
    interior = [g for g in gaps if g.start > 0 and g.stop < n]
    chunk = int(rng.integers(3, 40))  # pieces that cut gaps anywhere
    report = CleaningReport()
    report.gaps_found, _ = find_gaps_spilled(lambda a, b: vis[a:b], n, names, chunk)
    fill_candidates(report, n, 100.0, "none", 0.0, None, names)
    warned = _Warnings()
    warn_open_gaps(report, n, 100.0, warned)
    assert f"{len(interior)} gaps are not filled" in str(list(warned))
    worst = max(interior, key=lambda g: g.length)
    assert list(warned)
    assert f"longest: {worst.marker}, frames {worst.start}-{worst.stop - 1}" in str(list(warned))


def test_trc_blocks_equal_the_whole_read() -> None:
    for p in sorted((TEST_DATA / "trc").glob("*.trc")):
        whole = read_trc(p)
        parts = list(TrcStream(p).blocks(rows=7))
        np.testing.assert_array_equal(np.concatenate([t for t, _ in parts]), whole.time)
        np.testing.assert_array_equal(np.concatenate([x for _, x in parts]), whole.positions)


def test_time_going_back_in_a_later_block_is_named(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    trial = _synthetic_trc(tmp_path / "walk.trc", n=120)
    lines = trial.read_text().splitlines()
    cells = lines[6 + 100].split("\t")
    cells[1] = "0.5"  # frame 100 at 0.5 s, after frame 99 at 1.65 s
    lines[6 + 100] = "\t".join(cells)
    trial.write_text("\n".join(lines) + "\n")
    monkeypatch.setattr(streamed, "READ_ROWS", 30)
    out = tmp_path / "st.mot"
    with pytest.raises(DataError, match="not strictly increasing at frame 100"):
        reconstruct_streamed(trial, None, "gait2392", 1.8, 72.0, ReconstructionOptions(), out)
    assert not out.exists()
    assert not list(tmp_path.glob("*.part"))


def test_a_crop_without_frames_is_refused(tmp_path: Path) -> None:
    trial = _synthetic_trc(tmp_path / "walk.trc", n=60)
    opts = ReconstructionOptions(start_s=5.0, end_s=6.0)
    with pytest.raises(DataError, match="no frame between 5.0 s and 6.0 s"):
        reconstruct_streamed(trial, None, "gait2392", 1.8, 72.0, opts, tmp_path / "o.mot")


def test_cli_streams_and_prints_the_same_figures(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from mocapkit.cli.main import main

    trial = _synthetic_trc(tmp_path / "walk.trc", n=90)
    metrics, _ = _whole(trial, tmp_path / "whole.mot")
    rc = main(["markers", "reconstruct", str(trial), "--markerset", "gait2392", "--height-m",
               "1.8", "--mass-kg", "72", "-o", str(tmp_path / "cli.mot"), "--json"])  # fmt: skip
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert {k: out[k] for k in metrics if k != "solve_fps"} == _figures(metrics)
    _same_tables(tmp_path / "whole.mot", tmp_path / "cli.mot")


def test_a_marker_partly_nan_in_a_later_block_is_named(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    trial = _synthetic_trc(tmp_path / "walk.trc", n=120)
    lines = trial.read_text().splitlines()
    cells = lines[6 + 95].split("\t")
    cells[3] = "NaN"  # the first marker's y in frame 95
    lines[6 + 95] = "\t".join(cells)
    trial.write_text("\n".join(lines) + "\n")
    monkeypatch.setattr(streamed, "READ_ROWS", 30)
    with pytest.raises(DataError, match="partly NaN at frame 95"):
        reconstruct_streamed(
            trial, None, "gait2392", 1.8, 72.0, ReconstructionOptions(), tmp_path / "o.mot"
        )


@pytest.mark.parametrize(
    "options",
    [ReconstructionOptions(method="ik"), ReconstructionOptions(mode="online")],
    ids=["ik", "online"],
)
def test_ik_and_online_mode_run_piece_by_piece(
    tmp_path: Path, options: ReconstructionOptions
) -> None:
    """IK warm-starts each piece from the last frame's solution (its first frame with the
    usual iterations, not the trial's first frame's); online mode steps the same
    controller on: the whole trial's files and figures."""
    assert streamed.streamable(tmp_path / "x.trc", options) is None
    trial = _synthetic_trc(tmp_path / "walk.trc", n=150)
    result, _, _ = run(trial, None, "gait2392", 1.8, 72.0, options)
    result.write_mot(tmp_path / "whole.mot")
    s = reconstruct_streamed(trial, None, "gait2392", 1.8, 72.0, options, tmp_path / "st.mot",
                             chunk_frames=37)  # fmt: skip
    _same_tables(tmp_path / "whole.mot", tmp_path / "st.mot")
    assert _figures(s.metrics) == _figures(result.metrics())
