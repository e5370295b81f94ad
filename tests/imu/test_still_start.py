"""The still start: gyroscope bias and orientation from the first seconds at rest."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_angle_between, quat_exp, quat_mul, quat_rotate_inv
from mocapkit.imu.filters import make_filter
from mocapkit.imu.still_start import StillStartFilter
from tests.imu.synthetic import FIELD_WORLD, GRAVITY

RATE = 100.0
BIAS = np.array([0.012, -0.008, 0.01])  # rad/s: consumer-grade gyroscope bias


def _still_then_turn(n_still: int, n_turn: int, rng: np.random.Generator):
    """Rest at q0, then a constant turn; gyroscope with BIAS and white noise."""
    q0 = quat_exp(0.5 * np.array([0.3, -0.2, 1.0]))
    rate = np.array([0.0, 0.0, 0.0] * n_still + [0.4, -0.3, 0.2] * n_turn).reshape(-1, 3)
    q = [q0]
    for w in rate[1:]:
        q.append(quat_mul(q[-1], quat_exp(0.5 * w / RATE)))
    q = np.array(q)
    acc = quat_rotate_inv(q, np.array([0.0, 0.0, GRAVITY]))
    mag = quat_rotate_inv(q, FIELD_WORLD)
    gyr = rate + BIAS + rng.normal(0.0, 0.003, rate.shape)
    return q, gyr, acc, mag


def test_bias_is_removed_and_the_error_stays_small():
    rng = np.random.default_rng(1)
    q, gyr, acc, mag = _still_then_turn(100, 500, rng)
    plain = make_filter("miller", RATE).run(gyr, acc, mag)
    f = StillStartFilter(make_filter("miller", RATE), still_s=1.0)
    out = f.run(gyr, acc, mag)
    assert f.bias_ok
    # the mean of 100 noisy samples: within 4 sigma of the true bias (0.003 / 10 per axis)
    np.testing.assert_allclose(f.bias, BIAS, atol=4 * 0.003 / 10)
    err_plain = np.degrees(quat_angle_between(plain[100:], q[100:]))
    err = np.degrees(quat_angle_between(out[100:], q[100:]))
    # the bias leaves miller degrees off while turning; without it a fraction of a degree
    assert err_plain.max() > 1.0
    assert err.max() < 0.3


def test_split_runs_equal_one_run():
    rng = np.random.default_rng(2)
    _, gyr, acc, mag = _still_then_turn(50, 100, rng)
    one = StillStartFilter(make_filter("bachmann", RATE), still_s=0.5).run(gyr, acc, mag)
    f = StillStartFilter(make_filter("bachmann", RATE), still_s=0.5)
    # (the first part covers the inner filter's 0.1 s initialisation window)
    cuts = ((0, 20), (20, 49), (49, 50), (50, 150))
    parts = [f.run(gyr[a:b], acc[a:b], mag[a:b]) for a, b in cuts]
    np.testing.assert_allclose(np.concatenate(parts), one, atol=1e-12)  # same arithmetic
    per_sample = StillStartFilter(make_filter("bachmann", RATE), still_s=0.5)
    rows = [per_sample.run(gyr[:20], acc[:20], mag[:20])]
    rows += [per_sample.update(gyr[k], acc[k], mag[k])[None] for k in range(20, len(gyr))]
    np.testing.assert_allclose(np.concatenate(rows), one, atol=1e-12)


def test_motion_during_the_window_is_refused(caplog):
    rng = np.random.default_rng(3)
    _, gyr, acc, mag = _still_then_turn(0, 150, rng)  # turning at 0.5 rad/s from the start
    f = StillStartFilter(make_filter("miller", RATE), still_s=1.0, label="forearm_r")
    with caplog.at_level(logging.WARNING, logger="mocapkit.imu.still_start"):
        f.run(gyr, acc, mag)
    assert not f.bias_ok
    np.testing.assert_array_equal(f.bias, np.zeros(3))
    assert "forearm_r: moved during the still start" in caplog.text
    with pytest.raises(ConfigError, match="still_s: expected a duration >= 0"):
        StillStartFilter(make_filter("miller", RATE), still_s=-1.0)


def test_zero_duration_passes_through_and_reset_starts_over():
    rng = np.random.default_rng(4)
    _, gyr, acc, mag = _still_then_turn(100, 50, rng)
    a = StillStartFilter(make_filter("miller", RATE), still_s=0.0).run(gyr, acc, mag)
    b = make_filter("miller", RATE).run(gyr, acc, mag)
    np.testing.assert_array_equal(a, b)
    f = StillStartFilter(make_filter("miller", RATE), still_s=1.0)
    first = f.run(gyr, acc, mag)
    f.reset()
    assert not f.done
    np.testing.assert_allclose(f.run(gyr, acc, mag), first, atol=1e-12)


def test_a_bias_estimating_filter_is_told_what_the_still_start_removes():
    from mocapkit.imu.filters.miller import MillerFilter, MillerParams

    calls = []

    class Spy(MillerFilter):
        def gyr_bias_removed(self, bias, sigma=None):
            calls.append((np.array(bias), sigma))

    rng = np.random.default_rng(4)
    _, gyr, acc, mag = _still_then_turn(100, 50, rng)
    f = StillStartFilter(Spy(MillerParams(rate_hz=RATE)), still_s=1.0)
    f.run(gyr, acc, mag)
    assert len(calls) == 1  # once, when the window is full
    np.testing.assert_array_equal(calls[0][0], f.bias)
    # the standard error of the window's mean: 0.003 rad/s noise over 100 samples
    assert calls[0][1] == pytest.approx(0.003 / np.sqrt(100), rel=0.2)
