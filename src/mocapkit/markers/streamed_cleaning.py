"""Gap filling and low-pass filtering of a trial kept on disk (``markers reconstruct
--fill-gaps / --lowpass-hz`` at flat memory, issue 16): the whole-trial cleaning
(:mod:`mocapkit.markers.cleaning`) done piece by piece, with the same report.

1. **Prepare**: the spilled frames, as read, become the reconstruction's (units, the marker
   set's columns, z up) into a second file on disk, a piece at a time.
2. **Find the gaps** of every marker across the pieces (runs of missing frames carried
   from one piece to the next), in the whole-trial order (marker by marker, in time).
3. **Fill** each gap in that order, as the whole trial does, reading only the frames around
   it: the rigid-cluster fill needs the frame before, the frame after and the gap's own
   (the same numbers, so the same result); the spline fill uses the
   :data:`SPLINE_KNOTS` visible samples either side instead of the whole trial's. A cubic
   spline's dependence on a far sample falls by 2 - sqrt(3) ~ 0.27 per sample between, so
   64 either side reproduce the whole trial's spline to rounding (0.27**64 ~ 1e-37).
4. **Low-pass**: each visible run is filtered forwards and backwards as ``filtfilt`` does,
   a piece at a time with a margin either side long enough for the filter's memory of the
   margin's far end to fall below :data:`SETTLED` (from the filter's slowest pole): the
   whole run's result to rounding. Runs too short to pad are left as they are and listed,
   as the whole trial does.

Memory: one piece and its margins (the margins grow as the cut-off falls below the frame
rate: 0.5 Hz at 1 kHz needs ~30,000 frames either side), plus the list of gaps.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from mocapkit._spill import RowFile
from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError
from mocapkit.markers.cleaning import (
    CleaningReport,
    Gap,
    _rigid_fill_gap,
    _runs,
    fill_candidates,
)

#: visible samples either side of a gap that its spline fill sees (module docstring)
SPLINE_KNOTS = 64
#: the low-pass margin: the filter's memory of a sample falls below this (relative)
SETTLED = 1e-17
#: Butterworth order of the low-pass (as :func:`mocapkit.markers.cleaning.lowpass`)
ORDER = 4


def find_gaps_spilled(
    visible: Callable[[int, int], np.ndarray], n: int, names: Sequence[str], chunk: int
) -> tuple[list[Gap], list[str]]:
    """:func:`mocapkit.markers.cleaning.find_gaps` over ``n`` frames whose (b - a, M)
    visibility ``visible(a, b)`` gives, ``chunk`` frames at a time."""
    m_count = len(names)
    open_since: list[int | None] = [None] * m_count
    seen = np.zeros(m_count, dtype=bool)
    found: list[list[Gap]] = [[] for _ in range(m_count)]
    for a in range(0, n, chunk):
        b = min(n, a + chunk)
        vis = visible(a, b)
        seen |= vis.any(axis=0)
        for m in range(m_count):
            since = open_since[m]
            if since is not None and vis[0, m]:
                found[m].append(Gap(names[m], since, a))
                since = None
            for s, e in _runs(~vis[:, m]):
                start = since if s == 0 and since is not None else a + s
                since = None
                if e < b - a:
                    found[m].append(Gap(names[m], start, a + e))
                else:
                    since = start
            open_since[m] = since
    for m in range(m_count):
        since = open_since[m]
        if since is not None:
            found[m].append(Gap(names[m], since, n))
    never = [names[m] for m in range(m_count) if not seen[m]]
    gaps = [g for m in range(m_count) if seen[m] for g in found[m]]
    return gaps, never


def _side_samples(
    times: RowFile, positions: RowFile, m: int, start: int, stop: int, n: int
) -> tuple[FloatArray, FloatArray]:
    """Up to :data:`SPLINE_KNOTS` visible samples of marker ``m`` before ``start`` and as
    many from ``stop`` on (times (K,), positions (K, 3)), read outwards in growing steps."""
    keep_t: list[FloatArray] = []
    keep_x: list[FloatArray] = []
    for side in (-1, 1):
        got_t: list[FloatArray] = []
        got_x: list[FloatArray] = []
        have = 0
        edge = start if side < 0 else stop
        step = 4 * SPLINE_KNOTS
        while have < SPLINE_KNOTS and (edge > 0 if side < 0 else edge < n):
            lo, hi = (max(0, edge - step), edge) if side < 0 else (edge, min(n, edge + step))
            x = positions.read(lo, hi)[:, m]
            t = times.read(lo, hi)
            good = np.isfinite(x[:, 0])
            t, x = t[good], x[good]
            if side < 0:
                got_t.insert(0, t)
                got_x.insert(0, x)
            else:
                got_t.append(t)
                got_x.append(x)
            have += int(good.sum())
            edge = lo if side < 0 else hi
            step *= 2
        t_all = np.concatenate(got_t) if got_t else np.empty(0)
        x_all = np.concatenate(got_x) if got_x else np.empty((0, 3))
        if side < 0:
            keep_t.append(t_all[-SPLINE_KNOTS:])
            keep_x.append(x_all[-SPLINE_KNOTS:])
        else:
            keep_t.append(t_all[:SPLINE_KNOTS])
            keep_x.append(x_all[:SPLINE_KNOTS])
    return np.concatenate(keep_t), np.concatenate(keep_x)


def fill_gaps_spilled(
    times: RowFile,
    positions: RowFile,
    n: int,
    names: Sequence[str],
    rate: float,
    method: str,
    max_gap_s: float,
    clusters: Mapping[str, Sequence[str]] | None,
    chunk: int,
) -> CleaningReport:
    """:func:`mocapkit.markers.cleaning.fill_gaps` on the file, in place (module
    docstring); the same report."""
    report = CleaningReport()
    report.gaps_found, report.never_visible = find_gaps_spilled(
        lambda a, b: np.isfinite(positions.read(a, b)[..., 0]), n, names, chunk
    )
    for gap, m, donors in fill_candidates(report, n, rate, method, max_gap_s, clusters, names):
        if len(donors) >= 3:
            lo, hi = gap.start - 1, gap.stop + 1
            pos = positions.read(lo, hi)
            if _rigid_fill_gap(pos, m, donors, Gap(gap.marker, gap.start - lo, gap.stop - lo)):
                positions.write(gap.start, pos[1:-1])
                report.filled_rigid.append(gap)
                continue
        if method in ("spline", "both"):
            t_good, x_good = _side_samples(times, positions, m, gap.start, gap.stop, n)
            if len(t_good) >= 4:
                from scipy.interpolate import CubicSpline

                cs = CubicSpline(t_good, x_good)
                rows = positions.read(gap.start, gap.stop)
                rows[:, m] = cs(times.read(gap.start, gap.stop))
                positions.write(gap.start, rows)
                report.filled_spline.append(gap)
                continue
        report.left_open.append(gap)
    report.open_in_order()
    return report


def settle_frames(b: FloatArray, a: FloatArray) -> int:
    """Samples after which the filter ``(b, a)``'s memory of an input has fallen below
    :data:`SETTLED` (from its slowest pole)."""
    r = float(np.abs(np.roots(a)).max()) if len(a) > 1 else 0.0
    if r <= 0.0:
        return len(b)
    return math.ceil(math.log(SETTLED) / math.log(r)) + 3 * max(len(a), len(b))


def lowpass_spilled(
    positions: RowFile,
    out: RowFile,
    n: int,
    names: Sequence[str],
    rate: float,
    cutoff_hz: float,
    report: CleaningReport,
    chunk: int,
    progress: Callable[[int, int], None] | None = None,
) -> None:
    """:func:`mocapkit.markers.cleaning.lowpass` from ``positions`` into ``out`` (module
    docstring); the short runs left unfiltered are added to ``report``."""
    from scipy.signal import butter, filtfilt

    if not (0 < cutoff_hz < rate / 2):
        raise ConfigError(
            f"lowpass cutoff {cutoff_hz} Hz must be between 0 and the Nyquist frequency "
            f"{rate / 2:g} Hz"
        )
    report.lowpass_hz = cutoff_hz
    b_, a_ = butter(ORDER, cutoff_hz / (rate / 2))
    pad = 3 * max(len(a_), len(b_))
    margin = settle_frames(b_, a_)
    short: list[tuple[int, str, int, int]] = []
    for a in range(0, n, chunk):
        b = min(n, a + chunk)
        lo, hi = max(0, a - margin), min(n, b + margin)
        pos = positions.read(lo, hi)
        res = pos[a - lo : b - lo].copy()
        vis = np.isfinite(pos[..., 0])
        for m, name in enumerate(names):
            for s, e in _runs(vis[:, m]):
                if e <= a - lo or s >= b - lo:
                    continue  # outside this piece
                if e - s <= pad:  # a run this short touches no cut: it is the whole run
                    if s >= a - lo:  # listed once, in the piece where it starts
                        short.append((m, name, lo + s, lo + e))
                    continue
                y = filtfilt(b_, a_, pos[s:e, m], axis=0)
                s0, e0 = max(s, a - lo), min(e, b - lo)
                res[s0 - (a - lo) : e0 - (a - lo), m] = y[s0 - s : e0 - s]
        out.write(a, res)
        if progress is not None:
            progress(b, n)
    report.unfiltered_runs += [(name, s, e) for _, name, s, e in sorted(short)]
