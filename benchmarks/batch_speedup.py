"""``mocapkit batch`` on a marker corpus: whole-process time for 1 and 2 workers, and Ray.

    python -m benchmarks.batch_speedup [--copies 4] [--write-docs]

The corpus: the marker trials in ../shared/data (OpenSim's gait2392 walk, the CMU and
walking2 C3D files), each copied ``--copies`` times under new names. Each configuration
is the whole ``mocapkit batch markers DIR -o OUT --json`` process, as a user times it
(process start, imports, worker start-up, every file, the manifest), in a fresh output
directory: the local engine with 1 and 2 workers and the Ray engine with 2 workers on a
local cluster started for the run. Reported: seconds, speed-up over 1 worker, and for
Ray its overhead per file against the local engine's 2 workers, beside the mean time a
file takes.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks._docs import write_section

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
TRIALS = (
    SHARED / "opensim" / "gait2392" / "subject01_walk1.trc",
    SHARED / "c3d" / "cmu_85_02.c3d",
    SHARED / "c3d" / "walking2.c3d",
)


def _timed(argv: list[str]) -> tuple[float, dict]:  # type: ignore[type-arg]
    t0 = time.perf_counter()
    proc = subprocess.run(argv, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - t0
    if not proc.stdout.strip().startswith("{"):
        raise RuntimeError(f"{' '.join(argv)} failed: {proc.stderr[-2000:]}")
    return seconds, json.loads(proc.stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--copies", type=int, default=4)
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    missing = [str(p) for p in TRIALS if not p.exists()]
    if missing:
        raise SystemExit(f"needs ../shared/data: {', '.join(missing)}")
    exe = [sys.executable, "-c", "from mocapkit.cli.main import run; run()"]
    rows = []
    with tempfile.TemporaryDirectory() as d:
        corpus = Path(d) / "corpus"
        corpus.mkdir()
        for k in range(args.copies):
            for p in TRIALS:
                shutil.copy(p, corpus / f"{p.stem}_{k}{p.suffix}")
        n = args.copies * len(TRIALS)
        for label, extra in (
            ("local, 1 worker", ["--workers", "1"]),
            ("local, 2 workers", ["--workers", "2"]),
            ("ray (local cluster), 2 workers", ["--workers", "2", "--engine", "ray"]),
        ):
            out = Path(d) / f"out{len(rows)}"
            argv = [*exe, "batch", "markers", str(corpus), "-o", str(out), "--json", *extra]
            seconds, summary = _timed(argv)
            manifest = [json.loads(x) for x in (out / "manifest.jsonl").read_text().splitlines()]
            per_file = sum(r["seconds"] for r in manifest) / len(manifest)
            rows.append((label, seconds, summary, per_file))
            print(label, round(seconds, 2), summary["ok"], summary["failed"], flush=True)
    start_code = (
        "import time, ray; t0 = time.perf_counter(); "
        "ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False); "
        "ray.shutdown(); print(time.perf_counter() - t0)"
    )
    ray_start = float(
        subprocess.run([sys.executable, "-c", start_code], capture_output=True, text=True,
                       check=True).stdout.split()[-1]
    )  # fmt: skip
    base = rows[0][1]
    lines = [
        "| engine | whole process [s] | speed-up | files ok / failed | mean time in a file [s] |",
        "|---|---:|---:|---:|---:|",
    ]
    for label, seconds, summary, per_file in rows:
        lines.append(
            f"| {label} | {seconds:.2f} | {base / seconds:.2f}x | {summary['ok']} / "
            f"{summary['failed']} | {per_file:.2f} |"
        )
    ray_over = (rows[2][1] - rows[1][1] - ray_start) / n
    text = (
        f"`python -m benchmarks.batch_speedup --copies {args.copies}` ({n} marker trials: "
        f"gait2392 walk, CMU 85_02, walking2, x{args.copies}; {os.cpu_count()} cores; "
        "whole `mocapkit batch markers` processes). Starting a local Ray cluster and "
        f"stopping it takes {ray_start:.1f} s on its own (a standing cluster does not pay "
        f"it); beyond that, Ray's overhead against the local engine is {ray_over:+.2f} s "
        f"per file, {100 * ray_over / rows[1][3]:+.0f} % of a file's mean time.\n\n"
        + "\n".join(lines)
    )
    print(text)
    if args.write_docs:
        write_section("Batch: corpus speed-up (local processes and Ray)", text)


if __name__ == "__main__":
    main()
