"""``polaris``: synthetic ground truth, state contract, both backends, bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import ConfigError, DataError, ShapeError
from mocapkit.geometry import quat_from_axis_angle
from mocapkit.imu.filters import (
    Polaris,
    PolarisParams,
    make_filter,
    polaris_offline,
    polaris_offline_chunks,
)
from mocapkit.imu.filters.polaris_timing import estimate_mag_delay
from mocapkit.imu.metrics import error_quat_world, heading_error, inclination_error, total_error

from .polaris_synthetic import make_synthetic

RATE = 200.0


def _deg(x: np.ndarray) -> np.ndarray:
    return np.degrees(x)


@pytest.fixture(scope="module")
def tumbling() -> object:
    """60 s at 200 Hz: 5 s rest then 60 deg/s multi-axis motion, started at 150 deg about
    (1, 1, 0), gyroscope bias (0.4, -0.3, 0.25) deg/s."""
    q0 = quat_from_axis_angle(np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0), np.radians(150.0))
    return make_synthetic(q0=q0, rate_hz=RATE)


def test_synthetic_online_recovers_orientation_and_bias(tumbling) -> None:  # type: ignore[no-untyped-def]
    s = tumbling
    f = Polaris(rate_hz=s.rate_hz)
    q9, q6 = f.run_both(s.gyr, s.acc, s.mag)
    after = int(20 * s.rate_hz)
    # Noise-free readings made with the filter's own discrete kinematics: the only error
    # is the convergence from the unknown 0.4 deg/s bias. At 20-60 s we measured 0.023 deg
    # (9D total), 0.003 deg (6D inclination) and 0.003 deg/s (bias); the bounds leave a
    # factor 2-3 for platform rounding while failing for any modelling mistake (a sign
    # error or a missing bias state gives degrees).
    assert _deg(total_error(error_quat_world(q9[after:], s.q[after:]))).max() < 0.05
    assert _deg(inclination_error(error_quat_world(q6[after:], s.q[after:]))).max() < 0.01
    assert np.abs(_deg(f.state.bias - s.bias)).max() < 0.01


def test_synthetic_offline_beats_online(tumbling) -> None:  # type: ignore[no-untyped-def]
    s = tumbling
    f = Polaris(rate_hz=s.rate_hz)
    result = f.smooth(s.gyr, s.acc, s.mag)
    assert result.q9 is not None
    # Offline also fixes the first 20 s (the backward pass knows the bias there): measured
    # 0.014 deg (9D total) and 0.003 deg (6D inclination) over the whole run.
    assert _deg(total_error(error_quat_world(result.q9, s.q))).max() < 0.04
    assert _deg(inclination_error(error_quat_world(result.q6, s.q))).max() < 0.01
    assert np.abs(_deg(result.bias[-1] - s.bias)).max() < 0.01
    # run_offline returns the 9D estimate and leaves the filter untouched.
    q = f.run_offline(s.gyr, s.acc, s.mag)
    np.testing.assert_array_equal(q, result.q9)
    assert not f.get_state().started
    assert f.run_offline(s.gyr, s.acc).shape == (s.gyr.shape[0], 4)


def test_lag_model_keeps_the_bias_estimate_right() -> None:
    # Motion from the first sample (no rest) with a 1 deg/s bias: the low-passed tilt lags
    # behind the drift the bias causes. With the lag model (P8) we measured 0.04 deg of
    # inclination error after 5 s and a 0.002 deg/s bias error; without it 0.23 deg and
    # 0.23 deg/s (it mistakes the lag for a bias).
    s = make_synthetic(rate_hz=RATE, rest_s=0.0, bias_deg_s=(1.0, -0.8, 0.6))
    errs = {}
    for lag in (True, False):
        f = Polaris(rate_hz=RATE, lag_compensation=lag)
        _, q6 = f.run_both(s.gyr, s.acc, s.mag)
        incl = _deg(inclination_error(error_quat_world(q6, s.q)))[int(5 * RATE) :].max()
        errs[lag] = (incl, np.abs(_deg(f.state.bias - s.bias)).max())
    assert errs[True][0] < 0.1
    assert errs[True][1] < 0.02
    assert errs[False][0] > 3 * errs[True][0]
    assert errs[False][1] > 5 * errs[True][1]


@pytest.mark.parametrize(
    ("axis", "angle_deg"),
    [((1.0, 0.0, 0.0), 180.0), ((0.0, 1.0, 0.0), 90.0), ((1.0, -2.0, 0.5), 123.0)],
)
def test_starts_in_any_orientation(axis: tuple[float, ...], angle_deg: float) -> None:
    q0 = quat_from_axis_angle(np.array(axis) / np.linalg.norm(axis), np.radians(angle_deg))
    s = make_synthetic(q0=q0, rate_hz=RATE, duration_s=4.0)
    q9, q6 = Polaris(rate_hz=RATE).run_both(s.gyr, s.acc, s.mag)
    # At rest from the first sample: the inclination comes from the accelerometer, the
    # heading from the magnetometer; the unknown 0.4 deg/s bias drifts it by < 0.5 deg
    # before the rest detector (1.5 s) measures the bias (measured 0.40 deg, 0.64 deg).
    e = error_quat_world(q9, s.q)
    assert _deg(inclination_error(error_quat_world(q6, s.q))).max() < 1.0
    assert _deg(total_error(e[int(RATE) :])).max() < 1.5
    # The first sample is nearly exact: only the unknown bias integrated over the 0.1 s
    # initialisation window (0.4 deg/s x 0.1 s) smears it (measured up to 0.068 deg).
    assert _deg(total_error(e[:1])).max() < 0.15


def test_rest_detection_measures_the_bias() -> None:
    s = make_synthetic(rate_hz=RATE, duration_s=5.0)  # at rest throughout
    f = Polaris(rate_hz=RATE)
    f.run_both(s.gyr, s.acc, s.mag)
    assert f.at_rest
    # 3.5 s of rest readings of a noise-free gyroscope: measured 0.002 deg/s.
    assert np.abs(_deg(f.state.bias - s.bias)).max() < 0.01


def test_attached_magnet_is_learnt_as_hard_iron() -> None:
    iron = np.array([5.0, -3.0, 30.0])  # uT, moves with the sensor from t = 20 s
    s = make_synthetic(rate_hz=RATE, hard_iron=iron, hard_iron_from_s=20.0)
    f = Polaris(rate_hz=RATE)
    q9, _ = f.run_both(s.gyr, s.acc, s.mag)
    heading = _deg(heading_error(error_quat_world(q9, s.q)))
    # The field jumps by 30 uT (a 40 deg heading change if believed): the gate holds the
    # heading on the gyroscope, the hard iron is re-learnt within seconds (measured 0.10 deg
    # and 0.02 uT; 0.34 deg without the re-learning).
    assert heading[int(20 * RATE) :].max() < 0.3
    np.testing.assert_allclose(f.state.hard_iron, iron, atol=0.1)
    # Without the re-learning the field is rejected for good (gyroscope-only heading).
    g = Polaris(rate_hz=RATE, mag_reset_time=1e9)
    g.run_both(s.gyr, s.acc, s.mag)
    assert np.abs(g.state.hard_iron).max() < 0.1


def test_world_disturbance_is_rejected() -> None:
    # 15 uT towards east for 5 s: a 43 deg heading error for a filter that believes it.
    s = make_synthetic(
        rate_hz=RATE, world_disturbance=np.array([15.0, 0.0, 0.0]), disturbance_s=(30.0, 35.0)
    )
    q9, _ = Polaris(rate_hz=RATE).run_both(s.gyr, s.acc, s.mag)
    gated = _deg(heading_error(error_quat_world(q9, s.q)))[int(30 * RATE) :]
    q9_open, _ = Polaris(rate_hz=RATE, mag_gate=1e6).run_both(s.gyr, s.acc, s.mag)
    open_ = _deg(heading_error(error_quat_world(q9_open, s.q)))[int(30 * RATE) :]
    # Measured 0.65 deg with the gate (the first blocks leak in before it closes), 34 deg
    # without.
    assert gated.max() < 2.0
    assert open_.max() > 20.0


@pytest.mark.parametrize("backend", ["fast", "reference"])
def test_split_run_equals_one_run(backend: str) -> None:
    s = make_synthetic(rate_hz=RATE, duration_s=1.0, rest_s=0.2)
    whole = Polaris(rate_hz=RATE, backend=backend)
    split = Polaris(rate_hz=RATE, backend=backend)
    q_whole = whole.run(s.gyr[:200], s.acc[:200], s.mag[:200])
    # 101 is not a multiple of the 4-sample update block: the block state must carry over
    # (tests/imu/test_filter_contract.py splits at a block boundary).
    q_a = split.run(s.gyr[:101], s.acc[:101], s.mag[:101])
    q_b = split.run(s.gyr[101:200], s.acc[101:200], s.mag[101:200])
    np.testing.assert_array_equal(np.vstack([q_a, q_b]), q_whole)


def test_checkpoint_resumes_exactly() -> None:
    s = make_synthetic(rate_hz=RATE, duration_s=3.0, rest_s=0.5)
    f = Polaris(rate_hz=RATE)
    f.run(s.gyr[:333], s.acc[:333], s.mag[:333])
    checkpoint = f.get_state()
    rest_of_run = f.run(s.gyr[333:], s.acc[333:], s.mag[333:])
    g = Polaris(rate_hz=RATE)
    g.set_state(checkpoint)
    np.testing.assert_array_equal(g.run(s.gyr[333:], s.acc[333:], s.mag[333:]), rest_of_run)
    # The checkpoint is a copy: running on did not change it.
    h = Polaris(rate_hz=RATE)
    h.set_state(checkpoint)
    np.testing.assert_array_equal(h.run(s.gyr[333:], s.acc[333:], s.mag[333:]), rest_of_run)
    with pytest.raises(ConfigError, match="state: expected a PolarisState"):
        g.set_state({"quat": [1, 0, 0, 0]})


def test_fast_matches_reference_on_every_branch() -> None:
    # A magnet appears (gate, hard-iron reset), a disturbance passes, rest at the start.
    s = make_synthetic(
        rate_hz=100.0,
        duration_s=14.0,
        rest_s=2.0,
        hard_iron=np.array([0.0, 10.0, 20.0]),
        hard_iron_from_s=6.0,
        world_disturbance=np.array([10.0, 0.0, 0.0]),
        disturbance_s=(10.0, 11.0),
    )
    kw = {"rate_hz": 100.0, "mag_delay_s": 0.02}
    fast = Polaris(**kw)  # type: ignore[arg-type]
    ref = Polaris(backend="reference", **kw)  # type: ignore[arg-type]
    q9f, q6f = fast.run_both(s.gyr, s.acc, s.mag)
    q9r, q6r = ref.run_both(s.gyr, s.acc, s.mag)
    # Same arithmetic in another order: differences stay at rounding level (~1e-15).
    np.testing.assert_allclose(q9f, q9r, atol=1e-9)
    np.testing.assert_allclose(q6f, q6r, atol=1e-9)
    np.testing.assert_allclose(fast.state.hard_iron, ref.state.hard_iron, atol=1e-9)
    off_f = fast.smooth(s.gyr, s.acc, s.mag)
    off_r = ref.smooth(s.gyr, s.acc, s.mag)
    assert off_f.q9 is not None
    assert off_r.q9 is not None
    np.testing.assert_allclose(off_f.q9, off_r.q9, atol=1e-9)
    np.testing.assert_allclose(off_f.q6, off_r.q6, atol=1e-9)


def test_registry_and_params() -> None:
    f = make_filter("polaris", 100.0, tau_acc=2.0)
    assert isinstance(f, Polaris)
    assert f.params.tau_acc == 2.0
    p = PolarisParams(rate_hz=286.0)
    assert p.block_size == 6
    assert PolarisParams(rate_hz=286.0, mag_delay_s=0.014).mag_delay_samples == 4


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"tau_acc": 0.0}, "tau_acc: expected a positive finite number, got 0.0"),
        ({"tilt_noise": float("nan")}, "tilt_noise: expected a positive finite number"),
        ({"heading_process": -1.0}, "heading_process: expected a finite number >= 0"),
        ({"mag_delay_s": 1.0}, "mag_delay_s: 1.0 s is 100 samples at 100 Hz; at most 63"),
        ({"tau_acc": 0.001}, "tau_acc: 0.001 s is shorter than one sample at 100 Hz"),
        ({"rate_hz": 0.0}, "rate_hz: expected a positive sampling rate"),
    ],
)
def test_bad_params(kwargs: dict[str, float], message: str) -> None:
    with pytest.raises(ConfigError, match=message.replace("(", r"\(")):
        PolarisParams(**{"rate_hz": 100.0, **kwargs})


def test_constructor_needs_a_rate() -> None:
    with pytest.raises(ConfigError, match="rate_hz: required"):
        Polaris()
    with pytest.raises(ConfigError, match="either params or rate_hz"):
        Polaris(PolarisParams(rate_hz=100.0), rate_hz=100.0)


def test_bad_input_is_named() -> None:
    s = make_synthetic(rate_hz=RATE, duration_s=1.0)
    f = Polaris(rate_hz=RATE)
    gyr = s.gyr.copy()
    gyr[3, 1] = np.nan
    with pytest.raises(DataError, match="gyr: non-finite value at sample 3, column 1"):
        f.run(gyr, s.acc, s.mag)
    with pytest.raises(ShapeError, match=r"acc: expected shape \(200, 3\), got \(200, 2\)"):
        f.run(s.gyr, s.acc[:, :2], s.mag)
    with pytest.raises(DataError, match="acc: no usable sample"):
        f.run(s.gyr, np.zeros_like(s.acc), s.mag)
    with pytest.raises(DataError, match="acc: no usable sample"):
        f.run_offline(s.gyr, np.zeros_like(s.acc), s.mag)


def test_zero_norm_readings_are_skipped() -> None:
    s = make_synthetic(rate_hz=RATE, duration_s=3.0)
    acc = s.acc.copy()
    mag = s.mag.copy()
    acc[50:60] = 0.0  # a dead accelerometer: gyroscope-only for those samples
    mag[100:300] = 0.0  # a dead magnetometer: heading held by the gyroscope
    for run in (
        lambda f: f.run(s.gyr, acc, mag),
        lambda f: f.run_offline(s.gyr, acc, mag),
    ):
        q = run(Polaris(rate_hz=RATE))
        assert np.isfinite(q).all()
        # Noise-free data: skipping readings costs accuracy but never much (measured
        # 0.4 deg, the bias drift before the rest detector kicks in).
        assert _deg(total_error(error_quat_world(q, s.q))).max() < 1.0


def test_mag_delay_is_estimated_from_the_imu_alone() -> None:
    s = make_synthetic(rate_hz=RATE, duration_s=20.0, rest_s=1.0)
    delayed = np.vstack([np.repeat(s.mag[:1], 5, axis=0), s.mag[:-5]])  # 5 samples late
    assert estimate_mag_delay(s.gyr, delayed, RATE) == pytest.approx(5 / RATE)
    assert estimate_mag_delay(s.gyr, s.mag, RATE) == pytest.approx(0.0)
    rest = make_synthetic(rate_hz=RATE, duration_s=2.0, rest_s=5.0)
    with pytest.raises(DataError, match="gyr: only 0 samples rotate faster than 30 deg/s"):
        estimate_mag_delay(rest.gyr, rest.mag, RATE)


def test_reset_and_reset_heading() -> None:
    s = make_synthetic(rate_hz=RATE, duration_s=2.0)
    f = Polaris(rate_hz=RATE)
    first = f.run(s.gyr, s.acc, s.mag)
    f.reset_heading()
    q = f.run(s.gyr, s.acc, s.mag)
    assert np.isfinite(q).all()
    f.reset()
    assert not f.get_state().started
    np.testing.assert_array_equal(f.run(s.gyr, s.acc, s.mag), first)


def _validated(f: Polaris, gyr: np.ndarray, acc: np.ndarray, mag: np.ndarray | None) -> tuple:
    inputs, _ = f._prepare(gyr, acc, mag, None)
    return (inputs.gyr, inputs.acc, inputs.mag, inputs.dt, inputs.use_acc, inputs.use_mag,
            mag is not None)  # fmt: skip


def test_offline_pieces_equal_the_numpy_steps(tmp_path: Path) -> None:
    # Upside down the low-passed vertical is antiparallel to up at the start (the fused
    # inclination kernel leaves that to numpy); zero-norm accelerometer rows are
    # interpolated (here across a piece boundary, and at both ends); the kernels follow
    # numpy's arithmetic and carry their state from piece to piece, so equal to the bit
    # in one piece in memory, and in pieces of 97 samples on disk.
    s = make_synthetic(20.0, RATE, q0=quat_from_axis_angle([1.0, 0.0, 0.0], np.pi))
    acc = s.acc.copy()
    acc[:3] = 0.0
    acc[290:320] = 0.0
    acc[-2:] = 0.0
    for mag in (s.mag, None):
        f = Polaris(rate_hz=RATE)
        args = _validated(f, s.gyr, acc, mag)
        fused = polaris_offline.smooth(f.params, "fast", *args)
        steps = polaris_offline.smooth_steps(f.params, "fast", *args)
        gyr, acc_v, mag_v, dt, use_acc, use_mag, has_mag = args
        store = polaris_offline_chunks.DiskStore(tmp_path)
        for name, x in (("gyr", gyr), ("acc", acc_v), ("mag", mag_v), ("dt", dt)):
            for a in range(0, len(dt), 500):  # written in other pieces than read
                store.write(name, a, x[a : a + 500])
        pieces = list(polaris_offline_chunks.smooth_pieces(
            f.params, store, len(dt), use_acc, use_mag, has_mag, 97))  # fmt: skip
        store.close()
        assert [p.start for p in pieces] == list(range(0, len(dt), 97))
        assert not list(tmp_path.iterdir())  # the store's files are gone
        for result in (fused, steps):
            np.testing.assert_array_equal(np.concatenate([p.q6 for p in pieces]), result.q6)
            np.testing.assert_array_equal(np.concatenate([p.bias for p in pieces]), result.bias)
            if mag is not None:
                assert result.q9 is not None
                np.testing.assert_array_equal(
                    np.concatenate([p.q9 for p in pieces if p.q9 is not None]), result.q9
                )
