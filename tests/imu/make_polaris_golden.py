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
START_S = 44.0  # 1 s at rest, then the sensor is moved and tapped
N = 800
EVERY = 4  # outputs stored every 4th sample (keeps the file small)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    args = parser.parse_args()
    t = read_broad_trial(args.data / "24_disturbed_tapping_A.hdf5")
    r = t.rate_hz
    sl = slice(int(START_S * r), int(START_S * r) + N)
    gyr, acc, mag = (np.ascontiguousarray(x[sl]) for x in (t.imu.gyr, t.imu.acc, t.imu.mag))
    f = Polaris(rate_hz=r)
    q9, q6 = f.run_both(gyr, acc, mag)
    q9_off = f.smooth(gyr, acc, mag).q9
    assert q9_off is not None
    np.savez_compressed(OUT, rate_hz=r, every=EVERY, gyr=gyr, acc=acc, mag=mag,
                        q9=q9[::EVERY], q6=q6[::EVERY], q9_offline=q9_off[::EVERY])  # fmt: skip
    print(f"wrote {OUT} ({OUT.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
