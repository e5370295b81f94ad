"""The bundled BROAD crop is an unchanged slice of the original trial."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import FileFormatError
from mocapkit.io.broad import bundled_demo_trial, read_broad_crop, read_broad_trial


@pytest.mark.shared_data
def test_crop_equals_the_original_slice(shared_data: Path) -> None:
    crop = bundled_demo_trial()
    full = read_broad_trial(shared_data / "broad" / "07_undisturbed_fast_rotation_B.hdf5")
    start = int(crop.imu.meta["source_start"])
    sl = slice(start, start + crop.imu.n_samples)
    np.testing.assert_array_equal(crop.imu.gyr, full.imu.gyr[sl])
    np.testing.assert_array_equal(crop.imu.mag, full.imu.mag[sl])
    np.testing.assert_array_equal(crop.movement, full.movement[sl])
    np.testing.assert_allclose(crop.imu.time, full.imu.time[sl], rtol=0, atol=1e-9)


def test_crop_errors(tmp_path: Path) -> None:
    bad = tmp_path / "x.npz"
    np.savez(bad, imu_gyr=np.zeros((3, 3)))
    with pytest.raises(FileFormatError, match=r"missing array\(s\) imu_acc, imu_mag"):
        read_broad_crop(bad)
    (tmp_path / "y.npz").write_text("not a zip")
    with pytest.raises(FileFormatError, match="not a readable .npz file"):
        read_broad_crop(tmp_path / "y.npz")
