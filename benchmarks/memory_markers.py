"""Time and peak memory of ``mocapkit markers reconstruct`` against trial length (issue 16).

    python -m benchmarks.memory_markers [--minutes 1 10 60] [--write-docs]

OpenSim's gait2392 walk (``subject01_walk1.trc`` in ../shared: 151 frames at 60 Hz) is
played forwards then backwards, again and again, to the length asked for (the markers
stay continuous: no jump where one copy meets the next), written as a TRC, and
reconstructed by ``mocapkit markers reconstruct --height-m 1.80 -o OUT.mot`` (direct
marker control, offline) as a whole process; reported: wall time and the child's peak
resident memory. Target (issue 16): within 2x from 1 min to 1 h.

``--clean`` punches a gap into one marker every 2 s (0.1-0.4 s long, so that some stay
open past the default ``--max-gap-s 0.25``) and adds ``--fill-gaps both --lowpass-hz 6``,
as labs run it. ``--method ik`` / ``--mode online`` pass those options on.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.memory_vs_length import length_report, measure

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
TRC = SHARED / "opensim" / "gait2392" / "subject01_walk1.trc"


def long_trial(path: Path, minutes: float, gaps: bool = False) -> int:
    """The walk ping-ponged to ``minutes`` as a TRC at 60 Hz (``gaps``: one marker missing
    for 0.1-0.4 s every 2 s); returns its frames."""
    from mocapkit.io.trc import read_trc, write_trc
    from mocapkit.markers.trajectories import MarkerTrajectories

    walk = read_trc(TRC)
    rate = walk.rate_hz
    there_and_back = np.concatenate([walk.positions, walk.positions[-2:0:-1]])
    n = round(minutes * 60.0 * rate)
    reps = -(-n // there_and_back.shape[0])
    pos = np.concatenate([there_and_back] * reps)[:n]
    if gaps:
        rng = np.random.default_rng(0)
        every = round(2.0 * rate)
        for a in range(every, n - every, every):
            pos[a : a + int(rng.integers(6, 25)), int(rng.integers(pos.shape[1]))] = np.nan
    traj = MarkerTrajectories(np.arange(n) / rate, pos, walk.names, dict(walk.meta))
    write_trc(path, traj, rate_hz=rate)
    return n


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, nargs="+", default=[1.0, 10.0, 60.0])
    parser.add_argument(
        "--clean", action="store_true",
        help="gaps in the trial, filled and low-passed (--fill-gaps both --lowpass-hz 6)",
    )  # fmt: skip
    parser.add_argument("--method", choices=("osc", "ik"), default="osc")
    parser.add_argument("--mode", choices=("offline", "online"), default="offline")
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    if not TRC.exists():
        raise SystemExit(f"needs {TRC}")
    exe = [sys.executable, "-c", "from mocapkit.cli.main import run; run()"]
    clean = ["--fill-gaps", "both", "--lowpass-hz", "6"] if args.clean else []
    if args.method != "osc":
        clean += ["--method", args.method]
    if args.mode != "offline":
        clean += ["--mode", args.mode]
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for minutes in args.minutes:
            src = Path(d) / f"walk_{minutes:g}min.trc"
            frames = long_trial(src, minutes, gaps=args.clean)
            m = measure([*exe, "markers", "reconstruct", str(src), "--height-m", "1.80",
                         "-o", str(Path(d) / "out.mot"), *clean])  # fmt: skip
            rows.append((minutes, frames, m))
            print(minutes, frames, m, flush=True)
    lengths = " ".join(f"{x:g}" for x in args.minutes)
    flag = (" --clean" if args.clean else "") + "".join(
        f" --{k} {v}" for k, v in (("method", args.method), ("mode", args.mode))
        if v not in ("osc", "offline")
    )  # fmt: skip
    length_report(
        rows, f"python -m benchmarks.memory_markers --minutes {lengths}{flag}",
        "OpenSim's gait2392 walk played forwards and backwards to the length, 60 Hz"
        + (", a gap in one marker every 2 s (0.1-0.4 s)" if args.clean else "")
        + ", `mocapkit markers reconstruct --height-m 1.80"
        + (" --fill-gaps both --lowpass-hz 6" if args.clean else "")
        + "".join(f" {c}" for c in clean if c.startswith("--m") or c in ("ik", "online"))
        + "`, "
        + ("inverse kinematics" if args.method == "ik" else "direct marker control")
        + f" {args.mode if args.method == 'osc' else ''}".rstrip()
        + ", whole processes",
        "Memory and time against recording length: markers"
        + (", filled and filtered" if args.clean else "")
        + (", IK" if args.method == "ik" else "")
        + (", online" if args.mode == "online" and args.method == "osc" else ""),
        args.write_docs,
    )  # fmt: skip


if __name__ == "__main__":
    main()
