"""The whole pipeline on OpenSim's gait2392 tutorial trial, and every bad-input path."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import ConfigError, DataError
from mocapkit.io.trc import read_trc, write_trc
from mocapkit.markers.reconstruct import ReconstructionOptions, run
from mocapkit.markers.trajectories import MarkerTrajectories
from mocapkit.viz.marker_report import agreement, write_report

OPENSIM_RMS_31_MM = 22.1  # OpenSim 4.6 IK on this trial (docs/benchmarks.md)
SAGITTAL = [
    "hip_flexion_r",
    "knee_angle_r",
    "ankle_angle_r",
    "hip_flexion_l",
    "knee_angle_l",
    "ankle_angle_l",
]
OPENSIM_31 = [
    "Sternum", "R.Acromium", "L.Acromium", "Top.Head", "R.ASIS", "L.ASIS", "V.Sacral",
    "R.Thigh.Upper", "R.Thigh.Front", "R.Thigh.Rear", "R.Shank.Upper", "R.Shank.Front",
    "R.Shank.Rear", "R.Heel", "R.Midfoot.Sup", "R.Midfoot.Lat", "R.Toe.Lat", "R.Toe.Med",
    "R.Toe.Tip", "L.Thigh.Upper", "L.Thigh.Front", "L.Thigh.Rear", "L.Shank.Upper",
    "L.Shank.Front", "L.Shank.Rear", "L.Heel", "L.Midfoot.Sup", "L.Midfoot.Lat", "L.Toe.Lat",
    "L.Toe.Med", "L.Toe.Tip",
]  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize("method", ["osc", "ik"])
def test_gait2392_against_opensim(gait_runs: dict, gait_dir: Path, method: str) -> None:
    result, _subject, _ = gait_runs[method]
    m = result.metrics(OPENSIM_31)
    assert m["frames"] == 151
    assert m["marker_rms_mm"] < OPENSIM_RMS_31_MM  # the target: at or below OpenSim's
    ag = agreement(
        result, gait_dir / "reference" / "OutputReference_subject01_walk1_ik.mot", SAGITTAL
    )
    for col in SAGITTAL:
        # "within a few degrees": measured 0.3-3.1 deg RMS (the left ankle keeps a -2.7 deg
        # offset; our knee turns about Rajagopal's axis, 4 deg from gait2392's, and the
        # reference's knee sign is gait2392's, flipped by agreement())
        assert ag[col]["rms_diff_deg"] < 3.5, (col, ag[col])
        assert ag[col]["correlation"] > 0.98
    assert any("wrist_flex_r" in w for w in result.warnings)  # no hand markers: said so


def test_outputs(gait_runs: dict, tmp_path: Path) -> None:
    from mocapkit.io.opensim_table import read_table

    result, _, _ = gait_runs["osc"]
    mot = read_table(result.write_mot(tmp_path / "a.mot"))
    assert "wrist_flex_r" not in mot.labels  # never determined: left out
    np.testing.assert_allclose(
        mot.column("knee_angle_r"), np.degrees(result.column("knee_angle_r")), atol=1e-6
    )
    csv = (result.write_csv(tmp_path / "a.csv")).read_text().splitlines()
    assert csv[0].startswith("time_s,pelvis_tx_m,")
    back = read_trc(result.write_tracked_trc(tmp_path / "t.trc"))
    assert back.n_markers == len(result.marker_names)
    # TRC as OpenSim expects it: y up (the head above the heels), the trial's exact rate
    # (its time column is rounded to 0.017 s: 1 / median dt would say 58.8 Hz)
    assert back.rate_hz == 60.0
    assert (back.marker("Top.Head")[:, 1] - back.marker("R.Heel")[:, 1] > 1.3).all()
    np.testing.assert_allclose(np.diff(back.time), 1.0 / 60.0, atol=1e-9)
    summary = write_report(result, tmp_path / "rep")
    assert set(summary["figures"]) == {
        "fig2_joint_angles.png",
        "fig3_markers.png",
        "fig4_margins.png",
    }
    assert (tmp_path / "rep" / "fig4_margins.png").stat().st_size > 10_000


# -- bad input -------------------------------------------------------------------------------
def _copy(traj: MarkerTrajectories, path: Path, positions: np.ndarray | None = None,
          names: tuple[str, ...] | None = None, units: str = "mm") -> Path:  # fmt: skip
    t = MarkerTrajectories(
        traj.time, traj.positions if positions is None else positions,
        traj.names if names is None else names, meta={"rate_hz": traj.rate_hz},
    )  # fmt: skip
    return write_trc(path, t, units=units)


@pytest.fixture(scope="module")
def walk(gait_dir: Path) -> tuple[MarkerTrajectories, MarkerTrajectories]:
    return read_trc(gait_dir / "subject01_walk1.trc"), read_trc(gait_dir / "subject01_static.trc")


def _run(trial: Path, static: Path | None, **kw: object):  # type: ignore[no-untyped-def]
    opts = ReconstructionOptions(method="ik", end_s=0.3, **kw)  # type: ignore[arg-type]
    return run(trial, static, "gait2392", 1.8, 72.6, opts)


def test_missing_and_never_appearing_markers(walk: tuple, gait_dir: Path, tmp_path: Path,
                                             caplog: pytest.LogCaptureFixture) -> None:  # fmt: skip
    trial, _ = walk
    pos = trial.positions.copy()
    pos[:, trial.index("L.Toe.Tip")] = np.nan  # never appears
    keep = [i for i, n in enumerate(trial.names) if n not in ("L.Heel", "L.Midfoot.Sup")]
    p = _copy(trial, tmp_path / "t.trc", pos[:, keep], tuple(trial.names[i] for i in keep))
    with caplog.at_level(logging.WARNING):
        result, _, _ = _run(p, gait_dir / "subject01_static.trc")
    assert "markers L.Toe.Tip never appear (all frames missing); they are dropped" in caplog.text
    assert "L.Heel" not in result.marker_names
    assert result.n_frames > 0
    assert np.isfinite(result.column("knee_angle_l")).all()


def test_long_gap_leaves_coordinates_undetermined(
    walk: tuple, gait_dir: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    trial, _ = walk
    pos = trial.positions.copy()
    for name in ("R.Heel", "R.Midfoot.Sup", "R.Midfoot.Lat", "R.Toe.Lat", "R.Toe.Med", "R.Toe.Tip"):
        pos[5:15, trial.index(name)] = np.nan  # the whole right foot vanishes for 10 frames
    p = _copy(trial, tmp_path / "g.trc", pos)
    with caplog.at_level(logging.WARNING):
        result, _, _ = _run(
            p, gait_dir / "subject01_static.trc", fill_gaps="spline", max_gap_s=0.05
        )
    assert "gaps are not filled (longest: R.Heel, frames 5-14, 0.17 s)" in caplog.text
    ankle = result.column("ankle_angle_r")
    assert np.isnan(ankle[5:15]).all()
    assert np.isfinite(ankle[:5]).all()


def test_flipped_axes_and_wrong_units(walk: tuple, gait_dir: Path, tmp_path: Path,
                                      caplog: pytest.LogCaptureFixture) -> None:  # fmt: skip
    trial, static = walk
    R = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # y-up -> z-up
    st = _copy(static, tmp_path / "s.trc", static.positions @ R.T)
    tr = _copy(trial, tmp_path / "t.trc", trial.positions @ R.T)
    result, _, _ = _run(tr, st)  # TRC says y-up by convention; the body says z: detected
    assert result.n_frames == 19
    with pytest.raises(DataError, match="along z, but the up axis was given as y"):
        _run(tr, st, up_axis="y")
    mixed = _copy(trial, tmp_path / "m.trc")  # the trial stays y-up: the files disagree
    with pytest.raises(DataError, match="the two files use different axes"):
        _run(mixed, st)
    metres_label = _copy(trial, tmp_path / "u.trc", trial.positions * 1000.0, units="m")
    with caplog.at_level(logging.WARNING):
        result, _, _ = _run(metres_label, gait_dir / "subject01_static.trc")
    assert "the data look like millimetres" in caplog.text
    with pytest.raises(DataError, match="Fix: pass --units mm"):
        _run(metres_label, gait_dir / "subject01_static.trc", units="m")


def test_names_not_in_set_and_static_mismatch(
    walk: tuple, gait_dir: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    trial, static = walk
    names = tuple("Foo" if n == "R.Bicep" else n for n in trial.names)
    p = _copy(trial, tmp_path / "n.trc", names=names)
    with caplog.at_level(logging.WARNING):
        _run(p, gait_dir / "subject01_static.trc")
    assert "1 markers are not in marker set 'gait2392' and are ignored (Foo)" in caplog.text
    swapped = list(static.names)
    a, b = swapped.index("R.Thigh.Upper"), swapped.index("R.Thigh.Rear")
    pos = static.positions.copy()
    pos[:, [a, b]] = pos[:, [b, a]]
    pos[:, a] += [0.0, 80.0, 0.0]  # and moved: not the same subject's cluster
    st = _copy(static, tmp_path / "s.trc", pos)
    with pytest.raises(
        DataError, match="the static trial does not match the trial: markers R.Thigh"
    ):
        _run(gait_dir / "subject01_walk1.trc", st)
    other = _copy(trial, tmp_path / "o.trc", names=tuple(f"X{i}" for i in range(trial.n_markers)))
    with pytest.raises(DataError, match="none of its markers .* is in marker set 'gait2392'"):
        _run(other, gait_dir / "subject01_static.trc")


def test_unknown_options() -> None:
    with pytest.raises(ConfigError, match="method: expected 'osc' or 'ik'"):
        ReconstructionOptions(method="magic")  # type: ignore[arg-type]
