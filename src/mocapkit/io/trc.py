"""TRC marker files (OpenSim, Motion Analysis, Cortex, Vicon/Qualisys exports): read and write.

Read: every variant OpenSim's own examples carry (tests/data/trc): header values separated
by one or several tabs or padded with spaces (``"  100.0\\t\\t  100.0"``), trailing tabs,
marker labels separated by extra tabs, blank or tab-only lines before the data, CRLF line
ends, E-notation, gaps written as empty cells, ``NaN``/``nan``/``NAN`` or ``"   NaN"``,
rows whose trailing empty cells were dropped, negative times. The declared ``Units`` are
converted to metres, the axes are kept as in the file (OpenSim's TRC files are y-up:
``meta["up_axis"] = "y"`` is a hint the reconstruction checks against the static trial).
The rate is the header's ``DataRate`` (the time column is often rounded to a few decimals:
1/60 s written as 0.017 would otherwise read as 58.8 Hz); a time column that drifts from
``time[0] + k / DataRate`` by more than a quarter frame is another clock (a resampled
file): it is then used, and the disagreement reported. A file with fewer rows than
``NumFrames`` says so.

Write: tab-separated, the layout OpenSim 4's ``TRCFileAdapter`` reads (every row has
exactly ``2 + 3 M`` cells: gaps are written ``NaN``, since that reader drops trailing empty
cells and then refuses the row), times ``first + k / rate`` to 1e-9 s.
"""

from __future__ import annotations

import logging
import re
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import FileFormatError
from mocapkit.io.units import length_scale
from mocapkit.markers.trajectories import MarkerTrajectories

log = logging.getLogger(__name__)

_HEADER_KEYS = (
    "DataRate",
    "CameraRate",
    "NumFrames",
    "NumMarkers",
    "Units",
    "OrigDataRate",
    "OrigDataStartFrame",
    "OrigNumFrames",
)
_KERNEL_PARSE_CHARS = 2_000_000  # larger data blocks: the numba parser (its load ~0.05 s)
_EMPTY_CELL = re.compile(r"\t[ ]*(?=\t|$)", re.MULTILINE)


def _cells(line: str) -> list[str]:
    """Tab-separated cells, stripped, empty ones dropped (header lines)."""
    return [c.strip() for c in line.split("\t") if c.strip()]


def _header(p: Path, lines: list[str]) -> dict[str, str]:
    keys = _cells(lines[1])
    values = _cells(lines[2])
    if len(values) != len(keys):
        # some writers separate the values by spaces only
        spaced = lines[2].split()
        if len(spaced) == len(keys):
            values = spaced
    if len(values) < len(keys):
        raise FileFormatError(
            f"{p}: line 3 holds {len(values)} values for the {len(keys)} header fields of "
            f"line 2 ({', '.join(keys)}); every field needs a value"
        )
    return dict(zip(keys, values, strict=False))


def _number(p: Path, header: dict[str, str], key: str, kind: type) -> Any:
    try:
        return kind(float(header[key])) if kind is int else kind(header[key])
    except ValueError:
        raise FileFormatError(
            f"{p}: header field {key!r} on line 3 is {header[key]!r}, not a number"
        ) from None


def _parse_data(
    p: Path, lines: list[str], first_line: int, width: int, short: list[int]
) -> np.ndarray:
    """(N, width) floats of the data rows (NaN for empty cells); rows with missing trailing
    cells are padded (their line numbers appended to ``short``), extra cells must be
    empty."""
    fixed: list[str] = []
    for offset, line in enumerate(lines):
        n = line.count("\t") + 1
        if n == width:
            fixed.append(line)
            continue
        cells = line.split("\t")
        if n > width:
            extra = [c for c in cells[width:] if c.strip()]
            if extra:
                raise FileFormatError(
                    f"{p}: line {first_line + offset} has {n} cells, more than the "
                    f"{width} (Frame#, Time, X/Y/Z of each marker) the header announces"
                )
            fixed.append("\t".join(cells[:width]))
        else:
            short.append(first_line + offset)
            fixed.append("\t".join(cells + [""] * (width - n)))
    block = _EMPTY_CELL.sub("\tnan", "\n".join(fixed))
    flat = np.empty(0)
    if len(block) > _KERNEL_PARSE_CHARS:
        from mocapkit.io._parse_kernels import parse_floats

        raw = np.frombuffer(block.encode("ascii", errors="replace"), dtype=np.uint8)
        out = np.empty(len(fixed) * width)
        count = parse_floats(raw, out)
        if count == out.size:
            flat = out
    if flat.size == 0:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            try:
                flat = np.fromstring(block.replace("\t", " "), dtype=np.float64, sep=" ")
            except ValueError:
                flat = np.empty(0)
    if flat.size == len(fixed) * width:
        return flat.reshape(len(fixed), width)
    # a cell that is not a number: find it for the message
    for offset, line in enumerate(fixed):
        for c, cell in enumerate(line.split("\t")):
            text = cell.strip()
            if not text:
                continue
            try:
                float(text)
            except ValueError:
                column = "Frame#" if c == 0 else "Time" if c == 1 else f"column {c + 1}"
                raise FileFormatError(
                    f"{p}: line {first_line + offset}, {column}: {text!r} is not a number"
                ) from None
    raise FileFormatError(f"{p}: the data rows could not be read as numbers")


