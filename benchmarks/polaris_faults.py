"""Faults injected into BROAD trials: how fast ``polaris`` and VQF come back, side by side.

    python -m benchmarks.polaris_faults [--data ../shared/data/broad] [--heldout DIR]
                                        [--write-docs]

Every fault of :mod:`mocapkit.imu.fault_injection` (and sizes from the issue: saturation
bursts 10-200 ms at 2000 deg/s, clock jumps and lost samples 0.1-5 s, duplicated and
backwards stamps, magnetometer dropouts and spikes, 16 g impacts) is put 20 s into every
trial. Both filters run 9D online with their defaults (``polaris`` told the gyroscope's
range, as a user who knows the sensor would; VQF has no such parameter and no time
stamps: it sees the samples only). The figure is the angle [deg] between the faulted
run's estimate and the same filter's unfaulted run, averaged over 1 s at 10, 30 and 60 s
after the fault ended, and each run's total error to the optical truth over its last
20 s. Target (issue 11): within 1 deg of the unfaulted run within 30 s, never slower
than VQF. Stamps that go backwards or repeat are refused by ``polaris`` with an error
naming the sample (counted as "refused").
"""

from __future__ import annotations

import argparse
import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks._docs import write_section
from benchmarks.polaris_vs_vqf import DEFAULT_DATA, _vqf
from mocapkit.errors import DataError
from mocapkit.imu.fault_injection import DEFAULT_GYR_RANGE, Faulted, inject
from mocapkit.imu.filters import Polaris
from mocapkit.imu.metrics import error_quat_world, total_error
from mocapkit.io.broad import BroadTrial, list_broad_trials, read_broad_trial

FAULTS: tuple[tuple[str, float], ...] = (
    ("gyr_saturation", 0.01),
    ("gyr_saturation", 0.05),
    ("gyr_saturation", 0.2),
    ("time_jump", 0.1),
    ("time_jump", 1.0),
    ("time_jump", 5.0),
    ("missing", 0.1),
    ("missing", 1.0),
    ("missing", 5.0),
    ("duplicate_stamp", 0.0),
    ("backwards_stamp", 0.0),
    ("mag_dropout", 1.0),
    ("mag_spike", 1.0),
    ("acc_impact", 0.02),
)
FAULT_AT_S = 20.0
AFTER_S = (10.0, 30.0, 60.0)
LAST_S = 20.0


@dataclass
class Outcome:
    """One filter on one faulted trial: deviation [deg] at each of AFTER_S (NaN past the
    end), error to truth over the last LAST_S [deg], or ``refused`` with the message."""

    after: list[float]
    last: float
    refused: str = ""


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(total_error(error_quat_world(a, b)))


def _polaris(t: BroadTrial, f: Faulted | None) -> np.ndarray:
    filt = Polaris(rate_hz=t.rate_hz, gyr_range=DEFAULT_GYR_RANGE)
    imu = t.imu
    if f is None:
        return filt.run(imu.gyr, imu.acc, imu.mag)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the gap and saturation warnings are expected
        return filt.run(f.gyr, f.acc, f.mag, dt=f.dt)


def _vqf_run(t: BroadTrial, f: Faulted | None) -> np.ndarray:
    vqf = _vqf()
    imu = t.imu
    g, a, m = (imu.gyr, imu.acc, imu.mag) if f is None else (f.gyr, f.acc, f.mag)
    m = np.where(np.isnan(m), 0.0, m)  # VQF skips an all-zero magnetometer sample
    out = vqf.VQF(1.0 / t.rate_hz).updateBatch(
        np.ascontiguousarray(g), np.ascontiguousarray(a), np.ascontiguousarray(m)
    )
    return np.asarray(out["quat9D"])


def _outcome(t: BroadTrial, f: Faulted, q: np.ndarray, clean: np.ndarray) -> Outcome:
    rate = t.rate_hz
    n = clean.shape[0]
    row_of = np.full(n, -1)
    row_of[f.source] = np.arange(f.source.size)
    end_src = int(f.source[min(f.end, f.source.size - 1)])
    after = []
    for s in AFTER_S:
        lo, hi = end_src + round(s * rate), end_src + round((s + 1.0) * rate)
        if hi > n:
            after.append(math.nan)
            continue
        src = np.arange(lo, hi)
        rows = row_of[src]
        ok = rows >= 0
        after.append(float(np.mean(_angle(q[rows[ok]], clean[src[ok]]))))
    ref = t.reference.quat
    tail = f.source >= n - round(LAST_S * rate)
    fine = tail & np.isfinite(ref[f.source]).all(axis=1)
    e = _angle(q[fine], ref[f.source[fine]])
    return Outcome(after, float(np.sqrt(np.mean(e * e))))


