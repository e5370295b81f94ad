"""The top-level Python API: importable names, keyword-only options, results as objects
with a DataFrame (units in the column names), and ``import mocapkit`` staying light."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import mocapkit

TRC = Path(__file__).resolve().parent / "data" / "trc" / "markers_walk_excerpt.trc"


def test_import_mocapkit_is_light() -> None:
    heavy = "('numpy', 'numba', 'scipy')"
    code = f"import sys, mocapkit; print(sorted(m for m in {heavy} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_names_and_keyword_only() -> None:
    for name in ("reconstruct", "read_c3d", "read_trc", "read_imu", "make_filter"):
        assert callable(getattr(mocapkit, name))
        assert getattr(mocapkit, name).__doc__
    with pytest.raises(TypeError):
        mocapkit.reconstruct(TRC, None, None)  # type: ignore[misc]  # options by keyword only
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        mocapkit.nope  # noqa: B018


def test_reconstruct_returns_angles_with_units() -> None:
    pytest.importorskip("pandas")
    rec = mocapkit.reconstruct(TRC, height_m=1.8)
    assert rec.angles.n_samples == rec.result.n_frames
    assert 0.0 < rec.rms_marker_error_m < 0.05
    df = rec.to_dataframe(degrees=True)
    assert df.index.name == "time_s"
    assert "knee_angle_r_deg" in df.columns
    assert "pelvis_tx_m" in df.columns
    knee = rec.angles.column("knee_angle_r")
    np.testing.assert_allclose(df["knee_angle_r_deg"].to_numpy(), np.degrees(knee))


def test_make_filter_and_read_imu(tmp_path: Path) -> None:
    from mocapkit.io.imu_csv import write_imu_csv
    from mocapkit.series import ImuRecording

    n = 100
    rec = ImuRecording(np.arange(n) / 100.0, np.zeros((n, 3)), np.tile([0.0, 0, 9.81], (n, 1)))
    src = write_imu_csv(tmp_path / "s.csv", rec)
    (got,) = mocapkit.read_imu(src).values()
    q = mocapkit.make_filter("polaris", got.rate_hz).run_recording(got)
    assert q.quat.shape == (n, 4)


def test_the_api_page_is_generated_from_the_docstrings() -> None:
    tools = Path(__file__).resolve().parents[1] / "tools" / "gen_api_docs.py"
    out = subprocess.run([sys.executable, str(tools), "--check"], check=False,
                         capture_output=True, text=True)  # fmt: skip
    if out.returncode == 2:
        pytest.skip(f"an extra is missing: {out.stderr.strip()}")
    assert out.returncode == 0, "docs/api.md is stale: run python tools/gen_api_docs.py"


def test_body_angles_from_a_table_and_from_series(tmp_path: Path) -> None:
    pytest.importorskip("pandas")
    from mocapkit.body.calibration import pose_coordinates
    from mocapkit.body.pipeline import run_body
    from mocapkit.body.sensor_tree import SensorTree
    from mocapkit.errors import ConfigError
    from mocapkit.io.opensense import write_orientations_sto
    from tests.body.synth import gait_like, random_mountings, sensor_orientations

    tree = SensorTree.preset("lower_body")
    t = np.arange(800) / 100.0
    coords = gait_like(tree, t, 1.0, pose_coordinates(tree, "npose"), seed=3)
    ori = sensor_orientations(tree, t, coords, random_mountings(tree, np.random.default_rng(3)), 0)
    path = write_orientations_sto(tmp_path / "legs.sto", ori)
    body = mocapkit.body_angles(path, preset="lower_body")
    want = run_body(tree, ori).body.angles
    assert body.angles.names == want.names
    np.testing.assert_allclose(body.angles.values, want.values, atol=1e-6)
    # the calibration finds the simulated motion: knee flexion as simulated
    knee = body.angles.column("knee_angle_r")
    assert np.sqrt(np.mean((knee - coords["knee_angle_r"]) ** 2)) < np.deg2rad(1.0)
    df = body.to_dataframe(degrees=True)
    np.testing.assert_allclose(df["knee_angle_r_deg"].to_numpy(), np.degrees(knee))
    assert set(body.segments) == set(tree.segment_names)
    again = mocapkit.body_angles(ori, preset="lower_body")  # {sensor: series} works too
    np.testing.assert_allclose(again.angles.values, body.angles.values, atol=1e-6)
    with pytest.raises(ConfigError, match="filter"):
        mocapkit.body_angles(ori, preset="lower_body", filter="polaris")
    with pytest.raises(TypeError):
        mocapkit.body_angles(path, "lower_body")  # type: ignore[misc]  # keyword-only


def test_retarget_a_reconstruction_onto_g1(tmp_path: Path) -> None:
    pytest.importorskip("pandas")
    pytest.importorskip("proxsuite", reason="the robots extra (pip install 'mocapkit[robots]')")
    pytest.importorskip("pinocchio", reason="the robots extra")
    rec = mocapkit.reconstruct(TRC, height_m=1.8)
    motion = mocapkit.retarget(rec, robot="g1")
    n = rec.angles.n_samples
    assert motion.robot == "g1"
    assert motion.q.shape == (n, len(motion.joint_names))
    assert motion.base.shape == (n, 7)
    np.testing.assert_allclose(np.linalg.norm(motion.base[:, 3:], axis=1), 1.0, atol=1e-9)
    assert motion.figures["limit_violations"] == {"position": 0, "velocity": 0}
    assert motion.figures["collisions"]["frames"] == 0
    df = motion.to_dataframe()
    assert list(df.columns[:7]) == ["base_x_m", "base_y_m", "base_z_m", "base_qw", "base_qx",
                                    "base_qy", "base_qz"]  # fmt: skip
    assert df.shape == (n, 7 + len(motion.joint_names))
    assert all(c.endswith("_rad") for c in df.columns[7:])
    out = motion.write(tmp_path / "walk_g1.csv")
    table = np.loadtxt(out, delimiter=",", skiprows=1)
    np.testing.assert_allclose(table[:, 8:], motion.q, rtol=1e-8, atol=1e-8)


def test_retarget_stays_callable_once_the_subpackage_is_imported() -> None:
    import mocapkit.retarget.robot_spec  # sets mocapkit.retarget to the package

    assert callable(mocapkit.retarget)
    with pytest.raises(TypeError):
        mocapkit.retarget(TRC, "g1")  # type: ignore[misc]  # options by keyword only
