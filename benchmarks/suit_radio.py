"""Benchmark: the paper's 33.6 kbit/s radio — our bundle vs the paper's naive packet vs
SlimeVR's own packets (rotation data, type 17, in a v2 bundle), computed and then run
through the radio model to check the rates are achievable without overflow.

Run: ``.venv/bin/python -m benchmarks.suit_radio``.
"""

from __future__ import annotations

import json

import numpy as np

from mocapkit.suit import slimevr
from mocapkit.suit.protocol import encode_bundle
from mocapkit.suit.radio import (
    NAIVE_PACKET_BYTES,
    PAPER_RADIO_BPS,
    RadioModel,
    RadioParams,
    ours_round_bytes,
    radio_rate_table,
    update_rate_hz,
)


def _slimevr_round_bytes(n: int) -> int:
    q = np.array([1.0, 0.0, 0.0, 0.0])
    return len(
        slimevr.build_bundle(0, [(17, slimevr.rotation_body(i, q)) for i in range(n)], v2=True)
    )


def _overflows(round_bytes: int, round_hz: float, seconds: float = 20.0) -> int:
    model = RadioModel(RadioParams(queue_bytes=4 * round_bytes), np.random.default_rng(0))
    for k in range(int(seconds * round_hz)):
        model.deliver_time(k / round_hz, round_bytes)
    return model.counts["overflow"]


def main() -> None:
    rows = []
    for r in radio_rate_table(15):
        n = int(r["n_sensors"])
        slime = update_rate_hz(_slimevr_round_bytes(n))
        rows.append({**r, "slimevr_v2_bundle_hz": slime})
    n = 15
    q = [np.array([1.0, 0.0, 0.0, 0.0])] * n
    bundle = len(encode_bundle(0, 0, list(zip(range(1, n + 1), q, strict=True))))
    assert bundle == ours_round_bytes(n)
    ours_hz = update_rate_hz(bundle)
    check = {
        "bundle_bytes_15": bundle,
        "naive_bytes_15": NAIVE_PACKET_BYTES * n,
        "slimevr_v2_bytes_15": _slimevr_round_bytes(n),
        "ours_hz_15": ours_hz,
        "overflow_at_99pct_of_ours_hz": _overflows(bundle, 0.99 * ours_hz),
        "overflow_at_105pct_of_ours_hz": _overflows(bundle, 1.05 * ours_hz),
        "radio_bps": PAPER_RADIO_BPS,
    }
    print(json.dumps({"table": rows, "check": check}, indent=1))


if __name__ == "__main__":
    main()
