"""The first rest period's gyroscope bias read piece by piece (mocapkit.imu.rest_streaming)
against the whole recording's (mocapkit.imu.calibration.calibrate_from_rest)."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import DataError
from mocapkit.imu.calibration import calibrate_from_rest
from mocapkit.imu.rest_streaming import first_rest_bias
from mocapkit.series import ImuRecording


def _recording(rests: list[tuple[int, int]], n: int = 3000, seed: int = 0) -> ImuRecording:
    """Moving at 100 Hz, still (bias and noise only) over ``rests``."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 100.0
    gyr = np.column_stack([np.sin(2 * t), np.cos(3 * t), np.sin(t)]) + 0.01 * rng.normal(
        size=(n, 3)
    )
    acc = np.tile([0.0, 0.0, 9.81], (n, 1)) + 0.5 * rng.normal(size=(n, 3))
    for a, b in rests:
        gyr[a:b] = [0.004, -0.006, 0.002] + 0.002 * rng.normal(size=(b - a, 3))
        acc[a:b] = [0.0, 0.0, 9.81] + 0.01 * rng.normal(size=(b - a, 3))
    return ImuRecording(t, gyr, acc, name="shank")


def _pieces(rec: ImuRecording, size: int) -> list[ImuRecording]:
    return [
        ImuRecording(
            rec.time[a : a + size],
            rec.gyr[a : a + size],
            rec.acc[a : a + size],
            name=rec.name,
            meta={"sampling_rate": 100.0},
        )
        for a in range(0, rec.n_samples, size)
    ]


@pytest.mark.parametrize("size", [2, 7, 50, 333, 5000])
@pytest.mark.parametrize(
    "rests",
    [
        [(0, 200)],  # at the start
        [(400, 420), (1000, 1200)],  # a short one first (too short: skipped)
        [(2900, 3000)],  # at the very end
        [(1000, 1050), (1500, 1600)],  # exactly the minimum first
    ],
)
def test_the_first_rest_period_as_the_whole_recording_finds_it(
    rests: list[tuple[int, int]], size: int
) -> None:
    rec = _recording(rests)
    want = calibrate_from_rest(rec, use_mag=False).gyr_bias
    got = first_rest_bias(_pieces(rec, size))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-15)


def test_it_stops_reading_once_the_period_ended() -> None:
    rec = _recording([(100, 300)])
    read = []

    def pieces():  # type: ignore[no-untyped-def]
        for p in _pieces(rec, 100):
            read.append(p.time[0])
            yield p

    first_rest_bias(pieces())
    assert len(read) == 4  # the period ends in the 4th piece, decided one window later


def test_no_rest_is_refused_as_the_whole_path_does() -> None:
    rec = _recording([(100, 140)])  # 0.4 s: shorter than the minimum
    with pytest.raises(DataError, match="shank: no rest period found") as whole:
        calibrate_from_rest(rec, use_mag=False)
    with pytest.raises(DataError) as piecewise:
        first_rest_bias(_pieces(rec, 64))
    assert str(piecewise.value) == str(whole.value)
