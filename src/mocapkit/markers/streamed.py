"""``mocapkit markers reconstruct`` at flat memory: a trial of any length read, tracked and
written piece by piece (issue 16).

1. **Read once** (:func:`_spill`): the file's frames go to a raw file on disk as they are
   read (a TRC a block of rows at a time; a C3D is read whole, as ezc3d does), with what
   must be known of the whole trial tallied on the way: which markers ever appear, the
   clock's regularity, the frame count. The first :data:`HEAD_S` seconds stay in memory.
2. **Decide from the start**: units, marker set, up axis, stature and the scaled subject
   from those first seconds (and the static trial), as the whole-trial path decides them
   from the whole trial: a trial shorter than :data:`HEAD_S` gets the same decisions.
3. **Track piece by piece**: direct marker control runs :data:`CHUNK_FRAMES` frames at a
   time with its state carried (:class:`mocapkit.markers.osc.OfflineTracker`; the target's
   derivatives read one frame either side), each piece's result built as the whole
   trial's would be (pelvis angles continued without 2 pi jumps), its figures and
   warnings summed (:mod:`mocapkit.markers.coverage`), its output columns spilled to disk.
4. **Write** the .mot/.csv (and the tracked markers' TRC) from the spill, a block at a
   time, once the columns no frame determines are known (they are left out, as always).

Equal to the whole-trial path (:func:`mocapkit.markers.reconstruct.run`) to rounding
(tests/markers/test_streamed.py), except that on trials longer than :data:`HEAD_S` the
decisions above rest on its first :data:`HEAD_S` seconds, and the conditioning figures
sample each visibility pattern per piece. Gap filling and low-pass filtering run on a
prepared copy of the frames on disk (:mod:`mocapkit.markers.streamed_cleaning`). IK
(each piece warm-started from the last frame) and online mode (the controller stepped
on) run piece by piece too; the reference backend takes the whole-trial path
(:func:`streamable` says why).
"""

from __future__ import annotations

import logging
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._spill import RowFile
from mocapkit._validate import FloatArray
from mocapkit.body.anthropometry import Sex
from mocapkit.body.markersets import load_markerset
from mocapkit.body.scaling import Subject
from mocapkit.errors import ConfigError, DataError
from mocapkit.markers.cleaning import CleaningReport, fill_candidates
from mocapkit.markers.conventions import UnitCheck
from mocapkit.markers.coverage import Coverage, MetricsTally
from mocapkit.markers.pieces import piece_solver
from mocapkit.markers.reconstruct import (
    Preparation,
    Progress,
    ReconstructionOptions,
    TrackingPlan,
    _initial_pose,
    _warm_up,
    _Warnings,
    apply_ik_setup,
    check_tracking,
    choose_markerset,
    load_markers,
    marker_clusters,
    plan_preparation,
    plan_tracking,
    warn_open_gaps,
)
from mocapkit.markers.result import (
    ReconstructionResult,
    csv_header,
    output_columns,
    write_csv_rows,
)
from mocapkit.markers.streamed_cleaning import (
    fill_gaps_spilled,
    find_gaps_spilled,
    lowpass_spilled,
)
from mocapkit.markers.subject import check_static_is_not_trial, scaled_subject
from mocapkit.markers.trajectories import MarkerTrajectories, check_whole_rows

log = logging.getLogger(__name__)

CHUNK_FRAMES = 5_000  # frames tracked, built and spilled at a time
HEAD_S = 300.0  # the start of the trial the decisions are made from [s]
HEAD_MAX_FRAMES = 36_000  # ... at most this many frames (a 1 kHz capture: 36 s)
READ_ROWS = 10_000  # TRC rows parsed at a time


def streamable(trial_path: str | Path, options: ReconstructionOptions) -> str | None:
    """None when the trial can be reconstructed piece by piece, else why not."""
    if Path(trial_path).suffix.lower() not in (".trc", ".c3d"):
        return "not a .trc or .c3d file"
    if options.osc.backend != "fast":
        return "the reference backend runs on the whole trial"
    return None


