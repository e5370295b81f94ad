"""Gap filling (rigid cluster, spline) and low-pass filtering, with exact answers."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.markers.cleaning import fill_gaps, find_gaps, lowpass
from mocapkit.markers.trajectories import MarkerTrajectories


def _rigid_cluster(n: int = 60) -> MarkerTrajectories:
    """Four markers of one rigid body rotating and translating (exactly rigid)."""
    t = np.arange(n) / 60.0
    body = np.array([[0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1], [0.05, 0.05, 0.05]])
    pos = np.empty((n, 4, 3))
    for f, a in enumerate(2.0 * t):
        R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        pos[f] = body @ R.T + [0.5 * t[f], 0, 1.0]
    return MarkerTrajectories(t, pos, ("A", "B", "C", "D"))


def test_rigid_fill_is_exact_for_a_rigid_cluster() -> None:
    traj = _rigid_cluster()
    gappy = traj.positions.copy()
    gappy[20:30, 3] = np.nan
    cleaned, report = fill_gaps(traj.with_positions(gappy), "both", 0.5, {"D": ["A", "B", "C"]})
    assert [(g.marker, g.start, g.stop) for g in report.filled_rigid] == [("D", 20, 30)]
    np.testing.assert_allclose(cleaned.positions, traj.positions, atol=1e-12)  # Kabsch: exact


def test_spline_fill_and_long_gaps() -> None:
    t = np.arange(100) / 100.0
    pos = np.zeros((100, 1, 3))
    pos[:, 0, 0] = np.sin(2 * np.pi * t)
    truth = pos.copy()
    pos[40:45, 0] = np.nan  # 0.05 s
    pos[60:90, 0] = np.nan  # 0.3 s: longer than max_gap_s
    traj = MarkerTrajectories(t, pos, ("A",))
    cleaned, report = fill_gaps(traj, "spline", 0.1)
    assert len(report.filled_spline) == 1
    assert len(report.left_open) == 1
    # a cubic spline through a smooth sine sampled at 100 Hz: error ~1e-5
    np.testing.assert_allclose(cleaned.positions[40:45], truth[40:45], atol=1e-4)
    assert np.isnan(cleaned.positions[60:90]).all()
    assert cleaned.meta["cleaning"]["filled_spline"] == 1


def test_find_gaps_reports_never_visible() -> None:
    pos = np.zeros((5, 2, 3))
    pos[:, 1] = np.nan
    gaps, never = find_gaps(MarkerTrajectories(np.arange(5) / 10, pos, ("A", "B")))
    assert gaps == []
    assert never == ["B"]


def test_lowpass() -> None:
    t = np.arange(600) / 120.0
    pos = np.zeros((600, 1, 3))
    pos[:, 0, 0] = np.sin(2 * np.pi * 1.0 * t) + 0.2 * np.sin(2 * np.pi * 30.0 * t)
    pos[300:302, 0] = np.nan
    filtered, report = lowpass(MarkerTrajectories(t, pos, ("A",)), 6.0)
    # the 30 Hz component is attenuated by a 4th-order 6 Hz Butterworth to < 1 %
    err = filtered.positions[50:250, 0, 0] - np.sin(2 * np.pi * t[50:250])
    assert np.abs(err).max() < 0.01
    assert np.isnan(filtered.positions[300, 0, 0])  # gaps are not bridged
    assert report.lowpass_hz == 6.0
    with pytest.raises(ConfigError, match="must be between 0 and the Nyquist frequency 60 Hz"):
        lowpass(MarkerTrajectories(t, pos, ("A",)), 80.0)
    with pytest.raises(ConfigError, match="fill method: expected none, rigid, spline or both"):
        fill_gaps(MarkerTrajectories(t, pos, ("A",)), "magic")
