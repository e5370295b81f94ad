"""Validated containers: shapes, NaN, time order, read-only storage, documented fallbacks."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import DataError, ShapeError
from mocapkit.series import ImuRecording, OrientationSeries


def _arrays(n: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(n) * 0.01
    return t, np.zeros((n, 3)), np.tile([0.0, 0.0, 9.81], (n, 1))


def test_recording_basics() -> None:
    t, g, a = _arrays()
    rec = ImuRecording(t, g, a, name="s1")
    assert rec.n_samples == 5
    assert rec.rate_hz == pytest.approx(100.0)
    assert not rec.has_mag
    with pytest.raises(ValueError, match="read-only"):
        rec.gyr[0, 0] = 1.0
    g[0, 0] = 5.0  # the caller's array stays the caller's
    assert rec.gyr[0, 0] == 0.0


def test_recording_errors_name_field_and_sample() -> None:
    t, g, a = _arrays()
    with pytest.raises(ShapeError, match=r"s1.acc: expected shape \(5, 3\), got \(5, 2\)"):
        ImuRecording(t, g, a[:, :2], name="s1")
    a_bad = a.copy()
    a_bad[3, 1] = np.nan
    with pytest.raises(
        DataError, match=r"s1.acc: non-finite value at sample 3, column 1 .*with_gaps"
    ):
        ImuRecording(t, g, a_bad, name="s1")
    t_bad = t.copy()
    t_bad[2] = t_bad[1]
    with pytest.raises(DataError, match=r"s1.time: not strictly increasing at sample 2"):
        ImuRecording(t_bad, g, a, name="s1")


def test_gap_interpolation_fallback_is_reported() -> None:
    t, g, a = _arrays()
    g = g.copy()
    g[2] = np.nan
    g[1] = [1.0, 1.0, 1.0]
    g[3] = [3.0, 3.0, 3.0]
    rec = ImuRecording.with_gaps_interpolated(t, g, a, name="s1")
    np.testing.assert_allclose(rec.gyr[2], [2.0, 2.0, 2.0])
    assert rec.meta["interpolated"] == {"gyr": 1, "acc": 0}


def test_slice_and_without_mag() -> None:
    t, g, a = _arrays(10)
    rec = ImuRecording(t, g, a, mag=np.ones((10, 3)))
    part = rec.slice(2, 6)
    assert part.n_samples == 4
    assert part.time[0] == pytest.approx(0.02)
    assert rec.without_mag().mag is None


def test_orientation_series_validation() -> None:
    t = np.arange(3) * 0.1
    q = np.array([[1.0, 0, 0, 0], [np.nan] * 4, [0, 1.0, 0, 0]])
    s = OrientationSeries(t, q)
    np.testing.assert_array_equal(s.valid, [True, False, True])
    with pytest.raises(DataError, match=r"sample 1 has norm 2.000000"):
        OrientationSeries(t, [[1.0, 0, 0, 0], [2.0, 0, 0, 0], [1.0, 0, 0, 0]])
    with pytest.raises(DataError, match="sample 0 is partly NaN"):
        OrientationSeries(t, [[np.nan, 0, 0, 0], [1.0, 0, 0, 0], [1.0, 0, 0, 0]])


def test_mag_gaps_are_all_nan_rows() -> None:
    t, g, a = _arrays(6)
    mag = np.ones((6, 3))
    mag[2] = np.nan
    rec = ImuRecording(t, g, a, mag=mag, name="s1")
    np.testing.assert_array_equal(rec.mag_valid, [True, True, False, True, True, True])
    assert not ImuRecording(t, g, a).mag_valid.any()
    mag[4, 1] = np.nan  # partly NaN: not a gap marker
    with pytest.raises(DataError, match=r"s1.mag: non-finite value at sample 4, column 1 .*gap"):
        ImuRecording(t, g, a, mag=mag, name="s1")
    mag[4, 1] = np.inf
    with pytest.raises(DataError, match=r"s1.mag: non-finite value at sample 4, column 1"):
        ImuRecording(t, g, a, mag=mag, name="s1")


def test_joint_angle_series() -> None:
    from mocapkit.series import JointAngleSeries

    t = np.arange(3) * 0.1
    s = JointAngleSeries(t, ["knee_angle_r", "hip_flexion_r"], np.zeros((3, 2)))
    assert s.column("hip_flexion_r").shape == (3,)
    with pytest.raises(DataError, match="no coordinate 'ankle'; available: knee_angle_r"):
        s.column("ankle")
    with pytest.raises(DataError, match="duplicated coordinate name"):
        JointAngleSeries(t, ["a", "a"], np.zeros((3, 2)))
    with pytest.raises(ShapeError, match=r"joints.values: expected shape \(3, 2\)"):
        JointAngleSeries(t, ["a", "b"], np.zeros((3, 3)))
