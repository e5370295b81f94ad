"""The filter bank: many sensors advanced per batch equal one still-start filter per sensor
fed sample by sample (the batched fast path against the readable per-sensor path)."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_exp, quat_mul, quat_rotate_inv
from mocapkit.imu import filter_bank
from mocapkit.imu.filter_bank import FilterBank, has_bank_kernel
from mocapkit.imu.filters import make_filter
from mocapkit.imu.still_start import StillStartFilter
from tests.imu.synthetic import FIELD_WORLD, GRAVITY

RATE = 100.0
S = 4


def _signals(rng: np.random.Generator, n: int) -> tuple[np.ndarray, ...]:
    """(n, S, 3) gyroscope, accelerometer, magnetometer of S sensors: still for 0.5 s,
    then turning (biased, noisy gyroscopes; exact vectors, a little noise)."""
    rate = np.zeros((n, S, 3))
    rate[50:] = rng.normal(0.0, 0.6, (1, S, 3))  # a constant turn per sensor
    q = np.empty((n, S, 4))
    q[0] = quat_exp(0.5 * rng.normal(size=(S, 3)))
    for k in range(1, n):
        q[k] = quat_mul(q[k - 1], quat_exp(0.5 * rate[k] / RATE))
    acc = quat_rotate_inv(q, np.array([0.0, 0.0, GRAVITY])) + rng.normal(0, 0.05, (n, S, 3))
    mag = quat_rotate_inv(q, FIELD_WORLD) + rng.normal(0, 0.3, (n, S, 3))
    gyr = rate + rng.normal(0.0, 0.01, (1, S, 3)) + rng.normal(0.0, 0.003, (n, S, 3))
    return gyr, acc, mag


@pytest.mark.parametrize(
    ("name", "batched"),
    [("miller", True), ("bachmann", True), ("polaris", True), ("miller", False)],
)
@pytest.mark.parametrize("use_mag", [True, False])
def test_bank_equals_one_still_start_filter_per_sensor(
    name: str, batched: bool, use_mag: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    if not batched:  # a filter without a bank kernel: every sample on its object
        monkeypatch.setattr(filter_bank, "_SPECS", {})
    rng = np.random.default_rng(3)
    n = 160
    gyr, acc, mag = _signals(rng, n)
    mag[70, 2] = np.nan  # a magnetometer gap (all three NaN): 6D for that sample
    gyr[90, 1, 0] = np.nan  # a broken gyroscope sample: refused, the state unchanged
    bank = FilterBank(name, RATE, S, still_s=0.3, use_mag=use_mag)
    assert bank.batched == batched == has_bank_kernel(name)
    objs = [StillStartFilter(make_filter(name, RATE), 0.3) for _ in range(S)]
    # batches of varying make-up: some sensors missing, some twice (a late drain)
    queue = [(k, s) for k in range(n) for s in range(S)]
    pos = 0
    max_diff = 0.0
    while pos < len(queue):
        take = queue[pos : pos + int(rng.integers(1, 2 * S))]
        pos += len(take)
        ks, ss = np.array([t[0] for t in take]), np.array([t[1] for t in take])
        m = np.where(np.isnan(mag[ks, ss]), np.nan, mag[ks, ss])
        q, errors = bank.update(ss, gyr[ks, ss], acc[ks, ss], m if use_mag else None)
        for i, (k, s) in enumerate(take):
            if k == 90 and s == 1:
                assert set(errors) == {i}
                assert errors[i].startswith("gyr: non-finite value")
                assert np.isnan(q[i]).all()
                continue
            ref = objs[s].update(gyr[k, s], acc[k, s], mag[k, s] if use_mag else None)
            max_diff = max(max_diff, float(np.abs(ref - q[i]).max()))
    # the same kernels on the same numbers, in the same order
    assert max_diff < 1e-12
    if bank.batched:
        assert bank.in_bank.all()
        np.testing.assert_allclose(bank.bias, [o.bias for o in objs], atol=1e-15)


def test_errors_in_the_still_start_are_named_by_the_filter_object() -> None:
    bank = FilterBank("polaris", RATE, 1, still_s=0.5)
    q, errors = bank.update([0], [[np.nan, 0.0, 0.0]], [[0.0, 0.0, GRAVITY]])
    assert np.isnan(q).all()
    assert errors[0].startswith("gyr: non-finite value at sample 0")
    assert not bank.in_bank[0]


def test_bank_input_errors() -> None:
    with pytest.raises(ConfigError, match="n_sensors: expected at least 1"):
        FilterBank("miller", RATE, 0)
    with pytest.raises(ConfigError, match="filter: unknown name 'kalman'"):
        FilterBank("kalman", RATE, 2)
    bank = FilterBank("miller", RATE, 2, still_s=0.0)
    bank.update([0, 1], np.zeros((2, 3)), [[0, 0, GRAVITY]] * 2, [FIELD_WORLD] * 2)
    assert bank.in_bank.all()
    _, errors = bank.update([0, 1], np.zeros((2, 3)), [[0, 0, GRAVITY]] * 2,
                            [[np.nan, 1.0, 2.0], [np.inf, 0, 0]])  # fmt: skip
    assert errors == {
        0: "mag: non-finite value (mark a gap with all three components NaN)",
        1: "mag: non-finite value (mark a gap with all three components NaN)",
    }