_READ_BYTES = 8 << 20  # bytes read from the file at a time


def _lines(f: Any) -> Iterator[bytes]:
    """The lines of a binary file, ``\n``, ``\r\n`` or ``\r`` ended, read in blocks."""
    rest = b""
    while True:
        chunk = f.read(_READ_BYTES)
        if not chunk:
            break
        lines = (rest + chunk).splitlines()
        rest = lines.pop() if lines and not chunk.endswith((b"\n", b"\r")) else b""
        yield from lines
    if rest:
        yield rest


class TrcStream:
    """A TRC file opened for reading: its header at once, its data rows block by block
    (:meth:`blocks`), so an hour-long trial never sits in memory as text.

    Attributes:
        names: the marker labels; rate_hz: ``DataRate``; scale: metres per file unit;
        meta: as :func:`read_trc` returns it (before the time column is checked);
        declared_frames: the header's ``NumFrames`` (None when absent).
    """

    def __init__(self, path: str | Path, units: str | None = None) -> None:
        p = Path(path)
        self.path = p
        self._f = open(p, "rb")  # noqa: SIM115 (closed by close() / the last block)
        if b"\x00" in self._f.read(4096):
            self._f.close()
            raise FileFormatError(f"{p}: not a text TRC file (binary content)")
        self._f.seek(0)
        self._it = _lines(self._f)
        head: list[str] = []
        for raw in self._it:
            try:
                head.append(raw.decode("utf-8"))
            except UnicodeDecodeError:
                head.append(raw.decode("latin-1"))  # a Windows path in the first line, say
            if len(head) == 5:
                break
        try:
            self._parse_header(p, head, units)
        except BaseException:
            self._f.close()
            raise

    def _parse_header(self, p: Path, lines: list[str], units: str | None) -> None:
        if len(lines) < 5 or not lines[0].split() or lines[0].split()[0] != "PathFileType":
            raise FileFormatError(
                f"{p}: not a TRC file (the first line should start with 'PathFileType')"
            )
        header = _header(p, lines)
        for key in ("DataRate", "NumMarkers", "Units"):
            if key not in header or not header[key]:
                raise FileFormatError(
                    f"{p}: header field {key!r} missing on lines 2-3 (found: "
                    f"{', '.join(header) or 'none'}); a TRC header names DataRate, "
                    "CameraRate, NumFrames, NumMarkers, Units, OrigDataRate, "
                    "OrigDataStartFrame, OrigNumFrames"
                )
        rate = _number(p, header, "DataRate", float)
        n_markers = _number(p, header, "NumMarkers", int)
        if not (np.isfinite(rate) and rate > 0):
            raise FileFormatError(f"{p}: DataRate is {header['DataRate']}; expected a rate > 0 Hz")
        self.scale = length_scale(units or header["Units"], f"{p}: Units")
        labels = _cells(lines[3])
        if len(labels) < 2 or labels[0] != "Frame#" or labels[1] != "Time":
            raise FileFormatError(
                f"{p}: line 4 should start with 'Frame#\\tTime', then the markers"
            )
        names = labels[2:]
        if len(names) != n_markers:
            raise FileFormatError(
                f"{p}: header says NumMarkers={n_markers} but line 4 names {len(names)} markers"
            )
        seen: set[str] = set()
        for n in names:
            if n in seen:
                raise FileFormatError(
                    f"{p}: marker {n!r} is named twice on line 4; labels must be unique"
                )
            seen.add(n)
        declared = header.get("NumFrames", "")
        try:
            self.declared_frames: int | None = int(float(declared)) if declared else None
        except ValueError:
            self.declared_frames = None
        self.names = tuple(names)
        self.rate_hz = float(rate)
        self.meta: dict[str, Any] = {
            "source": str(p),
            "format": "trc",
            "units": units or header["Units"],
            "rate_hz": rate,
            "up_axis": "y",
            "up_axis_source": "TRC convention (OpenSim)",
        }

    def blocks(self, rows: int = 10_000) -> Iterator[tuple[FloatArray, FloatArray]]:
        """``(time (n,), positions (n, M, 3) [m])`` of up to ``rows`` data rows at a time
        (blank lines skipped; a row without a time named by its line)."""
        width = 2 + 3 * len(self.names)
        line_no = 5
        block: list[str] = []
        first = 0
        short: list[int] = []
        try:
            for raw in self._it:
                line_no += 1
                text = raw.decode("latin-1")
                if not text.strip():
                    continue
                if not block:
                    first = line_no
                block.append(text)
                if len(block) == rows:
                    yield self._block(block, first, width, short)
                    block = []
            if block:
                yield self._block(block, first, width, short)
        finally:
            self.close()
        if short:
            log.warning(
                "%s: %d data rows have fewer than %d cells (first: line %d); their missing "
                "trailing markers are read as gaps",
                self.path,
                len(short),
                width,
                short[0],
            )

    def _block(
        self, lines: list[str], first: int, width: int, short: list[int]
    ) -> tuple[FloatArray, FloatArray]:
        table = _parse_data(self.path, lines, first, width, short)
        time = table[:, 1].copy()
        if not np.isfinite(time).all():
            bad = int(np.flatnonzero(~np.isfinite(time))[0])
            raise FileFormatError(
                f"{self.path}: the data row on line {first + bad} has no time; every row needs one"
            )
        pos = table[:, 2:].reshape(len(time), len(self.names), 3) * self.scale
        return time, pos

    def close(self) -> None:
        self._f.close()


