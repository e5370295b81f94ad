"""Benchmark: batch decoding of a suit recording (numba) against per-packet decoding.

Builds a recording of 15 sensors x 1 kHz raw samples (``--seconds`` long, written with
McapRecorder as the receiver would), then times: reading the frames with the generic
mcap reader and with the chunk reader (``mcap_fast``), the numba stream decoder, the
whole ``decode_recording`` (file -> arrays), and the per-packet reference decoder.

Run: ``.venv/bin/python -m benchmarks.suit_decode [--seconds 20]``.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from mocapkit.suit.batch import decode_stream
from mocapkit.suit.mcap_fast import read_frame_buffer
from mocapkit.suit.protocol import decode
from mocapkit.suit.recording import McapRecorder, decode_recording, read_frames
from mocapkit.suit.simulator import SuitSimConfig, SuitSimulator


def _best(fn, repeats: int = 3) -> float:  # type: ignore[no-untyped-def]
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return float(best)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=20.0)
    args = ap.parse_args()
    sim = SuitSimulator.from_motion(
        "walk", 15, args.seconds, 1000.0, SuitSimConfig(mode="raw"), np.random.default_rng(0)
    )
    frames = [f for _, f in sim.timeline()]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.mcap"
        t0 = time.perf_counter_ns()
        with McapRecorder(path) as rec:
            for i, f in enumerate(frames):
                rec.write_frame(f, t0 + i * 66_667, ("127.0.0.1", 40000))
        size = path.stat().st_size
        read_s = _best(lambda: read_frames(path), 1)
        buf = b"".join(f.data for f in read_frames(path))
        read_frame_buffer(path)  # load the numba kernels
        fast_read_s = _best(lambda: read_frame_buffer(path))
        decode_stream(buf[:1000])
        numba_s = _best(lambda: decode_stream(buf))
        end_to_end_s = _best(lambda: decode_recording(path))
    subset = frames[:50_000]
    ref_s = _best(lambda: [decode(f) for f in subset], 1) * len(frames) / len(subset)
    n = len(frames)
    print(
        json.dumps(
            {
                "packets": n,
                "recording_mb": size / 1e6,
                "read_mcap_generic_s": read_s,
                "read_mcap_generic_packets_per_s": n / read_s,
                "read_mcap_fast_s": fast_read_s,
                "read_mcap_fast_packets_per_s": n / fast_read_s,
                "numba_decode_s": numba_s,
                "numba_packets_per_s": n / numba_s,
                "reference_packets_per_s": n / ref_s,
                "decode_recording_s": end_to_end_s,
                "decode_recording_packets_per_s": n / end_to_end_s,
                "load_avg_1min": os.getloadavg()[0],
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
