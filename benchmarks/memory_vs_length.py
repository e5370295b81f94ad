"""Time and peak memory of whole commands against recording length (issue 16).

    python -m benchmarks.memory_vs_length [--minutes 1 10 60] [--write-docs]

A one-sensor IMU recording at 100 Hz (a mocapkit CSV of a smooth motion with
consumer-grade noise) of each length is run through ``mocapkit imu run --filter
polaris`` online and ``--offline``, as whole processes; reported: wall time and the
child's peak resident memory (``getrusage(RUSAGE_CHILDREN)``, the maximum of the run
that just finished, each run in its own fresh parent so the maximum is that run's).
Target (issue 16): peak memory within 2x from 1 min to 1 h. ``--format hdf5`` writes the
same samples as a BROAD ``.hdf5`` trial instead (read piece by piece through h5py).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from benchmarks._docs import write_section

_MEASURE = """
import resource, subprocess, sys, time, json
t0 = time.perf_counter()
subprocess.run(sys.argv[1:], check=True, capture_output=True)
print(json.dumps({"seconds": time.perf_counter() - t0,
                  "peak_mb": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024}))
"""


def make_recording(path: Path, minutes: float, rate: float = 100.0) -> None:
    """A CSV, or a BROAD-like .hdf5 when ``path`` ends so."""
    from mocapkit.io.imu_csv import write_imu_csv
    from mocapkit.series import ImuRecording

    n = round(minutes * 60 * rate)
    t = np.arange(n) / rate
    rng = np.random.default_rng(0)
    gyr = np.column_stack([np.sin(0.7 * t), np.sin(1.1 * t), np.sin(0.3 * t)])
    gyr = gyr + 0.01 * rng.normal(size=(n, 3))
    acc = np.tile([0.0, 0.0, 9.81], (n, 1)) + 0.05 * rng.normal(size=(n, 3))
    mag = np.tile([0.0, 20.0, -40.0], (n, 1)) + 0.3 * rng.normal(size=(n, 3))
    if path.suffix == ".hdf5":
        import h5py

        with h5py.File(path, "w") as f:
            f.attrs["sampling_rate"] = rate
            f["imu_gyr"], f["imu_acc"], f["imu_mag"] = gyr, acc, mag
            f["opt_quat"] = np.full((n, 4), np.nan)
            f["movement"] = np.ones(n, dtype=bool)
        return
    write_imu_csv(path, ImuRecording(t, gyr, acc, mag, name="s"))


def measure(argv: list[str]) -> dict[str, float]:
    out = subprocess.run(
        [sys.executable, "-c", _MEASURE, *argv], capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout)  # type: ignore[no-any-return]


def length_report(
    rows: list[tuple[float, int, dict[str, float]]],
    command: str,
    setup: str,
    section: str,
    write_docs: bool,
    count_label: str = "frames",
    count_cell: Callable[[int], str] = str,
    rate: bool = True,
) -> str:
    """The table of a run against recording length (minutes, count, whole process,
    ``count / s`` when ``rate``, peak memory), the growth from the shortest to the longest,
    printed and, with ``write_docs``, written to docs/benchmarks.md under ``section``."""
    head = ["recording", count_label, "whole process [s]", *(["frames/s"] if rate else []),
            "peak memory [MB]"]  # fmt: skip
    lines = ["| " + " | ".join(head) + " |", "|" + "---:|" * len(head)]
    for minutes, count, m in rows:
        per_s = [f"{count / m['seconds']:.0f}"] if rate else []
        cells = [f"{minutes:g} min", count_cell(count), f"{m['seconds']:.1f}", *per_s,
                 f"{m['peak_mb']:.0f}"]  # fmt: skip
        lines.append("| " + " | ".join(cells) + " |")
    growth = rows[-1][2]["peak_mb"] / rows[0][2]["peak_mb"]
    text = (
        f"`{command}` ({setup}). Peak memory from the shortest to the longest: "
        f"x{growth:.1f} (target: within x2).\n\n" + "\n".join(lines)
    )
    print(text)
    if write_docs:
        write_section(section, text)
    return text


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, nargs="+", default=[1.0, 10.0, 60.0])
    parser.add_argument("--rate", type=float, default=100.0, help="sampling rate [Hz]")
    parser.add_argument("--format", choices=("csv", "hdf5"), default="csv",
                        help="the recording as a mocapkit CSV or a BROAD .hdf5")  # fmt: skip
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    exe = [sys.executable, "-c", "from mocapkit.cli.main import run; run()"]
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for minutes in args.minutes:
            src = Path(d) / f"rec_{minutes:g}min.{args.format}"
            make_recording(src, minutes, args.rate)
            for offline in (False, True):
                out = str(Path(d) / "out.sto")
                argv = [*exe, "imu", "run", str(src), "--filter", "polaris", "-o", out]
                argv += ["--offline"] if offline else []
                m = measure(argv)
                rows.append((minutes, "offline" if offline else "online", m))
                print(minutes, offline, m, flush=True)
    lines = ["| length | mode | whole process [s] | peak memory [MB] |", "|---:|---|---:|---:|"]
    for minutes, mode, m in rows:
        lines.append(f"| {minutes:g} min | {mode} | {m['seconds']:.2f} | {m['peak_mb']:.0f} |")
    first = {mode: m["peak_mb"] for mn, mode, m in rows if mn == args.minutes[0]}
    last = {mode: m["peak_mb"] for mn, mode, m in rows if mn == args.minutes[-1]}
    growth = ", ".join(f"{mode} x{last[mode] / first[mode]:.1f}" for mode in first)
    rate_arg = f" --rate {args.rate:g}" if args.rate != 100 else ""
    rate_arg += " --format hdf5" if args.format == "hdf5" else ""
    what = "a BROAD .hdf5 trial" if args.format == "hdf5" else "a mocapkit CSV"
    text = (
        f"`python -m benchmarks.memory_vs_length{rate_arg}"
        f" --minutes {' '.join(f'{m:g}' for m in args.minutes)}` (one sensor at "
        f"{args.rate:g} Hz, {what}, `mocapkit imu run --filter polaris`, whole "
        "processes; both stream the file in pieces of 100,000 rows, offline through files "
        "on disk, ~400 bytes a sample while it runs). Peak memory from the shortest to the "
        "longest recording: "
        f"{growth} (target: within x2).\n\n" + "\n".join(lines)
    )
    print(text)
    if args.write_docs:
        heading = "Memory and time against recording length"
        heading += f", {args.rate:g} Hz" if args.rate != 100 else ""
        write_section(heading + (", BROAD .hdf5" if args.format == "hdf5" else ""), text)


if __name__ == "__main__":
    main()
