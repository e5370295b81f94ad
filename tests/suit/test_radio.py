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


def test_lossy_reordering_radio_into_the_receiver() -> None:
    """Through a radio that loses and reorders, the receiver delivers every surviving
    sample exactly once and in order per sensor, and counts the holes as lost."""
    from mocapkit.suit.receiver import Receiver, ReceiverConfig
    from mocapkit.suit.simulator import SuitSimConfig, SuitSimulator
    from mocapkit.suit.transport import UdpTransport

    sim = SuitSimulator.from_motion(
        "walk", 3, 0.5, 200.0, SuitSimConfig(), np.random.default_rng(0)
    )
    rx_t = UdpTransport.bind("127.0.0.1", 0)
    tx = UdpTransport.connect("127.0.0.1", rx_t.port)
    rx = Receiver(rx_t, ReceiverConfig(reorder_window_s=0.05)).start()
    params = RadioParams(bps=2e6, latency_s=0.001, loss=0.1, reorder=0.1, reorder_delay_s=0.012,
                         queue_bytes=100_000)  # fmt: skip
    link = RadioLink(tx.send, params, np.random.default_rng(3))
    try:
        n = sim.stream(link.send, speed=1.0)
        link.close()
        time.sleep(0.2)
        got = rx.get_batch(10_000, 0.5)
    finally:
        rx.stop()
        tx.close()
        rx_t.close()
    counts = link.model.counts
    assert n == 3 * 101
    st_ = rx.stats()
    stale = sum(s.stale for s in st_.sensors.values())
    # a sensor's first packet overtaken by its second comes "behind" the stream: stale
    assert stale <= 3
    assert len(got) + stale == n - counts["lost"]
    for sid in (1, 2, 3):
        seqs = [s.seq for s in got if s.sensor_id == sid]
        assert seqs == sorted(set(seqs))  # in order, no duplicates
    lost = sum(s.lost for s in st_.sensors.values())
    assert lost <= counts["lost"]  # a loss at the very end of a stream leaves no gap
    assert sum(s.reordered for s in st_.sensors.values()) > 0
