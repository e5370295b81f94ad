"""Parsing of numeric text tables (CSV, tab-separated) with errors naming file, line and column."""

from __future__ import annotations

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
