"""``polaris`` after faults in the data: one synthetic case with an exact truth per fault
type and one real BROAD trial. The property checked is recovery (back within 1 deg of
the unfaulted run 30 s after the fault, and of the truth), never a timing."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import DataError
from mocapkit.imu.fault_injection import DEFAULT_GYR_RANGE, inject
from mocapkit.imu.filters import (
    Polaris,
    SensorSaturationWarning,
    TimeGapWarning,
    make_filter,
)
from mocapkit.imu.filters.inputs import clipped_gyr
from mocapkit.imu.metrics import error_quat_world, total_error
from tests.imu.polaris_synthetic import make_synthetic

RATE = 100.0
AT_S = 20.0
BROAD = Path(__file__).resolve().parents[3] / "shared" / "data" / "broad"


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(total_error(error_quat_world(a, b)))


@pytest.fixture(scope="module")
def synthetic():  # type: ignore[no-untyped-def]
    s = make_synthetic(duration_s=70.0, rate_hz=RATE, amplitude_deg_s=90.0)
    time = np.arange(s.gyr.shape[0]) / RATE
    clean = Polaris(rate_hz=RATE, gyr_range=DEFAULT_GYR_RANGE).run(s.gyr, s.acc, s.mag)
    return s, time, clean


RECOVERABLE = [
    ("gyr_saturation", 0.05, SensorSaturationWarning),
    ("gyr_saturation", 0.2, SensorSaturationWarning),
    ("time_jump", 1.0, TimeGapWarning),
    ("missing", 1.0, TimeGapWarning),
    ("missing", 5.0, TimeGapWarning),
    ("mag_dropout", 1.0, None),
    ("mag_spike", 0.5, None),
    ("acc_impact", 0.02, None),
]


@pytest.mark.parametrize(("kind", "size", "warning"), RECOVERABLE)
def test_synthetic_fault_is_recovered(synthetic, kind, size, warning) -> None:  # type: ignore[no-untyped-def]
    s, time, clean = synthetic
    at = round(AT_S * RATE)
    f = inject(kind, time, s.gyr, s.acc, s.mag, at, size)
    filt = Polaris(rate_hz=RATE, gyr_range=DEFAULT_GYR_RANGE)
    if warning is None:
        q = filt.run(f.gyr, f.acc, f.mag, dt=f.dt)
    else:
        with pytest.warns(warning, match=rf"sample {at}\b"):
            q = filt.run(f.gyr, f.acc, f.mag, dt=f.dt)
        assert filt.state.recoveries == 1
    later = f.source >= f.source[min(f.end, f.source.size - 1)] + round(30.0 * RATE)
    assert later.sum() > RATE  # the check has samples to look at
    to_clean = _angle_deg(q[later], clean[f.source[later]])
    to_truth = _angle_deg(q[later], s.q[f.source[later]])
    assert to_clean.max() < 1.0, f"{kind}: {to_clean.max():.2f} deg off the unfaulted run"
    assert to_truth.max() < 1.5, f"{kind}: {to_truth.max():.2f} deg off the truth"


def test_without_recovery_the_saturation_would_stay_wrong(synthetic) -> None:  # type: ignore[no-untyped-def]
    # The contrast that makes the test above mean something: a filter without fault
    # recovery (bachmann) is still tens of degrees off 30 s after the same burst.
    s, time, _ = synthetic
    at = round(AT_S * RATE)
    f = inject("gyr_saturation", time, s.gyr, s.acc, s.mag, at, 0.05)
    with pytest.warns(SensorSaturationWarning):
        q = make_filter("bachmann", RATE).run(f.gyr, f.acc, f.mag)
    later = np.arange(at + round(35 * RATE), at + round(36 * RATE))
    assert _angle_deg(q[later], s.q[later]).mean() > 5.0


@pytest.mark.parametrize("kind", ["duplicate_stamp", "backwards_stamp"])
def test_stamps_that_do_not_advance_are_refused_naming_the_sample(synthetic, kind) -> None:  # type: ignore[no-untyped-def]
    s, time, _ = synthetic
    at = round(AT_S * RATE)
    f = inject(kind, time, s.gyr, s.acc, s.mag, at)
    with pytest.raises(DataError, match=rf"dt: sample {at} has time step"):
        Polaris(rate_hz=RATE).run(f.gyr, f.acc, f.mag, dt=f.dt)


def test_a_run_split_inside_the_recovery_equals_one_run(synthetic) -> None:  # type: ignore[no-untyped-def]
    s, time, _ = synthetic
    at = round(AT_S * RATE)
    f = inject("gyr_saturation", time, s.gyr, s.acc, s.mag, at, 0.05)
    with pytest.warns(SensorSaturationWarning):
        whole = Polaris(rate_hz=RATE, gyr_range=DEFAULT_GYR_RANGE).run(f.gyr, f.acc, f.mag)
    filt = Polaris(rate_hz=RATE, gyr_range=DEFAULT_GYR_RANGE)
    parts = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SensorSaturationWarning)
        for a, b in ((0, at + 2), (at + 2, at + 150), (at + 150, f.gyr.shape[0])):
            parts.append(filt.run(f.gyr[a:b], f.acc[a:b], f.mag[a:b]))
    np.testing.assert_allclose(np.concatenate(parts), whole, atol=1e-12)


def test_other_filters_hold_a_gap_and_report_it() -> None:
    s = make_synthetic(duration_s=30.0, rate_hz=RATE)
    time = np.arange(s.gyr.shape[0]) / RATE
    f = inject("missing", time, s.gyr, s.acc, s.mag, 1000, 2.0)
    filt = make_filter("bachmann", RATE)
    with pytest.warns(TimeGapWarning, match=r"time gap of 2.01? s before sample 1000"):
        filt.run(f.gyr, f.acc, f.mag, dt=f.dt)
    (sample, seconds), *_ = filt.last_report.gaps
    assert sample == 1000
    assert seconds == pytest.approx(2.01, abs=0.011)


def test_clip_detector_needs_a_flat_top() -> None:
    t = np.arange(2000) / 286.0
    smooth = np.column_stack([5.0 * np.sin(2 * np.pi * t), 0 * t, 0 * t])
    smooth = np.round(smooth / 0.00107) * 0.00107  # a 16-bit converter's steps
    assert not clipped_gyr(smooth).any()
    clipped = np.clip(smooth, -4.5, 4.5)
    assert clipped_gyr(clipped).any()


@pytest.mark.skipif(not BROAD.is_dir(), reason="needs ../shared/data/broad (BROAD trials)")
@pytest.mark.parametrize(("kind", "size"), [("gyr_saturation", 0.05), ("missing", 1.0)])
def test_real_trial_recovers(kind: str, size: float) -> None:
    from mocapkit.io.broad import read_broad_trial

    trial = read_broad_trial(BROAD / "07_undisturbed_fast_rotation_B.hdf5")
    imu, rate = trial.imu, trial.rate_hz
    clean = Polaris(rate_hz=rate, gyr_range=DEFAULT_GYR_RANGE).run(imu.gyr, imu.acc, imu.mag)
    at = round(AT_S * rate)
    f = inject(kind, imu.time, imu.gyr, imu.acc, imu.mag, at, size)
    filt = Polaris(rate_hz=rate, gyr_range=DEFAULT_GYR_RANGE)
    with pytest.warns((SensorSaturationWarning, TimeGapWarning)):
        q = filt.run(f.gyr, f.acc, f.mag, dt=f.dt)
    start = f.source[f.end] + round(30.0 * rate)
    later = f.source >= start
    dev = _angle_deg(q[later], clean[f.source[later]])
    assert math.isfinite(dev.max())
    assert dev.max() < 1.0
