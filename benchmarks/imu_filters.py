"""Orientation filters on the BROAD trials: every registered mocapkit filter and the
peers, side by side in one run, with BROAD's metric.

    python -m benchmarks.imu_filters [--data ../shared/data/broad] [--no-write] [--quick]

Writes the table and the command into the ``## Inertial orientation`` section of
docs/benchmarks.md. Peers (the ``bench`` extra, never imported by the library):

- vqf: ``VQF.updateBatch`` (online; one call gives 6D and 9D) and ``offlineVQF``;
- imufusion 1.3.3: ENU set as an attribute after construction (the constructor
  argument is ignored), deg/s and g as it expects, per-sample ``update`` calls;
- ahrs: Madgwick (NWU output, turned into ENU) and Mahony (ENU), batch mode with
  their defaults; and Madgwick with BROAD's tuned gain (beta 0.12, the value BROAD's
  grid search chose over all 39 trials), started like BROAD's example code from the
  first sample's accelerometer and magnetometer, per-sample ``updateMARG`` (the batch
  mode ignores ``q0`` in 9D). Its per-trial errors are checked against BROAD's
  published ones.

Throughput is samples / wall time of the calls that produce the quaternions, one
thread, compilation excluded (our kernels are warmed up first); Python-loop peers
include their loop. ``--quick`` skips the slow pure-Python ahrs peers.
"""

from __future__ import annotations

import argparse
import platform
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.geometry import quat_from_axis_angle, quat_mul
from mocapkit.imu.calibration import calibrate_from_rest, remove_gyro_bias
from mocapkit.imu.evaluation import evaluate_trial, warm_up
from mocapkit.imu.filters import available_filters
from mocapkit.imu.initialisation import initial_orientation
from mocapkit.imu.metrics import orientation_rmse
from mocapkit.io.broad import BroadTrial, list_broad_trials, read_broad_trial

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "broad"
Q_ENU_NWU = quat_from_axis_angle([0.0, 0.0, 1.0], np.pi / 2)
# BROAD's published Madgwick results at beta = 0.12 (example_code/out/
# results_madgwick_average_rmse.json of github.com/dlaidig/broad), total RMSE [deg].
BROAD_MADGWICK_012 = {
    "02_undisturbed_slow_rotation_B": 1.4968,
    "07_undisturbed_fast_rotation_B": 4.9963,
    "11_undisturbed_slow_translation_B": 4.2409,
    "16_undisturbed_fast_translation_B": 4.8248,
    "24_disturbed_tapping_A": 1.7684,
    "27_disturbed_phone_vibration_B": 10.6170,
    "30_disturbed_stationary_magnet_C": 5.5660,
    "33_disturbed_attached_magnet_2cm": 7.0876,
}

# A runner: (trial, mode) -> (q (N, 4) ENU, seconds); mode "both" returns a dict.
Runner = Callable[[BroadTrial, str], tuple[np.ndarray, float]]


@dataclass
class Row:
    name: str
    e9: list[dict[str, float]]
    e6: list[dict[str, float]]
    samples: int = 0
    seconds: float = 0.0
    note: str = ""

    def mean(self, mode: str, key: str) -> float:
        rows = self.e9 if mode == "9d" else self.e6
        return float(np.mean([r[key] for r in rows])) if rows else float("nan")


def _arrays(trial: BroadTrial) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    imu = trial.imu
    return (
        np.ascontiguousarray(imu.gyr),
        np.ascontiguousarray(imu.acc),
        np.ascontiguousarray(imu.mag),
    )


def _errors(trial: BroadTrial, q: np.ndarray, mode: str) -> dict[str, float]:
    e = orientation_rmse(q, trial.reference.quat, trial.movement, align_heading=mode == "6d")
    return e.as_degrees()


def _ours(name: str, prepare: Any = None) -> Callable[[BroadTrial, str], tuple[np.ndarray, float]]:
    def run(trial: BroadTrial, mode: str) -> tuple[np.ndarray, float]:
        result, q = evaluate_trial(trial, name, mode, prepare=prepare)  # type: ignore[arg-type]
        return q, result.seconds

    return run


def _rest_bias(trial: BroadTrial) -> Any:
    return remove_gyro_bias(trial.imu, calibrate_from_rest(trial.imu, use_mag=False).gyr_bias)


def _vqf_online(trial: BroadTrial) -> tuple[dict[str, np.ndarray], float]:
    import vqf

    gyr, acc, mag = _arrays(trial)
    start = time.perf_counter()
    out = vqf.VQF(1.0 / trial.rate_hz).updateBatch(gyr, acc, mag)
    return {"9d": out["quat9D"], "6d": out["quat6D"]}, time.perf_counter() - start


