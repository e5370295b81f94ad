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
    with pytest.raises(FileFormatError, match=r"no .hdf5 or .mat files found"):
        list_broad_trials(tmp_path / "..")
    bad_mat = tmp_path / "y.mat"
    bad_mat.write_text("not mat")
    with pytest.raises(FileFormatError, match="not a readable MATLAB .mat file"):
        read_broad_trial(bad_mat)


def test_mat_trial_equals_hdf5_trial(shared_data: Path, tmp_path: Path) -> None:
    # BROAD ships every trial as data_mat/*.mat too (some only there): the same arrays
    import scipy.io

    src = read_broad_trial(shared_data / "broad" / "24_disturbed_tapping_A.hdf5")
    mat = tmp_path / "24_disturbed_tapping_A.mat"
    scipy.io.savemat(
        mat,
        {
            "imu_gyr": src.imu.gyr,
            "imu_acc": src.imu.acc,
            "imu_mag": src.imu.mag,
            "opt_quat": src.reference.quat,
            "opt_pos": src.position,
            "movement": src.movement.astype(np.uint8)[:, None],
            "sampling_rate": np.array([[src.rate_hz]]),
        },
    )
    got = read_broad_trial(mat)
    assert got.name == src.name
    assert got.rate_hz == src.rate_hz
    np.testing.assert_array_equal(got.imu.gyr, src.imu.gyr)
    np.testing.assert_allclose(got.reference.quat, src.reference.quat, atol=1e-12)
    np.testing.assert_array_equal(got.movement, src.movement)
    assert list_broad_trials(tmp_path) == [mat]
    scipy.io.savemat(tmp_path / "z.mat", {"imu_gyr": src.imu.gyr})
    with pytest.raises(FileFormatError, match="missing variable"):
        read_broad_trial(tmp_path / "z.mat")
