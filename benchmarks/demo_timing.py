"""How long the demo takes, and what it measures (writes "## Viewer, report and demo").

    python -m benchmarks.demo_timing [--runs 2] [--no-write]

Runs ``mocapkit demo --json`` in a fresh process ``--runs`` times (the first run also
pays numba's compilation when the cache is cold) and records the wall time per run and
per section, and the demo's teleoperation figures.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from benchmarks.imu_filters import REPO

HEADING = "## Viewer, report and demo"


def run_once(out_dir: Path) -> tuple[float, dict[str, Any]]:
    t0 = time.perf_counter()
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "mocapkit",
            "demo",
            "--json",
            "--no-progress",
            "--out",
            str(out_dir),
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    return time.perf_counter() - t0, json.loads(proc.stdout)


def write_section(text: str) -> Path:
    path = REPO / "docs" / "benchmarks.md"
    content = path.read_text()
    section = f"{HEADING}\n\n{text}\n"
    if HEADING in content:
        start = content.index(HEADING)
        nxt = content.find("\n## ", start + len(HEADING))
        content = content[:start] + section + (content[nxt + 1 :] if nxt >= 0 else "")
    else:
        content = content.rstrip("\n") + "\n\n" + section
    path.write_text(content)
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    rows = []
    last: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.runs):
            wall, last = run_once(Path(tmp) / f"run{k}")
            rows.append((wall, last["seconds"]))
            print(f"run {k + 1}: {wall:.1f} s {last['seconds']}", flush=True)
    t = last.get("teleop", {})
    lines = [
        "Command: `python -m benchmarks.demo_timing` (runs `mocapkit demo --json` in a fresh "
        f"process {args.runs} times). Measured on {platform.machine()} / Python "
        f"{platform.python_version()}, 2 cores shared with other jobs (load average "
        f"{os.getloadavg()[0]:.1f} at the end): provisional.",
        "",
        "| run | wall [s] | teleop [s] | markers [s] | imu [s] | report [s] |",
        "|---|---|---|---|---|---|",
    ]
    for k, (wall, secs) in enumerate(rows):
        cells = [f"{secs.get(s, float('nan')):.1f}" for s in ("teleop", "markers", "imu", "report")]
        lines.append(f"| {k + 1} | {wall:.1f} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "The teleoperation section runs in real time through the live session (N-pose 2 s, "
        "reach 2 s, settle 1 s, a 6 s shape, hold 1 s: 12 s of motion) plus the operator's "
        "IK, the robot server's and the sender's start; the wall time includes Python's and "
        "numba's start-up.",
        "",
        "A run that finds numba's cache missing or stale (a fresh install, or sources edited "
        "since) compiles the kernels first: about 75 s more on 2 cores (measured: run 1 "
        "104.6 s, markers 75.5 s, after the marker kernels changed). `make setup` therefore "
        "compiles them once with `mocapkit demo --warm-up` (4 tasks in 2 processes: 61-72 s "
        "wall measured with one other job running), so `make demo` on a fresh machine runs "
        "as a warm run does.",
        "",
        f"Demo teleoperation figures of the last run (shape {t.get('shape')}, "
        f"{t.get('preset')}, filter {t.get('filter')} on the {t.get('fusion')}, "
        "consumer-grade IMU errors):",
        "",
        "| figure | value |",
        "|---|---|",
    ]
    for key in ("ee_rmse_mm", "command_rmse_mm", "tracking_rmse_mm", "robot_lag_ms",
                "pipeline_ms_p50", "pipeline_ms_p99"):  # fmt: skip
        v = t.get(key)
        lines.append(f"| {key} | {'n/a' if v is None else f'{v:.2f}'} |")
    for coord, v in t.get("joint_rmse_deg", {}).items():
        lines.append(f"| joint RMSE {coord} [deg] | {v:.2f} |")
    for sensor, v in t.get("filter_rmse_deg", {}).items():
        lines.append(f"| filter RMSE {sensor} [deg] | {v:.2f} |")
    text = "\n".join(lines)
    print(text)
    if not args.no_write:
        print(f"written to {write_section(text)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