@dataclass
class StreamedReconstruction:
    """What the command reports: the figures of ``--json`` (without ``fps`` and
    ``seconds``), the warnings, the scaled subject and where the files went."""

    metrics: dict[str, Any]
    warnings: list[str]
    subject: Subject
    written: list[Path] = field(default_factory=list)


@dataclass
class _Spilled:
    """The trial after the first pass: frames on disk, tallies in memory."""

    names: tuple[str, ...]
    meta: dict[str, Any]
    n: int
    times: RowFile
    positions: RowFile
    ever: np.ndarray  # (M,) markers seen in any frame of the file (before any crop)
    head_raw: MarkerTrajectories  # the file's first frames (before the crop)
    head: MarkerTrajectories  # the cropped trial's first frames

    def frames(self, a: int, b: int) -> MarkerTrajectories:
        return MarkerTrajectories(
            self.times.read(a, b), self.positions.read(a, b), self.names, meta=self.meta
        )

    def close(self) -> None:
        self.times.close()
        self.positions.close()


def _blocks(path: Path, units: str | None) -> tuple[Any, dict[str, Any], Iterator[Any]]:
    """(names, meta, blocks of (time, positions)) of a TRC (streamed) or C3D (whole)."""
    if path.suffix.lower() == ".trc":
        from mocapkit.io.trc import TrcStream

        stream = TrcStream(path, units)
        meta = {**stream.meta, "declared_frames": stream.declared_frames}
        return stream.names, meta, stream.blocks(READ_ROWS)
    traj = load_markers(path, units)

    def pieces() -> Iterator[tuple[FloatArray, FloatArray]]:
        for a in range(0, traj.n_frames, READ_ROWS):
            yield traj.time[a : a + READ_ROWS], traj.positions[a : a + READ_ROWS]

    return traj.names, dict(traj.meta), pieces()


def _check_block(
    src: str, time: FloatArray, pos: FloatArray, names: tuple[str, ...], offset: int,
    last: float | None,
) -> None:  # fmt: skip
    """What :class:`MarkerTrajectories` checks, with frames counted from the file's start."""
    t = np.concatenate([[last], time]) if last is not None else time
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0]) + (0 if last is not None else 1)
        f = offset + i
        raise DataError(
            f"{src}: time not strictly increasing at frame {f} ({t[int(bad[0])]:.6f} s then "
            f"{t[int(bad[0]) + 1]:.6f} s); sort the frames and drop duplicates"
        )
    check_whole_rows(pos, names, src, offset)


