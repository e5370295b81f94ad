"""``body angles`` on an hour in flat memory: the recording is read in pieces, never whole.

An OpenSense quaternion ``.sto`` (what ``imu run`` writes, what OpenSense reads) is read
``rows`` rows at a time (:func:`mocapkit.io.opensense.iter_orientations_sto`). The
calibration needs only a window at the start: the still pose (searched in the first
``HEAD_S`` seconds unless a window is given) and the motion up to
``functional.MAX_MOTION_S`` after it, which the whole-recording path uses too; those
first pieces are kept, the calibration computed on them up to the motion window's end,
and then every piece goes
through :class:`mocapkit.body.kinematics.BodyStream` (its unwrapping, gimbal and dropout
hold carried from piece to piece) and out to the ``.mot`` and segment ``.sto`` row block
by row block. The range checks and the JSON summary are tallied piece by piece.

The result equals :func:`mocapkit.body.pipeline.run_body` on the whole recording
(tests/body/test_streamed.py, pieces of a few hundred rows) except the summary's
``rate_hz``, which is the median sample interval of the first piece kept. Memory: the
still pose and the ``MAX_MOTION_S`` seconds after it, plus a piece, whatever the length.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.calibration import BodyCalibration, CalibrationError, find_still_window
from mocapkit.body.calibration_checks import CalibrationFinding, warn_calibration
from mocapkit.body.functional import MAX_MOTION_S
from mocapkit.body.joint_angles import log_gimbal
from mocapkit.body.kinematics import BodyStream
from mocapkit.body.pipeline import (
    calibrate,
    calibration_summary,
    findings_summary,
    placement_source,
)
from mocapkit.body.plausibility import Finding, RangeTally, warn_findings
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError, DataError
from mocapkit.series import OrientationSeries

#: without a calibration window, the still pose is looked for in this many seconds
#: from the start (the whole-recording path searches everywhere; a pose held later
#: needs ``window``).
HEAD_S = 600.0
# the head reaches this far past the motion window, so that the angular rates at its
# end are the whole recording's (one-sided differences only past the window)
_MARGIN_S = 1.0


@dataclass(frozen=True)
class StreamedBody:
    """What :func:`stream_body` computed; ``summary`` has the keys of
    :func:`mocapkit.body.pipeline.summary`."""

    calibration: BodyCalibration
    summary: dict[str, Any]
    implausible: tuple[Finding, ...]
    calibration_findings: tuple[CalibrationFinding, ...]


def _pieces(
    path: Path, tree: SensorTree, rows: int, start: float | None, stop: float | None
) -> Iterator[tuple[FloatArray, FloatArray]]:
    """(time (n,), q_world_sensor (n, S, 4) in tree order), cropped to [start, stop]."""
    from mocapkit.io.opensense import iter_orientations_sto

    cols: list[int] | None = None
    last_t: float | None = None
    row0 = 0
    for labels, t, q in iter_orientations_sto(path, rows):
        if cols is None:
            tree.check_sensors(labels)
            cols = [labels.index(s.sensor) for s in tree.segments]
        steps = np.diff(t, prepend=t[0] if last_t is None else last_t)
        bad = np.flatnonzero(steps <= 0.0)
        bad = bad[bad > 0] if last_t is None else bad
        if bad.size or not np.isfinite(t).all():
            i = int(bad[0]) if bad.size else int(np.flatnonzero(~np.isfinite(t))[0])
            raise DataError(
                f"{path}: time not strictly increasing and finite at row {row0 + i} "
                f"({t[i]:.6f} s). Sort the samples and drop duplicates."
            )
        last_t = float(t[-1])
        row0 += t.shape[0]
        keep = np.ones(t.shape[0], dtype=bool)
        if start is not None:
            keep &= t >= start
        if stop is not None:
            keep &= t <= stop
        if keep.any():
            yield t[keep], q[keep][:, cols]
        if stop is not None and t[-1] > stop:
            return


class _Tally:
    """The summary's figures, piece by piece."""

    def __init__(self, tree: SensorTree) -> None:
        k, s = len(tree.coordinate_names), len(tree.segments)
        self.tree = tree
        self.frames = 0
        self.t0 = self.t1 = np.nan
        self.lo = np.full(k, np.inf)
        self.hi = np.full(k, -np.inf)
        self.missing = np.zeros(k, dtype=np.int64)
        self.held = np.zeros(s, dtype=np.int64)
        self.gimbal = np.zeros(s, dtype=np.int64)
        self.near = np.zeros(s, dtype=np.int64)
        self.first: list[tuple[int, float] | None] = [None] * s
        self.ranges = RangeTally(tree, tree.coordinate_names)

    def add(
        self, t: FloatArray, values: FloatArray, q_seg: FloatArray, flags: dict[str, np.ndarray]
    ) -> None:
        if self.frames == 0:
            self.t0 = float(t[0])
        self.t1 = float(t[-1])
        deg = np.rad2deg(values)
        good = np.isfinite(deg)
        self.missing += (~good).sum(axis=0)
        self.lo = np.fmin(self.lo, np.where(good, deg, np.inf).min(axis=0))
        self.hi = np.fmax(self.hi, np.where(good, deg, -np.inf).max(axis=0))
        self.held += (flags["stale"] & np.isfinite(q_seg[:, :, 0])).sum(axis=0)
        self.gimbal += flags["gimbal"].sum(axis=0)
        self.near += flags["near_gimbal"].sum(axis=0)
        for i in range(len(self.first)):
            if self.first[i] is None:
                hit = np.flatnonzero(flags["gimbal"][:, i])
                if hit.size == 0:
                    hit = np.flatnonzero(flags["near_gimbal"][:, i])
                if hit.size:
                    self.first[i] = (self.frames + int(hit[0]), float(t[hit[0]]))
        self.ranges.add(values)
        self.frames += t.shape[0]

    def coordinates(self) -> dict[str, dict[str, Any]]:
        out = {}
        for k, name in enumerate(self.tree.coordinate_names):
            seen = self.missing[k] < self.frames
            out[name] = {
                "min_deg": float(self.lo[k]) if seen else None,
                "max_deg": float(self.hi[k]) if seen else None,
                "missing": int(self.missing[k]),
            }
        return out

    def report_gimbal(self) -> tuple[dict[str, int], dict[str, int]]:
        """{joint: exactly locked samples}, {joint: samples near the lock}; logged as the
        whole-recording path logs them."""
        exact, close = {}, {}
        for i, seg in enumerate(self.tree.segments):
            first = self.first[i]
            if self.near[i]:
                close[seg.joint.name] = int(self.near[i])
            if self.gimbal[i]:
                exact[seg.joint.name] = int(self.gimbal[i])
            if first is not None:
                log_gimbal(seg, int(self.near[i]), int(self.gimbal[i]), *first)
        return exact, close


