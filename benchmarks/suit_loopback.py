"""Benchmark: 15 sensors x 1 kHz raw samples, simulator -> loopback UDP -> receiver.

Run: ``.venv/bin/python -m benchmarks.suit_loopback [--repeats 3] [--seconds 10]``.
Each repeat runs the simulator in its own process and then in a thread of the receiver's
process. Prints one JSON object per run and a summary; figures go to docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import json
import os

from mocapkit.suit.bench import run_loopback_bench


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sensors", type=int, default=15)
    ap.add_argument("--rate-hz", type=float, default=1000.0)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    runs = []
    for i in range(args.repeats):
        for sender in ("process", "thread"):
            r = run_loopback_bench(args.sensors, args.rate_hz, args.seconds, seed=i, sender=sender)
            r["load_avg_1min"] = os.getloadavg()[0]
            runs.append(r)
            print(json.dumps(r))
    print(
        json.dumps(
            {
                "load_avg_1min": os.getloadavg()[0],
                "runs": len(runs),
                "lost_total": sum(r["lost"] for r in runs),
                "latency_ms_p50_median": sorted(r["latency_ms_p50"] for r in runs)[len(runs) // 2],
                "latency_ms_p99_worst": max(r["latency_ms_p99"] for r in runs),
            }
        )
    )


if __name__ == "__main__":
    main()
