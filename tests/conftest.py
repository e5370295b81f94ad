"""Shared fixtures: the hypothesis CI profile and access to ../shared/data."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "ci",
    derandomize=True,
    deadline=None,
    max_examples=200,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile("dev", deadline=None, max_examples=100)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "dev"))

REPO = Path(__file__).resolve().parents[1]
TEST_DATA = REPO / "tests" / "data"


def _shared_data_dir() -> Path | None:
    env = os.environ.get("MOCAPKIT_SHARED_DATA")
    candidates = [Path(env)] if env else []
    candidates.append(REPO.parent / "shared" / "data")
    for c in candidates:
        if c.is_dir():
            return c
    return None


SHARED_DATA = _shared_data_dir()


@pytest.fixture
def shared_data() -> Path:
    """Path to ../shared/data; skips the test (with the reason) when it is absent."""
    if SHARED_DATA is None:
        pytest.skip("../shared/data is not present (set MOCAPKIT_SHARED_DATA to its path)")
    return SHARED_DATA


def require_peer(module: str, extra: str = "bench") -> object:
    """Import a peer library (opensim, vqf, ezc3d's tools...) for a test that runs it.

    On a user's machine a missing peer skips the test with the install hint. In CI
    (`MOCAPKIT_REQUIRE_PEERS=1`, set by `.ci/run`, which installs the `bench` extra) a
    missing peer is a failure: a round-trip test that silently skipped there would prove
    nothing.
    """
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        hint = f"needs {module} (pip install -e '.[{extra}]')"
        if os.environ.get("MOCAPKIT_REQUIRE_PEERS") == "1":
            pytest.fail(f"{hint}; MOCAPKIT_REQUIRE_PEERS=1 requires it: {exc}")
        pytest.skip(hint)