def _head(
    pieces: Iterator[tuple[FloatArray, FloatArray]],
    tree: SensorTree,
    window: tuple[float, float] | None,
    still_duration_s: float,
) -> tuple[list[tuple[FloatArray, FloatArray]], dict[str, OrientationSeries], tuple[float, float]]:
    """The first pieces (all of them processed later), the part of them the calibration
    uses (up to the motion window's end), and the calibration window."""
    head: list[tuple[FloatArray, FloatArray]] = []

    def read_one() -> bool:
        nxt = next(pieces, None)
        if nxt is not None:
            head.append(nxt)
        return nxt is not None

    if not read_one():
        raise DataError("no samples in the recording (after --start/--stop)")
    t_first = float(head[0][0][0])
    while window is None:
        # the first still window, as the whole recording's search finds it: not at the
        # head's end, where the rates' median filter sees only one side
        try:
            found = find_still_window(_series(tree, head), still_duration_s)
        except CalibrationError as exc:
            found, error = None, exc
        more = head[-1][0][-1] < t_first + HEAD_S
        if found is not None and (found[1] < head[-1][0][-1] - _MARGIN_S or not more):
            window = found
        elif not (more and read_one()):
            if found is not None:
                window = found
                break
            raise CalibrationError(
                f"{error} (looked in the first {HEAD_S:.0f} s; for a pose held later give "
                "its window, --calib-window T0 T1)"
            ) from None
    end = window[1] + MAX_MOTION_S + _MARGIN_S
    while head[-1][0][-1] < end and read_one():
        pass
    series = _series(tree, head, until=end)
    return head, series, window


def _series(
    tree: SensorTree, pieces: list[tuple[FloatArray, FloatArray]], until: float = np.inf
) -> dict[str, OrientationSeries]:
    """The pieces' samples with ``t <= until`` as {sensor: series}."""
    t = np.concatenate([p[0] for p in pieces])
    q = np.concatenate([p[1] for p in pieces])
    keep = t <= until
    t, q = t[keep], q[keep]
    return {s.sensor: OrientationSeries(t, q[:, i], name=s.sensor) for i, s in
            enumerate(tree.segments)}  # fmt: skip


