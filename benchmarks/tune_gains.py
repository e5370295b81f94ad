"""Tune the single gain ``alpha`` of the ``miller`` and ``bachmann`` filters on BROAD.

    python -m benchmarks.tune_gains [--data ../shared/data/broad]

For each filter, every trial is run for every ``alpha`` of a log-spaced grid, in 9D
and in 6D. The criterion is BROAD's primary figure, the mean 9D total RMSE. Because
the grid search sees the same 8 trials we report on, the honest estimate of the
tuned filter's error is leave-one-out: for each trial, ``alpha`` is chosen on the
other 7 and the error is taken on the held-out one. Both are printed, with the 6D
inclination at the chosen gain.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mocapkit.imu.evaluation import evaluate_trial
from mocapkit.io.broad import list_broad_trials, read_broad_trial

GRID = np.round(np.logspace(np.log10(0.02), np.log10(5.0), 17), 4)
DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "broad"


def errors_deg(trials: list, name: str, mode: str, alpha: float) -> np.ndarray:  # type: ignore[type-arg]
    """(n_trials,) total (9D) or inclination (6D) RMSE in degrees."""
    key = "total" if mode == "9d" else "inclination"
    out = []
    for t in trials:
        result, _ = evaluate_trial(t, name, mode, alpha=alpha)  # type: ignore[arg-type]
        out.append(np.degrees(getattr(result.errors, key)))
    return np.array(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--filters", nargs="+", default=["miller", "bachmann"])
    args = parser.parse_args()
    trials = [read_broad_trial(p) for p in list_broad_trials(args.data)]
    for name in args.filters:
        e9 = np.array([errors_deg(trials, name, "9d", a) for a in GRID])  # (grid, trials)
        e6 = np.array([errors_deg(trials, name, "6d", a) for a in GRID])
        print(f"\n{name}: alpha [1/s] | mean 9D total | mean 6D inclination  [deg]")
        for a, r9, r6 in zip(GRID, e9.mean(axis=1), e6.mean(axis=1), strict=True):
            print(f"  {a:8.4f} | {r9:8.3f} | {r6:8.3f}")
        best = int(np.argmin(e9.mean(axis=1)))
        loo9, loo6, picks = [], [], []
        for k in range(len(trials)):
            others = np.delete(np.arange(len(trials)), k)
            j = int(np.argmin(e9[:, others].mean(axis=1)))
            picks.append(float(GRID[j]))
            loo9.append(e9[j, k])
            loo6.append(e6[j, k])
        print(
            f"  chosen on all trials: alpha = {GRID[best]} (9D {e9[best].mean():.3f}, "
            f"6D inclination {e6[best].mean():.3f})"
        )
        print(
            f"  leave-one-out: 9D {np.mean(loo9):.3f}, 6D inclination {np.mean(loo6):.3f} "
            f"(alphas picked: {sorted(set(picks))})"
        )
        best6 = int(np.argmin(e6.mean(axis=1)))
        print(f"  (best 6D-only gain would be {GRID[best6]}: {e6[best6].mean():.3f})")


if __name__ == "__main__":
    main()
