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


def test_exported_model_and_mot_reproduce_our_markers_in_opensim(
    shared_data: Path, tmp_path: Path
) -> None:
    """`markers reconstruct --osim`: OpenSim loads the model, the .mot poses it (read the
    way the GUI reads it: Storage, degrees to radians), and its markers are ours to 1 mm
    (measured ~1e-9 m: the same kinematics, %.10g text)."""
    osim = require_peer("opensim")
    osim.Logger.setLevelString("error")
    from mocapkit.cli.main import main
    from mocapkit.io.trc import read_trc

    gait = shared_data / "opensim" / "gait2392"
    mot, model_file, trc = tmp_path / "walk.mot", tmp_path / "subject.osim", tmp_path / "t.trc"
    assert main([
        "markers", "reconstruct", str(gait / "subject01_walk1.trc"), "--static",
        str(gait / "subject01_static.trc"), "--height-m", "1.8034", "--mass-kg", "72.6",
        "--end-s", "0.4", "-o", str(mot), "--osim", str(model_file), "--tracked-trc", str(trc),
    ]) == 0  # fmt: skip
    model = osim.Model(str(model_file))
    state = model.initSystem()
    storage = osim.Storage(str(mot))
    model.getSimbodyEngine().convertDegreesToRadians(storage)
    all_labels = storage.getColumnLabels()
    labels = [all_labels.get(i) for i in range(1, all_labels.size())]  # after "time"
    coords = model.getCoordinateSet()
    used = [c for c in labels if coords.contains(c)]
    assert {"knee_angle_r", "abdomen_extension", "pelvis_tx"} <= set(used)
    ours = read_trc(trc)  # the model's markers, OpenSim's y-up ground, mm
    markers = model.getMarkerSet()
    assert all(markers.contains(n) for n in ours.names)  # and the static trial's extras
    worst = 0.0
    for row in range(storage.getSize()):
        values = storage.getStateVector(row).getData()
        for k, c in enumerate(labels):
            if c in used:
                coords.get(c).setValue(state, values.get(k), False)
        model.realizePosition(state)
        for m, name in enumerate(ours.names):
            loc = markers.get(name).getLocationInGround(state)
            got = np.array([loc[0], loc[1], loc[2]])
            worst = max(worst, float(np.linalg.norm(got - ours.positions[row, m])))
    assert storage.getSize() == ours.n_frames
    assert worst < 1e-3  # the 1 mm; measured ~1e-6 m (text precision of the TRC)
