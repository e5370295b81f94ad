"""Put orientation series from sensors with their own clocks on one time base (slerp)."""

from __future__ import annotations

from typing import Any

import numpy as np

from mocapkit._validate import FloatArray, as_float_array, check_shape
from mocapkit.errors import DataError
from mocapkit.geometry import quat_slerp
from mocapkit.series import OrientationSeries


def resample_orientation(series: OrientationSeries, time: Any) -> FloatArray:
    """``series`` at the times ``time`` (M,) [s], by slerp between the neighbouring
    samples. Every time must lie within the series' own time range (no extrapolation)."""
    t = as_float_array(time, "time")
    check_shape(t, "time", None)
    src = series.time
    if t.size and (t[0] < src[0] or t[-1] > src[-1]):
        raise DataError(
            f"time: {t[0]:.6f}..{t[-1]:.6f} s leaves the range of {series.name} "
            f"({src[0]:.6f}..{src[-1]:.6f} s); resampling never extrapolates"
        )
    if src.size == 1:
        return np.repeat(series.quat, t.size, axis=0)
    j = np.clip(np.searchsorted(src, t, side="right"), 1, src.size - 1)
    frac = (t - src[j - 1]) / (src[j] - src[j - 1])
    return quat_slerp(series.quat[j - 1], series.quat[j], np.clip(frac, 0.0, 1.0))


def common_time_base(series: list[OrientationSeries]) -> FloatArray:
    """A uniform time base over the range all series share, at their median rate."""
    if not series:
        raise DataError("series: nothing to resample")
    start = max(float(s.time[0]) for s in series)
    stop = min(float(s.time[-1]) for s in series)
    if stop <= start:
        raise DataError(
            "series: the sensors' recordings do not overlap in time; are they from the same "
            "trial and clock?"
        )
    steps = [float(np.median(np.diff(s.time))) for s in series if s.n_samples > 1]
    step = float(np.median(steps)) if steps else stop - start
    n = int(np.floor((stop - start) / step + 1e-9)) + 1
    return np.asarray(start + step * np.arange(n), dtype=np.float64)