def _vqf_offline(trial: BroadTrial) -> tuple[dict[str, np.ndarray], float]:
    import vqf

    gyr, acc, mag = _arrays(trial)
    start = time.perf_counter()
    out = vqf.offlineVQF(gyr, acc, mag, 1.0 / trial.rate_hz)
    return {"9d": out["quat9D"], "6d": out["quat6D"]}, time.perf_counter() - start


def _imufusion(trial: BroadTrial, mode: str) -> tuple[np.ndarray, float]:
    import imufusion

    gyr, acc, mag = _arrays(trial)
    gyr_deg = np.degrees(gyr)
    acc_g = acc / 9.81
    ahrs = imufusion.Ahrs()
    settings = imufusion.AhrsSettings()
    settings.convention = imufusion.CONVENTION_ENU  # the constructor argument is ignored
    settings.sample_rate = round(trial.rate_hz)
    ahrs.set_settings(settings)
    ahrs.set_sample_period(1.0 / trial.rate_hz)
    q = np.empty((len(gyr), 4))
    start = time.perf_counter()
    if mode == "9d":
        for i in range(len(gyr)):
            ahrs.update(gyr_deg[i], acc_g[i], mag[i])
            q[i] = ahrs.get_quaternion()
    else:
        for i in range(len(gyr)):
            ahrs.update_no_magnetometer(gyr_deg[i], acc_g[i])
            q[i] = ahrs.get_quaternion()
    return q, time.perf_counter() - start


def _ahrs_madgwick(trial: BroadTrial, mode: str) -> tuple[np.ndarray, float]:
    from ahrs.filters import Madgwick

    gyr, acc, mag = _arrays(trial)
    start = time.perf_counter()
    f = Madgwick(gyr=gyr, acc=acc, mag=mag if mode == "9d" else None, frequency=trial.rate_hz)
    seconds = time.perf_counter() - start
    return quat_mul(Q_ENU_NWU, f.Q), seconds  # NWU -> ENU


def _ahrs_mahony(trial: BroadTrial, mode: str) -> tuple[np.ndarray, float]:
    from ahrs.filters import Mahony

    gyr, acc, mag = _arrays(trial)
    start = time.perf_counter()
    f = Mahony(gyr=gyr, acc=acc, mag=mag if mode == "9d" else None, frequency=trial.rate_hz)
    return np.asarray(f.Q), time.perf_counter() - start  # already ENU


def _madgwick_broad_gain(trial: BroadTrial, mode: str) -> tuple[np.ndarray, float]:
    from ahrs.filters import Madgwick

    gyr, acc, mag = _arrays(trial)
    f = Madgwick(frequency=trial.rate_hz, gain=0.12)
    # BROAD starts from the first sample's accelerometer and magnetometer (NWU frame)
    q = quat_mul(
        np.array([np.cos(np.pi / 4), 0.0, 0.0, -np.sin(np.pi / 4)]),
        initial_orientation(acc[0], mag[0]),
    )
    out = np.empty((len(gyr), 4))
    start = time.perf_counter()
    for i in range(len(gyr)):
        q = f.updateMARG(q, gyr[i], acc[i], mag[i])
        out[i] = q
    return quat_mul(Q_ENU_NWU, out), time.perf_counter() - start


def _progress(row: Row) -> None:
    total, incl = row.mean("9d", "total_deg"), row.mean("6d", "inclination_deg")
    print(f"  {row.name}: 9D {total:.3f}, 6D inclination {incl:.3f}", flush=True)


def run_all(trials: list[BroadTrial], quick: bool) -> list[Row]:
    rows: list[Row] = []
    n_total = sum(t.imu.n_samples for t in trials)

    def per_mode(
        name: str, runner: Runner, modes: tuple[str, ...] = ("9d", "6d"), note: str = ""
    ) -> None:
        row = Row(name, [], [], note=note)
        for mode in modes:
            seconds = 0.0
            for t in trials:
                q, s = runner(t, mode)
                seconds += s
                (row.e9 if mode == "9d" else row.e6).append(_errors(t, q, mode))
            if mode == "9d" or len(modes) == 1:
                row.samples, row.seconds = n_total, seconds
        rows.append(row)
        _progress(row)

    def both_modes(
        name: str, fn: Callable[[BroadTrial], tuple[dict[str, np.ndarray], float]]
    ) -> None:
        row = Row(name, [], [], note="one call gives 6D and 9D")
        for t in trials:
            out, s = fn(t)
            row.seconds += s
            row.e9.append(_errors(t, out["9d"], "9d"))
            row.e6.append(_errors(t, out["6d"], "6d"))
        row.samples = n_total
        rows.append(row)
        _progress(row)

    for name in available_filters():
        warm_up(name)
        per_mode(f"mocapkit {name}", _ours(name))
    for name in ("miller", "bachmann"):
        per_mode(
            f"mocapkit {name} + rest gyro bias",
            _ours(name, _rest_bias),
            note="bias from the first rest period",
        )
    both_modes("vqf online", _vqf_online)
    both_modes("vqf offline", _vqf_offline)
    per_mode("imufusion (ENU, defaults)", _imufusion)
    if not quick:
        per_mode("ahrs Madgwick (defaults)", _ahrs_madgwick)
        per_mode("ahrs Mahony (defaults)", _ahrs_mahony)
        per_mode("Madgwick, BROAD's gain 0.12 (ahrs)", _madgwick_broad_gain, modes=("9d",))
    return rows


