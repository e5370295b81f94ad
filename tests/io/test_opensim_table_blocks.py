"""read_table in blocks: a table longer than one block reads back whole, and a bad row in
a later block is named with its row number across the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import FileFormatError
from mocapkit.io import opensim_table
from mocapkit.io.opensim_table import read_table, write_table


def test_blocks_read_back_whole(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(opensim_table, "_BLOCK_ROWS", 1000)
    t = np.arange(3500) / 100.0
    q = np.zeros((t.size, 2, 4))
    q[:, :, 0] = np.cos(t)[:, None]
    q[:, :, 3] = np.sin(t)[:, None]
    write_table(tmp_path / "q.sto", t, ["a", "b"], q)
    table = read_table(tmp_path / "q.sto")
    np.testing.assert_allclose(table.time, t)
    np.testing.assert_allclose(table.data, q, atol=1e-9)
    angles = np.column_stack([t, 2 * t])
    write_table(tmp_path / "m.mot", t, ["x", "y"], angles)
    np.testing.assert_allclose(read_table(tmp_path / "m.mot").data, angles, atol=1e-9)


def test_a_bad_row_in_a_later_block_is_named(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(opensim_table, "_BLOCK_ROWS", 100)
    t = np.arange(250) / 100.0
    write_table(tmp_path / "m.mot", t, ["x"], t[:, None])
    lines = (tmp_path / "m.mot").read_text().splitlines()
    first = lines.index("time\tx") + 1
    lines[first + 230] = "2.3\tnot-a-number"
    (tmp_path / "m.mot").write_text("\n".join(lines) + "\n")
    with pytest.raises(FileFormatError, match="row 230"):
        read_table(tmp_path / "m.mot")
