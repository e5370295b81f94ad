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
    out = subprocess.run([sys.executable, str(tools), "--check"], check=False)
    assert out.returncode == 0, "docs/api.md is stale: run python tools/gen_api_docs.py"
