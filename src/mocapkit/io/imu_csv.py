"""A plain CSV format for one IMU, with declared units (read and write).

Example (what :func:`write_imu_csv` produces)::

    # mocapkit imu csv v1
    # name: pelvis
    time [s],gyr_x [deg/s],gyr_y [deg/s],gyr_z [deg/s],acc_x [g],acc_y [g],acc_z [g]
    0,0.5,-1.2,0.2,0.01,0.02,0.99

(with ``mag_x [uT],mag_y [uT],mag_z [uT]`` columns in 9D).

Rules:

- Lines starting with ``#`` are comments; ``# name: <label>`` names the sensor.
- The first other line holds the column labels, each ``<column> [<unit>]``. Columns
  ``time``, ``gyr_x/y/z`` and ``acc_x/y/z`` are required, ``mag_x/y/z`` optional (6D
  without them); any order; other columns are ignored. Every column needs a unit.
- Units, converted on read to SI: time ``s``, ``ms``, ``us``; gyroscope ``rad/s``,
  ``deg/s``; accelerometer ``m/s^2``, ``g`` (9.80665 m/s^2); magnetometer ``uT``,
  ``nT``, ``mT``, ``G`` (gauss) -> uT, or ``a.u.`` (kept as is).
- An empty magnetometer row (all three cells empty) is a gap (all-NaN row).
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.errors import FileFormatError
from mocapkit.io._text_table import parse_rows
from mocapkit.series import ImuRecording

STANDARD_GRAVITY = 9.80665  # [m/s^2 per g]
MAGIC = "# mocapkit imu csv v1"

UNITS: dict[str, dict[str, float]] = {
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6},
    "gyr": {"rad/s": 1.0, "deg/s": np.pi / 180.0},
    "acc": {"m/s^2": 1.0, "m/s2": 1.0, "g": STANDARD_GRAVITY},
    "mag": {"ut": 1.0, "nt": 1e-3, "mt": 1e3, "g": 100.0, "gauss": 100.0, "a.u.": 1.0},
}
_REQUIRED = ["time", "gyr_x", "gyr_y", "gyr_z", "acc_x", "acc_y", "acc_z"]
_MAG = ["mag_x", "mag_y", "mag_z"]


def _parse_label(path: Path, label: str, lineno: int) -> tuple[str, str]:
    text = label.strip()
    if "[" not in text or not text.endswith("]"):
        raise FileFormatError(
            f"{path}: line {lineno}: column {text!r} has no unit; write it as "
            "'<name> [<unit>]', e.g. 'gyr_x [deg/s]'"
        )
    name, unit = text[:-1].split("[", 1)
    return name.strip().lower(), unit.strip()


def _factor(path: Path, column: str, unit: str) -> float:
    kind = column.split("_")[0]
    table = UNITS[kind]
    key = unit.lower() if kind == "mag" else unit
    if key not in table:
        raise FileFormatError(
            f"{path}: column {column!r} has unit {unit!r}; supported: {', '.join(table)}"
        )
    return table[key]


def read_imu_csv(path: str | Path, name: str | None = None) -> ImuRecording:
    """Read one IMU from the plain CSV format (see the module docstring)."""
    chunks = list(iter_imu_csv(path, name))
    if len(chunks) == 1:
        return chunks[0]
    first = chunks[0]
    mag = None if first.mag is None else np.concatenate([c.mag for c in chunks])
    return ImuRecording(
        np.concatenate([c.time for c in chunks]),
        np.concatenate([c.gyr for c in chunks]),
        np.concatenate([c.acc for c in chunks]),
        mag,
        name=first.name,
        meta=first.meta,
    )


CHUNK_ROWS = 100_000


def iter_imu_csv(
    path: str | Path, name: str | None = None, chunk_rows: int = CHUNK_ROWS
) -> Iterator[ImuRecording]:
    """The recording of :func:`read_imu_csv` in pieces of ``chunk_rows`` rows, read as it
    goes (memory bounded by one piece: an hour at 1 kHz streams through ``imu run``).
    Errors name the line in the file, as the whole-file reader's do."""
    p = Path(path)
    try:
        f = open(p, encoding="utf-8")  # noqa: SIM115 (closed below, generator)
    except UnicodeDecodeError as exc:  # pragma: no cover (open does not decode)
        raise FileFormatError(f"{p}: not a text file ({exc})") from exc
    with f:
        label = name
        lineno = 0
        header = None
        try:
            for line in f:
                lineno += 1
                if line.startswith("#") or not line.strip():
                    comment = line.lstrip("#").strip()
                    if comment.lower().startswith("name:") and label is None:
                        label = comment.split(":", 1)[1].strip()
                    continue
                header = line.rstrip("\n")
                break
        except UnicodeDecodeError as exc:
            raise FileFormatError(f"{p}: not a text file ({exc})") from exc
        if header is None:
            raise FileFormatError(f"{p}: no column labels (expected 'time [s],gyr_x [rad/s],...')")
        layout = _Layout(p, header, lineno)
        meta: dict[str, object] = {"source": str(p), "format": "mocapkit imu csv"}
        if layout.mag_unit:
            meta["mag_unit"] = layout.mag_unit
        first_line = lineno + 1
        row0 = 0  # data rows before this block
        sent = False
        while True:
            try:
                block = [line.rstrip("\n") for line in itertools.islice(f, chunk_rows)]
            except UnicodeDecodeError as exc:
                raise FileFormatError(f"{p}: not a text file ({exc})") from exc
            if not block:
                break
            if any(line.strip() for line in block):
                piece = layout.recording(block, first_line, row0, label or p.stem, meta)
                row0 += piece.n_samples
                sent = True
                yield piece
            first_line += len(block)
        if not sent:
            raise FileFormatError(f"{p}: no data rows")


