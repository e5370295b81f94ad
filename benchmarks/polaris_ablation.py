"""What each part of ``polaris`` buys on BROAD: switch one off at a time.

    python -m benchmarks.polaris_ablation [--data ../shared/data/broad]

Every row is the online filter with its defaults except for the one change named;
errors with BROAD's metric, means over the trials (9D total RMSE, 6D inclination RMSE,
degrees), and the 9D error per trial.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mocapkit.imu.filters import Polaris
from mocapkit.imu.metrics import orientation_rmse
from mocapkit.io.broad import BroadTrial, list_broad_trials, read_broad_trial

DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "broad"
# BROAD's magnetometer latency, estimated from the IMU data alone
# (python -c "...estimate_mag_delay(...)" gives 4 samples on 6 of the 8 trials).
DELAY_S = 4 / 285.714

ABLATIONS: dict[str, dict[str, float]] = {
    "polaris (all parts)": {},
    "no lag model in the tilt measurement": {"lag_compensation": False},
    "no rest detection": {"rest_min_time": 1e9},
    "no bias estimation (rest or motion)": {
        "rest_min_time": 1e9,
        "bias_sigma_init": 1e-12,
        "bias_process": 0.0,
    },
    "no hard-iron re-learning": {"mag_reset_time": 1e9},
    "no magnetic gate (and no re-learning)": {"mag_gate": 1e6},
    "no magnetometer timing noise": {"mag_timing_sigma_s": 0.0},
    "delay compensated instead (14 ms, from the IMU data), timing noise 2 ms": {
        "mag_delay_s": DELAY_S,
        "mag_timing_sigma_s": 0.002,
    },
}


def errors(trial: BroadTrial, params: dict[str, float], offline: bool) -> tuple[float, float]:
    f = Polaris(rate_hz=trial.rate_hz, **params)
    imu = trial.imu
    if offline:
        sm = f.smooth(imu.gyr, imu.acc, imu.mag)
        assert sm.q9 is not None
        q9, q6 = sm.q9, sm.q6
    else:
        q9, q6 = f.run_both(imu.gyr, imu.acc, imu.mag)
    e9 = orientation_rmse(q9, trial.reference.quat, trial.movement)
    e6 = orientation_rmse(q6, trial.reference.quat, trial.movement, align_heading=True)
    return math.degrees(e9.total), math.degrees(e6.inclination)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    args = parser.parse_args()
    trials = [read_broad_trial(p) for p in list_broad_trials(args.data)]
    short = [t.name[:2] for t in trials]
    print("| variant | mode | mean 9D total | mean 6D incl. | 9D per trial (" + " ".join(short)
          + ") |\n|---|---|---:|---:|---|")  # fmt: skip
    for offline in (False, True):
        rows = ABLATIONS if not offline else {"polaris (all parts)": {}}
        for label, change in rows.items():
            params = dict(change)
            res = np.array([errors(t, params, offline) for t in trials])
            per = " ".join(f"{v:.2f}" for v in res[:, 0])
            mode = "offline" if offline else "online"
            print(f"| {label} | {mode} | {res[:, 0].mean():.3f} | {res[:, 1].mean():.3f} "
                  f"| {per} |")  # fmt: skip


if __name__ == "__main__":
    main()
