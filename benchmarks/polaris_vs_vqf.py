"""``polaris`` against VQF on BROAD, side by side: errors per trial and throughput.

    python -m benchmarks.polaris_vs_vqf [--data ../shared/data/broad] [--repeat 3]

Both filters run online (VQF: ``VQF.updateBatch``, C++) and offline (``offlineVQF``) in 9D
and 6D on every trial; errors with BROAD's metric (:mod:`mocapkit.imu.metrics`: 9D total
RMSE, 6D inclination RMSE and heading-aligned total, over the movement phases).
``polaris`` runs with its defaults, VQF with its own.

Throughput: samples per second of one thread over all trials (best of ``--repeat`` rounds,
the filters interleaved), after a warm-up run (numba compilation excluded); ``run()``
includes the common input validation of the filter base. Peers are imported here only.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from mocapkit.errors import MissingDependencyError
from mocapkit.imu.filters import Polaris
from mocapkit.imu.metrics import orientation_rmse
from mocapkit.io.broad import BroadTrial, list_broad_trials, read_broad_trial

DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "broad"


def _vqf():  # type: ignore[no-untyped-def]
    try:
        import vqf
    except ImportError as exc:
        raise MissingDependencyError("vqf is not installed: pip install 'mocapkit[bench]'") from exc
    return vqf


def _errors(q9: np.ndarray, q6: np.ndarray, trial: BroadTrial) -> tuple[float, float, float]:
    ref, mask = trial.reference.quat, trial.movement
    e9 = orientation_rmse(q9, ref, mask)
    e6 = orientation_rmse(q6, ref, mask, align_heading=True)
    return math.degrees(e9.total), math.degrees(e6.inclination), math.degrees(e6.total)


def _arrays(trial: BroadTrial) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    imu = trial.imu
    return (
        np.ascontiguousarray(imu.gyr),
        np.ascontiguousarray(imu.acc),
        np.ascontiguousarray(imu.mag),
    )


def run_polaris(trial: BroadTrial, offline: bool) -> tuple[np.ndarray, np.ndarray]:
    g, a, m = _arrays(trial)
    f = Polaris(rate_hz=trial.rate_hz)
    if offline:
        result = f.smooth(g, a, m)
        assert result.q9 is not None
        return result.q9, result.q6
    return f.run_both(g, a, m)


def run_vqf(trial: BroadTrial, offline: bool) -> tuple[np.ndarray, np.ndarray]:
    vqf = _vqf()
    g, a, m = _arrays(trial)
    dt = 1.0 / trial.rate_hz
    if offline:
        out = vqf.offlineVQF(g, a, m, dt)
        return out["quat9D"], out["quat6D"]
    out = vqf.VQF(dt).updateBatch(g, a, m)
    return out["quat9D"], out["quat6D"]


def throughputs(
    fns: dict[str, Callable[[], object]], n_samples: int, repeat: int
) -> dict[str, float]:
    """Samples per second of each function, best of ``repeat`` rounds that run every
    function once in turn (so a busy moment of the machine hits all alike); one warm-up
    call each first."""
    for fn in fns.values():
        fn()
    best = dict.fromkeys(fns, math.inf)
    for _ in range(repeat):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            best[name] = min(best[name], time.perf_counter() - t0)
    return {name: n_samples / t for name, t in best.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args()
    trials = [read_broad_trial(p) for p in list_broad_trials(args.data)]
    cols = ("polaris online", "polaris offline", "vqf online", "vqf offline")
    runners: dict[str, Callable[[BroadTrial], tuple[np.ndarray, np.ndarray]]] = {
        "polaris online": lambda t: run_polaris(t, False),
        "polaris offline": lambda t: run_polaris(t, True),
        "vqf online": lambda t: run_vqf(t, False),
        "vqf offline": lambda t: run_vqf(t, True),
    }
    table: dict[str, dict[str, tuple[float, float, float]]] = {}
    for t in trials:
        table[t.name] = {c: _errors(*runners[c](t), t) for c in cols}
    for title, idx in (
        ("9D total RMSE [deg]", 0),
        ("6D inclination RMSE [deg]", 1),
        ("6D heading-aligned total RMSE [deg]", 2),
    ):
        print(f"{title}\n\n| trial | " + " | ".join(cols) + " |")
        print("|---|" + "---:|" * len(cols))
        for name, row in table.items():
            print(f"| {name} | " + " | ".join(f"{row[c][idx]:.3f}" for c in cols) + " |")
        means = [np.mean([row[c][idx] for row in table.values()]) for c in cols]
        print("| **mean** | " + " | ".join(f"**{v:.3f}**" for v in means) + " |\n")
    n = sum(t.imu.n_samples for t in trials)
    data = [(*_arrays(t), t.rate_hz) for t in trials]
    vqf = _vqf()

    def polaris_all(mode: str) -> None:
        for g, a, m, rate in data:
            f = Polaris(rate_hz=rate)
            if mode == "9d":
                f.run(g, a, m)
            elif mode == "6d":
                f.run(g, a)
            else:
                f.smooth(g, a, m)

    def vqf_all(mode: str) -> None:
        for g, a, m, rate in data:
            if mode == "9d":
                vqf.VQF(1.0 / rate).updateBatch(g, a, m)
            elif mode == "6d":
                vqf.VQF(1.0 / rate).updateBatch(g, a)
            else:
                vqf.offlineVQF(g, a, m, 1.0 / rate)

    print("Throughput [million samples/s, one thread]\n")
    print("| filter | 9D online | 6D online | 9D offline |\n|---|---:|---:|---:|")
    fns: dict[str, Callable[[], object]] = {}
    for name, fn in (("polaris (numba)", polaris_all), ("vqf (C++)", vqf_all)):
        for mode in ("9d", "6d", "offline"):
            fns[f"{name}|{mode}"] = lambda f=fn, m=mode: f(m)  # type: ignore[misc]
    rates = throughputs(fns, n, args.repeat)
    for name in ("polaris (numba)", "vqf (C++)"):
        row = [rates[f"{name}|{mode}"] / 1e6 for mode in ("9d", "6d", "offline")]
        print(f"| {name} | " + " | ".join(f"{r:.2f}" for r in row) + " |")


if __name__ == "__main__":
    main()
