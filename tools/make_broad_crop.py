"""Cut the bundled demo recording out of a BROAD trial (run once; the result is
committed as src/mocapkit/data/broad/07_undisturbed_fast_rotation_B_crop.npz).

    .venv/bin/python tools/make_broad_crop.py ../shared/data/broad/07_undisturbed_fast_rotation_B.hdf5

The crop starts 5 s before the first movement sample (the sensor at rest) and lasts
30 s. Arrays are copied unchanged (float64), so figures on the crop can be reproduced
from the original file by slicing ``start:start + n``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from mocapkit.io.broad import read_broad_trial

OUT = Path(__file__).resolve().parents[1] / "src" / "mocapkit" / "data" / "broad"


def main(path: str, before_s: float = 5.0, duration_s: float = 30.0) -> Path:
    trial = read_broad_trial(path)
    rate = trial.rate_hz
    start = int(np.flatnonzero(trial.movement)[0]) - round(before_s * rate)
    n = round(duration_s * rate)
    sl = slice(start, start + n)
    out = OUT / f"{trial.name}_crop.npz"
    np.savez_compressed(
        out,
        imu_gyr=trial.imu.gyr[sl],
        imu_acc=trial.imu.acc[sl],
        imu_mag=trial.imu.mag[sl],
        opt_quat=trial.reference.quat[sl],
        movement=trial.movement[sl],
        sampling_rate=np.float64(rate),
        source_trial=np.str_(trial.name),
        source_start=np.int64(start),
    )
    return out


if __name__ == "__main__":
    print(main(sys.argv[1]))
