"""Put several sensors' orientation streams on one time base (slerp), keeping gaps as gaps."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from mocapkit._validate import FloatArray, as_float_array, check_shape
from mocapkit.errors import DataError
from mocapkit.geometry import quat_slerp
from mocapkit.series import OrientationSeries


def common_time(
    series: Mapping[str, OrientationSeries], rate_hz: float | None = None
) -> FloatArray:
    """A time grid covered by every series: from the latest start to the earliest end.

    The rate is ``rate_hz`` or the median rate of the inputs.
    """
    if not series:
        raise DataError("no orientation series given")
    start = max(float(s.time[0]) for s in series.values())
    stop = min(float(s.time[-1]) for s in series.values())
    if stop <= start:
        spans = ", ".join(f"{k}: {s.time[0]:.3f}-{s.time[-1]:.3f} s" for k, s in series.items())
        raise DataError(f"the sensors' recordings do not overlap in time ({spans})")
    if rate_hz is None:
        dts = [float(np.median(np.diff(s.time))) for s in series.values() if s.n_samples > 1]
        rate_hz = 1.0 / float(np.median(dts))
    n = int(np.floor((stop - start) * rate_hz + 1e-9)) + 1
    return start + np.arange(n) / rate_hz


def resample_orientation(series: OrientationSeries, time: FloatArray) -> OrientationSeries:
    """Slerp ``series`` onto ``time`` [s]. Samples outside its span, or between two
    samples of which one is missing (NaN), are NaN."""
    t = as_float_array(time, "time")
    check_shape(t, "time", None)
    src_t, q = series.time, series.quat
    if src_t.shape == t.shape and np.array_equal(src_t, t):
        return series
    idx = np.searchsorted(src_t, t, side="right") - 1
    inside = (idx >= 0) & (t <= src_t[-1])
    i0 = np.clip(idx, 0, len(src_t) - 1)
    i1 = np.clip(idx + 1, 0, len(src_t) - 1)
    span = src_t[i1] - src_t[i0]
    frac = np.where(span > 0, (t - src_t[i0]) / np.where(span > 0, span, 1.0), 0.0)
    a, b = q[i0], q[i1]
    ok = inside & np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    out = np.full((len(t), 4), np.nan)
    if ok.any():
        out[ok] = quat_slerp(a[ok], b[ok], frac[ok])
    return OrientationSeries(t, out, name=series.name, frame=series.frame)


def align_orientations(
    series: Mapping[str, OrientationSeries], rate_hz: float | None = None
) -> dict[str, OrientationSeries]:
    """Every series on one common time grid (:func:`common_time`)."""
    times = [s.time for s in series.values()]
    same = all(t.shape == times[0].shape and np.array_equal(t, times[0]) for t in times)
    if times and same and rate_hz is None:
        return dict(series)
    t = common_time(series, rate_hz)
    return {k: resample_orientation(s, t) for k, s in series.items()}


def orientations_from_frames(
    frames: list[Mapping[str, object]], time: object
) -> dict[str, OrientationSeries]:
    """Frames as a live stream delivers them (``{sensor: q (4,)}`` per frame, a sensor may
    be absent) -> ``{sensor: OrientationSeries}`` with NaN where a sensor was absent. For
    calibrating from the first seconds of a live session (``calibrate_pose``)."""
    t = as_float_array(time, "time")
    check_shape(t, "time", len(frames))
    names = sorted({k for f in frames for k in f})
    out = {}
    for name in names:
        q = np.full((len(frames), 4), np.nan)
        for i, f in enumerate(frames):
            if name in f:
                q[i] = np.asarray(f[name], dtype=np.float64)
        out[name] = OrientationSeries(t, q, name=name)
    return out
