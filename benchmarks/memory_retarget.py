"""Time and peak memory of ``mocapkit retarget`` against recording length (issue 16).

    python -m benchmarks.memory_retarget [--minutes 1 10 60] [--robot g1]
        [--source mot|trc|ximu3] [--write-docs]

OpenSim's gait2392 walk (``subject01_walk1.trc`` in ../shared), reconstructed once by
``mocapkit markers reconstruct`` into joint angles, is played forwards then backwards to
the length asked for (continuous) and written as a .mot; ``mocapkit retarget WALK.mot
--robot g1 -o OUT.csv`` (collision guard on, as by default) runs on it as a whole process.
``--source trc``: the TRC itself played to the length (``benchmarks.memory_markers``), so
the command reconstructs and retargets it. ``--source ximu3``: the 7-sensor x-IMU3
lower-body recording tiled to the length (``benchmarks.memory_ximu3``, its devices'
orientations too), retargeted with ``--preset lower_body`` through the body model.
Reported: wall time and the child's peak resident memory. Target (issue 16): within 2x
from 1 min to 1 h.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.memory_markers import long_trial
from benchmarks.memory_vs_length import length_report, measure
from benchmarks.memory_ximu3 import long_export

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
TRC = SHARED / "opensim" / "gait2392" / "subject01_walk1.trc"
CLI = [sys.executable, "-c", "from mocapkit.cli.main import run; run()"]


def long_angles(walk: Path, path: Path, minutes: float) -> int:
    """The reconstructed walk's .mot ping-ponged to ``minutes``; returns its frames."""
    from mocapkit.io.opensim_table import read_table, write_table

    table = read_table(walk)
    rate = 1.0 / float(np.median(np.diff(table.time)))
    there_and_back = np.concatenate([table.data, table.data[-2:0:-1]])
    n = round(minutes * 60.0 * rate)
    reps = -(-n // there_and_back.shape[0])
    data = np.concatenate([there_and_back] * reps)[:n]
    write_table(path, np.arange(n) / rate, table.labels, data, name="walk", in_degrees=True)
    return n


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, nargs="+", default=[1.0, 10.0, 60.0])
    parser.add_argument("--robot", default="g1")
    parser.add_argument("--source", choices=["mot", "trc", "ximu3"], default="mot")
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    if not TRC.exists():
        raise SystemExit(f"needs {TRC}")
    rows = []
    with tempfile.TemporaryDirectory() as d:
        walk = Path(d) / "walk.mot"
        if args.source == "mot":  # the angles come from our own reconstruction
            subprocess.run([*CLI, "markers", "reconstruct", str(TRC), "--height-m", "1.80",
                            "-o", str(walk)], check=True, capture_output=True)  # fmt: skip
        for minutes in args.minutes:
            src = Path(d) / f"walk_{minutes:g}min.{args.source}"
            extra = ["--height", "1.80"] if args.source == "trc" else []
            if args.source == "ximu3":
                long_export(src, minutes, ("Inertial.csv", "Quaternion.csv"))
                first = next(p for p in src.iterdir() if p.is_dir())
                with open(first / "Quaternion.csv") as f:
                    frames = sum(1 for _ in f) - 1
                extra = ["--preset", "lower_body"]
            elif args.source == "mot":
                frames = long_angles(walk, src, minutes)
            else:
                frames = long_trial(src, minutes)
            m = measure([*CLI, "retarget", str(src), "--robot", args.robot, *extra,
                         "-o", str(Path(d) / "out.csv")])  # fmt: skip
            rows.append((minutes, frames, m))
            print(minutes, frames, m, flush=True)
            if src.is_dir():
                shutil.rmtree(src)
            else:
                src.unlink()
    lengths = " ".join(f"{x:g}" for x in args.minutes)
    command = f"python -m benchmarks.memory_retarget --minutes {lengths} --robot {args.robot}"
    if args.source == "mot":
        length_report(
            rows, command,
            "OpenSim's gait2392 walk reconstructed by mocapkit, its joint angles played "
            "forwards and backwards to the length at 60 Hz; `mocapkit retarget WALK.mot "
            f"--robot {args.robot} -o OUT.csv`, collision guard on, whole processes",
            "Memory and time against recording length: retarget", args.write_docs,
        )  # fmt: skip
    elif args.source == "ximu3":
        length_report(
            rows, f"{command} --source ximu3",
            "the 7-sensor x-IMU3 lower-body recording in ../shared (18.6 s at 50 Hz) tiled "
            "to the length (`benchmarks.memory_ximu3`); `mocapkit retarget EXPORT --robot "
            f"{args.robot} --preset lower_body -o OUT.csv` (the devices' orientations "
            "through the body model, then retargeted), collision guard on, whole processes",
            "Memory and time against recording length: retarget from an x-IMU3 export",
            args.write_docs,
        )  # fmt: skip
    else:
        length_report(
            rows, f"{command} --source trc",
            "OpenSim's gait2392 walk TRC played forwards and backwards to the length at "
            f"60 Hz (`benchmarks.memory_markers`); `mocapkit retarget WALK.trc --robot "
            f"{args.robot} --height 1.80 -o OUT.csv` (reconstructed, then retargeted), "
            "collision guard on, whole processes",
            "Memory and time against recording length: retarget from markers",
            args.write_docs,
        )  # fmt: skip


if __name__ == "__main__":
    main()
