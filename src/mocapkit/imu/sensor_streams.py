"""Several sensors on their own clocks, read piece by piece into files on disk (issue 16):
an x-IMU3 export (a directory per sensor) or Xsens MT Manager exports (an ``MT_*.txt``
per sensor, trimmed to the packets they share after one pass over each).

Each sensor's raw samples go through its own filter (online, or the offline smoother
through files on disk) or its device orientations are read as they are; the orientations
between ``crop``'s times are spilled (:class:`~mocapkit.imu.sensor_spill.SensorSpill`),
then aligned onto one time base a piece at a time by the callers (``imu run`` writes a
table, ``body angles`` streams the body model, ``retarget`` both). The numbers of the
whole-recording readers (:func:`mocapkit.io.imu_files.read_imu_recordings`,
:func:`~mocapkit.io.imu_files.read_device_orientations`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError, DataError, FileFormatError
from mocapkit.imu.streaming import (
    SENSOR_CHUNK_ROWS,
    StreamReport,
    smoothed_pieces,
    without_rest_bias,
)
from mocapkit.io.opensim_table import QuaternionTableWriter
from mocapkit.series import ImuRecording

Crop = tuple[float | None, float | None]
RawSource = Callable[[], Iterator[ImuRecording]]
DeviceSource = Callable[[], Iterator[tuple[FloatArray, FloatArray]]]


def is_sensor_export(path: str | Path) -> bool:
    """An x-IMU3 export or a directory of Xsens MT Manager exports."""
    from mocapkit.io.ximu3 import is_ximu3_export

    p = Path(path)
    return is_ximu3_export(p) or (p.is_dir() and any(p.glob("MT_*.txt")))


def sensor_names(path: Path) -> list[str]:
    """The sensors of an x-IMU3 or Xsens export (directory names or file ids; no data
    read)."""
    from mocapkit.io.ximu3 import is_ximu3_export, ximu3_sensors
    from mocapkit.io.xsens import xsens_streams

    return list(ximu3_sensors(path) if is_ximu3_export(path) else xsens_streams(path))


def raw_sources(path: Path, rows: int = SENSOR_CHUNK_ROWS) -> dict[str, RawSource]:
    """``{sensor: a function giving its raw samples in pieces of ``rows``}``. Xsens exports
    are read once here (their checks, their warnings and the packets they share)."""
    from mocapkit.io.ximu3 import is_ximu3_export, iter_ximu3_sensor, ximu3_sensors

    if is_ximu3_export(path):
        return {name: partial(iter_ximu3_sensor, d, name, rows=rows)
                for name, d in ximu3_sensors(path).items()}  # fmt: skip
    from mocapkit.io.xsens import common_packets, trimmed_blocks, xsens_streams

    def recording(s: Any, first: int, last: int) -> Iterator[ImuRecording]:
        return (b.to_recording() for b in trimmed_blocks(s, first, last, rows))

    streams = xsens_streams(path)
    first, last = common_packets(streams, rows)
    return {name: partial(recording, s, first, last) for name, s in streams.items()}


def device_sources(path: Path, rows: int = SENSOR_CHUNK_ROWS) -> dict[str, DeviceSource]:
    """``{sensor: a function giving its device orientations as (t, q_world_sensor ENU)
    pieces}``: an x-IMU3 ``Quaternion.csv`` (as ``read_ximu3_quaternion``), an Xsens
    export's matrices or quaternions (trimmed as ``read_xsens_directory`` trims them)."""
    from mocapkit.io.ximu3 import is_ximu3_export, ximu3_sensors

    if is_ximu3_export(path):

        def quaternions(d: Path) -> Iterator[tuple[FloatArray, FloatArray]]:
            from mocapkit.geometry import quat_mul
            from mocapkit.io.ximu3 import Q_ENU_NWU, QUAT_COLUMNS, _blocks

            if not (d / "Quaternion.csv").is_file():
                raise FileFormatError(f"{d}: no Quaternion.csv in this x-IMU3 export")
            for data in _blocks(d / "Quaternion.csv", QUAT_COLUMNS, rows):
                yield data[:, 0] * 1e-6, quat_mul(Q_ENU_NWU, data[:, 1:5])

        return {name: partial(quaternions, d) for name, d in ximu3_sensors(path).items()}
    from mocapkit.io.xsens import common_packets, trimmed_blocks, xsens_streams

    def device(s: Any, first: int, last: int) -> Iterator[tuple[FloatArray, FloatArray]]:
        return ((b.time, b.orientation.quat) for b in trimmed_blocks(s, first, last, rows))

    streams = xsens_streams(path)
    first, last = common_packets(streams, rows)
    return {name: partial(device, s, first, last) for name, s in streams.items()}


