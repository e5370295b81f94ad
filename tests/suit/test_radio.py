"""The radio budget table (and docs/protocol.md staying equal to it) and the radio model."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.suit.radio import (
    NAIVE_PACKET_BYTES,
    RadioLink,
    RadioModel,
    RadioParams,
    radio_rate_markdown,
    radio_rate_table,
)

DOCS = Path(__file__).resolve().parents[2] / "docs" / "protocol.md"


def test_rate_table_values() -> None:
    rows = radio_rate_table(15)
    assert len(rows) == 15
    # naive: 19 bytes x 10 bits per sensor update; ours: one bundle of 12 + 7 n bytes
    assert NAIVE_PACKET_BYTES == 19
    assert rows[14]["naive_hz"] == pytest.approx(33_600 / (190 * 15))
    assert rows[14]["ours_hz"] == pytest.approx(33_600 / ((12 + 7 * 15) * 10))
    assert rows[14]["ratio"] >= 2.0  # the target at 15 sensors
    assert all(r["ours_hz"] >= r["naive_hz"] for r in rows)


def test_docs_table_is_generated_from_code() -> None:
    assert radio_rate_markdown() in DOCS.read_text(), (
        "docs/protocol.md is stale: paste `mocapkit suit radio-table` into it"
    )


def test_serialisation_spaces_packets_by_bandwidth() -> None:
    model = RadioModel(
        RadioParams(bps=10_000, latency_s=0.0, queue_bytes=10_000), np.random.default_rng(0)
    )
    times = [model.deliver_time(0.0, 100) for _ in range(3)]
    # 100 bytes x 10 bits / 10 kbit/s = 0.1 s each, back to back
    assert times == pytest.approx([0.1, 0.2, 0.3])


def test_overflow_loss_and_reorder_counts() -> None:
    p = RadioParams(bps=10_000, latency_s=0.0, queue_bytes=250)
    model = RadioModel(p, np.random.default_rng(0))
    out = [model.deliver_time(0.0, 100) for _ in range(4)]
    assert out[2] is None
    assert out[3] is None
    assert model.counts["overflow"] == 2
    lossy = RadioModel(
        RadioParams(loss=0.3, reorder=0.2, queue_bytes=10**9), np.random.default_rng(5)
    )
    res = [lossy.deliver_time(i * 1.0, 18) for i in range(2000)]
    lost = sum(r is None for r in res)
    # binomial(2000, 0.3): sd ~ 20, so +-5 sd
    assert abs(lost - 600) < 100
    assert lossy.counts["lost"] == lost
    assert abs(lossy.counts["reordered"] - 0.2 * (2000 - lost)) < 80


def test_radio_params_validation() -> None:
    with pytest.raises(ConfigError, match=r"radio.loss: out of range \(1.5\)"):
        RadioParams(loss=1.5)
    with pytest.raises(ConfigError, match="radio.bps"):
        RadioParams(bps=0)


def test_radio_link_delivers_on_the_real_clock() -> None:
    got: list[tuple[bytes, float]] = []
    lock = threading.Lock()

    def deliver(b: bytes) -> None:
        with lock:
            got.append((b, time.perf_counter()))

    params = RadioParams(bps=33_600, latency_s=0.005, reorder=0.0)
    link = RadioLink(deliver, params, np.random.default_rng(0))
    t0 = time.perf_counter()
    for i in range(5):
        link.send(bytes([i]) * 18)
    link.close()
    assert [b[0] for b, _ in got] == [0, 1, 2, 3, 4]
    # 5 x 18 bytes at 3360 B/s = 26.8 ms, plus 5 ms latency: the last cannot be earlier
    assert got[-1][1] - t0 >= 0.0318 - 1e-3
