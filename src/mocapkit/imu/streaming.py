"""One sensor's recording through an online filter piece by piece: memory bounded by a
piece, whatever the recording's length (issue 16: an hour at 1 kHz).

``mocapkit imu run`` takes this path for one sensor's file, a mocapkit IMU CSV or a BROAD
``.hdf5`` trial, run online (:func:`run_file_streaming`): the file is read ``chunk_rows``
rows at a time (:func:`recording_pieces`), each piece goes through the same filter
object (its state carried from piece to piece: the result equals one run over the whole
recording), and its orientations are appended to the output table at once. Everything
else (several sensors on their own clocks, device orientations,
bias removal from a rest period) reads the whole recording first.

Offline (``--offline``, polaris) the file is read the same way and its validated samples
go to files in a temporary directory (:func:`run_file_offline`); the smoother's passes then
run over those files piece by piece (:mod:`mocapkit.imu.filters.polaris_offline_chunks`,
the same numbers as in memory), and each smoothed piece is appended to the table.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError, DataError
from mocapkit.io.imu_csv import CHUNK_ROWS, iter_imu_csv
from mocapkit.io.opensim_table import QuaternionTableWriter
from mocapkit.series import ImuRecording

SENSOR_CHUNK_ROWS = 20_000  # rows of one sensor of several in memory at a time


@dataclass
class StreamReport:
    """What a streamed run did."""

    sensor: str = ""
    sensors: list[str] = field(default_factory=list)  # several sensors: their names
    rows: int = 0
    chunks: int = 0
    mag_gaps: int = 0
    mag_rejected: int = 0
    acc_rejected: int = 0
    time_span: tuple[float, float] = (0.0, 0.0)
    notes: list[str] = field(default_factory=list)


def recording_pieces(
    path: Path, chunk_rows: int = CHUNK_ROWS, remove_gyr_bias: bool = False
) -> Iterator[ImuRecording]:
    """One sensor's recording file in pieces of ``chunk_rows`` rows, read as they go: a
    mocapkit IMU CSV (:func:`~mocapkit.io.imu_csv.iter_imu_csv`) or a BROAD ``.hdf5``
    trial (:func:`~mocapkit.io.broad.iter_broad_imu`). ``remove_gyr_bias``: the bias of
    the first rest period (read ahead until it ends) subtracted from every piece."""

    def read() -> Iterator[ImuRecording]:
        if Path(path).suffix.lower() in (".hdf5", ".h5"):
            from mocapkit.io.broad import iter_broad_imu

            return iter_broad_imu(path, chunk_rows)
        return iter_imu_csv(path, chunk_rows=chunk_rows)

    return without_rest_bias(read) if remove_gyr_bias else read()


def without_rest_bias(read: Callable[[], Iterator[ImuRecording]]) -> Iterator[ImuRecording]:
    """The pieces ``read()`` gives, less the gyroscope bias of the recording's first rest
    period (:func:`mocapkit.imu.rest_streaming.first_rest_bias`: ``read()`` is called
    twice, once to find it), as ``imu run --remove-gyr-bias`` removes it from a whole
    recording."""
    from mocapkit.imu.calibration import remove_gyro_bias
    from mocapkit.imu.rest_streaming import first_rest_bias

    bias = first_rest_bias(read())
    return (remove_gyro_bias(p, bias) for p in read())


def run_file_streaming(
    path: Path,
    filter_name: str,
    output: Path,
    *,
    mode: str = "9d",
    params: dict[str, Any] | None = None,
    chunk_rows: int = CHUNK_ROWS,
    remove_gyr_bias: bool = False,
) -> StreamReport:
    """One sensor's file (a mocapkit IMU CSV or a BROAD .hdf5) through an online filter
    into an orientation table, piece by piece (module docstring). Time in the table starts
    at 0 (the first sample). ``remove_gyr_bias``: as :func:`recording_pieces`."""
    from mocapkit.imu.sensor_spill import filter_pieces

    report = StreamReport()
    writer: QuaternionTableWriter | None = None
    t0 = t_last = 0.0
    pieces = recording_pieces(path, chunk_rows, remove_gyr_bias)
    try:
        for piece, q, r in filter_pieces(pieces, filter_name, mode, params, source=path):
            if writer is None:
                t0 = float(piece.time[0])
                report.sensor = piece.name
                label = "_".join(piece.name.split())
                writer = QuaternionTableWriter(output, [label], piece.rate_hz, path.stem)
            report.mag_gaps += r.mag_gaps
            report.mag_rejected += r.mag_rejected
            report.acc_rejected += r.acc_rejected
            writer.write(piece.time - t0, q[:, None, :])
            t_last = float(piece.time[-1])
            report.rows += piece.n_samples
            report.chunks += 1
    finally:
        if writer is not None:
            writer.close()
    report.time_span = (t0, t_last)
    return report


def run_file_offline(
    path: Path,
    filter_name: str,
    output: Path,
    *,
    mode: str = "9d",
    params: dict[str, Any] | None = None,
    chunk_rows: int = CHUNK_ROWS,
    workdir: str | Path | None = None,
    remove_gyr_bias: bool = False,
) -> StreamReport:
    """One sensor's file (a mocapkit IMU CSV or a BROAD .hdf5) through the offline
    smoother (polaris, forward-backward) into an orientation table in bounded memory
    (module docstring): ``chunk_rows`` samples in memory at a time, ~400 bytes a sample on
    disk in ``workdir`` (default
    :func:`~mocapkit.imu.filters.polaris_offline_chunks.default_workdir`) while it runs."""
    report = StreamReport()
    pieces = recording_pieces(path, chunk_rows, remove_gyr_bias)
    writer: QuaternionTableWriter | None = None
    t0 = 0.0
    try:
        for t, q, rate in smoothed_pieces(pieces, path, filter_name, mode, params, chunk_rows,
                                          workdir, report):  # fmt: skip
            if writer is None:
                t0 = float(t[0])
                label = "_".join(report.sensor.split())
                writer = QuaternionTableWriter(output, [label], rate, path.stem)
            writer.write(t - t0, q[:, None, :])
            report.chunks += 1
    finally:
        if writer is not None:
            writer.close()
    return report


def smoothed_pieces(
    pieces: Iterable[ImuRecording], source: str | Path, filter_name: str, mode: str,
    params: dict[str, Any] | None, chunk_rows: int, workdir: str | Path | None,
    report: StreamReport,
) -> Iterator[tuple[FloatArray, FloatArray, float]]:  # fmt: skip
    """One sensor's pieces through the offline smoother in bounded memory: the validated
    samples to files in a temporary directory in ``workdir``, then the smoother's passes
    piece by piece (:mod:`mocapkit.imu.filters.polaris_offline_chunks`); yields
    ``(t (n,), q (n, 4), rate [Hz])``. ``report`` tallies the rows and rejections."""
    import tempfile

    from mocapkit.imu.filters.polaris_offline_chunks import (
        DiskStore,
        default_workdir,
        smooth_pieces,
    )

    with tempfile.TemporaryDirectory(prefix="mocapkit-smooth-",
                                     dir=workdir or default_workdir()) as tmp:  # fmt: skip
        store = DiskStore(tmp)
        try:
            filt, use_acc, use_mag, rate = _spill_pieces(
                pieces, source, filter_name, mode, params, store, report
            )
            for piece in smooth_pieces(filt.params, store, report.rows, use_acc, use_mag,
                                       mode == "9d", chunk_rows):  # fmt: skip
                q = piece.q9 if piece.q9 is not None else piece.q6
                bad = ~np.isfinite(q).all(axis=1)
                if bad.any():  # a kernel bug must never reach the user as NaN
                    raise DataError(
                        f"polaris: non-finite orientation at sample "
                        f"{piece.start + int(np.flatnonzero(bad)[0])}; this is a bug, "
                        "please report it with the input"
                    )
                yield store.read("time", piece.start, piece.stop)[:, 0], q, rate
        finally:
            store.close()


def _spill_pieces(
    pieces: Iterable[ImuRecording], source: str | Path, filter_name: str, mode: str,
    params: dict[str, Any] | None, store: Any, report: StreamReport,
) -> tuple[Any, np.ndarray, np.ndarray, float]:  # fmt: skip
    """Read the pieces in turn, validate each piece as the filter would (with the
    previous piece's last gyroscope reading), and write the validated samples and their
    time to ``store``. Returns the filter, the accelerometer and magnetometer flags (N,)
    and the rate [Hz]."""
    from mocapkit.imu.evaluation import check_offline
    from mocapkit.imu.filters import make_filter
    from mocapkit.io.imu_files import check_units

    filt: Any = None
    flags_acc: list[np.ndarray] = []
    flags_mag: list[np.ndarray] = []
    last_gyr: np.ndarray | None = None
    rate = 0.0
    t_last = 0.0
    for piece in pieces:
        if filt is None:
            check_units(piece)
            if piece.n_samples < 2:
                raise ConfigError(
                    f"{source}: {piece.n_samples} data row: at least 2 are needed to know "
                    "the sampling rate"
                )
            filt = check_offline(make_filter(filter_name, piece.rate_hz, **(params or {})),
                                 filter_name)  # fmt: skip
            rate = piece.rate_hz
            report.sensor = piece.name
            steps = np.concatenate([[filt.params.dt], np.diff(piece.time)])
            report.time_span = (float(piece.time[0]), 0.0)
        else:
            steps = np.concatenate([[piece.time[0] - t_last], np.diff(piece.time)])
        mag = piece.mag if mode == "9d" else None
        # the previous piece's last reading: a step over lost samples at this piece's start
        # is integrated as in one run
        inputs, rep = filt._prepare(piece.gyr, piece.acc, mag, steps, last_gyr)
        a = report.rows
        for name in ("gyr", "acc", "mag", "dt"):
            store.write(name, a, getattr(inputs, name))
        store.write("time", a, piece.time)
        flags_acc.append(inputs.use_acc.copy())
        flags_mag.append(inputs.use_mag.copy())
        report.acc_rejected += rep.acc_rejected
        report.mag_gaps += rep.mag_gaps
        report.mag_rejected += rep.mag_rejected
        last_gyr = piece.gyr[-1].copy()
        t_last = float(piece.time[-1])
        report.rows += piece.n_samples
    if filt is None:
        raise DataError(f"{source}: no samples")
    report.time_span = (report.time_span[0], t_last)
    return filt, np.concatenate(flags_acc), np.concatenate(flags_mag), rate


# the names before BROAD files streamed too
run_csv_streaming = run_file_streaming
run_csv_offline = run_file_offline

__all__ = ["StreamReport", "recording_pieces", "run_file_offline", "run_file_streaming"]


def spill_ximu3(
    path: Path,
    filter_name: str,
    mode: str,
    directory: str | Path,
    *,
    params: dict[str, Any] | None = None,
    sensors: list[str] | None = None,
    chunk_rows: int = SENSOR_CHUNK_ROWS,
    report: StreamReport | None = None,
    remove_gyr_bias: bool = False,
    offline: bool = False,
    crop: tuple[float | None, float | None] = (None, None),
) -> list[Any]:
    """Every sensor of an x-IMU3 export (or ``sensors``, in that order) through its own
    online filter piece by piece (``offline``: the offline smoother, through files on disk
    in ``directory``, :func:`smoothed_pieces`) into
    :class:`~mocapkit.imu.sensor_spill.SensorSpill` files in ``directory``; ``report``
    tallies what the filters rejected, per sensor in ``notes``. ``crop``: (start, stop)
    [s], only the orientations between them are kept (the filters run over the whole
    recording first, as ``body angles --start/--stop`` does)."""
    from mocapkit.imu.sensor_spill import SensorSpill, filter_pieces
    from mocapkit.io.ximu3 import iter_ximu3_sensor, ximu3_sensors

    dirs = ximu3_sensors(path)
    if sensors:
        unknown = [s for s in sensors if s not in dirs]
        if unknown:
            raise ConfigError(
                f"--sensor {', '.join(unknown)}: not in {path}; sensors: {', '.join(dirs)}"
            )
        dirs = {s: dirs[s] for s in sensors}
    rep = report if report is not None else StreamReport()
    rep.sensor, rep.sensors = ", ".join(dirs), list(dirs)
    spills = [SensorSpill(directory, name, i) for i, name in enumerate(dirs)]
    try:
        for spill, d in zip(spills, dirs.values(), strict=True):
            counts = [0, 0, 0]
            keep = _cropper(spill, crop)

            def read(d: Path = d, name: str = spill.name) -> Iterator[ImuRecording]:
                return iter_ximu3_sensor(d, name, rows=chunk_rows)

            pieces = without_rest_bias(read) if remove_gyr_bias else read()
            if offline:
                one = StreamReport()
                for t, q, _ in smoothed_pieces(pieces, d, filter_name, mode, params,
                                               chunk_rows, directory, one):  # fmt: skip
                    keep(t, q)
                    rep.chunks += 1
                counts = [one.mag_gaps, one.mag_rejected, one.acc_rejected]
            for piece, q, r in ([] if offline else
                                filter_pieces(pieces, filter_name, mode, params)):  # fmt: skip
                keep(piece.time, q)
                counts = [
                    c + x
                    for c, x in zip(
                        counts, (r.mag_gaps, r.mag_rejected, r.acc_rejected), strict=True
                    )
                ]
                rep.chunks += 1
            keep.check()
            rep.mag_gaps += counts[0]
            rep.mag_rejected += counts[1]
            rep.acc_rejected += counts[2]
            if any(counts):
                rep.notes.append(
                    f"{spill.name}: {counts[0]} magnetometer gaps and {counts[1]} rejected "
                    f"samples processed as 6D, {counts[2]} accelerometer samples rejected"
                )
    except BaseException:
        for s in spills:
            s.close()
        raise
    return spills


def spill_ximu3_device(
    path: Path, directory: str | Path, sensors: list[str], chunk_rows: int = SENSOR_CHUNK_ROWS,
    crop: tuple[float | None, float | None] = (None, None),
) -> list[Any]:  # fmt: skip
    """The devices' own orientations (``Quaternion.csv``, ENU, as
    :func:`~mocapkit.io.ximu3.read_ximu3_quaternion`) of the x-IMU3 export's ``sensors``
    (by name, in that order) into :class:`~mocapkit.imu.sensor_spill.SensorSpill` files in
    ``directory``, read ``chunk_rows`` rows at a time; ``crop`` as :func:`spill_ximu3`. A
    sensor without a name in the export is refused naming the ones it has."""
    from mocapkit.geometry import quat_mul
    from mocapkit.imu.sensor_spill import SensorSpill
    from mocapkit.io.ximu3 import Q_ENU_NWU, QUAT_COLUMNS, _blocks, ximu3_sensors

    dirs = ximu3_sensors(path)
    unknown = [s for s in sensors if s not in dirs]
    if unknown:
        raise ConfigError(f"{path}: no sensor {', '.join(unknown)}; sensors: {', '.join(dirs)}")
    spills = [SensorSpill(directory, name, i) for i, name in enumerate(sensors)]
    try:
        for spill in spills:
            quat_file = dirs[spill.name] / "Quaternion.csv"
            if not quat_file.is_file():
                raise DataError(f"{dirs[spill.name]}: no Quaternion.csv in this x-IMU3 export")
            keep = _cropper(spill, crop)
            for data in _blocks(quat_file, QUAT_COLUMNS, chunk_rows):
                keep(data[:, 0] * 1e-6, quat_mul(Q_ENU_NWU, data[:, 1:5]))
            keep.check()
    except BaseException:
        for s in spills:
            s.close()
        raise
    return spills


class _cropper:
    """Appends a sensor's orientations to its spill, only those with ``start <= t <=
    stop``; :meth:`check` then refuses fewer than two, as ``body.pipeline.crop`` does."""

    def __init__(self, spill: Any, crop: tuple[float | None, float | None]) -> None:
        self.spill, self.crop = spill, crop
        self.lo = -np.inf if crop[0] is None else crop[0]
        self.hi = np.inf if crop[1] is None else crop[1]
        self.span = [np.inf, -np.inf]

    def __call__(self, t: FloatArray, q: FloatArray) -> None:
        if len(t):
            self.span = [min(self.span[0], float(t[0])), float(t[-1])]
        inside = (t >= self.lo) & (t <= self.hi)
        self.spill.append(t[inside], q[inside])

    def check(self) -> None:
        if self.spill.n < 2:
            raise DataError(
                f"sensor {self.spill.name!r}: fewer than 2 samples between {self.crop[0]} "
                f"and {self.crop[1]} s (recording {self.span[0]:.3f}-{self.span[1]:.3f} s)"
            )


def run_ximu3_streaming(
    path: Path,
    filter_name: str,
    output: Path,
    *,
    mode: str = "9d",
    params: dict[str, Any] | None = None,
    sensors: list[str] | None = None,
    chunk_rows: int = SENSOR_CHUNK_ROWS,
    workdir: str | Path | None = None,
    remove_gyr_bias: bool = False,
    offline: bool = False,
) -> StreamReport:
    """An x-IMU3 export directory (one sub-directory per sensor, each on its own clock)
    through an online filter into one orientation table, in bounded memory
    (:mod:`mocapkit.imu.sensor_spill`): every sensor filtered piece by piece into a file
    on disk (:func:`spill_ximu3`), then all resampled onto one time base (slerp) and
    written a piece at a time. ``sensors``: only these (by name). The numbers of the
    whole-recording path."""
    import sys
    import tempfile

    from mocapkit.imu.resample import resample_orientation
    from mocapkit.imu.sensor_spill import aligned_pieces, imu_time_base

    report = StreamReport()
    with tempfile.TemporaryDirectory(prefix="mocapkit-sensors-", dir=workdir) as tmp:
        spills = spill_ximu3(path, filter_name, mode, tmp, params=params, sensors=sensors,
                             chunk_rows=chunk_rows, report=report,
                             remove_gyr_bias=remove_gyr_bias, offline=offline)  # fmt: skip
        try:
            labels = ["_".join(s.name.split()) for s in spills]
            grid: Callable[[int, int], FloatArray]
            if len(spills) == 1:  # its own clock
                grid, n = spills[0].time.read, spills[0].n
                rows = _own_clock(spills[0], chunk_rows)
            else:
                grid, n = imu_time_base(spills)
                rows = aligned_pieces(spills, grid, n, resample_orientation, chunk_rows)
                print(f"resampled {len(spills)} sensors onto one time base ({n} samples, "
                      f"{grid(0, 1)[0]:.3f}..{grid(n - 1, n)[0]:.3f} s) by slerp",
                      file=sys.stderr)  # fmt: skip
            whole = grid(0, n)
            t0 = float(whole[0])
            rate = 1.0 / float(np.median(np.diff(whole))) if n > 1 else 0.0
            del whole
            with QuaternionTableWriter(output, labels, rate, path.stem) as writer:
                for t, q in rows:
                    writer.write(t - t0, q)
                    report.rows += len(t)
        finally:
            for s in spills:
                s.close()
    return report


def _own_clock(spill: Any, rows: int) -> Any:
    """One sensor's spilled series as it is: ``(t, q (n, 1, 4))`` pieces."""
    for a in range(0, spill.n, rows):
        b = min(spill.n, a + rows)
        yield spill.time.read(a, b), spill.quat.read(a, b)[:, None, :]
