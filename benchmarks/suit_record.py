"""Benchmark: recording a 15 sensors x 1 kHz session to MCAP while receiving it.

Compares the two ways of writing the decoded-samples channel: ``live`` (JSON per
delivered sample, on the fly) and ``at_close`` (decoded from the frames when the file
closes). Frames are always recorded live.

Run: ``.venv/bin/python -m benchmarks.suit_record [--seconds 5]``.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from mocapkit.suit.receiver import Receiver
from mocapkit.suit.recording import McapRecorder
from mocapkit.suit.simulator import SuitSimConfig, SuitSimulator
from mocapkit.suit.transport import UdpTransport


def run(mode: str, seconds: float, path: Path) -> dict[str, object]:
    sim = SuitSimulator.from_motion(
        "walk", 15, seconds, 1000.0, SuitSimConfig(), np.random.default_rng(0)
    )
    items = sim.timeline()
    rx_t = UdpTransport.bind("127.0.0.1", 0)
    tx = UdpTransport.connect("127.0.0.1", rx_t.port)
    rec = McapRecorder(path, samples=mode)  # type: ignore[arg-type]
    rx = Receiver(rx_t, recorder=rec).start()
    stop = threading.Event()

    def drain() -> None:
        while not stop.is_set():
            rx.get_batch(4096, 0.05)

    th = threading.Thread(target=drain)
    th.start()
    sim.stream(tx.send, 1.0)
    time.sleep(1.0)
    rx.stop()
    stop.set()
    th.join()
    t0 = time.perf_counter()
    rec.close()
    close_s = time.perf_counter() - t0
    tx.close()
    rx_t.close()
    lost = sum(s.lost for s in rx.stats().sensors.values())
    return {
        "samples_mode": mode,
        "sent": len(items),
        "frames_recorded": rec.frames,
        "samples_recorded": rec.samples,
        "lost": lost,
        "close_s": close_s,
        "mb": path.stat().st_size / 1e6,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=5.0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for mode in ("at_close", "live"):
            r = run(mode, args.seconds, Path(tmp) / f"{mode}.mcap")
            r["load_avg_1min"] = os.getloadavg()[0]
            print(json.dumps(r))


if __name__ == "__main__":
    main()
