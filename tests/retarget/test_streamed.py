"""Joint-angle files retargeted piece by piece (retarget.streamed) against the whole path."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from mocapkit.errors import ConfigError, DataError
from mocapkit.retarget.run import retarget, write_trajectory
from mocapkit.retarget.streamed import retarget_streamed
from tests.body.synth import write_walk_mot

# with the collision guard (the default), two runs of the whole path differ this much (its
# near-contact decisions follow rounding: retarget.streamed docstring); the pieces must not
# differ more: mostly ~1e-6, up to ~1e-3 rad after such a flip
SOLVER_NOISE_RAD = 1e-2
SOLVER_NOISE_MEDIAN_RAD = 1e-4


def _close(a: np.ndarray, b: np.ndarray) -> None:
    e = np.abs(a - b).reshape(len(a), -1).max(axis=1)
    assert e.max() < SOLVER_NOISE_RAD
    assert np.median(e) < SOLVER_NOISE_MEDIAN_RAD


def _same_figures(a: dict, b: dict) -> None:
    assert a["keypoint_rmse_mm"] == pytest.approx(b["keypoint_rmse_mm"], abs=0.15)
    assert a["foot_skate_mm"] == pytest.approx(b["foot_skate_mm"], abs=0.01)
    for key in ("contact_frames", "ground_penetration", "limit_violations", "held_frames"):
        assert a[key] == b[key], key
    assert a["collisions"]["frames"] == b["collisions"]["frames"]


@pytest.mark.parametrize(("speed", "suffix"), [(1.2, ".csv"), (0.0, ".npz")])
def test_pieces_give_the_whole_paths_trajectory_figures_and_notes(tmp_path, speed, suffix):
    """Overground (translation in the file) and on a treadmill (the belt found over the
    whole recording, added back across the seams), 37-frame pieces."""
    still = 0.5 if speed else 0.0  # a still start would hide the belt
    mot = write_walk_mot(tmp_path / "walk.mot", duration_s=4.0, still_s=still, speed=speed)
    whole = retarget(mot, "g1")
    write_trajectory(tmp_path / f"whole{suffix}", whole)
    out = tmp_path / f"pieces{suffix}"
    res = retarget_streamed(mot, "g1", out, piece_frames=37)
    assert res.frames == whole.frames
    assert res.notes == whole.notes
    assert any("treadmill" in n for n in res.notes) == (speed == 0.0)
    assert (res.steered, res.stopped_short) == (whole.steered, whole.stopped_short)
    _same_figures(res.figures, whole.figures)
    if suffix == ".csv":
        a = np.loadtxt(tmp_path / "whole.csv", delimiter=",", skiprows=1)
        b = np.loadtxt(out, delimiter=",", skiprows=1)
        assert (
            out.read_text().splitlines()[0] == (tmp_path / "whole.csv").read_text().split("\n")[0]
        )
        assert a.shape == b.shape
        _close(a, b)
    else:
        with np.load(tmp_path / "whole.npz") as a, np.load(out) as b:
            assert sorted(a.files) == sorted(b.files)
            for k in a.files:
                assert a[k].shape == b[k].shape, k
                assert a[k].dtype == b[k].dtype, k
                if a[k].dtype.kind == "f":
                    _close(a[k], b[k])
                else:
                    assert np.array_equal(a[k], b[k]), k
    assert not list(tmp_path.glob("*.rows"))  # the npz rows' spill is gone


def test_mcap_in_pieces_holds_every_frame(tmp_path):
    from mcap.reader import make_reader

    mot = write_walk_mot(tmp_path / "walk.mot", duration_s=1.0, still_s=0.5)
    out = tmp_path / "g1.mcap"
    res = retarget_streamed(mot, "g1", out, piece_frames=23)
    with open(out, "rb") as f:
        topics = [ch.topic for _, ch, _ in make_reader(f).iter_messages()]
    assert topics.count("/robot/joints") == res.frames
    assert topics.count("/robot/tf") == res.frames


def _rows(mot) -> list[str]:
    lines = mot.read_text().splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader") + 2
    return lines[:head], lines[head:]


def test_time_going_back_in_a_later_piece_is_named_by_row(tmp_path):
    mot = write_walk_mot(tmp_path / "walk.mot", duration_s=1.0, still_s=0.5)
    head, rows = _rows(mot)
    rows[60], rows[61] = rows[61], rows[60]
    mot.write_text("\n".join(head + rows) + "\n")
    with pytest.raises(DataError, match="row 61"):
        retarget_streamed(mot, "g1", tmp_path / "out.csv", piece_frames=25)
    assert not (tmp_path / "out.csv").exists()


def test_an_infinite_angle_is_named_by_row_and_an_empty_file_refused(tmp_path):
    mot = write_walk_mot(tmp_path / "walk.mot", duration_s=1.0, still_s=0.5)
    head, rows = _rows(mot)
    cells = rows[70].split("\t")
    cells[3] = "inf"
    bad = tmp_path / "bad.mot"
    bad.write_text("\n".join([*head, *rows[:70], "\t".join(cells), *rows[71:]]) + "\n")
    with pytest.raises(DataError, match="row 70"):
        retarget_streamed(bad, "g1", None, piece_frames=25)
    empty = tmp_path / "empty.mot"
    empty.write_text("\n".join(head) + "\n")
    with pytest.raises(DataError, match="no frames"):
        retarget_streamed(empty, "g1", None)


def _write_then_fail(writer, whole) -> None:
    with writer as w:
        w.write(whole.solution, whole.targets)
        raise RuntimeError("the solve failed")


def test_a_failed_run_leaves_no_output(tmp_path):
    """A trajectory cut short must not look like a whole one."""
    from mocapkit.retarget.trajectory_io import TrajectoryWriter

    mot = write_walk_mot(tmp_path / "walk.mot", duration_s=0.5, still_s=0.5)
    whole = retarget(mot, "g1", check_collisions=False, guard_collisions=False)
    for suffix in (".csv", ".npz", ".mcap"):
        out = tmp_path / f"cut{suffix}"
        with pytest.raises(RuntimeError):
            _write_then_fail(TrajectoryWriter(out, whole.robot), whole)
        assert not out.exists(), suffix
        assert not list(tmp_path.glob("*.rows"))


def test_an_orientation_table_goes_through_the_body_model_in_pieces(tmp_path):
    """An OpenSense quaternion .sto (an IMU recording) was read as joint angles and
    refused with a shape error; now it goes through the body model, whole or streamed
    (the angles through a .mot on disk: 10 significant digits, far below the solver's
    noise)."""
    from mocapkit.body.calibration import pose_coordinates
    from mocapkit.body.sensor_tree import SensorTree
    from mocapkit.io.opensense import write_orientations_sto
    from tests.body.synth import gait_like, random_mountings, sensor_orientations

    tree = SensorTree.preset("full_body_15")
    t = np.arange(800) / 100.0
    coords = gait_like(tree, t, 1.0, pose_coordinates(tree, "npose"), seed=2)
    mounts = random_mountings(tree, np.random.default_rng(2))
    sto = write_orientations_sto(
        tmp_path / "suit.sto", sensor_orientations(tree, t, coords, mounts, heading_rad=0.3)
    )
    whole = retarget(sto, "g1")
    write_trajectory(tmp_path / "whole.csv", whole)
    out = tmp_path / "pieces.csv"
    res = retarget_streamed(sto, "g1", out, piece_frames=230)
    assert res.frames == whole.frames == t.size
    assert res.notes == whole.notes
    assert "inertial recording" in res.notes[0]
    _same_figures(res.figures, whole.figures)
    a = np.loadtxt(tmp_path / "whole.csv", delimiter=",", skiprows=1)
    _close(a, np.loadtxt(out, delimiter=",", skiprows=1))
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_a_marker_trial_is_reconstructed_and_retargeted_in_pieces(tmp_path):
    """Reconstructed piece by piece (configurations spilled), then the scaled model's
    segments through the same two passes: the whole path's notes, figures, trajectory."""
    from tests.markers.test_streamed import _synthetic_trc

    trc = _synthetic_trc(tmp_path / "walk.trc")
    # without the collision guard, whose near-contact decisions follow rounding (two whole
    # runs differ up to ~1e-2 rad here), the pieces give the whole trajectory to the bit
    kw = {"check_collisions": False, "guard_collisions": False}
    whole = retarget(trc, "g1", height_m=1.8, **kw)
    write_trajectory(tmp_path / "whole.csv", whole)
    out = tmp_path / "pieces.csv"
    res = retarget_streamed(trc, "g1", out, height_m=1.8, piece_frames=70, **kw)
    assert res.frames == whole.frames == 260
    # the same notes, but how poorly determined a joint is counts per piece when streamed
    # (markers.streamed docstring)
    poorly = "poorly determined"
    assert [n for n in res.notes if poorly not in n] == [n for n in whole.notes if poorly not in n]
    assert any(poorly in n for n in res.notes) == any(poorly in n for n in whole.notes)
    assert res.figures == whole.figures
    assert out.read_bytes() == (tmp_path / "whole.csv").read_bytes()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def _ximu3_export(tmp_path, seconds: float = 8.0):  # type: ignore[no-untyped-def]
    """A lower-body x-IMU3 export of a gait-like motion: per sensor a directory with the
    device's orientation (Quaternion.csv, NWU, each sensor on its own clock, 2 ms apart)
    and an Inertial.csv (which marks the directory as a sensor's)."""
    from mocapkit.body.calibration import pose_coordinates
    from mocapkit.body.sensor_tree import SensorTree
    from mocapkit.geometry import quat_conj, quat_mul
    from mocapkit.io.ximu3 import Q_ENU_NWU
    from tests.body.synth import gait_like, random_mountings, sensor_orientations

    tree = SensorTree.preset("lower_body")
    t = np.arange(int(seconds * 100)) / 100.0
    coords = gait_like(tree, t, 1.0, pose_coordinates(tree, "npose"), seed=5)
    mounts = random_mountings(tree, np.random.default_rng(5))
    oris = sensor_orientations(tree, t, coords, mounts, heading_rad=0.8)
    root = tmp_path / "export"
    for k, (name, s) in enumerate(oris.items()):
        d = root / f"{name} {0x64F00000 + k:08X} (UDP)"
        d.mkdir(parents=True)
        us = np.round((s.time + 0.002 * k) * 1e6)
        q = quat_mul(quat_conj(Q_ENU_NWU), s.quat)
        rows = "\n".join(f"{u:.0f},{w:.9f},{x:.9f},{y:.9f},{z:.9f}" for u, (w, x, y, z)
                         in zip(us, q, strict=True))  # fmt: skip
        (d / "Quaternion.csv").write_text("Timestamp (us),W,X,Y,Z\n" + rows + "\n")
        (d / "Inertial.csv").write_text(
            "Timestamp (us),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s),"
            "Accelerometer X (g),Accelerometer Y (g),Accelerometer Z (g)\n0,0,0,0,0,0,1\n"
        )
    return root


