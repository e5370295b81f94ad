"""What we write for OpenSim, read by OpenSim itself (skipped without it, required in CI)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.io.opensim_table import read_table, write_table
from tests.conftest import require_peer


def _gappy_table() -> tuple[np.ndarray, list[str], np.ndarray]:
    t = np.arange(40) / 100.0
    data = np.column_stack([np.sin(t * 7.0) * 30.0, np.cos(t * 3.0) * 10.0, t * 2.0])
    data[3] = np.nan  # a whole row undetermined (the row OpenSim's Storage used to stop at)
    data[10:15, 1] = np.nan  # a gap in one column
    data[-1, 2] = np.nan  # the last cell
    return t, ["knee_angle_r", "hip_flexion_r", "pelvis_tx"], data


@pytest.mark.parametrize("suffix", [".mot", ".sto"])
def test_gaps_read_in_full_by_storage_and_time_series_table(tmp_path: Path, suffix: str) -> None:
    osim = require_peer("opensim")
    osim.Logger.setLevelString("error")
    t, labels, data = _gappy_table()
    p = write_table(tmp_path / f"gaps{suffix}", t, labels, data, in_degrees=True)
    storage = osim.Storage(str(p))  # what the GUI's File > Load Motion uses
    assert storage.getSize() == len(t)
    assert storage.isInDegrees()
    table = osim.TimeSeriesTable(str(p))
    assert table.getNumRows() == len(t)
    for k, label in enumerate(labels):
        col = osim.ArrayDouble()
        storage.getDataColumn(label, col)
        from_storage = np.array([col.get(i) for i in range(col.size())])
        from_table = table.getDependentColumn(label).to_numpy()
        for got in (from_storage, from_table):
            np.testing.assert_array_equal(np.isnan(got), np.isnan(data[:, k]))
            fin = ~np.isnan(data[:, k])
            # %.10g text: 1e-8 relative
            np.testing.assert_allclose(got[fin], data[fin, k], rtol=1e-9, atol=1e-12)
    ours = read_table(p)
    np.testing.assert_array_equal(np.isnan(ours.data), np.isnan(data))
