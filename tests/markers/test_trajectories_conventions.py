"""The trajectories container and the unit / axis checks."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from mocapkit.errors import DataError
from mocapkit.markers import conventions
from mocapkit.markers.trajectories import MarkerTrajectories
from tests.markers import synthetic


def test_container_validation() -> None:
    t = np.arange(3) / 10
    with pytest.raises(DataError, match="not strictly increasing at frame 2"):
        MarkerTrajectories([0.0, 0.1, 0.1], np.zeros((3, 1, 3)), ("A",))
    with pytest.raises(DataError, match="marker 'A' appears twice"):
        MarkerTrajectories(t, np.zeros((3, 2, 3)), ("A", "A"))
    pos = np.zeros((3, 1, 3))
    pos[1, 0, 2] = np.nan
    with pytest.raises(DataError, match="marker 'A' is partly NaN at frame 1"):
        MarkerTrajectories(t, pos, ("A",))
    traj = MarkerTrajectories(t, np.zeros((3, 2, 3)), ("A", "B"))
    assert traj.select(["B"]).names == ("B",)
    assert traj.between(0.05, None).n_frames == 2
    with pytest.raises(DataError, match="no frame between 5 s and None s"):
        traj.between(5, None)
    with pytest.raises(DataError, match="marker 'Z' not in trajectories; available: A, B"):
        traj.marker("Z")


@pytest.mark.parametrize("up", conventions.UP_AXES)
def test_rotations_are_proper_and_take_up_to_z(up: str) -> None:
    R = conventions.rotation_to_z_up(up)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(R) == pytest.approx(1.0)
    axis = np.zeros(3)
    axis["xyz".index(up[-1])] = -1.0 if up.startswith("-") else 1.0
    np.testing.assert_allclose(R @ axis, [0, 0, 1], atol=1e-15)


def _static(up: str = "z", scale: float = 1.0) -> tuple[MarkerTrajectories, dict[str, str]]:
    human, ms = synthetic.subject()
    q = human.neutral()
    X = synthetic.markers(human, list(ms.names), np.tile(q, (5, 1)))
    R = conventions.rotation_to_z_up(up)
    traj = MarkerTrajectories(np.arange(5) / 60, (X @ R) * scale, ms.names, meta={"units": "m"})
    return traj, {m.name: m.segment for m in ms.markers}


@pytest.mark.parametrize("up", ["z", "y", "-x"])
def test_up_axis_detected_from_static(up: str) -> None:
    static, segments = _static(up)
    found = conventions.detect_up_axis(static, segments)
    assert found is not None
    assert found.axis == up
    assert found.angle_deg < 10.0  # a standing body is vertical within a few degrees
    assert conventions.resolve_up_axis(static, segments) == up


def test_declared_up_axis_that_contradicts_static_is_an_error() -> None:
    static, segments = _static("y")
    with pytest.raises(
        DataError, match="above its foot markers along y, but the up axis was given as z"
    ):
        conventions.resolve_up_axis(static, segments, "z")


def test_wrong_units_detected(caplog: pytest.LogCaptureFixture) -> None:
    static, _ = _static(scale=1000.0)  # millimetres labelled as metres
    with caplog.at_level(logging.WARNING):
        check = conventions.check_units(static)
    assert check.factor == 1e-3
    assert "look like millimetres" in caplog.text
    with pytest.raises(DataError, match="Fix: pass --units mm"):
        conventions.check_units(static, explicit=True)
    tiny, _ = _static(scale=1e-6)
    with pytest.raises(DataError, match="no unit \\(mm, cm, m\\) makes that a human body"):
        conventions.check_units(tiny)
