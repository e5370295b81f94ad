"""Arrays too long to hold in memory, kept in raw files and read back by row range.

Plain file reads, not memory maps: a map's touched pages count as the process's memory,
which is what spilling is meant to bound (issue 16)."""

from __future__ import annotations

from pathlib import Path
from typing import IO, Any

import numpy as np

from mocapkit._validate import FloatArray


class RowFile:
    """An (N, *shape) float64 array in the raw file ``path`` (row-major), written and read by
    row range; removed by :meth:`close`."""

    def __init__(self, path: str | Path, shape: tuple[int, ...] = ()) -> None:
        self.path = Path(path)
        self.shape = tuple(shape)
        self.width = int(np.prod(self.shape, dtype=np.int64))
        self.rows = 0
        self._f: IO[bytes] = open(self.path, "w+b")  # noqa: SIM115 (closed in close())

    def write(self, a: int, rows: Any) -> None:
        """Rows ``a .. a + len(rows)``."""
        arr = np.ascontiguousarray(rows, dtype=np.float64)
        self._f.seek(a * self.width * 8)
        self._f.write(arr.tobytes())
        self.rows = max(self.rows, a + (arr.size // self.width if self.width else 0))

    def append(self, rows: Any) -> None:
        self.write(self.rows, rows)

    def read(self, a: int, b: int) -> FloatArray:
        """Rows ``a .. b`` as an (b - a, *shape) array."""
        self._f.seek(a * self.width * 8)
        out = np.fromfile(self._f, dtype=np.float64, count=(b - a) * self.width)
        if out.size != (b - a) * self.width:
            raise OSError(f"{self.path}: rows {a}..{b} not written")
        return out.reshape(b - a, *self.shape)

    def close(self) -> None:
        if not self._f.closed:
            self._f.close()
        self.path.unlink(missing_ok=True)
