"""Shared, expensive fixtures of the marker tests (computed once per test session)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import SHARED_DATA


@pytest.fixture(scope="session")
def gait_dir() -> Path:
    if SHARED_DATA is None:
        pytest.skip("../shared/data is not present (set MOCAPKIT_SHARED_DATA to its path)")
    return SHARED_DATA / "opensim" / "gait2392"


@pytest.fixture(scope="session")
def gait_runs(gait_dir: Path) -> dict[str, object]:
    """OSC and IK reconstructions of subject01_walk1 (the benchmark trial)."""
    from mocapkit.markers.reconstruct import ReconstructionOptions, run

    out: dict[str, object] = {}
    for method in ("osc", "ik"):
        out[method] = run(
            gait_dir / "subject01_walk1.trc",
            gait_dir / "subject01_static.trc",
            "gait2392",
            1.8034,
            72.6,
            ReconstructionOptions(method=method),
        )
    return out
