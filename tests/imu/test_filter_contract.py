"""The filter contract (imu/filters/base.py), checked on every registered filter:
split runs, checkpoints, initialisation, re-initialisation, and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError, DataError, ShapeError
from mocapkit.geometry import quat_angle_between, quat_from_axis_angle
from mocapkit.imu.filters import available_filters, make_filter
from mocapkit.imu.filters.base import SensorSaturationWarning
from mocapkit.series import ImuRecording
from tests.imu.synthetic import constant_rotation

FILTERS = available_filters()
BACKENDS = ["fast", "reference"]
RATE = 100.0


def _signals(n: int = 300, seed: int = 0) -> tuple[np.ndarray, ...]:
    q0 = quat_from_axis_angle([0.2, -0.4, 1.0], 0.9)
    q, gyr, acc, mag = constant_rotation(q0, [0.3, -0.2, 0.5], n, RATE)
    rng = np.random.default_rng(seed)
    return (
        q,
        gyr + rng.normal(scale=0.01, size=gyr.shape),
        acc + rng.normal(scale=0.05, size=acc.shape),
        mag + rng.normal(scale=0.5, size=mag.shape),
    )


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", FILTERS)
@pytest.mark.parametrize("use_mag", [True, False])
def test_split_run_equals_one_run(name: str, backend: str, use_mag: bool) -> None:
    _, gyr, acc, mag = _signals()
    m = mag if use_mag else None
    whole = make_filter(name, RATE, backend).run(gyr, acc, m)
    f = make_filter(name, RATE, backend)
    first = f.run(gyr[:100], acc[:100], None if m is None else m[:100])
    second = f.run(gyr[100:], acc[100:], None if m is None else m[100:])
    # same arithmetic in the same order: identical to the last bit
    np.testing.assert_array_equal(np.vstack([first, second]), whole)


@pytest.mark.parametrize("name", FILTERS)
def test_checkpoint_restores_the_run(name: str) -> None:
    _, gyr, acc, mag = _signals()
    f = make_filter(name, RATE)
    f.run(gyr[:150], acc[:150], mag[:150])
    state = f.get_state()
    rest = f.run(gyr[150:], acc[150:], mag[150:])
    f.set_state(state)
    np.testing.assert_array_equal(f.run(gyr[150:], acc[150:], mag[150:]), rest)
    state.quat[:] = 0.0  # the checkpoint is a copy: mutating it changes nothing
    assert np.isfinite(f.quat).all()
    assert np.linalg.norm(f.quat) == pytest.approx(1.0)
    with pytest.raises(ConfigError, match="state: expected a"):
        f.set_state(object())  # type: ignore[arg-type]


@pytest.mark.parametrize("name", FILTERS)
def test_update_equals_run(name: str) -> None:
    _, gyr, acc, mag = _signals(20)
    first = make_filter(name, RATE)
    batch = first.run(gyr, acc, mag)
    # update() would initialise from its single first sample, run() from the first 10:
    # start both from the same state
    f = make_filter(name, RATE)
    f.reset(batch[0], dip=first.state.dip)
    g = make_filter(name, RATE)
    g.reset(batch[0], dip=first.state.dip)
    steps = np.array([f.update(gyr[i], acc[i], mag[i]) for i in range(1, 20)])
    np.testing.assert_array_equal(steps, g.run(gyr[1:], acc[1:], mag[1:]))


@pytest.mark.parametrize("name", FILTERS)
def test_starts_from_the_first_samples_not_identity(name: str) -> None:
    q_true, gyr, acc, mag = constant_rotation(
        quat_from_axis_angle([1.0, 0.0, 0.0], 2.8), [0.0, 0.0, 0.0], 50, RATE
    )
    f = make_filter(name, RATE)
    assert not f.initialised
    out = f.run(gyr, acc, mag)
    assert f.initialised
    assert f.last_report.initialised_here
    # exact static signals: the first estimate is the truth up to rounding
    assert np.degrees(quat_angle_between(out[0], q_true[0])) < 1e-6


@pytest.mark.parametrize("name", FILTERS)
def test_a_moving_start_is_compensated_with_the_gyroscope(name: str) -> None:
    q0 = quat_from_axis_angle([0.3, 1.0, -0.2], 2.0)
    q_true, gyr, acc, mag = constant_rotation(q0, [1.5, -1.0, 2.0], 50, RATE)  # 2.7 rad/s
    f = make_filter(name, RATE, init_window_s=0.2)
    out = f.run(gyr, acc, mag)
    # the 0.2 s window spans 31 deg of rotation; compensated, the start is exact up to
    # the filter's own first-order integration step (well below 0.01 deg)
    assert np.degrees(quat_angle_between(out[0], q_true[0])) < 0.01


@pytest.mark.parametrize("name", FILTERS)
def test_reinitialize_on_command(name: str) -> None:
    q_true, gyr, acc, mag = constant_rotation(
        quat_from_axis_angle([0.2, -0.4, 1.0], 0.9), [0.3, -0.2, 0.5], 20, RATE
    )
    f = make_filter(name, RATE)
    f.reset(quat_from_axis_angle([0.0, 1.0, 0.0], 2.0))  # badly wrong
    f.run(gyr[:10], acc[:10], mag[:10])
    q_new = f.reinitialize(acc[11], mag[11])
    # exact signals: the truth up to rounding
    assert np.degrees(quat_angle_between(q_new, q_true[11])) < 1e-6
    # 6D: the inclination is reset, the heading of the current estimate is kept
    f.reset(quat_from_axis_angle([0.0, 0.0, 1.0], 1.0))
    q6 = f.reinitialize(np.array([[0.0, 0.0, 9.81]]))
    np.testing.assert_allclose(q6, quat_from_axis_angle([0.0, 0.0, 1.0], 1.0), atol=1e-12)


@pytest.mark.parametrize("name", FILTERS)
def test_bad_input_messages(name: str) -> None:
    _, gyr, acc, mag = _signals(20)
    f = make_filter(name, RATE)
    bad = gyr.copy()
    bad[3, 1] = np.nan
    with pytest.raises(DataError, match=r"gyr: non-finite value at sample 3, column 1"):
        f.run(bad, acc, mag)
    bad = acc.copy()
    bad[5, 0] = np.inf
    with pytest.raises(DataError, match=r"acc: non-finite value at sample 5, column 0"):
        f.run(gyr, bad, mag)
    with pytest.raises(ShapeError, match=r"acc: expected shape \(20, 3\), got \(20, 4\)"):
        f.run(gyr, np.zeros((20, 4)), mag)
    with pytest.raises(ShapeError, match=r"mag: expected shape \(20, 3\), got \(19, 3\)"):
        f.run(gyr, acc, mag[:19])
    with pytest.raises(ShapeError, match=r"gyr: expected shape \(3,\), got \(4,\)"):
        f.update(np.zeros(4), acc[0])
    bad = mag.copy()
    bad[7, 2] = np.nan
    with pytest.raises(DataError, match=r"mag: non-finite value at sample 7, column 2 .*gap"):
        f.run(gyr, acc, bad)
    with pytest.raises(DataError, match=r"dt: sample 2 has time step -0.01 s"):
        f.run(gyr[:4], acc[:4], dt=[0.01, 0.01, -0.01, 0.01])
    with pytest.raises(DataError, match="acc: no usable sample among the first 10 samples"):
        f.run(gyr, np.zeros_like(acc))
    assert not f.initialised  # every failed call left the filter untouched
    with pytest.raises(ConfigError, match=r"rate_hz: the filter expects 100 Hz but s1 is sampled"):
        f.run_recording(ImuRecording(np.arange(20) / 50.0, gyr, acc, name="s1"))


@pytest.mark.parametrize("name", FILTERS)
def test_zero_norm_and_saturated_samples_skip_the_correction(name: str) -> None:
    _, gyr, acc, mag = _signals(60)
    acc = acc.copy()
    mag = mag.copy()
    acc[30] = 0.0
    mag[31] = 0.0
    f = make_filter(name, RATE, acc_range=20.0, gyr_range=4.0)
    acc[32] = [25.0, 0.0, 0.0]  # beyond the range: saturated
    out = f.run(gyr, acc, mag)
    assert np.isfinite(out).all()
    report = f.last_report
    assert (report.acc_rejected, report.mag_rejected, report.gyr_saturated) == (2, 1, 0)
    gyr = gyr.copy()
    gyr[40] = [5.0, 0.0, 0.0]
    with pytest.warns(SensorSaturationWarning, match=r"gyr: saturated at sample 40 \(1 samples"):
        f.run(gyr, acc, mag)


@pytest.mark.parametrize("name", FILTERS)
def test_never_a_nan_quaternion(name: str) -> None:
    rng = np.random.default_rng(7)
    n = 500
    gyr = rng.normal(scale=50.0, size=(n, 3))  # violent, far beyond any real rate
    acc = rng.normal(scale=100.0, size=(n, 3))
    mag = rng.normal(scale=1e4, size=(n, 3))
    mag[::7] = np.nan  # many gaps
    for backend in BACKENDS:
        out = make_filter(name, RATE, backend).run(gyr, acc, mag)
        assert np.isfinite(out).all()
        np.testing.assert_allclose(np.linalg.norm(out, axis=1), 1.0, atol=1e-12)


def test_registry_errors() -> None:
    with pytest.raises(ConfigError, match="filter: unknown name 'nope'; choose one of"):
        make_filter("nope", RATE)
    with pytest.raises(ConfigError, match="filter 'miller': bad parameter"):
        make_filter("miller", RATE, gain=3.0)
    with pytest.raises(ConfigError, match="backend: expected 'fast' or 'reference'"):
        make_filter("miller", RATE, backend="gpu")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="rate_hz: expected a positive sampling rate"):
        make_filter("miller", 0.0)
    with pytest.raises(ConfigError, match="init_window_s: expected a duration"):
        make_filter("miller", RATE, init_window_s=-1.0)
    with pytest.raises(ConfigError, match="acc_range: expected a positive full-scale range"):
        make_filter("bachmann", RATE, acc_range=0.0)
    with pytest.raises(DataError, match="quat: expected a unit quaternion"):
        make_filter("miller", RATE).reset([0.0, 0.0, 0.0, 0.0])


@pytest.mark.parametrize("name", FILTERS)
def test_empty_batch(name: str) -> None:
    f = make_filter(name, RATE)
    assert f.run(np.zeros((0, 3)), np.zeros((0, 3))).shape == (0, 4)
    assert not f.initialised


def test_the_cli_list_of_filter_names_equals_the_registry() -> None:
    from mocapkit.imu.filter_names import BUILTIN_FILTERS

    assert sorted(BUILTIN_FILTERS) == sorted(FILTERS)