def check_clock(p: Path, meta: dict[str, Any], frames: int, deviation: float, step: float) -> None:
    """The time column against ``DataRate``: ``deviation`` the largest distance of a time
    from ``time[0] + k / DataRate`` [s], ``step`` the column's median step. Another clock
    (beyond a quarter frame): its step is used (``meta["rate_hz"]``), and said. A file with
    fewer rows than ``meta["declared_frames"]`` (NumFrames) is said too."""
    rate = float(meta["rate_hz"])
    declared = meta.get("declared_frames")
    if declared is not None and declared > frames:
        meta["truncated"] = {"frames": frames, "declared": declared}
        log.warning(
            "%s: the header announces %d frames (NumFrames) but the file holds %d: it may be "
            "cut short; only those %d frames are used",
            p,
            declared,
            frames,
            frames,
        )
    if frames > 2 and deviation > 0.25 / rate:  # not the same clock, not rounding
        if step > 0:
            meta["rate_hz"] = 1.0 / step
            meta["declared_rate_hz"] = rate
        log.warning(
            "%s: DataRate says %g Hz but the time column advances %.6g s per frame "
            "(%.6g Hz); the time column is used. Fix the header's DataRate if the file "
            "was resampled",
            p,
            rate,
            step,
            1.0 / step if step > 0 else float("nan"),
        )


def read_trc(path: str | Path, units: str | None = None) -> MarkerTrajectories:
    """Read a TRC file.

    Args:
        path: the ``.trc`` file.
        units: override the file's declared length unit (``"mm"``, ``"cm"``, ``"m"``).

    Returns:
        Trajectories in metres, file axes; ``meta`` holds ``source``, ``units`` (declared),
        ``rate_hz`` (``DataRate``) and ``up_axis="y"`` (the TRC convention; checked later).
    """
    stream = TrcStream(path, units)
    parts = list(stream.blocks(rows=50_000))
    if not parts:
        raise FileFormatError(f"{stream.path}: no data rows after the header")
    time = np.concatenate([t for t, _ in parts])
    pos = np.concatenate([x for _, x in parts])
    meta = {**stream.meta, "declared_frames": stream.declared_frames}
    regular = time[0] + np.arange(len(time)) / stream.rate_hz
    step = float(np.median(np.diff(time))) if len(time) > 1 else 0.0
    check_clock(stream.path, meta, len(time), float(np.abs(time - regular).max()), step)
    del meta["declared_frames"]
    return MarkerTrajectories(time, pos, stream.names, meta=meta)