class _Layout:
    """The columns of a mocapkit IMU CSV: which is which, and their units."""

    def __init__(self, path: Path, header: str, lineno: int) -> None:
        self.path = path
        parsed = [_parse_label(path, c, lineno) for c in header.split(",")]
        columns = [c for c, _ in parsed]
        missing = [c for c in _REQUIRED if c not in columns]
        if missing:
            raise FileFormatError(f"{path}: missing column(s) {', '.join(missing)}")
        has_mag = [c in columns for c in _MAG]
        if any(has_mag) and not all(has_mag):
            raise FileFormatError(f"{path}: give all of mag_x, mag_y, mag_z or none of them")
        if len(set(columns)) != len(columns):
            raise FileFormatError(f"{path}: duplicated column names {columns}")
        self.columns = columns
        self.wanted = _REQUIRED + (_MAG if all(has_mag) else [])
        self.factors = {c: _factor(path, c, parsed[columns.index(c)][1]) for c in self.wanted}
        self.mag_unit = None
        if all(has_mag):
            unit = parsed[columns.index("mag_x")][1]
            self.mag_unit = "a.u." if unit.lower() == "a.u." else "uT"

    def recording(
        self, block: list[str], first_line: int, row0: int, name: str, meta: dict[str, object]
    ) -> ImuRecording:
        p = self.path
        data = _parse_block(p, block, first_line, self.columns)
        values = {}
        for c in self.wanted:
            col = data[:, self.columns.index(c)] * self.factors[c]
            if c not in _MAG:
                bad = np.flatnonzero(~np.isfinite(col))
                if bad.size:
                    raise FileFormatError(
                        f"{p}: column {c!r} is empty or not finite at data row "
                        f"{row0 + int(bad[0])} (line {_line_of(block, first_line, int(bad[0]))})"
                    )
            values[c] = col
        mag = np.column_stack([values[c] for c in _MAG]) if self.mag_unit else None
        return ImuRecording(
            values["time"],
            np.column_stack([values[c] for c in _REQUIRED[1:4]]),
            np.column_stack([values[c] for c in _REQUIRED[4:7]]),
            mag,
            name=name,
            meta=dict(meta),
        )


def _parse_block(path: Path, block: list[str], first_line: int, columns: list[str]) -> Any:
    """Rows of numbers: numpy's parser when every cell is a number (fast), else the
    checked one (empty magnetometer cells are NaN; a bad cell is named with its line)."""
    rows = [line for line in block if line.strip()]
    try:
        data = np.loadtxt(rows, delimiter=",", dtype=np.float64, ndmin=2)
        if data.shape[1] == len(columns):
            return data
    except ValueError:
        pass
    return parse_rows(path, block, first_line, columns, allow_empty=True)


def _line_of(block: list[str], first_line: int, row: int) -> int:
    """The file's line number of data row ``row`` of a block (blank lines skipped)."""
    seen = -1
    for offset, line in enumerate(block):
        if line.strip():
            seen += 1
            if seen == row:
                return first_line + offset
    return first_line + len(block)


def write_imu_csv(path: str | Path, rec: ImuRecording, mag_unit: str | None = None) -> Path:
    """Write ``rec`` in SI units (magnetometer in ``mag_unit``, default from
    ``rec.meta["mag_unit"]`` or uT). Gaps in the magnetometer are written as empty cells."""
    p = Path(path)
    unit = mag_unit or str(rec.meta.get("mag_unit", "uT"))
    header = [
        "time [s]",
        *(f"gyr_{a} [rad/s]" for a in "xyz"),
        *(f"acc_{a} [m/s^2]" for a in "xyz"),
    ]
    cols = [rec.time[:, None], rec.gyr, rec.acc]
    if rec.mag is not None:
        header += [f"mag_{a} [{unit}]" for a in "xyz"]
        cols.append(rec.mag)
    table = np.hstack(cols)
    lines = [MAGIC, f"# name: {rec.name}", ",".join(header)]
    for row in table:
        lines.append(",".join("" if np.isnan(v) else f"{v:.10g}" for v in row))
    p.write_text("\n".join(lines) + "\n")
    return p
