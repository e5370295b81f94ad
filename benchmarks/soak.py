"""Soak: a 15-sensor, 100 Hz live session with recording, for a long time.

    python -m benchmarks.soak [--minutes 30] [--every 30] [--write-docs]

The simulated suit (15 sensors of ``full_body_15``, consumer-grade errors, RAW datagrams
fused on the host) streams over real UDP into the live session, which runs the whole
per-packet path, drives a robot-server process and records everything to MCAP
(``teleop run --record``'s recorder). Every ``--every`` seconds the benchmark reads this
process's resident memory (``/proc/self/status``: the receiver, pipeline and recorder
live here), the pipeline latency of the last 1,000 commands, the packets delivered and
lost, and the recording's size. The claims: memory flat after the first window, latency
not growing, nothing lost, the recording readable whole at the end. When the session
has stopped following (the full-body operator reaches beyond the robot arm at times) the
benchmark disengages and engages again, as an operator would, and counts it.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path
from typing import Any

from benchmarks._docs import write_section
from mocapkit.errors import MocapkitError
from mocapkit.teleop.recording import read_messages
from mocapkit.teleop.simulated import SimulatedConfig, SimulatedSession


def rss_mb() -> float:
    """This process's resident memory [MB] (Linux)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def soak(seconds: float, every_s: float, record: Path) -> list[dict[str, Any]]:
    """Run the session for ``seconds``; one row of figures every ``every_s``."""
    cfg = SimulatedConfig(
        preset="full_body_15", duration_s=seconds + 5.0, auto_engage=True, record=str(record)
    )
    rows: list[dict[str, Any]] = []
    reengaged = 0
    with SimulatedSession(cfg) as sim:
        t0 = time.monotonic()
        while (elapsed := time.monotonic() - t0) < seconds:
            time.sleep(min(every_s, seconds - elapsed))
            snap = sim.snapshot()
            if snap.get("state") != "engaged" and sim.live is not None:
                # as an operator would: the session stopped following (the full-body
                # operator's reach exceeds the arm's at times): disengage, engage again
                try:
                    sim.live.disengage()
                    sim.live.engage()
                    reengaged += 1
                except MocapkitError as exc:  # not calibrated yet: the next window
                    print(f"soak: {exc}", flush=True)
            sensors = snap.get("sensors", {}).values()
            lat = snap.get("latency_ms", {})
            rows.append(
                {
                    "t_s": round(time.monotonic() - t0, 1),
                    "rss_mb": round(rss_mb(), 1),
                    "p50_ms": lat.get("p50"),
                    "p99_ms": lat.get("p99"),
                    "delivered": sum(s["delivered"] for s in sensors),
                    "lost": sum(s["lost"] for s in sensors),
                    "state": snap.get("state"),
                    "record_mb": round(record.stat().st_size / 1e6, 2) if record.exists() else 0,
                    "reengaged": reengaged,
                }
            )
            print(rows[-1], flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=30.0)
    parser.add_argument("--every", type=float, default=30.0, help="seconds between rows")
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as d:
        record = Path(d) / "soak.mcap"
        rows = soak(args.minutes * 60.0, args.every, record)
        commands = len(read_messages(record, "/teleop/command"))
    first, last = rows[0], rows[-1]
    lines = [
        "| t [s] | RSS [MB] | latency p50 / p99 [ms] | delivered | lost | state | re-engaged "
        "| recording [MB] |",
        "|---:|---:|---:|---:|---:|---|---:|---:|",
    ]
    for r in rows:
        p50 = "-" if r["p50_ms"] is None else f"{r['p50_ms']:.2f}"
        p99 = "-" if r["p99_ms"] is None else f"{r['p99_ms']:.2f}"
        lines.append(
            f"| {r['t_s']:.0f} | {r['rss_mb']:.1f} | {p50} / {p99} | {r['delivered']:,} | "
            f"{r['lost']} | {r['state']} | {r['reengaged']} | {r['record_mb']:.2f} |"
        )
    text = (
        f"`python -m benchmarks.soak --minutes {args.minutes:g} --every {args.every:g}` "
        "(15 sensors at 100 Hz, RAW datagrams fused on the host, recording on). Memory "
        f"{first['rss_mb']:.1f} MB after the first window, {last['rss_mb']:.1f} MB at the end; "
        f"{last['lost']} packets lost of {last['delivered']:,}; the recording read back whole: "
        f"{commands:,} commands.\n\n" + "\n".join(lines)
    )
    print(text)
    if args.write_docs:
        write_section("Soak: a long live session", text)


if __name__ == "__main__":
    main()