def write_trc(
    path: str | Path,
    trajectories: MarkerTrajectories,
    units: str = "mm",
    rate_hz: float | None = None,
) -> Path:
    """Write trajectories (metres, axes as given) as a TRC file in ``units``.

    ``rate_hz``: the frame rate (default: the trajectories' declared rate); the time column
    is written as ``time[0] + k / rate`` when the times are that regular to 1e-6 s, else as
    given. Gaps are ``NaN`` cells (OpenSim 4 reads them as missing markers).
    """
    p = Path(path)
    traj = trajectories
    rate = (
        float(rate_hz)
        if rate_hz is not None
        else (traj.rate_hz if traj.n_frames > 1 else float(traj.meta.get("rate_hz", 0.0)))
    )
    if not (np.isfinite(rate) and rate > 0):
        raise FileFormatError(f"{p}: the frame rate is {rate}; a TRC file needs a rate > 0 Hz")
    regular = traj.time[0] + np.arange(traj.n_frames) / rate
    time = regular if np.allclose(traj.time, regular, rtol=0.0, atol=1e-6) else traj.time
    with TrcWriter(p, traj.names, rate, traj.n_frames, units) as w:
        w.write(time, traj.positions)
    return p


class TrcWriter:
    """A TRC file written block by block (the frame count, which the header states, is
    given up front): :func:`write_trc`'s layout, one C-level format per row."""

    def __init__(
        self, path: str | Path, names: Sequence[str], rate_hz: float, n_frames: int,
        units: str = "mm",
    ) -> None:  # fmt: skip
        self.path = Path(path)
        self.scale = 1.0 / length_scale(units, "units")
        self.n_markers = len(names)
        self.frames = 0
        self.n_frames = n_frames
        rate = float(rate_hz)
        if not (np.isfinite(rate) and rate > 0):
            raise FileFormatError(
                f"{self.path}: the frame rate is {rate}; a TRC file needs a rate > 0 Hz"
            )
        m = self.n_markers
        head = [
            f"PathFileType\t4\t(X/Y/Z)\t{self.path.name}",
            "\t".join(_HEADER_KEYS),
            "\t".join([f"{rate:.10g}", f"{rate:.10g}", str(n_frames), str(m), units,
                       f"{rate:.10g}", "1", str(n_frames)]),
            "\t".join(["Frame#", "Time", *[f"{n}\t\t" for n in names]]),
            "\t".join(["", "", *[f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(m)]]),
            "",
        ]  # fmt: skip
        self._f: IO[str] = open(self.path, "w")  # noqa: SIM115 (closed in close())
        self._f.write("\n".join(head) + "\n")
        self._fmt = "\t".join(["%d", "%.9f"] + ["%.6f"] * (3 * m))

    def write(self, time: FloatArray, positions: FloatArray) -> None:
        """Append frames: ``time`` (n,) [s], ``positions`` (n, M, 3) [m]."""
        n = len(time)
        data = np.asarray(positions, dtype=float).reshape(n, 3 * self.n_markers) * self.scale
        rows = np.column_stack([np.arange(self.frames + 1, self.frames + n + 1), time, data])
        text = "\n".join([self._fmt % tuple(r) for r in rows.tolist()])
        self._f.write(text.replace("nan", "NaN") + "\n")
        self.frames += n

    def close(self) -> None:
        if self._f.closed:
            return
        self._f.close()
        if self.frames != self.n_frames:
            raise FileFormatError(
                f"{self.path}: {self.frames} frames written, the header says {self.n_frames}"
            )

    def __enter__(self) -> TrcWriter:
        return self

    def __exit__(self, *exc: Any) -> None:
        if exc[0] is not None:  # an error on the way: it is the one to report
            self._f.close()
            return
        self.close()
