"""Regenerate tests/data/polaris_golden.npz (run deliberately, then review the diff):

python -m tests.imu.make_polaris_golden [--data ../shared/data/broad]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mocapkit.imu.filters import Polaris
from mocapkit.io.broad import read_broad_trial

OUT = Path(__file__).resolve().parents[1] / "data" / "polaris_golden.npz"
DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "broad"
START_S = 38.0  # at rest, then the tapping starts
N = 1000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    args = parser.parse_args()
    t = read_broad_trial(args.data / "24_disturbed_tapping_A.hdf5")
    r = t.rate_hz
    sl = slice(int(START_S * r), int(START_S * r) + N)
    gyr, acc, mag = (np.ascontiguousarray(x[sl]) for x in (t.imu.gyr, t.imu.acc, t.imu.mag))
    delay = 4 / 285.714
    f = Polaris(rate_hz=r, mag_delay_s=delay)
    q9, q6 = f.run_both(gyr, acc, mag)
    q9_off = f.smooth(gyr, acc, mag).q9
    np.savez_compressed(OUT, rate_hz=r, mag_delay_s=delay, gyr=gyr, acc=acc, mag=mag,
                        q9=q9, q6=q6, q9_offline=q9_off)  # fmt: skip
    print(f"wrote {OUT} ({OUT.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
