"""Start-up: ``mocapkit --help`` and each command group's ``--help`` as whole processes
(issue 16: under 0.3 s; it was ~1.5 s and 235 MB when the parser imported scipy.signal,
numba and matplotlib).

    python -m benchmarks.startup [--repeat 5] [--write-docs]

Reported: the median wall time over ``--repeat`` runs and the peak resident memory of
the process, beside a bare ``python -c pass``. The numba kernels are compiled once per
install by ``make setup`` (``mocapkit demo --warm-up``), cached on disk, not per run.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from benchmarks._docs import write_section
from benchmarks.memory_vs_length import measure

COMMANDS = (
    [],
    ["imu"],
    ["body"],
    ["markers"],
    ["retarget"],
    ["batch"],
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    cli = [sys.executable, "-c", "from mocapkit.cli.main import run; run()"]
    rows = []
    for label, argv in [("python -c pass", [sys.executable, "-c", "pass"])] + [
        (" ".join(["mocapkit", *c, "--help"]), [*cli, *c, "--help"]) for c in COMMANDS
    ]:
        runs = [measure(argv) for _ in range(args.repeat)]
        sec = float(np.median([r["seconds"] for r in runs]))
        mb = max(r["peak_mb"] for r in runs)
        rows.append((label, sec, mb))
        print(label, f"{sec:.3f} s", f"{mb:.0f} MB", flush=True)
    lines = ["| command | wall time, median [s] | peak memory [MB] |", "|---|---:|---:|"]
    lines += [f"| `{label}` | {sec:.3f} | {mb:.0f} |" for label, sec, mb in rows]
    text = (
        f"`python -m benchmarks.startup --repeat {args.repeat}` (whole processes; target "
        "(issue 16): `mocapkit --help` under 0.3 s; before the parser imported only what a "
        "command runs: ~1.5 s and 235 MB).\n\n" + "\n".join(lines)
    )
    print(text)
    if args.write_docs:
        write_section("Start-up", text)


if __name__ == "__main__":
    main()
