"""One sensor's recording through an online filter piece by piece: memory bounded by a
piece, whatever the recording's length (issue 16: an hour at 1 kHz).

``mocapkit imu run`` takes this path for a mocapkit IMU CSV run online
(:func:`run_csv_streaming`): the CSV is read ``chunk_rows`` rows at a time
(:func:`mocapkit.io.imu_csv.iter_imu_csv`), each piece goes through the same filter
object (its state carried from piece to piece: the result equals one run over the whole
recording), and its orientations are appended to the output table at once. Everything
else (several sensors on their own clocks, the offline smoother, device orientations,
bias removal from a rest period) reads the whole recording first.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.errors import ConfigError
from mocapkit.io.imu_csv import CHUNK_ROWS, iter_imu_csv
from mocapkit.io.opensim_table import QuaternionTableWriter


@dataclass
class StreamReport:
    """What a streamed run did."""

    sensor: str = ""
    rows: int = 0
    chunks: int = 0
    mag_gaps: int = 0
    mag_rejected: int = 0
    acc_rejected: int = 0
    time_span: tuple[float, float] = (0.0, 0.0)
    notes: list[str] = field(default_factory=list)


def run_csv_streaming(
    path: Path,
    filter_name: str,
    output: Path,
    *,
    mode: str = "9d",
    params: dict[str, Any] | None = None,
    chunk_rows: int = CHUNK_ROWS,
) -> StreamReport:
    """A mocapkit IMU CSV through an online filter into an orientation table, piece by
    piece (module docstring). Time in the table starts at 0 (the first sample)."""
    from mocapkit.imu.filters import make_filter
    from mocapkit.io.imu_files import check_units

    report = StreamReport()
    writer: QuaternionTableWriter | None = None
    filt = None
    t0 = t_last = 0.0
    try:
        for piece in iter_imu_csv(path, chunk_rows=chunk_rows):
            if filt is None:
                check_units(piece)  # a gyroscope in deg/s shows in the first piece
                if piece.n_samples < 2:
                    raise ConfigError(
                        f"{path}: {piece.n_samples} data row: at least 2 are needed to know "
                        "the sampling rate"
                    )
                filt = make_filter(filter_name, piece.rate_hz, **(params or {}))
                t0 = float(piece.time[0])
                steps = np.concatenate([[filt.params.dt], np.diff(piece.time)])
                report.sensor = piece.name
                label = "_".join(piece.name.split())
                writer = QuaternionTableWriter(output, [label], piece.rate_hz, path.stem)
            else:
                steps = np.concatenate([[piece.time[0] - t_last], np.diff(piece.time)])
            mag = piece.mag if mode == "9d" else None
            q = filt.run(piece.gyr, piece.acc, mag, dt=steps)
            r = filt.last_report
            report.mag_gaps += r.mag_gaps
            report.mag_rejected += r.mag_rejected
            report.acc_rejected += r.acc_rejected
            assert writer is not None
            writer.write(piece.time - t0, q[:, None, :])
            t_last = float(piece.time[-1])
            report.rows += piece.n_samples
            report.chunks += 1
    finally:
        if writer is not None:
            writer.close()
    report.time_span = (t0, t_last)
    return report


__all__ = ["StreamReport", "run_csv_streaming"]