def select_sensors(
    available: dict[str, Any], sensors: list[str] | None, path: str | Path
) -> dict[str, Any]:
    """``available`` (by sensor name) cut to ``sensors`` in that order (``imu run
    --sensor``; None or empty: all); an unknown name is refused naming the ones there are."""
    if not sensors:
        return available
    unknown = [s for s in sensors if s not in available]
    if unknown:
        raise ConfigError(
            f"--sensor {', '.join(unknown)}: not in {path}; sensors: {', '.join(available)}"
        )
    return {s: available[s] for s in sensors}


class Cropper:
    """Appends a sensor's orientations to its spill, only those with ``start <= t <=
    stop``; :meth:`check` then refuses fewer than two, as ``body.pipeline.crop`` does."""

    def __init__(self, spill: Any, crop: Crop) -> None:
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


def spill_filtered(
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
    crop: Crop = (None, None),
) -> list[Any]:
    """Every sensor of the export (or ``sensors``, in that order) through its own online
    filter piece by piece (``offline``: the offline smoother, through files on disk in
    ``directory``) into :class:`~mocapkit.imu.sensor_spill.SensorSpill` files in
    ``directory``; ``report`` tallies what the filters rejected, per sensor in ``notes``.
    ``crop``: (start, stop) [s], only the orientations between them are kept (the filters
    run over the whole recording first, as ``body angles --start/--stop`` does)."""
    from mocapkit.imu.sensor_spill import SensorSpill, filter_pieces

    sources = select_sensors(raw_sources(path, chunk_rows), sensors, path)
    rep = report if report is not None else StreamReport()
    rep.sensor, rep.sensors = ", ".join(sources), list(sources)
    spills = [SensorSpill(directory, name, i) for i, name in enumerate(sources)]
    try:
        for spill, read in zip(spills, sources.values(), strict=True):
            keep = Cropper(spill, crop)
            pieces = without_rest_bias(read) if remove_gyr_bias else read()
            counts = [0, 0, 0]
            if offline:
                one = StreamReport()
                for t, q, _ in smoothed_pieces(pieces, spill.name, filter_name, mode, params,
                                               chunk_rows, directory, one):  # fmt: skip
                    keep(t, q)
                    rep.chunks += 1
                counts = [one.mag_gaps, one.mag_rejected, one.acc_rejected]
            else:
                for piece, q, r in filter_pieces(pieces, filter_name, mode, params):
                    keep(piece.time, q)
                    counts[0] += r.mag_gaps
                    counts[1] += r.mag_rejected
                    counts[2] += r.acc_rejected
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


def spill_device(
    path: Path, directory: str | Path, sensors: list[str] | None = None,
    chunk_rows: int = SENSOR_CHUNK_ROWS, crop: Crop = (None, None),
) -> list[Any]:  # fmt: skip
    """The devices' own orientations of the export's ``sensors`` (by name, in that order;
    None: all) into :class:`~mocapkit.imu.sensor_spill.SensorSpill` files in
    ``directory``; ``crop`` as :func:`spill_filtered`."""
    from mocapkit.imu.sensor_spill import SensorSpill

    sources = select_sensors(device_sources(path, chunk_rows), sensors, path)
    spills = [SensorSpill(directory, name, i) for i, name in enumerate(sources)]
    try:
        for spill, read in zip(spills, sources.values(), strict=True):
            keep = Cropper(spill, crop)
            for t, q in read():
                keep(t, q)
            keep.check()
    except BaseException:
        for s in spills:
            s.close()
        raise
    return spills


def run_sensors_streaming(
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
    """An export of sensors on their own clocks (x-IMU3, Xsens) through a filter (or, with
    ``filter_name="device"``, the devices' own orientations) into one orientation table in
    bounded memory: every sensor into a file on disk, then all resampled onto one time
    base (slerp) and written a piece at a time. ``sensors``: only these (by name). The
    numbers of the whole-recording path."""
    import sys
    import tempfile

    from mocapkit.imu.resample import resample_orientation
    from mocapkit.imu.sensor_spill import aligned_pieces, imu_time_base

    report = StreamReport()
    with tempfile.TemporaryDirectory(prefix="mocapkit-sensors-", dir=workdir) as tmp:
        if filter_name == "device":
            spills = spill_device(path, tmp, sensors, chunk_rows)
            report.sensors = [s.name for s in spills]
            report.sensor = ", ".join(report.sensors)
        else:
            spills = spill_filtered(path, filter_name, mode, tmp, params=params,
                                    sensors=sensors, chunk_rows=chunk_rows, report=report,
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
