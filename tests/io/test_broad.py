"""BROAD reader on the real trials in ../shared/data/broad."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import FileFormatError
from mocapkit.io.broad import list_broad_trials, read_broad_trial


def test_reads_real_trial(shared_data: Path) -> None:
    trial = read_broad_trial(shared_data / "broad" / "02_undisturbed_slow_rotation_B.hdf5")
    assert trial.rate_hz == pytest.approx(285.714, abs=1e-3)
    assert trial.imu.has_mag
    assert trial.imu.n_samples == trial.reference.n_samples == trial.movement.shape[0]
    # at rest at the start the accelerometer reads about +g
    assert np.linalg.norm(trial.imu.acc[:100].mean(axis=0)) == pytest.approx(9.81, abs=0.1)
    assert trial.movement.any()
    assert (~trial.reference.valid).any()  # the optical reference has gaps


def test_lists_trials(shared_data: Path) -> None:
    assert len(list_broad_trials(shared_data / "broad")) == 8


def test_not_a_broad_file(tmp_path: Path) -> None:
    bad = tmp_path / "x.hdf5"
    bad.write_text("not hdf5")
    with pytest.raises(FileFormatError, match="not a readable HDF5 file"):
        read_broad_trial(bad)
    with pytest.raises(FileFormatError, match="no .hdf5 files found"):
        list_broad_trials(tmp_path / "..")
