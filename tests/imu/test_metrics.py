"""BROAD's error metric on cases with exact answers."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import DataError
from mocapkit.geometry import quat_from_axis_angle, quat_mul, quat_normalize
from mocapkit.imu.metrics import orientation_rmse


def _random_refs(n: int = 200) -> np.ndarray:
    return quat_normalize(np.random.default_rng(4).normal(size=(n, 4)))


def test_pure_heading_error() -> None:
    ref = _random_refs()
    est = quat_mul(quat_from_axis_angle([0, 0, 1], np.radians(5.0)), ref)
    err = orientation_rmse(est, ref)
    assert np.degrees(err.total) == pytest.approx(5.0)
    assert np.degrees(err.heading) == pytest.approx(5.0)
    assert np.degrees(err.inclination) == pytest.approx(0.0, abs=1e-6)
    aligned = orientation_rmse(est, ref, align_heading=True)
    assert np.degrees(aligned.total) == pytest.approx(0.0, abs=1e-6)


def test_pure_inclination_error() -> None:
    ref = _random_refs()
    est = quat_mul(quat_from_axis_angle([1, 0, 0], np.radians(3.0)), ref)
    err = orientation_rmse(est, ref)
    assert np.degrees(err.inclination) == pytest.approx(3.0)
    assert np.degrees(err.heading) == pytest.approx(0.0, abs=1e-6)


def test_mask_and_missing_reference() -> None:
    ref = _random_refs(4)
    est = ref.copy()
    est[0] = quat_mul(quat_from_axis_angle([0, 0, 1], 1.0), ref[0])
    ref_nan = ref.copy()
    ref_nan[1] = np.nan
    err = orientation_rmse(est, ref_nan, mask=[False, True, True, True])
    assert err.n_samples == 2
    assert err.total == pytest.approx(0.0, abs=1e-7)
    with pytest.raises(DataError, match="no sample with a finite reference"):
        orientation_rmse(est, ref_nan, mask=[False, True, False, False])
    est_nan = est.copy()
    est_nan[2] = np.nan
    with pytest.raises(DataError, match="non-finite estimate at sample 2"):
        orientation_rmse(est_nan, ref)
