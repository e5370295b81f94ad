"""OpenSim storage tables: ``.mot`` and ``.sto`` (numeric columns, or quaternion
columns as written by OpenSense, ``w,x,y,z`` in one tab-separated cell).

A table is ``time`` (N,) plus named columns. Angles in ``.mot`` files are in degrees
when the header says ``inDegrees=yes``; :func:`read_table` returns what the file
holds and reports ``in_degrees`` so callers convert at the edge.

Written as OpenSim 4's own ``STOFileAdapter`` writes (``version=3``, ``DataType``), with
missing values as ``nan``: OpenSim's ``TimeSeriesTable`` and its ``Storage`` (the GUI's
Load Motion) then both read every row. A ``version=1`` header sends ``Storage`` to its
legacy stream reader, which stops at the first ``nan`` and silently keeps the rows before
it (tests/io/test_opensim_round_trips.py runs both readers).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from mocapkit._validate import FloatArray, as_float_array, check_shape
from mocapkit.errors import FileFormatError, ShapeError


@dataclass(frozen=True)
class OpenSimTable:
    """Columns over time. ``data`` is (N, k) for numeric tables, (N, k, 4) for quaternion ones."""

    time: FloatArray
    labels: list[str]
    data: FloatArray
    in_degrees: bool = False
    header: dict[str, str] = field(default_factory=dict)

    @property
    def is_quaternion(self) -> bool:
        return self.data.ndim == 3

    def column(self, label: str) -> FloatArray:
        """One column by name; the error lists the available names."""
        try:
            i = self.labels.index(label)
        except ValueError:
            raise FileFormatError(
                f"column {label!r} not in table; available: {', '.join(self.labels)}"
            ) from None
        return self.data[:, i]


class QuaternionTableWriter:
    """An orientation table written as it comes: OpenSense's quaternion ``.sto``/``.mot``
    (as :func:`mocapkit.io.opensim_table.write_table` writes it) or a plain ``.csv``
    (``time_s`` then ``<sensor>_w, _x, _y, _z``). The ``.sto`` header needs the rate,
    given up front; ``csv`` chooses the format instead of the suffix."""

    def __init__(
        self, path: Path, labels: list[str], rate_hz: float, name: str,
        data_type: str = "Quaternion", csv: bool | None = None,
    ) -> None:  # fmt: skip
        self.path = Path(path)
        suffix = self.path.suffix.lower()
        if csv is None and suffix not in (".sto", ".mot", ".csv"):
            raise ShapeError(f"{path}: an orientation table is .sto, .mot or .csv")
        self.csv = suffix == ".csv" if csv is None else csv
        self._f: IO[str] = open(self.path, "w")  # noqa: SIM115 (closed in close())
        if self.csv:
            header = ["time_s"] + [f"{s}_{c}" for s in labels for c in "wxyz"]
            self._f.write(",".join(header) + "\n")
            self._fmt = ",".join(["%.10g"] * (1 + 4 * len(labels)))
        else:
            lines = [name, "version=3", f"DataRate={rate_hz:.6f}", f"DataType={data_type}",
                     "OpenSimVersion=4.1", "endheader", "\t".join(["time", *labels])]  # fmt: skip
            self._f.write("\n".join(lines) + "\n")
            cell = ",".join(["%.10g"] * 4)
            self._fmt = "\t".join(["%.10g", *([cell] * len(labels))])
        self.rows = 0

    def write(self, time: FloatArray, quats: FloatArray) -> None:
        """Append rows: ``time`` (N,) [s], ``quats`` (N, k, 4)."""
        _write_rows(self._f, self._fmt, time, quats.reshape(time.shape[0], -1))
        self.rows += time.shape[0]

    def close(self) -> None:
        self._f.close()

    def __enter__(self) -> QuaternionTableWriter:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


# rows formatted at once: Python floats and strings take ~100 B a value, so an hour's
# table goes out a few megabytes at a time
_FORMAT_ROWS = 5_000


def _write_rows(f: IO[str], fmt: str, time: FloatArray, values: FloatArray) -> None:
    """``time`` (N,) and ``values`` (N, k) as text rows, ``_FORMAT_ROWS`` at a time."""
    for a in range(0, time.shape[0], _FORMAT_ROWS):
        rows = np.column_stack([time[a : a + _FORMAT_ROWS], values[a : a + _FORMAT_ROWS]])
        f.write("\n".join([fmt % tuple(r) for r in rows.tolist()]) + "\n")


def write_table(
    path: str | Path,
    time: Any,
    labels: list[str],
    data: Any,
    *,
    name: str = "mocapkit",
    in_degrees: bool = True,
    data_type: str | None = None,
) -> Path:
    """Write a ``.mot``/``.sto`` table.

    Args:
        time: (N,) seconds.
        labels: k column names.
        data: (N, k) values, or (N, k, 4) quaternions ``[w, x, y, z]`` (written as
            OpenSense's quaternion ``.sto``, ``DataType=Quaternion``).
        in_degrees: value of the ``inDegrees`` header (callers convert angles first).
    """
    t = as_float_array(time, "time")
    check_shape(t, "time", None)
    d = as_float_array(data, "data")
    quat = d.ndim == 3
    if quat:
        check_shape(d, "data", t.shape[0], len(labels), 4)
    else:
        check_shape(d, "data", t.shape[0], len(labels))
    for i, label in enumerate(labels):
        if not label or any(c in label for c in "\t\n"):
            raise ShapeError(f"labels[{i}]: {label!r} is not a valid column name")
    p = Path(path)
    if quat:
        rate = 1.0 / float(np.median(np.diff(t))) if t.size > 1 else 0.0
        with QuaternionTableWriter(p, labels, rate, name, data_type or "Quaternion",
                                   csv=False) as w:  # fmt: skip
            for a in range(0, t.shape[0], _BLOCK_ROWS):
                w.write(t[a : a + _BLOCK_ROWS], d[a : a + _BLOCK_ROWS])
        return p
    with TableWriter(p, labels, name=name, in_degrees=in_degrees,
                     data_type=data_type or "double") as w:  # fmt: skip
        for a in range(0, t.shape[0], _BLOCK_ROWS):
            w.write(t[a : a + _BLOCK_ROWS], d[a : a + _BLOCK_ROWS])
    return p


class TableWriter:
    """A numeric ``.mot``/``.sto`` written as it comes, row block by row block (bounded
    memory for hour-long tables; one C-level format per row instead of one Python
    f-string per value: ``imu run`` once spent 60 % of its time writing). The header's
    ``nRows`` is a fixed-width field filled in by :meth:`close`, so the row count need
    not be known up front; OpenSim's ``TimeSeriesTable`` and ``Storage`` read it whole
    (tests/io/test_opensim_round_trips.py)."""

    _NROWS_WIDTH = 12

    def __init__(
        self, path: str | Path, labels: list[str], *, name: str = "mocapkit",
        in_degrees: bool = True, data_type: str = "double",
    ) -> None:  # fmt: skip
        for i, label in enumerate(labels):
            if not label or any(c in label for c in "\t\n"):
                raise ShapeError(f"labels[{i}]: {label!r} is not a valid column name")
        self.path = Path(path)
        self.labels = list(labels)
        self.rows = 0
        self._f: IO[str] = open(self.path, "w")  # noqa: SIM115 (closed in close())
        self._f.write(f"{name}\nversion=3\n")
        self._nrows_at = self._f.tell() + len("nRows=")
        lines = [f"nRows={'0':<{self._NROWS_WIDTH}}", f"nColumns={len(labels) + 1}",
                 f"inDegrees={'yes' if in_degrees else 'no'}", f"DataType={data_type}",
                 "endheader", "\t".join(["time", *labels])]  # fmt: skip
        self._f.write("\n".join(lines) + "\n")
        self._fmt = "\t".join(["%.10g"] * (len(labels) + 1))

    def write(self, time: Any, values: Any) -> None:
        """Append rows: ``time`` (N,) [s], ``values`` (N, k) (NaN is written ``nan``)."""
        t = np.asarray(time, dtype=np.float64)
        v = np.asarray(values, dtype=np.float64)
        check_shape(v, "values", t.shape[0], len(self.labels))
        _write_rows(self._f, self._fmt, t, v)
        self.rows += t.shape[0]

    def close(self) -> None:
        if self._f.closed:
            return
        self._f.seek(self._nrows_at)
        self._f.write(f"{self.rows:<{self._NROWS_WIDTH}}")
        self._f.close()

    def __enter__(self) -> TableWriter:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


_BLOCK_ROWS = 50_000


def _parse_block_fast(block: list[str], k: int, quat: bool) -> tuple[FloatArray, FloatArray] | None:
    """Vectorised parse of well-formed rows (numpy does the float conversion); None when
    any row is irregular, so the row-by-row parser can name it."""
    n = len(block)
    if n == 0:
        return None
    tabs = np.fromiter((line.count("\t") for line in block), dtype=np.int64, count=n)
    if (tabs != k).any():
        return None
    if quat:
        commas = np.fromiter((line.count(",") for line in block), dtype=np.int64, count=n)
        if (commas != 3 * k).any():
            return None
    text = " ".join(block).replace("\t", " ").replace(",", " ")
    with warnings.catch_warnings():
        # a non-numeric token stops the parse (a ValueError, or a DeprecationWarning and a
        # short result in older numpy): the row-by-row parser then names the bad row
        warnings.simplefilter("ignore", DeprecationWarning)
        try:
            flat = np.fromstring(text, dtype=np.float64, sep=" ")
        except ValueError:
            return None
    width = 1 + k * (4 if quat else 1)
    if flat.size != n * width:
        return None
    table = flat.reshape(n, width)
    data = table[:, 1:].reshape(n, k, 4) if quat else table[:, 1:].copy()
    return table[:, 0].copy(), data


def read_table(path: str | Path) -> OpenSimTable:
    """Read a ``.mot``/``.sto`` file (numeric or quaternion columns). The rows are read
    and parsed ``_BLOCK_ROWS`` at a time (an hour-long table never sits in memory as
    text)."""
    p = Path(path)
    try:
        with open(p, encoding="utf-8") as f:
            return _read_table(p, f)
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{p}: not a text file ({exc})") from exc


def _read_table(p: Path, f: Any) -> OpenSimTable:
    header, labels = _read_header(p, f)
    k = len(labels)
    times: list[FloatArray] = []
    datas: list[FloatArray] = []
    quat: bool | None = None
    for t, d in _iter_blocks(p, f, header, k, _BLOCK_ROWS):
        quat = d.ndim == 3
        times.append(t)
        datas.append(d)
    shape = (0, k, 4) if quat else (0, k)
    time = np.concatenate(times) if times else np.empty(0)
    data = np.concatenate(datas) if datas else np.empty(shape)
    in_deg = header.get("inDegrees", "no").lower() == "yes"
    return OpenSimTable(time, labels, data, in_degrees=in_deg, header=header)


def iter_table(path: str | Path, rows: int = _BLOCK_ROWS) -> Iterator[OpenSimTable]:
    """A ``.mot``/``.sto`` file ``rows`` rows at a time (each piece an
    :class:`OpenSimTable` with the file's labels and header): the flat-memory reader for
    hour-long tables. A bad row is named by its row number in the whole file."""
    if rows < 1:
        raise ShapeError(f"rows: expected a positive number of rows per piece, got {rows}")
    p = Path(path)
    try:
        with open(p, encoding="utf-8") as f:
            header, labels = _read_header(p, f)
            in_deg = header.get("inDegrees", "no").lower() == "yes"
            for t, d in _iter_blocks(p, f, header, len(labels), rows):
                yield OpenSimTable(t, labels, d, in_degrees=in_deg, header=header)
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{p}: not a text file ({exc})") from exc


def table_is_quaternion(path: str | Path) -> bool:
    """Whether a ``.mot``/``.sto`` holds quaternions (OpenSense orientations), from its
    header and first row only."""
    p = Path(path)
    try:
        with open(p, encoding="utf-8") as f:
            header, _ = _read_header(p, f)
            first = next((ln for ln in f if ln.strip()), "").split("\t")
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{p}: not a text file ({exc})") from exc
    return header.get("DataType", "").lower() == "quaternion" or (
        len(first) > 1 and "," in first[1]
    )


def _read_header(p: Path, f: Any) -> tuple[dict[str, str], list[str]]:
    """The header's ``key=value`` lines and the column labels after ``time``."""
    header: dict[str, str] = {}
    for line in f:
        if line.strip().lower() == "endheader":
            break
        if "=" in line:
            key, value = line.split("=", 1)
            header[key.strip()] = value.strip()
    else:
        raise FileFormatError(f"{p}: no 'endheader' line; is this an OpenSim .mot/.sto file?")
    label_line = next(f, None)
    if label_line is None:
        raise FileFormatError(f"{p}: no column labels after 'endheader'")
    labels = label_line.rstrip("\r\n").split("\t")
    if labels[0].strip().lower() != "time":
        raise FileFormatError(f"{p}: first column must be 'time', got {labels[0]!r}")
    return header, [s.strip() for s in labels[1:]]


def _iter_blocks(
    p: Path, f: Any, header: dict[str, str], k: int, rows: int
) -> Iterator[tuple[FloatArray, FloatArray]]:
    """(time (n,), data (n, k) or (n, k, 4)) for each block of ``rows`` lines."""
    import itertools

    quat: bool | None = None
    row0 = 0
    while True:
        block = [ln.rstrip("\r\n") for ln in itertools.islice(f, rows)]
        if not block:
            break
        block = [ln for ln in block if ln.strip()]
        if not block:
            continue
        if quat is None:
            first = block[0].split("\t")
            quat = header.get("DataType", "").lower() == "quaternion" or bool(
                len(first) > 1 and "," in first[1]
            )
        parsed = _parse_block_fast(block, k, quat) or _parse_block_checked(p, block, k, quat, row0)
        yield parsed
        row0 += len(block)


def _parse_block_checked(
    p: Path, block: list[str], k: int, quat: bool, row0: int
) -> tuple[FloatArray, FloatArray]:
    """The rows one by one, naming the first bad one (``row0``: rows before the block)."""
    n = len(block)
    time = np.empty(n)
    data = np.empty((n, k, 4)) if quat else np.empty((n, k))
    for i, line in enumerate(block):
        cells = line.split("\t")
        if len(cells) != k + 1:
            raise FileFormatError(f"{p}: row {row0 + i} has {len(cells)} cells, expected {k + 1}")
        try:
            time[i] = float(cells[0])
            if quat:
                data[i] = [[float(v) for v in c.split(",")] for c in cells[1:]]
            else:
                data[i] = [float(c) for c in cells[1:]]
        except ValueError as exc:
            raise FileFormatError(f"{p}: row {row0 + i}: {exc}") from exc
    return time, data