def test_an_ximu3_export_goes_through_the_body_model_in_pieces(tmp_path):
    """The devices' own orientations, as the whole path reads them: each sensor spilled
    to disk on its own clock, aligned onto one time base a piece at a time, through the
    streamed body model, then retargeted in pieces."""
    from mocapkit.retarget.streamed import streamable

    src = _ximu3_export(tmp_path)
    assert streamable(src)
    kw = {"preset": "lower_body", "guard_collisions": False}
    whole = retarget(src, "g1", **kw)  # type: ignore[arg-type]
    write_trajectory(tmp_path / "whole.csv", whole)
    res = retarget_streamed(src, "g1", tmp_path / "pieces.csv", piece_frames=170, **kw)  # type: ignore[arg-type]
    assert res.frames == whole.frames
    assert res.notes == whole.notes
    assert res.figures == whole.figures
    a = np.loadtxt(tmp_path / "whole.csv", delimiter=",", skiprows=1)
    b = np.loadtxt(tmp_path / "pieces.csv", delimiter=",", skiprows=1)
    # without the guard the pieces are the whole path's, but for the .mot on disk between
    # the body model and the solver (10 significant digits)
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-7)
    shutil.rmtree(next(src.glob("Right Foot*")))  # a sensor the tree needs, missing
    with pytest.raises(ConfigError, match="calcn_r <- 'Right Foot'"):
        retarget_streamed(src, "g1", tmp_path / "x.csv", **kw)  # type: ignore[arg-type]