def _spill(
    path: Path, units: str | None, crop: tuple[float | None, float | None], directory: Path,
    progress: Progress | None,
) -> _Spilled:  # fmt: skip
    names, meta, blocks = _blocks(path, units)
    src = str(meta.get("source", path))
    declared = meta.pop("declared_frames", None)
    rate0 = float(meta.get("rate_hz") or 0.0)
    times = RowFile(directory / "time.f64")
    positions = RowFile(directory / "positions.f64", (len(names), 3))
    ever = np.zeros(len(names), dtype=bool)
    t0, t1 = crop
    lo = -np.inf if t0 is None else t0 - 1e-9
    hi = np.inf if t1 is None else t1 + 1e-9
    head_cap = HEAD_MAX_FRAMES if rate0 <= 0 else min(HEAD_MAX_FRAMES, int(HEAD_S * rate0) + 1)
    head_raw: list[tuple[FloatArray, FloatArray]] = []
    head: list[tuple[FloatArray, FloatArray]] = []
    n_raw = n_raw_head = n_head = 0
    first_t: float | None = None
    last_t: float | None = None
    deviation = 0.0
    try:
        for time, pos in blocks:
            time = np.asarray(time, dtype=float)
            pos = np.array(pos, dtype=float)
            _check_block(src, time, pos, names, n_raw, last_t)
            pos[~np.isfinite(pos).all(axis=2)] = np.nan
            if first_t is None:
                first_t = float(time[0])
            if rate0 > 0:
                regular = first_t + (n_raw + np.arange(len(time))) / rate0
                deviation = max(deviation, float(np.abs(time - regular).max()))
            ever |= np.isfinite(pos[:, :, 0]).any(axis=0)
            if n_raw_head < head_cap:
                take = min(len(time), head_cap - n_raw_head)
                head_raw.append((time[:take], pos[:take]))
                n_raw_head += take
            keep = (time >= lo) & (time <= hi)
            if keep.any():
                kt, kp = time[keep], pos[keep]
                times.append(kt)
                positions.append(kp)
                if n_head < head_cap:
                    take = min(len(kt), head_cap - n_head)
                    head.append((kt[:take], kp[:take]))
                    n_head += take
            n_raw += len(time)
            last_t = float(time[-1])
            if progress is not None:
                progress("reading", n_raw, max(n_raw, declared or 0))
        if n_raw == 0:
            raise DataError(f"{src}: no data rows after the header")
        raw_t = np.concatenate([t for t, _ in head_raw])
        if meta.get("format") == "trc":
            from mocapkit.io.trc import check_clock

            step = float(np.median(np.diff(raw_t))) if raw_t.size > 1 else 0.0
            meta["declared_frames"] = declared
            check_clock(path, meta, n_raw, deviation, step)
            del meta["declared_frames"]
        if times.rows == 0:
            raise DataError(
                f"no frame between {t0} s and {t1} s; the trial spans {first_t:.3f}-{last_t:.3f} s"
            )
        head_raw_traj = MarkerTrajectories(
            raw_t, np.concatenate([x for _, x in head_raw]), names, meta=dict(meta)
        )
        head_traj = MarkerTrajectories(
            np.concatenate([t for t, _ in head]), np.concatenate([x for _, x in head]),
            names, meta=dict(meta),
        )  # fmt: skip
    except BaseException:
        times.close()
        positions.close()
        raise
    return _Spilled(names, meta, times.rows, times, positions, ever, head_raw_traj, head_traj)


def _crop(options: ReconstructionOptions, ik_setup: str | Path | None) -> tuple[Any, Any]:
    """The time range to keep: the options', else an IK setup's (as apply_ik_setup)."""
    if options.start_s is not None or options.end_s is not None or ik_setup is None:
        return options.start_s, options.end_s
    from mocapkit.io.opensim_ik_setup import read_ik_setup

    rng = read_ik_setup(ik_setup).time_range
    return (None, None) if rng is None else (rng[0], rng[1])


@dataclass
class _Columns:
    """The pieces' output columns on disk, and which of them some frame determines."""

    time: RowFile
    coords: RowFile
    dofs: RowFile
    tracked: RowFile | None
    keep: np.ndarray
    keep_dofs: np.ndarray
    first_t: float

    def close(self) -> None:
        for f in (self.time, self.coords, self.dofs, self.tracked):
            if f is not None:
                f.close()


