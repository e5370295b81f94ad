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

    def corpus_of(root: Path, copies: int) -> Path:
        corpus = root / f"corpus{copies}"
        corpus.mkdir()
        for k in range(copies):
            for p in TRIALS:
                shutil.copy(p, corpus / f"{p.stem}_{k}{p.suffix}")
        return corpus

    def batch(corpus: Path, out: Path, extra: list[str]) -> tuple[float, dict, float]:  # type: ignore[type-arg]
        argv = [*exe, "batch", "markers", str(corpus), "-o", str(out), "--json", *extra]
        seconds, summary = _timed(argv)
        manifest = [json.loads(x) for x in (out / "manifest.jsonl").read_text().splitlines()]
        return seconds, summary, sum(r["seconds"] for r in manifest) / len(manifest)

    rows = []
    two = ["--workers", "2"]
    ray = ["--workers", "2", "--engine", "ray"]
    with tempfile.TemporaryDirectory() as d:
        small = corpus_of(Path(d), args.copies)
        n = args.copies * len(TRIALS)
        configs = (("local, 1 worker", ["--workers", "1"]), ("local, 2 workers", two),
                   ("ray (local cluster), 2 workers", ray))  # fmt: skip
        for label, extra in configs:
            seconds, summary, per_file = batch(small, Path(d) / f"out{len(rows)}", extra)
            rows.append((label, seconds, summary, per_file))
            print(label, round(seconds, 2), summary["ok"], summary["failed"], flush=True)
        # a corpus three times larger separates Ray's per-file cost from its fixed cost
        # (its workers start once per run): the difference of the two slopes
        large = corpus_of(Path(d), 3 * args.copies)
        t_local3, _, _ = batch(large, Path(d) / "out_large_local", two)
        t_ray3, _, _ = batch(large, Path(d) / "out_large_ray", ray)
        print("x3", round(t_local3, 2), round(t_ray3, 2), flush=True)
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
    lines.append(f"| local, 2 workers, {3 * n} files | {t_local3:.2f} | | | |")
    lines.append(f"| ray (local cluster), 2 workers, {3 * n} files | {t_ray3:.2f} | | | |")
    per_file_over = ((t_ray3 - t_local3) - (rows[2][1] - rows[1][1])) / (2 * n)
    fixed = (rows[2][1] - rows[1][1]) - per_file_over * n
    text = (
        f"`python -m benchmarks.batch_speedup --copies {args.copies}` ({n} marker trials: "
        f"gait2392 walk, CMU 85_02, walking2, x{args.copies}, and x{3 * args.copies}; "
        f"{os.cpu_count()} cores; whole `mocapkit batch markers` processes). Ray against the "
        f"local engine, from the two corpus sizes: {fixed:+.1f} s once per run (starting and "
        f"stopping a local cluster alone takes {ray_start:.1f} s; a standing cluster does not "
        f"pay it; Ray's workers start once) and {per_file_over:+.3f} s per file, "
        f"{100 * per_file_over / rows[1][3]:+.1f} % of a file's mean time (target: below 5 %)."
        "\n\n" + "\n".join(lines)
    )
    print(text)
    if args.write_docs:
        write_section("Batch: corpus speed-up (local processes and Ray)", text)


if __name__ == "__main__":
    main()
