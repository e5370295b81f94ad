"""Reader for Xsens MT Manager text exports (``MT_<device>_<trial>_<sensor>.txt``).

Format: ``//`` header lines (``// Update Rate: 100.0Hz`` gives the rate), one
tab-separated label line, then rows. Columns used:

- ``PacketCounter`` (16-bit, wraps at 65536: unwrapped here);
- ``Acc_X, Acc_Y, Acc_Z`` [m/s^2];
- the orientation as ``Mat[i][j]`` (the rotation matrix ``R_world_sensor``, row i,
  column j; verified on the OpenSense files: the accelerometer at rest equals
  ``g`` times the matrix's third row) or as ``Quat_q0..Quat_q3`` [w, x, y, z];
- optional ``Gyr_X..Z`` [rad/s] and ``Mag_X..Z`` [a.u.] when the export includes them.

The OpenSense example exports have no gyroscope or magnetometer: an
:class:`XsensExport` then holds the accelerometer and the device's orientation (in
Xsens's default ENU world frame) and cannot feed an orientation filter;
:meth:`XsensExport.to_recording` says so. Exports of one trial start at the same
packet but end at different ones: :func:`trim_to_common_packets` (used by
:func:`read_xsens_directory`) keeps the packet range all sensors share.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import DataError, FileFormatError
from mocapkit.geometry import quat_from_matrix
from mocapkit.io._text_table import parse_rows
from mocapkit.series import ImuRecording, OrientationSeries


class DataGapWarning(UserWarning):
    """Packets missing from an export, or rows dropped to align the sensors."""


_ACC = ["Acc_X", "Acc_Y", "Acc_Z"]
_GYR = ["Gyr_X", "Gyr_Y", "Gyr_Z"]
_MAG = ["Mag_X", "Mag_Y", "Mag_Z"]
_QUAT = ["Quat_q0", "Quat_q1", "Quat_q2", "Quat_q3"]
_MAT = [f"Mat[{i}][{j}]" for i in (1, 2, 3) for j in (1, 2, 3)]


@dataclass(frozen=True)
class XsensExport:
    """One sensor of an MT Manager export.

    Attributes:
        name: sensor id (the file name's last part, e.g. ``"00B421E6"``).
        packet: (N,) unwrapped packet counter.
        time: (N,) s, ``(packet - origin) / rate_hz``.
        acc: (N, 3) specific force [m/s^2].
        orientation: the device's ``q_world_sensor`` (ENU) over ``time``.
        gyr, mag: (N, 3) or None when the export has no such columns.
    """

    name: str
    rate_hz: float
    packet: np.ndarray
    time: FloatArray
    acc: FloatArray
    orientation: OrientationSeries
    gyr: FloatArray | None = None
    mag: FloatArray | None = None
    header: dict[str, str] = field(default_factory=dict, compare=False)

    @property
    def n_samples(self) -> int:
        return int(self.packet.shape[0])

    def select(self, rows: Any, origin: int) -> XsensExport:
        """Rows ``rows`` (slice or mask), with time measured from packet ``origin``."""
        packet = self.packet[rows]
        time = (packet - origin) / self.rate_hz
        ori = OrientationSeries(time, self.orientation.quat[rows], self.orientation.name, "ENU")
        gyr = None if self.gyr is None else self.gyr[rows]
        mag = None if self.mag is None else self.mag[rows]
        return XsensExport(
            self.name, self.rate_hz, packet, time, self.acc[rows], ori, gyr, mag, self.header
        )

    def to_recording(self) -> ImuRecording:
        """An :class:`ImuRecording` for the filters; needs the gyroscope columns."""
        if self.gyr is None:
            raise DataError(
                f"{self.name}: this Xsens export has no gyroscope columns (Gyr_X..Gyr_Z), so "
                "no orientation filter can run on it; its own orientations are in "
                "XsensExport.orientation (re-export with 'Rate of turn' to filter it here)"
            )
        meta = {"source": self.header.get("source", ""), "format": "Xsens MT Manager"}
        return ImuRecording(self.time, self.gyr, self.acc, self.mag, name=self.name, meta=meta)


def _stack(cols: dict[str, FloatArray], names: list[str]) -> FloatArray:
    return np.column_stack([cols[c] for c in names])


def _unwrap_packets(raw: FloatArray) -> np.ndarray:
    packet = raw.astype(np.int64)
    wraps = np.concatenate([[0], np.cumsum(np.diff(packet) < 0)])
    return packet + 65536 * wraps


@dataclass
class _Tally:
    """What a pass over an export found, for the checks that name a row and count rows."""

    lost: int = 0  # packets missing from the counter
    gaps: int = 0
    biggest: tuple[int, int, int, int] | None = None  # (jump, row, packet, next packet)
    bad_first: tuple[int, float, float] | None = None  # (row, |R R^T - I| or norm, det)
    bad: int = 0


class XsensStream:
    """One MT Manager export read block by block (the whole reader is its blocks joined):
    its header at construction, :meth:`blocks` the rows, checked as they come."""

    def __init__(self, path: str | Path, name: str | None = None) -> None:
        p = Path(path)
        self.path = p
        header: dict[str, str] = {"source": str(p)}
        try:
            with open(p, encoding="utf-8") as f:
                line = f.readline()
                k = 0
                while line.startswith("//"):
                    key, _, value = line[2:].rstrip("\n").partition(":")
                    header[key.strip()] = value.strip()
                    line = f.readline()
                    k += 1
        except UnicodeDecodeError as exc:
            raise FileFormatError(f"{p}: not a text file ({exc})") from exc
        if not line:
            raise FileFormatError(f"{p}: no column labels after the '//' header")
        self.header = header
        self.labels = [c.strip() for c in line.rstrip("\n").split("\t")]
        self.data_line = k + 2  # the first data row's line number
        rate_text = header.get("Update Rate", "").lower().replace("hz", "").strip()
        try:
            self.rate = float(rate_text)
        except ValueError:
            raise FileFormatError(
                f"{p}: no '// Update Rate: <Hz>' header line; is this an MT Manager text export?"
            ) from None
        labels = self.labels
        missing = [c for c in ["PacketCounter", *_ACC] if c not in labels]
        self.has_quat = all(c in labels for c in _QUAT)
        if not self.has_quat and not all(c in labels for c in _MAT):
            missing.append("Mat[1][1]..Mat[3][3] or Quat_q0..Quat_q3")
        if missing:
            raise FileFormatError(f"{p}: missing column(s) {', '.join(missing)}")
        self.wanted = ["PacketCounter", *_ACC, *(_QUAT if self.has_quat else _MAT)]
        for extra in (_GYR, _MAG):
            if all(c in labels for c in extra):
                self.wanted += extra
        self.name = name or p.stem.rsplit("_", 1)[-1]

    @property
    def has_gyr(self) -> bool:
        return _GYR[0] in self.wanted

    def blocks(self, rows: int = 50_000, warn: bool = True) -> Iterator[XsensExport]:
        """The rows ``rows`` at a time as :class:`XsensExport` pieces (packet unwrapped
        across blocks, time from the file's first packet). Every check of the whole reader,
        naming the data row; a missing-packet warning (``warn``) once the file is read."""
        p = self.path
        tally = _Tally()
        row0 = 0
        origin: int | None = None
        last_raw: int | None = None
        last: int | None = None
        wraps = 0
        with open(p, encoding="utf-8") as f:
            for _ in range(self.data_line - 1):
                f.readline()
            line = self.data_line
            while True:
                chunk = list(itertools.islice(f, rows))
                if not chunk:
                    break
                data_rows = [ln.rstrip("\n") for ln in chunk if ln.strip()]
                first_line, line = line, line + len(chunk)
                if not data_rows:
                    continue
                cols = self._fast(data_rows)
                if cols is None:  # the slow path names the bad line and column
                    table = parse_rows(p, data_rows, first_line, self.labels, sep="\t",
                                       allow_empty=True)  # fmt: skip
                    cols = {c: table[:, self.labels.index(c)] for c in self.wanted}
                for c in self.wanted:
                    bad = np.flatnonzero(~np.isfinite(cols[c]))
                    if bad.size:
                        raise FileFormatError(
                            f"{p}: column {c!r} is empty or non-finite at data row {row0 + bad[0]}"
                        )
                raw = cols["PacketCounter"].astype(np.int64)
                if last_raw is None:  # a wrap: the 16-bit counter going down
                    steps = np.diff(raw)
                    down = np.concatenate([[0], np.cumsum(steps < 0)])
                else:
                    steps = np.diff(np.concatenate([[last_raw], raw]))
                    down = np.cumsum(steps < 0)
                packet = raw + 65536 * (wraps + down)
                wraps += int(np.sum(steps < 0))
                joined = packet if last is None else np.concatenate([[last], packet])
                d = np.diff(joined)
                if np.any(d <= 0):
                    i = int(np.flatnonzero(d <= 0)[0]) + (1 if last is None else 0)
                    raise FileFormatError(f"{p}: packet counter repeats at data row {row0 + i}")
                jumps = np.flatnonzero(d > 1)
                if jumps.size:
                    tally.lost += int(np.sum(d[jumps] - 1))
                    tally.gaps += jumps.size
                    j = int(jumps[np.argmax(d[jumps])])
                    if tally.biggest is None or d[j] > tally.biggest[0]:
                        r = row0 + j - (0 if last is None else 1)
                        tally.biggest = (int(d[j]), r, int(joined[j]), int(joined[j + 1]))
                quat = self._orientation(cols, row0, tally)
                if origin is None:
                    origin = int(packet[0])
                time = (packet - origin) / self.rate
                ori = OrientationSeries(time, quat, name=f"{self.name}.device", frame="ENU")
                gyr = _stack(cols, _GYR) if _GYR[0] in cols else None
                mag = _stack(cols, _MAG) if _MAG[0] in cols else None
                yield XsensExport(self.name, self.rate, packet, time, _stack(cols, _ACC), ori,
                                  gyr, mag, self.header)  # fmt: skip
                last_raw, last = int(raw[-1]), int(packet[-1])
                row0 += len(packet)
        self._finish(tally, warn)

    def _fast(self, rows: list[str]) -> dict[str, FloatArray] | None:
        """The wanted columns of rows that have every cell and plain numbers in them
        (numpy parses only those columns: MT Manager leaves many others empty), else
        None."""
        k = len(self.labels)
        if any(ln.count("\t") != k - 1 for ln in rows):
            return None
        idx = [self.labels.index(c) for c in self.wanted]
        try:
            data = np.loadtxt(rows, delimiter="\t", usecols=idx, dtype=np.float64, ndmin=2)
        except ValueError:
            return None
        if data.shape[1] != len(idx) or not np.isfinite(data).all():
            return None
        return {c: data[:, j] for j, c in enumerate(self.wanted)}

    def _orientation(self, cols: dict[str, FloatArray], row0: int, tally: _Tally) -> FloatArray:
        """The device's quaternions of a block; rows that are no rotation are tallied (the
        error, with their count, once the file is read)."""
        if self.has_quat:
            quat = np.column_stack([cols[c] for c in _QUAT])
            norm = np.linalg.norm(quat, axis=1)
            bad = np.flatnonzero(np.abs(norm - 1.0) > 0.01)
            if bad.size and tally.bad_first is None:
                tally.bad_first = (row0 + int(bad[0]), float(norm[bad[0]]), 0.0)
            tally.bad += bad.size
            return quat
        R = np.stack([cols[c] for c in _MAT], axis=1).reshape(-1, 3, 3)
        off = np.abs(R @ np.transpose(R, (0, 2, 1)) - np.eye(3)).max(axis=(1, 2))
        det = np.linalg.det(R)
        bad = np.flatnonzero((off > 0.01) | (det < 0.0))
        if bad.size and tally.bad_first is None:
            tally.bad_first = (row0 + int(bad[0]), float(off[bad[0]]), float(det[bad[0]]))
        tally.bad += bad.size
        good = np.ones(len(R), dtype=bool)
        good[bad] = False
        out = np.tile([1.0, 0.0, 0.0, 0.0], (len(R), 1))
        out[good] = quat_from_matrix(R[good])
        return out

    def _finish(self, tally: _Tally, warn: bool) -> None:
        p = self.path
        if tally.bad_first is not None:
            row, value, det = tally.bad_first
            if self.has_quat:
                raise FileFormatError(
                    f"{p}: Quat_q0..q3 at data row {row} has norm {value:.4g}, not a unit "
                    f"quaternion ({tally.bad} such rows); is the column order w, x, y, z?"
                )
            raise FileFormatError(
                f"{p}: Mat[1][1]..Mat[3][3] at data row {row} is not a rotation matrix "
                f"(|R R^T - I| = {value:.3g}, det {det:.3g}; {tally.bad} such rows)"
            )
        if warn and tally.biggest is not None:
            _, big, before, after = tally.biggest
            warnings.warn(
                f"{p}: {tally.lost} packets missing from the packet counter ({tally.gaps} "
                f"gaps, the largest after data row {big}: {before} -> {after}); the time "
                "axis follows the counter, so the gaps stay gaps",
                DataGapWarning,
                stacklevel=3,
            )


def read_xsens_export(path: str | Path, name: str | None = None) -> XsensExport:
    """Read one MT Manager ``.txt`` export (see the module docstring): its
    :class:`XsensStream` blocks joined."""
    stream = XsensStream(path, name)
    parts = list(stream.blocks(rows=1_000_000))
    if not parts:
        raise FileFormatError(f"{stream.path}: no data rows after the column labels")
    return _joined(parts)


def _joined(parts: list[XsensExport]) -> XsensExport:
    """Consecutive pieces of one export as one."""
    if len(parts) == 1:
        return parts[0]
    first = parts[0]

    def cat(field: str) -> Any:
        values = [getattr(x, field) for x in parts]
        return None if values[0] is None else np.concatenate(values)

    time = cat("time")
    q = np.concatenate([x.orientation.quat for x in parts])
    ori = OrientationSeries(time, q, name=first.orientation.name, frame="ENU")
    return XsensExport(first.name, first.rate_hz, cat("packet"), time, cat("acc"), ori,
                       cat("gyr"), cat("mag"), first.header)  # fmt: skip


def trim_to_common_packets(exports: dict[str, XsensExport]) -> dict[str, XsensExport]:
    """Keep the packets every export has (from the latest first packet to the earliest
    last one); time then starts at 0 at the common first packet for all sensors."""
    if not exports:
        return {}
    first = max(int(e.packet[0]) for e in exports.values())
    last = min(int(e.packet[-1]) for e in exports.values())
    if last < first:
        raise DataError(
            f"the exports share no packet (latest start {first}, earliest end {last}); "
            "are they from the same trial?"
        )
    out = {}
    for key, e in exports.items():
        rows = (e.packet >= first) & (e.packet <= last)
        _few_kept(key, int(rows.sum()), e.packet.size, first, last)
        out[key] = e.select(rows, first)
    return out


def xsens_streams(directory: str | Path, prefix: str = "") -> dict[str, XsensStream]:
    """``{sensor id: stream}`` of the ``MT_*.txt`` exports in a directory (headers read)."""
    d = Path(directory)
    if not d.is_dir():
        raise FileFormatError(f"{d}: not a directory of Xsens MT Manager exports")
    files = sorted(f for f in d.glob(f"{prefix}*.txt") if f.name.startswith("MT_"))
    if not files:
        raise FileFormatError(f"{d}: no MT_*.txt Xsens MT Manager exports")
    streams = [XsensStream(f) for f in files]
    return {s.name: s for s in streams}


def common_packets(streams: dict[str, XsensStream], rows: int = 50_000) -> tuple[int, int]:
    """The packet range every export has (:func:`trim_to_common_packets`), from one pass
    over each file (its checks and warnings as the whole reader's)."""
    first, last = [], []
    for s in streams.values():
        lo = hi = None
        for block in s.blocks(rows):
            lo = int(block.packet[0]) if lo is None else lo
            hi = int(block.packet[-1])
        if lo is None or hi is None:
            raise FileFormatError(f"{s.path}: no data rows after the column labels")
        first.append(lo)
        last.append(hi)
    lo, hi = max(first), min(last)
    if hi < lo:
        raise DataError(
            f"the exports share no packet (latest start {lo}, earliest end {hi}); "
            "are they from the same trial?"
        )
    return lo, hi


def trimmed_blocks(
    stream: XsensStream, first: int, last: int, rows: int = 50_000
) -> Iterator[XsensExport]:
    """``stream``'s rows with packets ``first .. last``, time from ``first`` (as
    :func:`trim_to_common_packets` keeps them), block by block; the same warning when
    few of its rows are kept."""
    kept = total = 0
    for block in stream.blocks(rows, warn=False):
        total += block.n_samples
        keep = (block.packet >= first) & (block.packet <= last)
        kept += int(keep.sum())
        if keep.any():
            yield block.select(keep, first)
    _few_kept(stream.name, kept, total, first, last)


def _few_kept(key: str, kept: int, total: int, first: int, last: int) -> None:
    if kept < 0.9 * total and total - kept > 100:  # not a ragged end
        warnings.warn(
            f"sensor {key}: only {kept} of its {total} rows lie in the packets "
            f"all sensors share ({first}..{last}); check the exports' packet counters "
            "(a sensor that started late or stopped early shortens every sensor), or "
            "read them with trim=False",
            DataGapWarning,
            stacklevel=3,
        )


def read_xsens_directory(
    directory: str | Path, trim: bool = True, prefix: str = ""
) -> dict[str, XsensExport]:
    """All ``MT_*.txt`` exports in a directory (optionally only those starting with
    ``prefix``): ``{sensor id: export}``, trimmed to the common packets by default."""
    exports = {}
    for key, stream in xsens_streams(directory, prefix).items():
        exports[key] = read_xsens_export(stream.path)
    return trim_to_common_packets(exports) if trim else exports