@dataclass
class _Outputs:
    """What the files need of the whole trial, gathered piece by piece."""

    directory: Path
    with_tracked: bool
    columns: _Columns | None = None
    any_fitted: bool = False
    deviation: float = 0.0

    def add(self, r: ReconstructionResult, rate: float) -> None:
        dofs = r.model_dof_values if r.model_dof_values is not None else np.zeros((r.n_frames, 0))
        c = self.columns
        if c is None:
            d = self.directory
            c = self.columns = _Columns(
                RowFile(d / "out_time.f64"),
                RowFile(d / "coords.f64", (r.coordinates.shape[1],)),
                RowFile(d / "dofs.f64", (dofs.shape[1],)),
                RowFile(d / "tracked.f64", r.commanded.shape[1:]) if self.with_tracked else None,
                np.zeros(r.coordinates.shape[1], dtype=bool),
                np.zeros(dofs.shape[1], dtype=bool),
                float(r.time[0]),
            )
        k = c.time.rows + np.arange(r.n_frames)
        regular = c.first_t + k / rate
        self.deviation = max(self.deviation, float(np.abs(r.time - regular).max()))
        c.time.append(r.time)
        c.coords.append(r.coordinates)
        c.dofs.append(dofs)
        if c.tracked is not None:
            c.tracked.append(r.tracked_positions)
        c.keep |= np.isfinite(r.coordinates).any(axis=0)
        c.keep_dofs |= np.isfinite(dofs).any(axis=0)
        self.any_fitted |= bool(np.isfinite(r.coordinates[:, r.fitted_angles]).any())

    def times(self, c: _Columns, a: int, b: int, rate: float) -> FloatArray:
        """Frames a..b's times, on the exact clock when the trial keeps it (as the files of
        the whole-trial path: :func:`mocapkit.markers.result._exact_times`)."""
        if self.deviation <= 0.25 / rate:
            return c.first_t + np.arange(a, b) / rate
        return c.time.read(a, b)

    def close(self) -> None:
        if self.columns is not None:
            self.columns.close()


def _write(
    out: _Outputs, template: ReconstructionResult, names: tuple[str, ...], rate: float,
    output: Path, tracked_trc: Path | None, progress: Progress | None,
) -> list[Path]:  # fmt: skip
    """The .mot or .csv (and the tracked markers' TRC) from the spilled pieces."""
    from mocapkit.io.opensim_table import TableWriter
    from mocapkit.io.trc import TrcWriter
    from mocapkit.markers.coordinates import Z_UP_TO_OPENSIM

    c = out.columns
    if c is None:
        raise DataError("no frame to write")
    n = c.time.rows
    cn, ang = template.coordinate_names, template.angular
    mot = output.suffix.lower() == ".mot"

    def block(a: int, b: int) -> tuple[list[str], FloatArray]:
        return output_columns(
            cn, ang, c.coords.read(a, b), c.keep, template.model_dof_names,
            c.dofs.read(a, b) if mot else None, c.keep_dofs if mot else None,
        )  # fmt: skip

    labels, _ = block(0, min(n, 1))
    tmp = output.with_name(output.name + ".part")
    try:
        if mot:
            with TableWriter(tmp, labels, name="mocapkit_markers", in_degrees=True) as w:
                for a in range(0, n, CHUNK_FRAMES):
                    b = min(n, a + CHUNK_FRAMES)
                    w.write(c.time.read(a, b), block(a, b)[1])
                    if progress is not None:
                        progress("writing", b, n)
        else:
            with open(tmp, "w") as f:
                f.write(csv_header(labels, cn, ang) + "\n")
                for a in range(0, n, CHUNK_FRAMES):
                    b = min(n, a + CHUNK_FRAMES)
                    write_csv_rows(f, c.time.read(a, b), block(a, b)[1])
        tmp.replace(output)
    finally:
        tmp.unlink(missing_ok=True)
    written = [output]
    if tracked_trc is not None and c.tracked is not None:
        with TrcWriter(tracked_trc, names, rate, n) as tw:
            for a in range(0, n, CHUNK_FRAMES):
                b = min(n, a + CHUNK_FRAMES)
                tw.write(out.times(c, a, b, rate), c.tracked.read(a, b) @ Z_UP_TO_OPENSIM.T)
        written.append(tracked_trc)
    return written


