"""A suit's hour offline: 15 sensors, 1 kHz, 1 h each, smoothed (issue 16's target: under
2 GB).

    python -m benchmarks.memory_suit_offline [--sensors 15] [--minutes 60] [--rate 1000]
        [--workers 2] [--write-docs]

One sensor's mocapkit CSV of the length (``memory_vs_length.make_recording``: a smooth
motion with consumer-grade noise) is written once and hard-linked under as many sensor names
(the smoother's cost does not depend on the values). ``mocapkit batch imu DIR -o OUT
--workers N --args '--filter polaris --offline'`` runs as one whole process; reported:
its wall time, and the peak of the resident memory of the whole process tree (the
batch's parent and its workers together, sampled every 0.1 s from /proc) and of the
largest single process, and the peak size of the smoother's temporary files.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from benchmarks._docs import write_section
from benchmarks.memory_vs_length import make_recording


def _tree_rss_mb(root: int) -> tuple[float, float]:
    """(sum, max) resident memory [MB] of ``root`` and its descendants."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                ppid = int(f.read().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        children.setdefault(ppid, []).append(int(entry))
    total = largest = 0.0
    todo = [root]
    while todo:
        pid = todo.pop()
        todo += children.get(pid, [])
        try:
            with open(f"/proc/{pid}/status") as f:
                for line in f:
                    if line.startswith("VmRSS:"):
                        mb = int(line.split()[1]) / 1024
                        total += mb
                        largest = max(largest, mb)
        except OSError:
            continue
    return total, largest


def _dir_mb(path: Path) -> float:
    size = 0
    for dirpath, _, files in os.walk(path):
        for name in files:
            with contextlib.suppress(OSError):  # removed meanwhile
                size += os.path.getsize(os.path.join(dirpath, name))
    return size / 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sensors", type=int, default=15)
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--rate", type=float, default=1000.0)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as d:
        root = Path(d)
        src = root / "one.csv"
        t0 = time.perf_counter()
        make_recording(src, args.minutes, args.rate)
        print(f"wrote {src} ({src.stat().st_size / 1e6:.0f} MB) in "
              f"{time.perf_counter() - t0:.0f} s", flush=True)  # fmt: skip
        suit = root / "suit"
        suit.mkdir()
        for i in range(args.sensors):
            # hard links: the batch takes a symlinked file once (inputs are resolved)
            os.link(src, suit / f"sensor_{i + 1:02d}.csv")
        work = root / "tmp"
        work.mkdir()
        argv = [sys.executable, "-c", "from mocapkit.cli.main import run; run()", "batch",
                "imu", str(suit), "-o", str(root / "out"), "--workers", str(args.workers),
                "--json", "--args", "--filter polaris --offline"]  # fmt: skip
        env = {**os.environ, "MOCAPKIT_TMPDIR": str(work)}
        peak = {"sum": 0.0, "max": 0.0, "disk": 0.0}
        t0 = time.perf_counter()
        proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                env=env, text=True)  # fmt: skip

        def watch() -> None:
            while proc.poll() is None:
                total, largest = _tree_rss_mb(proc.pid)
                peak["sum"] = max(peak["sum"], total)
                peak["max"] = max(peak["max"], largest)
                peak["disk"] = max(peak["disk"], _dir_mb(work))
                time.sleep(0.1)

        thread = threading.Thread(target=watch, daemon=True)
        thread.start()
        out, _ = proc.communicate()
        seconds = time.perf_counter() - t0
        thread.join()
        report = json.loads(out)
    hours = args.minutes / 60
    text = (
        f"`python -m benchmarks.memory_suit_offline --sensors {args.sensors} --minutes "
        f"{args.minutes:g} --rate {args.rate:g} --workers {args.workers}` (method in the "
        "module docstring: `mocapkit batch imu SUIT --workers N --args '--filter polaris "
        "--offline'` on one CSV per sensor, a whole process). Target (issue 16): a "
        "15-sensor 1 kHz hour offline under 2 GB.\n\n"
        "| sensors x length | workers | files ok / failed | whole process [s] | peak memory, "
        "all processes [MB] | largest process [MB] | peak temporary files [MB] |\n"
        "|---|---:|---:|---:|---:|---:|---:|\n"
        f"| {args.sensors} x {hours:g} h at {args.rate:g} Hz | {args.workers} | "
        f"{report['ok']} / {report['failed']} | {seconds:.0f} | {peak['sum']:.0f} | "
        f"{peak['max']:.0f} | {peak['disk']:.0f} |"
    )
    print(text)
    if args.write_docs:
        write_section("Memory: a suit's hour offline", text)


if __name__ == "__main__":
    main()
