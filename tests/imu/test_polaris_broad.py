"""``polaris`` on real BROAD recordings: both backends agree, errors stay where measured,
and a small recorded excerpt reproduces its golden output."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.imu.filters import Polaris
from mocapkit.imu.metrics import orientation_rmse
from mocapkit.io.broad import read_broad_trial

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "polaris_golden.npz"
# BROAD's magnetometer lags the gyroscope by 4 samples (14 ms; estimate_mag_delay finds it
# from the IMU data): used to exercise the delay path of both backends.
DELAY_S = 4 / 285.714


def _trial(shared_data: Path, name: str):  # type: ignore[no-untyped-def]
    return read_broad_trial(shared_data / "broad" / f"{name}.hdf5")


def test_fast_matches_reference_on_broad(shared_data: Path) -> None:
    # Trial 33 from 39 s: a magnet is attached to the resting sensor, then it moves, so the
    # gate, the hard-iron reset and the rest detector all act on real data.
    t = _trial(shared_data, "33_disturbed_attached_magnet_2cm")
    r = t.rate_hz
    sl = slice(int(39 * r), int(39 * r) + 1800)
    g, a, m = t.imu.gyr[sl], t.imu.acc[sl], t.imu.mag[sl]
    fast = Polaris(rate_hz=r, mag_delay_s=DELAY_S)
    ref = Polaris(rate_hz=r, mag_delay_s=DELAY_S, backend="reference")
    q9f, q6f = fast.run_both(g, a, m)
    q9r, q6r = ref.run_both(g, a, m)
    # The two implementations order some sums differently: rounding-level differences
    # (measured 6e-15) that the stable filter does not amplify.
    np.testing.assert_allclose(q9f, q9r, atol=1e-9)
    np.testing.assert_allclose(q6f, q6r, atol=1e-9)
    off_f = fast.smooth(g[:1200], a[:1200], m[:1200])
    off_r = ref.smooth(g[:1200], a[:1200], m[:1200])
    assert off_f.q9 is not None
    assert off_r.q9 is not None
    np.testing.assert_allclose(off_f.q9, off_r.q9, atol=1e-9)  # measured 4e-12
    np.testing.assert_allclose(off_f.q6, off_r.q6, atol=1e-9)


@pytest.mark.parametrize(
    ("name", "max_9d", "max_6d_incl"),
    [
        # measured 1.54 / 0.39 and 1.46 / 0.99 deg with the defaults (docs/benchmarks.md);
        # the bounds leave ~20 % before a regression fails the test
        ("02_undisturbed_slow_rotation_B", 1.85, 0.47),
        ("07_undisturbed_fast_rotation_B", 1.75, 1.2),
    ],
)
def test_errors_on_broad_trials(
    shared_data: Path, name: str, max_9d: float, max_6d_incl: float
) -> None:
    t = _trial(shared_data, name)
    q9, q6 = Polaris(rate_hz=t.rate_hz).run_both(t.imu.gyr, t.imu.acc, t.imu.mag)
    e9 = orientation_rmse(q9, t.reference.quat, t.movement)
    e6 = orientation_rmse(q6, t.reference.quat, t.movement, align_heading=True)
    assert np.degrees(e9.total) < max_9d
    assert np.degrees(e6.inclination) < max_6d_incl


def test_golden_output() -> None:
    """A 2.8 s excerpt of BROAD trial 24 (1 s at rest, then moved and tapped; CC BY 4.0, see
    tests/data/polaris_golden.SOURCE.md) with the online 9D/6D and offline 9D outputs
    recorded when the filter was validated (default parameters). Any change of the
    algorithm or its defaults shows here; regenerate deliberately with
    ``python -m tests.imu.make_polaris_golden``."""
    data = np.load(GOLDEN)
    every = int(data["every"])
    f = Polaris(rate_hz=float(data["rate_hz"]))
    q9, q6 = f.run_both(data["gyr"], data["acc"], data["mag"])
    offline = f.smooth(data["gyr"], data["acc"], data["mag"]).q9
    assert offline is not None
    # Same code, same inputs: only the platform's libm may differ, by a few ulp.
    np.testing.assert_allclose(q9[::every], data["q9"], atol=1e-9)
    np.testing.assert_allclose(q6[::every], data["q6"], atol=1e-9)
    np.testing.assert_allclose(offline[::every], data["q9_offline"], atol=1e-9)