def run_trial(t: BroadTrial) -> dict[tuple[str, float], dict[str, Outcome]]:
    imu = t.imu
    clean = {"polaris": _polaris(t, None), "vqf": _vqf_run(t, None)}
    at = round(FAULT_AT_S * t.rate_hz)
    out: dict[tuple[str, float], dict[str, Outcome]] = {}
    for kind, size in FAULTS:
        f = inject(kind, imu.time, imu.gyr, imu.acc, imu.mag, at, size)
        row: dict[str, Outcome] = {}
        try:
            row["polaris"] = _outcome(t, f, _polaris(t, f), clean["polaris"])
        except DataError as exc:
            row["polaris"] = Outcome([math.nan] * len(AFTER_S), math.nan, str(exc))
        row["vqf"] = _outcome(t, f, _vqf_run(t, f), clean["vqf"])
        out[(kind, size)] = row
    return out


def _fmt(values: list[float]) -> str:
    v = np.asarray([x for x in values if math.isfinite(x)])
    if v.size == 0:
        return "-"
    return f"{np.median(v):.2f} / {v.max():.2f}"


def table(results: dict[str, dict[tuple[str, float], dict[str, Outcome]]]) -> str:
    """Markdown: per fault, median / max over trials of the deviation at each delay."""
    n_trials = len(results)
    head = " | ".join(f"+{s:.0f} s polaris | +{s:.0f} s vqf" for s in AFTER_S)
    lines = [
        f"| fault | size | {head} | within 1 deg at +30 s (polaris / vqf) "
        "| last 20 s error to truth (polaris / vqf) |",
        "|---|---:|" + "---:|" * (2 * len(AFTER_S)) + "---:|---:|",
    ]
    for kind, size in FAULTS:
        rows = [r[(kind, size)] for r in results.values()]
        refused = [r["polaris"].refused for r in rows if r["polaris"].refused]
        if len(refused) == len(rows):
            lines.append(
                f"| {kind} | {size:g} s | polaris refuses it on all {n_trials} trials: "
                f"`{refused[0][:90]}...` |" + " |" * (2 * len(AFTER_S))
            )
            continue
        cells = []
        for i in range(len(AFTER_S)):
            for name in ("polaris", "vqf"):
                cells.append(_fmt([r[name].after[i] for r in rows]))
        within = [sum(1 for r in rows if r[nm].after[1] <= 1.0) for nm in ("polaris", "vqf")]
        last = [float(np.mean([r[nm].last for r in rows])) for nm in ("polaris", "vqf")]
        lines.append(
            f"| {kind} | {size:g} s | "
            + " | ".join(cells)
            + f" | {within[0]}/{n_trials} / {within[1]}/{n_trials}"
            + f" | {last[0]:.2f} / {last[1]:.2f} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--heldout", type=Path, help="more BROAD trials (never tuned on)")
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    paths = list_broad_trials(args.data)
    if args.heldout:
        paths += list_broad_trials(args.heldout)
    results = {}
    for p in paths:
        trial = read_broad_trial(p)
        results[trial.name] = run_trial(trial)
        print(f"{trial.name}: done", flush=True)
    cmd = "python -m benchmarks.polaris_faults" + (" --heldout DIR" if args.heldout else "")
    text = (
        f"`{cmd}` ({len(results)} BROAD trials: the 8 in ../shared"
        + (f" and {len(results) - 8} held out" if args.heldout else "")
        + f"; each fault {FAULT_AT_S:.0f} s in). Angle [deg] between the faulted and the "
        "unfaulted run of the same filter, 9D online, mean over 1 s at 10/30/60 s after the "
        "fault: median / worst trial; a dash where the trials are too short.\n\n" + table(results)
    )
    print(text)
    if args.write_docs:
        write_section("Polaris after faults (beside VQF)", text)


if __name__ == "__main__":
    main()
