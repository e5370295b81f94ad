"""Time and peak memory of ``mocapkit body angles`` against recording length (issue 16).

    python -m benchmarks.memory_body [--repeats 1 10 30] [--write-docs]

The qmt 15-IMU full-body recording in ../shared (from 40.3 s: 99.7 s at 100 Hz, the
device's orientations) is tiled ``repeats`` times into an OpenSense quaternion ``.sto``
and run through ``mocapkit body angles --preset full_body_15`` (automatic calibration)
as a whole process; reported: wall time and the child's peak resident memory.
Target (issue 16): within 2x from the shortest to the longest.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from benchmarks._docs import write_section
from benchmarks.memory_vs_length import measure

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
MAT = SHARED / "full-body-15-imu" / "full_body_example_data.mat"


def tiled(path: Path, repeats: int) -> int:
    """The recording ``repeats`` times end to end as a quaternion .sto; returns frames."""
    from mocapkit.io.opensim_table import write_table
    from mocapkit.io.qmt_mat import read_qmt_mat

    o = read_qmt_mat(MAT).orientation
    names = list(o)
    keep = o[names[0]].time >= 40.3
    n = int(keep.sum())
    dt = float(np.median(np.diff(o[names[0]].time[keep])))
    quats = np.stack([np.concatenate([o[k].quat[keep]] * repeats) for k in names], axis=1)
    write_table(path, np.arange(n * repeats) * dt, names, quats, name="tiled")
    return n * repeats


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, nargs="+", default=[1, 10, 30])
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    if not MAT.exists():
        raise SystemExit(f"needs {MAT}")
    import sys

    exe = [sys.executable, "-c", "from mocapkit.cli.main import run; run()"]
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for k in args.repeats:
            src = Path(d) / f"tiled_{k}.sto"
            frames = tiled(src, k)
            m = measure([*exe, "body", "angles", str(src), "--preset", "full_body_15",
                         "-o", str(Path(d) / "out.mot")])  # fmt: skip
            rows.append((k, frames, m))
            print(k, frames, m, flush=True)
    lines = ["| recording | frames | whole process [s] | peak memory [MB] | per frame [KB] |",
             "|---|---:|---:|---:|---:|"]  # fmt: skip
    base = rows[0][2]["peak_mb"]
    for k, frames, m in rows:
        per = (m["peak_mb"] - base) * 1024 / max(frames - rows[0][1], 1) if k != rows[0][0] else 0
        lines.append(f"| x{k} ({frames / 6000:.0f} min) | {frames} | {m['seconds']:.2f} | "
                     f"{m['peak_mb']:.0f} | {per:.1f} |")  # fmt: skip
    growth = rows[-1][2]["peak_mb"] / base
    text = (
        f"`python -m benchmarks.memory_body --repeats {' '.join(map(str, args.repeats))}` "
        "(the 15-IMU recording tiled, `mocapkit body angles --preset full_body_15`, "
        "automatic calibration from the still pose and the first 300 s of motion after it, "
        "whole processes; the .sto is read, turned into joint angles and written 10,000 rows "
        "at a time, `mocapkit.body.streamed`). Peak memory from the shortest to the longest: "
        f"x{growth:.1f} (target: within x2).\n\n" + "\n".join(lines)
    )
    print(text)
    if args.write_docs:
        write_section("Memory and time against recording length: body angles", text)


if __name__ == "__main__":
    main()
