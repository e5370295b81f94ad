"""Several sensors on their own clocks, filtered and put on one time base piece by piece
(issue 16: an x-IMU3 suit's hour in bounded memory).

Each sensor's raw samples come in pieces (:func:`mocapkit.io.ximu3.iter_ximu3_sensor`),
go through its own filter object (state carried: one run's numbers) and its orientations
go to a raw file on disk (:class:`SensorSpill`). The common time base is then computed
from the spills as the whole-recording paths compute it from the series
(:func:`mocapkit.imu.resample.common_time_base` for ``imu run``,
:func:`mocapkit.body.timebase.common_time` for ``body angles``), and each sensor is
resampled onto it a piece at a time from a window of its own samples read forwards
(:meth:`SensorSpill.window`): slerp between the two samples either side of each time, so
the pieces give the whole path's numbers.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._spill import RowFile
from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError, DataError
from mocapkit.series import ImuRecording, OrientationSeries

RESAMPLE_ROWS = 50_000  # time-base samples resampled and yielded at a time


class SensorSpill:
    """One sensor's orientation series on disk, appended piece by piece and read forwards
    by time window."""

    def __init__(self, directory: str | Path, name: str, index: int) -> None:
        self.name = name
        self.time = RowFile(Path(directory) / f"s{index}_time.f64")
        self.quat = RowFile(Path(directory) / f"s{index}_quat.f64", (4,))
        self._pos = 0
        self._t = np.zeros(0)
        self._q = np.zeros((0, 4))

    def append(self, t: FloatArray, q: FloatArray) -> None:
        self.time.append(t)
        self.quat.append(q)

    @property
    def n(self) -> int:
        return self.time.rows

    def span(self) -> tuple[float, float]:
        return float(self.time.read(0, 1)[0]), float(self.time.read(self.n - 1, self.n)[0])

    def median_step(self) -> float:
        """The median interval of the whole series (its time column read once: 8 bytes a
        sample)."""
        return float(np.median(np.diff(self.time.read(0, self.n)))) if self.n > 1 else 0.0

    def window(self, t0: float, t1: float, block: int = RESAMPLE_ROWS) -> OrientationSeries:
        """The samples from the last one at or before ``t0`` to the first one after ``t1``
        (fewer at the ends); calls must come with increasing ``t0``."""
        while self._pos < self.n and (self._t.size == 0 or self._t[-1] <= t1):
            b = min(self.n, self._pos + block)
            self._t = np.concatenate([self._t, self.time.read(self._pos, b)])
            self._q = np.concatenate([self._q, self.quat.read(self._pos, b)])
            self._pos = b
        keep = max(0, int(np.searchsorted(self._t, t0, side="right")) - 1)
        self._t, self._q = self._t[keep:], self._q[keep:]
        return OrientationSeries(self._t, self._q, name=self.name)

    def close(self) -> None:
        self.time.close()
        self.quat.close()


def first_piece_filter(
    piece: ImuRecording, filter_name: str, params: dict[str, Any] | None,
    source: str | Path | None = None,
) -> Any:  # fmt: skip
    """The filter for a recording read in pieces, made from its first piece: its units
    checked (a gyroscope in deg/s), at least two rows to know the rate from. ``source``
    names the recording in messages (default: the sensor's name)."""
    from mocapkit.imu.filters import make_filter
    from mocapkit.io.imu_files import check_units

    check_units(piece)
    if piece.n_samples < 2:
        raise ConfigError(
            f"{source or piece.name}: {piece.n_samples} data row: at least 2 are needed to "
            "know the sampling rate"
        )
    return make_filter(filter_name, piece.rate_hz, **(params or {}))


def filter_pieces(
    pieces: Iterable[ImuRecording], filter_name: str, mode: str,
    params: dict[str, Any] | None = None, source: str | Path | None = None,
) -> Iterator[tuple[ImuRecording, FloatArray, Any]]:  # fmt: skip
    """Each piece through one filter object, its state carried: ``(piece, q (n, 4), the
    filter's last_report)``; the first piece's units are checked (a gyroscope in deg/s).
    ``source`` names the recording in messages (default: the sensor's name)."""
    filt = None
    t_last = 0.0
    for piece in pieces:
        if filt is None:
            filt = first_piece_filter(piece, filter_name, params, source)
            steps = np.concatenate([[filt.params.dt], np.diff(piece.time)])
        else:
            steps = np.concatenate([[piece.time[0] - t_last], np.diff(piece.time)])
        q = filt.run(piece.gyr, piece.acc, piece.mag if mode == "9d" else None, dt=steps)
        t_last = float(piece.time[-1])
        yield piece, q, filt.last_report


def aligned_pieces(
    spills: list[SensorSpill],
    grid: Callable[[int, int], FloatArray],
    n: int,
    resample: Callable[[OrientationSeries, FloatArray], FloatArray],
    rows: int = RESAMPLE_ROWS,
) -> Iterator[tuple[FloatArray, FloatArray]]:
    """``(t (m,), q (m, S, 4))`` over the time base ``grid(a, b)`` (its samples a..b, n in
    all), each sensor resampled by ``resample(window, t)``."""
    for a in range(0, n, rows):
        b = min(n, a + rows)
        t = grid(a, b)
        q = np.stack([resample(s.window(float(t[0]), float(t[-1])), t) for s in spills], axis=1)
        yield t, q


def imu_time_base(spills: list[SensorSpill]) -> tuple[Callable[[int, int], FloatArray], int]:
    """:func:`mocapkit.imu.resample.common_time_base` of the spilled series, as a function
    of the sample range, and its length."""
    spans = [s.span() for s in spills]
    start = max(a for a, _ in spans)
    stop = min(b for _, b in spans)
    if stop <= start:
        raise DataError(
            "series: the sensors' recordings do not overlap in time; are they from the same "
            "trial and clock?"
        )
    steps = [s.median_step() for s in spills if s.n > 1]
    step = float(np.median(steps)) if steps else stop - start
    n = int(np.floor((stop - start) / step + 1e-9)) + 1
    return (lambda a, b: np.asarray(start + step * np.arange(a, b), dtype=np.float64)), n


def body_pieces(
    spills: list[SensorSpill], rows: int = RESAMPLE_ROWS
) -> Iterator[tuple[FloatArray, FloatArray]]:
    """``(t, q (m, S, 4))`` as :func:`mocapkit.body.timebase.align_orientations` puts the
    spilled series on one grid (:func:`~mocapkit.body.timebase.common_time`; the series
    as they are when they share one clock), a piece at a time."""
    from mocapkit.body.timebase import resample_orientation

    n0 = spills[0].n
    same = all(s.n == n0 for s in spills) and all(
        np.array_equal(s.time.read(a, min(n0, a + rows)), spills[0].time.read(a, min(n0, a + rows)))
        for s in spills[1:] for a in range(0, n0, rows)
    )  # fmt: skip
    if same:
        for a in range(0, n0, rows):
            b = min(n0, a + rows)
            yield spills[0].time.read(a, b), np.stack([s.quat.read(a, b) for s in spills], 1)
        return
    spans = [s.span() for s in spills]
    start = max(a for a, _ in spans)
    stop = min(b for _, b in spans)
    if stop <= start:
        listed = ", ".join(
            f"{s.name}: {a:.3f}-{b:.3f} s" for s, (a, b) in zip(spills, spans, strict=True)
        )
        raise DataError(f"the sensors' recordings do not overlap in time ({listed})")
    rate = 1.0 / float(np.median([s.median_step() for s in spills if s.n > 1]))
    n = int(np.floor((stop - start) * rate + 1e-9)) + 1
    yield from aligned_pieces(
        spills, lambda a, b: start + np.arange(a, b) / rate, n,
        lambda series, t: resample_orientation(series, t).quat, rows,
    )  # fmt: skip