def table(rows: list[Row], trials: list[BroadTrial]) -> str:
    lines = [
        "| filter | 9D total | 9D heading | 9D inclination | 6D inclination "
        "| 6D total (heading-aligned) | samples/s |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        rate = r.samples / r.seconds if r.seconds > 0 else float("nan")
        cells = [
            r.mean("9d", "total_deg"),
            r.mean("9d", "heading_deg"),
            r.mean("9d", "inclination_deg"),
            r.mean("6d", "inclination_deg"),
            r.mean("6d", "total_deg"),
        ]
        text = " | ".join("n/a" if np.isnan(c) else f"{c:.3f}" for c in cells)
        lines.append(f"| {r.name} | {text} | {rate:,.0f} |")
    lines.append("")
    lines.append("Per trial, 9D total RMSE [deg]:")
    lines.append("")
    lines.append("| filter | " + " | ".join(t.name.split("_")[0] for t in trials) + " |")
    lines.append("|---|" + "---|" * len(trials))
    for r in rows:
        lines.append(f"| {r.name} | " + " | ".join(f"{e['total_deg']:.2f}" for e in r.e9) + " |")
    return "\n".join(lines)


def write_section(text: str) -> Path:
    path = REPO / "docs" / "benchmarks.md"
    heading = "## Inertial orientation"
    content = (
        path.read_text()
        if path.exists()
        else "# Benchmarks\n\nMeasured figures against peers, with the commands behind them.\n"
    )
    section = f"{heading}\n\n{text}\n"
    if heading in content:
        start = content.index(heading)
        nxt = content.find("\n## ", start + len(heading))
        content = content[:start] + section + (content[nxt + 1 :] if nxt >= 0 else "")
    else:
        content = content.rstrip("\n") + "\n\n" + section
    path.write_text(content)
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--no-write", action="store_true", help="print only")
    parser.add_argument("--quick", action="store_true", help="skip the slow ahrs peers")
    args = parser.parse_args()
    trials = [read_broad_trial(p) for p in list_broad_trials(args.data)]
    print(f"{len(trials)} trials, {sum(t.imu.n_samples for t in trials)} samples", flush=True)
    rows = run_all(trials, args.quick)
    madgwick = next((r for r in rows if r.name.startswith("Madgwick, BROAD")), None)
    check = ""
    if madgwick is not None:
        pairs = [
            (e["total_deg"], BROAD_MADGWICK_012[t.name])
            for e, t in zip(madgwick.e9, trials, strict=True)
            if t.name in BROAD_MADGWICK_012
        ]
        ours = np.mean([p[0] for p in pairs])
        published = np.mean([p[1] for p in pairs])
        worst = max(abs(p[0] - p[1]) for p in pairs)
        check = (
            f"Madgwick at BROAD's gain (beta 0.12) through ahrs gives {ours:.3f} deg on these "
            f"{len(pairs)} trials where BROAD published {published:.3f} deg (per trial up to "
            f"{worst:.2f} deg apart, largest on the disturbed trials): not an exact "
            "reproduction. BROAD ran Madgwick's single-precision C code; ahrs is a "
            "double-precision Python port, started here the way BROAD starts it."
        )
    body = table(rows, trials)
    text = (
        f"Command: `python -m benchmarks.imu_filters` (the `bench` extra installed), on the "
        f"{len(trials)} BROAD trials in `../shared/data/broad`; errors in degrees, RMS over the "
        "movement phases, mean over the trials (BROAD's metric, `mocapkit.imu.metrics`). "
        f"Measured on {platform.machine()} / Python {platform.python_version()}, 2 cores shared "
        "with other jobs: throughput figures are provisional.\n\n"
        + body
        + ("\n\n" + check if check else "")
        + "\n\nmiller and bachmann are the seed paper's filter and its comparison, implemented as "
        "written (no gyroscope-bias estimation, no disturbance rejection): they are here to be "
        "reported honestly, not to win. '+ rest gyro bias' subtracts the bias measured over "
        "each trial's first rest period (`mocapkit.imu.calibration`) before filtering. Gains: "
        "miller alpha 0.11 and bachmann alpha 0.16 [1/s], chosen by `python -m "
        "benchmarks.tune_gains` (leave-one-out figures in docs/imu.md)."
    )
    print(text)
    if not args.no_write:
        print(f"written to {write_section(text)}")


if __name__ == "__main__":
    main()
