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
from mocapkit.errors import DataError
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
    from mocapkit.imu.sensor_spill import first_piece_filter

    filt: Any = None
    flags_acc: list[np.ndarray] = []
    flags_mag: list[np.ndarray] = []
    last_gyr: np.ndarray | None = None
    rate = 0.0
    t_last = 0.0
    for piece in pieces:
        if filt is None:
            filt = check_offline(first_piece_filter(piece, filter_name, params, source),
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
