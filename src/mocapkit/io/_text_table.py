"""Parsing of numeric text tables (CSV, tab-separated) with errors naming file, line and column."""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import FileFormatError


def read_text(path: str | Path) -> list[str]:
    """The lines of a text file; FileFormatError for binary files, FileNotFoundError kept."""
    p = Path(path)
    try:
        return p.read_text().splitlines()
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{p}: not a text file ({exc})") from exc


def parse_rows(
    path: str | Path,
    lines: list[str],
    first_line: int,
    columns: list[str],
    sep: str = ",",
    allow_empty: bool = False,
) -> FloatArray:
    """Parse ``lines`` (data rows) into an (N, len(columns)) float array.

    ``first_line`` is the 1-based line number of ``lines[0]`` in the file, for messages.
    Empty cells are NaN when ``allow_empty``, otherwise an error. Blank lines are skipped.
    """
    rows = []
    k = len(columns)
    for offset, line in enumerate(lines):
        if not line.strip():
            continue
        cells = line.split(sep)
        lineno = first_line + offset
        if len(cells) != k:
            raise FileFormatError(
                f"{path}: line {lineno} has {len(cells)} cells, expected {k} ({', '.join(columns)})"
            )
        row = []
        for c, cell in enumerate(cells):
            text = cell.strip()
            if not text:
                if not allow_empty:
                    raise FileFormatError(
                        f"{path}: line {lineno}, column {columns[c]!r} is empty; every cell "
                        "needs a number"
                    )
                row.append(np.nan)
                continue
            try:
                row.append(float(text))
            except ValueError:
                raise FileFormatError(
                    f"{path}: line {lineno}, column {columns[c]!r}: {text!r} is not a number"
                ) from None
        rows.append(row)
    if not rows:
        raise FileFormatError(f"{path}: no data rows")
    return np.asarray(rows, dtype=np.float64)


def iter_csv_blocks(
    path: str | Path, columns: list[str], rows: int = 50_000, sep: str = ",",
    what: str = "expected columns", hint: str = "",
) -> Iterator[tuple[int, FloatArray]]:  # fmt: skip
    """A CSV whose first line is exactly ``columns``, ``rows`` data rows at a time:
    ``(line number of the block's first row, (n, len(columns)) floats)``. numpy parses a
    block of plain numbers; anything else goes through :func:`parse_rows`, which names the
    line and column at fault. ``what`` and ``hint`` word the message for a wrong header."""
    p = Path(path)
    try:
        with open(p, encoding="utf-8") as f:
            head = f.readline()
            if not head:
                raise FileFormatError(f"{p}: empty file")
            header = [c.strip() for c in head.rstrip("\n").split(sep)]
            if header != columns:
                raise FileFormatError(
                    f"{p}: header {header} does not match the {what} {columns}{hint}"
                )
            line = 2
            sent = False
            while True:
                block = [ln.rstrip("\n") for ln in itertools.islice(f, rows)]
                if not block:
                    break
                data = _parse_plain(block, len(columns), sep)
                if data is None:
                    data = parse_rows(p, block, line, columns, sep)
                if len(data):
                    sent = True
                    yield line, data
                line += len(block)
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{p}: not a text file ({exc})") from exc
    if not sent:
        raise FileFormatError(f"{p}: no data rows")


def _parse_plain(block: list[str], k: int, sep: str) -> FloatArray | None:
    """numpy's parse of rows that are all plain numbers (no blank line, no empty cell), else
    None."""
    if any(not ln.strip() for ln in block):
        return None
    try:
        data = np.loadtxt(block, delimiter=sep, dtype=np.float64, ndmin=2)
    except ValueError:
        return None
    return data if data.shape[1] == k and np.isfinite(data).all() else None
