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

import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import DataError, FileFormatError
from mocapkit.geometry import quat_from_matrix
from mocapkit.io._text_table import parse_rows, read_text
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


def read_xsens_export(path: str | Path, name: str | None = None) -> XsensExport:
    """Read one MT Manager ``.txt`` export (see the module docstring)."""
    p = Path(path)
    lines = read_text(p)
    header: dict[str, str] = {"source": str(p)}
    k = 0
    while k < len(lines) and lines[k].startswith("//"):
        key, _, value = lines[k][2:].partition(":")
        header[key.strip()] = value.strip()
        k += 1
    if k >= len(lines):
        raise FileFormatError(f"{p}: no column labels after the '//' header")
    labels = [c.strip() for c in lines[k].split("\t")]
    rate_text = header.get("Update Rate", "").lower().replace("hz", "").strip()
    try:
        rate = float(rate_text)
    except ValueError:
        raise FileFormatError(
            f"{p}: no '// Update Rate: <Hz>' header line; is this an MT Manager text export?"
        ) from None
    missing = [c for c in ["PacketCounter", *_ACC] if c not in labels]
    has_quat = all(c in labels for c in _QUAT)
    if not has_quat and not all(c in labels for c in _MAT):
        missing.append("Mat[1][1]..Mat[3][3] or Quat_q0..Quat_q3")
    if missing:
        raise FileFormatError(f"{p}: missing column(s) {', '.join(missing)}")
    wanted = ["PacketCounter", *_ACC, *(_QUAT if has_quat else _MAT)]
    for extra in (_GYR, _MAG):
        if all(c in labels for c in extra):
            wanted += extra
    data_rows = [line for line in lines[k + 1 :] if line.strip()]
    table = parse_rows(p, data_rows, k + 2, labels, sep="\t", allow_empty=True)
    cols = {c: table[:, labels.index(c)] for c in wanted}
    for c in wanted:
        bad = np.flatnonzero(~np.isfinite(cols[c]))
        if bad.size:
            raise FileFormatError(f"{p}: column {c!r} is empty or non-finite at data row {bad[0]}")
    packet = _unwrap_packets(cols["PacketCounter"])
    if np.any(np.diff(packet) <= 0):
        i = int(np.flatnonzero(np.diff(packet) <= 0)[0]) + 1
        raise FileFormatError(f"{p}: packet counter repeats at data row {i}")
    gaps = np.flatnonzero(np.diff(packet) > 1)
    if gaps.size:
        lost = int(np.sum(np.diff(packet)[gaps] - 1))
        big = int(gaps[np.argmax(np.diff(packet)[gaps])])
        warnings.warn(
            f"{p}: {lost} packets missing from the packet counter ({gaps.size} gaps, the "
            f"largest after data row {big}: {int(packet[big])} -> {int(packet[big + 1])}); "
            "the time axis follows the counter, so the gaps stay gaps",
            DataGapWarning,
            stacklevel=2,
        )
    if has_quat:
        quat = np.column_stack([cols[c] for c in _QUAT])
        norm = np.linalg.norm(quat, axis=1)
        bad = np.flatnonzero(np.abs(norm - 1.0) > 0.01)
        if bad.size:
            raise FileFormatError(
                f"{p}: Quat_q0..q3 at data row {bad[0]} has norm {norm[bad[0]]:.4g}, not a "
                f"unit quaternion ({bad.size} such rows); is the column order w, x, y, z?"
            )
    else:
        R = np.stack([cols[c] for c in _MAT], axis=1).reshape(-1, 3, 3)
        off = np.abs(R @ np.transpose(R, (0, 2, 1)) - np.eye(3)).max(axis=(1, 2))
        det = np.linalg.det(R)
        bad = np.flatnonzero((off > 0.01) | (det < 0.0))
        if bad.size:
            raise FileFormatError(
                f"{p}: Mat[1][1]..Mat[3][3] at data row {bad[0]} is not a rotation matrix "
                f"(|R R^T - I| = {off[bad[0]]:.3g}, det {det[bad[0]]:.3g}; {bad.size} such rows)"
            )
        quat = quat_from_matrix(R)
    time = (packet - packet[0]) / rate
    label = name or p.stem.rsplit("_", 1)[-1]
    ori = OrientationSeries(time, quat, name=f"{label}.device", frame="ENU")
    gyr = _stack(cols, _GYR) if _GYR[0] in cols else None
    mag = _stack(cols, _MAG) if _MAG[0] in cols else None
    return XsensExport(label, rate, packet, time, _stack(cols, _ACC), ori, gyr, mag, header)


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
        kept = int(rows.sum())
        if kept < 0.9 * e.packet.size and e.packet.size - kept > 100:  # not a ragged end
            warnings.warn(
                f"sensor {key}: only {kept} of its {e.packet.size} rows lie in the packets "
                f"all sensors share ({first}..{last}); check the exports' packet counters "
                "(a sensor that started late or stopped early shortens every sensor), or "
                "read them with trim=False",
                DataGapWarning,
                stacklevel=2,
            )
        out[key] = e.select(rows, first)
    return out


def read_xsens_directory(
    directory: str | Path, trim: bool = True, prefix: str = ""
) -> dict[str, XsensExport]:
    """All ``MT_*.txt`` exports in a directory (optionally only those starting with
    ``prefix``): ``{sensor id: export}``, trimmed to the common packets by default."""
    d = Path(directory)
    if not d.is_dir():
        raise FileFormatError(f"{d}: not a directory of Xsens MT Manager exports")
    files = sorted(f for f in d.glob(f"{prefix}*.txt") if f.name.startswith("MT_"))
    if not files:
        raise FileFormatError(f"{d}: no MT_*.txt Xsens MT Manager exports")
    exports = {}
    for f in files:
        e = read_xsens_export(f)
        exports[e.name] = e
    return trim_to_common_packets(exports) if trim else exports
