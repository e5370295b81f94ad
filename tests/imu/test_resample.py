"""Orientation series on a common time base (slerp, no extrapolation)."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import DataError
from mocapkit.geometry import quat_from_axis_angle
from mocapkit.imu.resample import common_time_base, resample_orientation
from mocapkit.series import OrientationSeries


def test_slerp_between_samples_and_no_extrapolation() -> None:
    angles = np.array([0.0, 0.2, 0.4])
    q = quat_from_axis_angle(np.tile([0.0, 0.0, 1.0], (3, 1)), angles)
    s = OrientationSeries([0.0, 1.0, 2.0], q)
    out = resample_orientation(s, [0.0, 0.25, 1.5, 2.0])
    expected = quat_from_axis_angle(np.tile([0.0, 0.0, 1.0], (4, 1)), [0.0, 0.05, 0.3, 0.4])
    np.testing.assert_allclose(out, expected, atol=1e-12)  # slerp about one axis is exact
    with pytest.raises(DataError, match="resampling never extrapolates"):
        resample_orientation(s, [1.0, 2.5])


def test_common_time_base() -> None:
    q = np.tile([1.0, 0.0, 0.0, 0.0], (11, 1))
    a = OrientationSeries(np.linspace(0.0, 1.0, 11), q)
    b = OrientationSeries(np.linspace(0.35, 1.35, 11), q)
    t = common_time_base([a, b])
    assert t[0] == pytest.approx(0.35)
    assert t[-1] <= 1.0
    np.testing.assert_allclose(np.diff(t), 0.1)
    c = OrientationSeries(np.linspace(5.0, 6.0, 11), q)
    with pytest.raises(DataError, match="do not overlap in time"):
        common_time_base([a, c])