def reconstruct_streamed(
    trial_path: str | Path,
    static_path: str | Path | None,
    markerset: str | Path | None,
    height_m: float | None,
    mass_kg: float | None,
    options: ReconstructionOptions,
    output: str | Path | None,
    *,
    sex: Sex = "male",
    ik_setup: str | Path | None = None,
    tracked_trc: str | Path | None = None,
    tracked_c3d: str | Path | None = None,
    progress: Progress | None = None,
    chunk_frames: int = CHUNK_FRAMES,
    on_piece: Callable[[ReconstructionResult], None] | None = None,
) -> StreamedReconstruction:
    """``markers reconstruct`` piece by piece (module docstring): the same arguments as
    :func:`mocapkit.markers.reconstruct.run`, and the files to write (``output`` None:
    none). ``on_piece``: called with each piece's result as it is built, in order (the
    streamed retargeting keeps its configurations)."""
    why = streamable(trial_path, options)
    if why is not None:
        raise ConfigError(f"cannot reconstruct piece by piece: {why}")
    path = Path(trial_path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such marker file")
    units = None if options.units in (None, "auto") else options.units
    static = load_markers(static_path, options.units) if static_path is not None else None
    check_static_is_not_trial(path, static_path)
    warn = _Warnings()
    with tempfile.TemporaryDirectory(prefix="mocapkit-markers-") as d:
        sp = _spill(path, units, _crop(options, ik_setup), Path(d), progress)
        out = _Outputs(Path(d), with_tracked=tracked_trc is not None or tracked_c3d is not None)
        try:
            if markerset is None:
                ms = choose_markerset(sp.head_raw, warn)
            else:
                ms = load_markerset(markerset)
            opts = options
            if ik_setup is not None:
                ms, opts = apply_ik_setup(ms, opts, ik_setup, warn)
            prep, _, static = plan_preparation(sp.head_raw, static, ms, opts, warn, ever=sp.ever)
            rate = prep.apply(sp.head).rate_hz
            if opts.fill_gaps != "none" or opts.lowpass_hz:
                sp, prep = _cleaned(sp, prep, ms, opts, rate, Path(d), chunk_frames, progress,
                                    warn)  # fmt: skip
            else:
                _gap_warning(sp, prep, chunk_frames, rate, warn)
            head = prep.apply(sp.head)
            subject = scaled_subject(head, static, ms, height_m, mass_kg, sex, warn)
            plan = plan_tracking(prep.names, subject, opts)
            result, tally, coverage = _track(
                sp, prep, subject, plan, opts, rate, out, chunk_frames, progress, on_piece
            )
            for msg in coverage.warnings():
                warn.add(msg)
            check_tracking(out.any_fitted, plan, warn)
            written = [] if output is None else _write(
                out, result, tuple(plan.names), rate, Path(output),
                None if tracked_trc is None else Path(tracked_trc), progress,
            )  # fmt: skip
            c = out.columns
            if tracked_c3d is not None and c is not None and c.tracked is not None:
                from mocapkit.markers.result import write_tracked_c3d

                written.append(write_tracked_c3d(
                    tracked_c3d, c.time.read(0, sp.n), rate, c.tracked.read(0, sp.n),
                    plan.names, prep.up, sp.meta.get("c3d"),
                ))  # fmt: skip
        finally:
            out.close()
            sp.close()
    return StreamedReconstruction(tally.metrics(), list(warn), subject, written)


def _cleaned(
    sp: _Spilled, prep: Preparation, ms: Any, opts: ReconstructionOptions, rate: float,
    directory: Path, chunk: int, progress: Progress | None, warn: _Warnings,
) -> tuple[_Spilled, Preparation]:  # fmt: skip
    """The trial prepared into a second file and cleaned there as the whole trial is
    (:mod:`mocapkit.markers.streamed_cleaning`); the frames are then read as they are."""
    names = prep.names
    ready = RowFile(directory / "prepared.f64", (len(names), 3))
    filtered = None
    try:
        for a in range(0, sp.n, chunk):
            ready.append(prep.apply(sp.frames(a, min(sp.n, a + chunk))).positions)
        report = fill_gaps_spilled(
            sp.times, ready, sp.n, names, rate, opts.fill_gaps, opts.max_gap_s,
            marker_clusters(ms), chunk,
        )  # fmt: skip
        if opts.lowpass_hz:
            filtered = RowFile(directory / "filtered.f64", (len(names), 3))
            lowpass_spilled(
                ready, filtered, sp.n, names, rate, opts.lowpass_hz, report, chunk,
                None if progress is None else (lambda k, n: progress("filtering", k, n)),
            )  # fmt: skip
            ready.close()
            ready, filtered = filtered, None
    except BaseException:
        ready.close()
        if filtered is not None:
            filtered.close()
        raise
    warn_open_gaps(report, sp.n, rate, warn)
    sp.positions.close()
    k = sp.head.n_frames
    head = MarkerTrajectories(sp.times.read(0, k), ready.read(0, k), names, meta=dict(sp.meta))
    same = Preparation(UnitCheck(1.0, 0.0, ""), tuple(range(len(names))), names, "z")
    return replace(sp, names=names, positions=ready, head=head), same


def _gap_warning(sp: _Spilled, prep: Preparation, chunk: int, rate: float, warn: _Warnings) -> None:
    """The interior gaps left open (no filling asked for), over the whole trial, as the
    whole-trial path warns about them (``fill_gaps(method="none")``)."""
    cols = list(prep.columns)
    report = CleaningReport()
    report.gaps_found, report.never_visible = find_gaps_spilled(
        lambda a, b: np.isfinite(sp.positions.read(a, b)[:, cols, 0]), sp.n, prep.names, chunk
    )
    fill_candidates(report, sp.n, rate, "none", 0.0, None, prep.names)  # all left open
    warn_open_gaps(report, sp.n, rate, warn)


def _track(
    sp: _Spilled, prep: Preparation, subject: Subject, plan: TrackingPlan,
    opts: ReconstructionOptions, rate: float, out: _Outputs, chunk: int,
    progress: Progress | None, on_piece: Callable[[ReconstructionResult], None] | None = None,
) -> tuple[ReconstructionResult, MetricsTally, Coverage]:  # fmt: skip
    """Direct marker control piece by piece; returns the last piece's result (the
    columns' names and kinds for the files), the whole trial's figures and coverage."""
    human, names = subject.human, plan.names
    sel = [prep.names.index(nm) for nm in names]

    def frames(a: int, b: int) -> tuple[FloatArray, FloatArray]:
        t = prep.apply(sp.frames(a, b))
        return np.asarray(t.time), np.ascontiguousarray(t.positions[:, sel])

    x_first = None
    for a in range(0, sp.n, chunk):
        _, X = frames(a, min(sp.n, a + chunk))
        ok = np.flatnonzero(np.isfinite(X[..., 0]).sum(axis=1) >= 3)
        if ok.size:
            x_first = X[int(ok[0])]
            break
    if x_first is None:
        raise DataError("no frame has 3 visible markers; nothing can be reconstructed")
    q_init = _initial_pose(subject, names, x_first, plan.weights)
    _, X2 = frames(0, min(sp.n, 2))
    _warm_up(subject, names, X2, plan.weights, plan.levels, q_init, rate, opts)
    solve = piece_solver(subject, plan, opts, q_init, rate, frames, sp.n)
    tally, coverage = MetricsTally(), Coverage(names=())
    tail = None
    levels = [list(level) for level in plan.levels]
    result: ReconstructionResult | None = None
    for a in range(0, sp.n, chunk):
        b = min(sp.n, a + chunk)
        t_p, X_p, Q, P, DQ, elapsed = solve(a, b)
        result = ReconstructionResult.build(
            t_p, human, names, plan.tracked, X_p, Q, DQ, elapsed, opts.method, opts.mode,
            levels, plan.tasks, [], plan.weights,
            with_total=opts.total_bound, P=P, root_angles_before=tail, quiet=True,
        )  # fmt: skip
        tail = result.root_angles_tail
        tally.add(result)
        assert result.coverage is not None
        coverage = coverage.merge(result.coverage)
        out.add(result, rate)
        if on_piece is not None:
            on_piece(result)
        if progress is not None:
            progress("reconstruction", b, sp.n)
    assert result is not None
    return result, tally, coverage
