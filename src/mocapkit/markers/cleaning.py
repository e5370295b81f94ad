"""Marker data cleaning: find gaps, fill them (rigid cluster or spline), low-pass filter.

Every step is reported in a :class:`CleaningReport` (and in ``meta["cleaning"]``), so
a reconstruction always says what was changed in its input.

- Rigid-cluster fill: a missing marker is placed by the rigid motion (Kabsch) of at least
  three other markers of the same segment, estimated between the gap frame and the nearest
  frames before and after the gap where all of them are visible; the two estimates are
  blended linearly across the gap.
- Spline fill: a cubic spline through the visible samples, only across gaps no longer than
  ``max_gap_s`` (a longer gap stays NaN: the marker is left out of those frames).
- Low-pass: zero-phase 4th-order Butterworth (``filtfilt``) on each visible run; runs too
  short to pad are left unfiltered and listed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError
from mocapkit.markers.trajectories import MarkerTrajectories


@dataclass(frozen=True)
class Gap:
    marker: str
    start: int  # first missing frame
    stop: int  # one past the last missing frame

    @property
    def length(self) -> int:
        return self.stop - self.start


@dataclass
class CleaningReport:
    gaps_found: list[Gap] = field(default_factory=list)
    filled_rigid: list[Gap] = field(default_factory=list)
    filled_spline: list[Gap] = field(default_factory=list)
    left_open: list[Gap] = field(default_factory=list)
    never_visible: list[str] = field(default_factory=list)
    lowpass_hz: float | None = None
    unfiltered_runs: list[tuple[str, int, int]] = field(default_factory=list)

    def open_in_order(self) -> None:
        """``left_open`` in the order the gaps were found (marker by marker, in time)."""
        rank = {g: i for i, g in enumerate(self.gaps_found)}
        self.left_open.sort(key=rank.__getitem__)

    def summary(self) -> dict[str, object]:
        return {
            "gaps_found": len(self.gaps_found),
            "frames_missing": int(sum(g.length for g in self.gaps_found)),
            "filled_rigid": len(self.filled_rigid),
            "filled_spline": len(self.filled_spline),
            "left_open": [f"{g.marker}[{g.start}:{g.stop}]" for g in self.left_open][:20],
            "never_visible": self.never_visible,
            "lowpass_hz": self.lowpass_hz,
            "unfiltered_runs": len(self.unfiltered_runs),
        }


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of the True runs of a 1-D bool array."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


def find_gaps(traj: MarkerTrajectories) -> tuple[list[Gap], list[str]]:
    """Interior and edge gaps of every marker, and the markers never visible."""
    gaps: list[Gap] = []
    never: list[str] = []
    vis = traj.visible
    for m, name in enumerate(traj.names):
        if not vis[:, m].any():
            never.append(name)
            continue
        gaps += [Gap(name, a, b) for a, b in _runs(~vis[:, m])]
    return gaps, never


def _kabsch(A: FloatArray, B: FloatArray) -> tuple[FloatArray, FloatArray]:
    """R, t with B ≈ R A + t (rows are points)."""
    ca, cb = A.mean(axis=0), B.mean(axis=0)
    U, _, Vt = np.linalg.svd((A - ca).T @ (B - cb))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, cb - R @ ca


def _rigid_fill_gap(pos: FloatArray, m: int, donors: Sequence[int], gap: Gap) -> bool:
    """Fill one gap of marker m in place from donor markers; False when impossible."""
    n = pos.shape[0]
    vis = np.isfinite(pos[..., 0])
    estimates = []
    for ref in (gap.start - 1, gap.stop):  # last frame before, first frame after
        if not (0 <= ref < n) or not vis[ref, m]:
            continue
        common = [d for d in donors if vis[ref, d] and vis[gap.start : gap.stop, d].all()]
        if len(common) < 3:
            continue
        est = np.empty((gap.length, 3))
        for k, f in enumerate(range(gap.start, gap.stop)):
            R, t = _kabsch(pos[ref, common], pos[f, common])
            est[k] = R @ pos[ref, m] + t
        estimates.append((ref, est))
    if not estimates:
        return False
    if len(estimates) == 1:
        pos[gap.start : gap.stop, m] = estimates[0][1]
    else:
        w = (np.arange(gap.length) + 1.0) / (gap.length + 1.0)  # 0 -> before, 1 -> after
        pos[gap.start : gap.stop, m] = (1 - w)[:, None] * estimates[0][1] + w[:, None] * estimates[
            1
        ][1]
    return True


def fill_candidates(
    report: CleaningReport,
    n: int,
    rate: float,
    method: str,
    max_gap_s: float,
    clusters: Mapping[str, Sequence[str]] | None,
    names: Sequence[str],
) -> list[tuple[Gap, int, list[int]]]:
    """The gaps of ``report.gaps_found`` a fill may close, in order, each with its
    marker's column and its rigid-cluster donors (empty: no rigid fill); the others (edge
    gaps, gaps longer than ``max_gap_s``, everything with ``method="none"``) go to
    ``report.left_open``. Shared by the whole-trial and the piecewise fills."""
    if method not in ("none", "rigid", "spline", "both"):
        raise ConfigError(f"fill method: expected none, rigid, spline or both, got {method!r}")
    if not max_gap_s >= 0:
        raise ConfigError(f"max_gap_s: expected >= 0, got {max_gap_s}")
    max_frames = int(np.floor(max_gap_s * rate + 1e-9))
    index = {nm: i for i, nm in enumerate(names)}
    out = []
    for gap in report.gaps_found:
        interior = gap.start > 0 and gap.stop < n
        if method == "none" or not interior or gap.length > max_frames:
            report.left_open.append(gap)
            continue
        donors = []
        if method in ("rigid", "both") and clusters:
            donors = [
                index[d] for d in clusters.get(gap.marker, ()) if d in index and d != gap.marker
            ]
        out.append((gap, index[gap.marker], donors))
    return out


def fill_gaps(
    traj: MarkerTrajectories,
    method: str = "both",
    max_gap_s: float = 0.25,
    clusters: Mapping[str, Sequence[str]] | None = None,
) -> tuple[MarkerTrajectories, CleaningReport]:
    """Fill interior gaps up to ``max_gap_s``.

    Args:
        method: ``"rigid"``, ``"spline"``, ``"both"`` (rigid first, spline for the rest) or
            ``"none"`` (only report).
        clusters: marker -> markers rigidly attached to it (same segment), for the rigid fill.
    """
    report = CleaningReport()
    report.gaps_found, report.never_visible = find_gaps(traj)
    todo = fill_candidates(report, traj.n_frames, traj.rate_hz, method, max_gap_s, clusters,
                           traj.names)  # fmt: skip
    pos = traj.positions.copy()
    for gap, m, donors in todo:
        if len(donors) >= 3 and _rigid_fill_gap(pos, m, donors, gap):
            report.filled_rigid.append(gap)
            continue
        if method in ("spline", "both"):
            good = np.isfinite(pos[:, m, 0])
            if good.sum() >= 4:
                from scipy.interpolate import CubicSpline

                cs = CubicSpline(traj.time[good], pos[good, m])
                pos[gap.start : gap.stop, m] = cs(traj.time[gap.start : gap.stop])
                report.filled_spline.append(gap)
                continue
        report.left_open.append(gap)
    report.open_in_order()
    cleaned = traj.with_positions(pos, {"cleaning": report.summary()})
    return cleaned, report


def lowpass(
    traj: MarkerTrajectories, cutoff_hz: float, order: int = 4, report: CleaningReport | None = None
) -> tuple[MarkerTrajectories, CleaningReport]:
    """Zero-phase Butterworth low-pass of every visible run (gaps are not bridged)."""
    from scipy.signal import butter, filtfilt

    rate = traj.rate_hz
    if not (0 < cutoff_hz < rate / 2):
        raise ConfigError(
            f"lowpass cutoff {cutoff_hz} Hz must be between 0 and the Nyquist frequency "
            f"{rate / 2:g} Hz"
        )
    rep = report or CleaningReport()
    rep.lowpass_hz = cutoff_hz
    b, a = butter(order, cutoff_hz / (rate / 2))
    pad = 3 * max(len(a), len(b))
    pos = traj.positions.copy()
    vis = traj.visible
    for m, name in enumerate(traj.names):
        for start, stop in _runs(vis[:, m]):
            if stop - start <= pad:
                rep.unfiltered_runs.append((name, start, stop))
                continue
            pos[start:stop, m] = filtfilt(b, a, pos[start:stop, m], axis=0)
    return traj.with_positions(pos, {"cleaning": rep.summary()}), rep