def stream_body(
    tree: SensorTree,
    path: str | Path,
    *,
    output: str | Path | None = None,
    segments_output: str | Path | None = None,
    calibration: str | BodyCalibration = "auto",
    placement: Mapping[str, OrientationSeries] | None = None,
    window: tuple[float, float] | None = None,
    start: float | None = None,
    stop: float | None = None,
    dropout: str = "nan",
    max_hold_s: float = 0.5,
    still_duration_s: float = 1.0,
    rows: int = 10_000,
    pieces: Iterator[tuple[FloatArray, FloatArray]] | None = None,
    **calibrate_kwargs: Any,
) -> StreamedBody:
    """:func:`mocapkit.body.pipeline.run_body` on an OpenSense quaternion ``.sto``, read
    and written ``rows`` rows at a time (module docstring).

    Args:
        output: joint angles ``.mot`` (degrees, as ``write_joint_angles_mot``), or None.
        segments_output: segment orientations as a quaternion ``.sto``, or None.
        calibration, placement, window, start, stop, dropout, max_hold_s: as ``run_body``.
        pieces: the orientations already on one time base, ``(t (n,), q (n, S, 4))`` in
            the tree's sensor order, instead of reading ``path`` (which then only names
            the recording in messages): raw samples filtered and aligned piece by piece
            (:func:`mocapkit.imu.sensor_spill.body_pieces`); no ``start``/``stop`` then
            (the whole path crops each sensor before aligning them).
    """
    from mocapkit.io.joint_angles_mot import JointAnglesMotWriter
    from mocapkit.io.opensim_table import QuaternionTableWriter

    if pieces is not None and (start is not None or stop is not None):
        raise ConfigError("stream_body: start/stop apply to a file read here, not to pieces")
    if pieces is None:
        pieces = _pieces(Path(path), tree, rows, start, stop)
    head: list[tuple[FloatArray, FloatArray]] = []
    checks: list[CalibrationFinding] = []
    if isinstance(calibration, BodyCalibration):
        cal = calibration
    elif placement is not None:
        source, window = placement_source(tree, placement, window)
        cal = calibrate(tree, source, calibration=calibration, window=window, **calibrate_kwargs)
        checks = warn_calibration(tree, cal)
    else:
        head, source, window = _head(pieces, tree, window, still_duration_s)
        cal = calibrate(tree, source, calibration=calibration, window=window,
                        **calibrate_kwargs)  # fmt: skip
        del source
        checks = warn_calibration(tree, cal)
    first = head[0] if head else next(pieces, None)
    if first is None:
        raise DataError(f"{path}: no samples (after --start/--stop)")
    if first[0].shape[0] > 1:
        rate = 1.0 / float(np.median(np.diff(first[0])))
    else:
        rate = float("nan")
    stream = BodyStream(tree, cal, dropout=dropout, max_hold_s=max_hold_s)
    tally = _Tally(tree)
    mot = JointAnglesMotWriter(output, tree.coordinate_names) if output else None
    seg = (
        QuaternionTableWriter(Path(segments_output), list(tree.segment_names), rate,
                              "orientations", csv=False)
        if segments_output else None
    )  # fmt: skip
    written = [Path(o) for o in (output, segments_output) if o]
    try:
        for t, q in itertools.chain(head or [first], pieces):
            values, q_seg, flags = stream.run(t, q)
            tally.add(t, values, q_seg, flags)
            if mot is not None:
                mot.write(t, values)
            if seg is not None:
                seg.write(t, q_seg)
        if tally.frames < 2:
            raise DataError(f"{path}: fewer than 2 samples between {start} and {stop} s")
    except BaseException:  # a bad row further on: no half-written output is left behind
        for w in (mot, seg):
            if w is not None:
                w.close()
        for f in written:
            f.unlink(missing_ok=True)
        raise
    for w in (mot, seg):
        if w is not None:
            w.close()
    findings = warn_findings(tally.ranges.findings())
    exact, close = tally.report_gimbal()
    summary = {
        "n_frames": tally.frames,
        "rate_hz": rate,
        "duration_s": tally.t1 - tally.t0,
        "calibration": calibration_summary(cal),
        "gimbal_lock": exact,
        "near_gimbal": close,
        "held": {
            s.sensor: int(tally.held[i]) for i, s in enumerate(tree.segments) if tally.held[i]
        },
        "coordinates": tally.coordinates(),
        **findings_summary(checks, findings),
    }
    return StreamedBody(cal, summary, tuple(findings), tuple(checks))
