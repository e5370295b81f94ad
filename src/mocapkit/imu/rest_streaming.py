"""The gyroscope bias of a recording's first rest period, read piece by piece (``imu run
--remove-gyr-bias`` on an hour's file in bounded memory, issue 16).

:func:`mocapkit.imu.calibration.calibrate_from_rest` finds the rest periods of the whole
recording (:func:`~mocapkit.imu.calibration.detect_rest`: a sample rests when some window
of ``window_s`` covering it is quiet; runs shorter than ``min_duration_s`` dropped) and
takes the first one's mean rate. Quiet windows and rest only look ``window_s`` ahead, so
the same decisions come from the pieces in turn, the last ``window - 1`` samples carried
over; reading stops once the first period has ended (usually within the first seconds).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from mocapkit._validate import FloatArray
from mocapkit.errors import DataError
from mocapkit.imu.calibration import (
    DEFAULT_ACC_THRESHOLD,
    DEFAULT_GYR_THRESHOLD,
    DEFAULT_MIN_DURATION,
    DEFAULT_WINDOW,
)
from mocapkit.series import ImuRecording


def _quiet(
    gyr_norm: FloatArray, acc: FloatArray, win: int, g_thr: float, a_thr: float
) -> np.ndarray:
    """Quiet flags of every full window of the samples (as ``detect_rest``)."""
    if len(gyr_norm) < win:
        return np.zeros(0, dtype=bool)
    gyr_max = sliding_window_view(gyr_norm, win).max(axis=1)
    acc_win = sliding_window_view(acc, win, axis=0)
    acc_dev = np.linalg.norm(acc_win - acc_win.mean(axis=2, keepdims=True), axis=1).max(axis=1)
    return np.asarray((gyr_max < g_thr) & (acc_dev < a_thr))


class _Runs:
    """Rest runs followed over the classified samples: the first one at least ``min_len``
    long gives the bias."""

    def __init__(self, min_len: int) -> None:
        self.min_len = min_len
        self.length = 0
        self.total = np.zeros(3)
        self.bias: FloatArray | None = None

    def add(self, rest: np.ndarray, gyr: FloatArray) -> None:
        """The next classified samples."""
        edges = np.flatnonzero(np.diff(rest.astype(np.int8)) != 0) + 1
        for a, b in zip([0, *edges.tolist()], [*edges.tolist(), len(rest)], strict=True):
            if self.bias is not None:
                return
            if rest[a]:
                self.length += b - a
                self.total = self.total + gyr[a:b].sum(axis=0)
            else:
                self.close()

    def close(self) -> None:
        if self.length >= self.min_len and self.bias is None:
            self.bias = self.total / self.length
        self.length = 0
        self.total = np.zeros(3)


def first_rest_bias(
    pieces: Iterable[ImuRecording],
    *,
    gyr_threshold: float = DEFAULT_GYR_THRESHOLD,
    acc_threshold: float = DEFAULT_ACC_THRESHOLD,
    window_s: float = DEFAULT_WINDOW,
    min_duration_s: float = DEFAULT_MIN_DURATION,
) -> FloatArray:
    """``calibrate_from_rest(rec, use_mag=False).gyr_bias`` of the recording ``pieces``
    make up (module docstring), the rate taken from the first piece. Raises the whole
    path's error when the recording has no rest period."""
    win = min_len = 0
    name = "recording"
    buf_g = np.zeros((0, 3))
    buf_a = np.zeros((0, 3))
    quiet_tail = np.zeros(0, dtype=bool)  # quiet flags of the windows before the buffer's
    runs: _Runs | None = None
    for piece in pieces:
        if runs is None:
            rate = piece.rate_hz
            win = max(1, round(window_s * rate))
            min_len = max(1, round(min_duration_s * rate))
            runs = _Runs(min_len)
            name = piece.name
        g = np.concatenate([buf_g, piece.gyr])
        a = np.concatenate([buf_a, piece.acc])
        quiet = _quiet(np.linalg.norm(g, axis=1), a, win, gyr_threshold, acc_threshold)
        if quiet.size == 0:  # fewer samples than a window so far
            buf_g, buf_a = g, a
            continue
        # rest of sample i: a quiet window starting in i - win + 1 .. i
        flags = np.concatenate([quiet_tail, quiet])
        covered = np.convolve(flags.astype(np.int64), np.ones(win, dtype=np.int64))
        lead = len(quiet_tail)
        rest = covered[lead : lead + len(quiet)] > 0  # the samples of g decided now
        runs.add(rest, g[: len(quiet)])
        if runs.bias is not None:
            return runs.bias
        buf_g, buf_a = g[len(quiet) :], a[len(quiet) :]
        quiet_tail = flags[-(win - 1) :] if win > 1 else np.zeros(0, dtype=bool)
    if runs is not None:
        if len(buf_g):  # the last samples: the windows that still cover them
            rest = np.zeros(len(buf_g), dtype=bool)
            if len(quiet_tail):
                covered = np.convolve(quiet_tail.astype(np.int64), np.ones(win, dtype=np.int64))
                rest = covered[len(quiet_tail) : len(quiet_tail) + len(buf_g)] > 0
            runs.add(rest, buf_g)
        runs.close()
        if runs.bias is not None:
            return runs.bias
    raise DataError(
        f"{name}: no rest period found (gyroscope below {np.degrees(gyr_threshold):.3g} "
        f"deg/s for {min_duration_s:g} s); keep the sensor still at the start of the "
        "recording"
    )
