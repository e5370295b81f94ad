"""Input validation of the filters: the one-pass numba path for clean batches gives
exactly what the numpy checks give (the checks keep the error messages, tested in
test_filter_contract.py)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from mocapkit.imu.filters.inputs import _prepare_checked, _prepare_clean


def _batch(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    n = 400
    gyr = rng.normal(size=(n, 3))
    acc = rng.normal(size=(n, 3)) * 5.0
    mag = rng.normal(size=(n, 3)) * 40.0
    acc[10] = 0.0  # zero-norm accelerometer
    acc[20] = [1e-7, 0.0, 0.0]  # below the norm threshold
    acc[30, 1] = 160.0  # saturated with acc_range=160
    mag[40:45] = np.nan  # a gap
    mag[50] = 0.0  # zero-norm magnetometer
    return gyr, acc, mag


@pytest.mark.parametrize("with_mag", [True, False])
@pytest.mark.parametrize("acc_range", [None, 160.0])
def test_clean_path_equals_the_checked_path(with_mag: bool, acc_range: float | None) -> None:
    gyr, acc, mag = _batch(1)
    m = mag if with_mag else None
    dt = np.full(gyr.shape[0], 0.01)
    fast = _prepare_clean(gyr, acc, m, dt, 0.01, acc_range, 40.0)
    assert fast is not None
    checked = _prepare_checked(gyr, acc, m, dt, 0.01, acc_range, 40.0)
    for name, a, b in zip(fast[0]._fields, fast[0], checked[0], strict=True):
        assert a.dtype == b.dtype, name
        assert a.flags.c_contiguous, name
        np.testing.assert_array_equal(a, b, err_msg=name)  # the same arrays, exactly
    assert fast[1] == checked[1]
    assert np.isnan(mag[40:45]).all()  # the caller's array is not modified


@pytest.mark.parametrize(
    "spoil",
    [
        lambda g, a, m: g.__setitem__((5, 1), np.nan),
        lambda g, a, m: a.__setitem__((6, 2), np.inf),
        lambda g, a, m: m.__setitem__((7, 0), np.nan),  # partly NaN row
        lambda g, a, m: m.__setitem__((8, 2), -np.inf),
        lambda g, a, m: g.__setitem__((9, 0), 40.0),  # saturated gyroscope: warns
    ],
)
def test_doubtful_batches_take_the_checked_path(
    spoil: Callable[[np.ndarray, np.ndarray, np.ndarray], None],
) -> None:
    gyr, acc, mag = _batch(2)
    spoil(gyr, acc, mag)
    assert _prepare_clean(gyr, acc, mag, None, 0.01, None, 40.0) is None


def test_bad_shapes_take_the_checked_path() -> None:
    gyr, acc, mag = _batch(3)
    assert _prepare_clean(gyr[:, :2], acc, mag, None, 0.01, None, None) is None
    assert _prepare_clean(gyr, acc[:-1], mag, None, 0.01, None, None) is None
    assert _prepare_clean(gyr, acc, mag[:, 0], None, 0.01, None, None) is None
    assert _prepare_clean(gyr[0], acc[0], None, None, 0.01, None, None) is None
    assert _prepare_clean("x", acc, None, None, 0.01, None, None) is None


@pytest.mark.parametrize("name", ["polaris"])
def test_lost_samples_are_integrated_with_the_trapezoidal_rule(name: str) -> None:
    """A sensor spinning up about the vertical (the rate a straight line in time), with
    150 ms of samples lost mid-way: the step over the loss turns it at the mean of the
    readings either side, which follows the line; the later reading alone would overshoot
    by half the rate change times the gap (here ~5 deg). 6D: nothing corrects the heading,
    so the yaw shows the integration as it is; compared with the same filter on every
    sample, which differs by a step's share only (0.3 deg). (bachmann, as published,
    integrates to first order: over a 72 deg step it falls 8 deg short whatever rate it
    is given.)"""
    from mocapkit.geometry import quat_to_matrix
    from mocapkit.imu.filters import make_filter

    rate = 100.0
    t = np.arange(300) / rate
    w = np.where(t < 0.5, 0.0, 8.0 * (t - 0.5))  # rad/s, from 0.5 s on
    gyr = np.column_stack([np.zeros_like(t), np.zeros_like(t), w])
    acc = np.tile([0.0, 0.0, 9.81], (t.size, 1))

    def yaw_turned(keep: np.ndarray) -> float:
        dt = np.diff(t[keep], prepend=t[keep][0] - 1.0 / rate)
        r = quat_to_matrix(make_filter(name, rate).run(gyr[keep], acc[keep], dt=dt))
        yaw = np.unwrap(np.arctan2(r[:, 1, 0], r[:, 0, 0]))
        return float(yaw[-1] - yaw[0])

    lost = (t > 1.5) & (t < 1.65)  # 14 samples
    every = yaw_turned(np.ones(t.size, dtype=bool))
    assert abs(yaw_turned(~lost) - every) < np.radians(1.0)
