"""The loopback benchmark behind ``mocapkit suit bench``: simulator -> UDP -> receiver.

The simulator's nodes forward raw samples (host-side fusion), so 15 sensors at 1 kHz are
15,000 datagrams per second. The sender stamps ``perf_counter_ns`` right before each
``sendto``; the receiver stamps each datagram when it reads it; *added latency* is the
difference (same clock, same machine). A consumer thread drains the sample stream as the
pipeline would.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

from mocapkit.suit.receiver import Receiver, ReceiverConfig
from mocapkit.suit.simulator import SuitSimConfig, SuitSimulator
from mocapkit.suit.transport import UdpTransport


def run_loopback_bench(
    n_sensors: int = 15,
    rate_hz: float = 1000.0,
    seconds: float = 10.0,
    motion: str = "walk",
    seed: int = 0,
    host: str = "127.0.0.1",
) -> dict[str, Any]:
    """Stream a simulated suit over loopback UDP to a receiver; return the figures.

    Returns ``{"sent", "received", "lost", "latency_ms_p50", "latency_ms_p99"}`` plus
    ``"drops"`` (receiver drop counters) and ``"send_late_ms_p99"`` (how late the sender
    was against its schedule: a loaded machine shows here, not in the latency).
    """
    sim = SuitSimulator.from_motion(
        motion, n_sensors, seconds, rate_hz, SuitSimConfig(mode="raw"), np.random.default_rng(seed)
    )
    items = sim.timeline()
    index: dict[tuple[int, int], int] = {}
    for i, (_, frame) in enumerate(items):
        index[(frame[2], frame[4] | (frame[5] << 8))] = i
    send_ns = np.zeros(len(items), dtype=np.int64)
    arrival_ns = np.zeros(len(items), dtype=np.int64)

    def on_sent(i: int, t_ns: int) -> None:
        send_ns[i] = t_ns

    rx_transport = UdpTransport.bind(host, 0)
    tx = UdpTransport.connect(host, rx_transport.port)
    rx = Receiver(rx_transport, ReceiverConfig(allowed_ids=frozenset(range(1, n_sensors + 1))))
    received = 0
    done = threading.Event()

    def consume() -> None:
        nonlocal received
        while not (done.is_set() and rx.pending == 0):
            for s in rx.get_batch(4096, 0.05):
                i = index.get((s.sensor_id, s.seq & 0xFFFF))
                if i is not None and arrival_ns[i] == 0:
                    arrival_ns[i] = s.t_arrival_ns
                    received += 1

    consumer = threading.Thread(target=consume, name="bench-consumer", daemon=True)
    rx.start()
    consumer.start()
    t_start = time.perf_counter_ns()
    try:
        sim_sent = _send(items, tx, on_sent)
        deadline = time.perf_counter() + 2.0
        while received < sim_sent and time.perf_counter() < deadline:
            time.sleep(0.01)
    finally:
        rx.stop()
        done.set()
        consumer.join(timeout=5.0)
        tx.close()
        rx_transport.close()
    ok = arrival_ns > 0
    lat = (arrival_ns[ok] - send_ns[ok]) * 1e-6
    schedule = np.array([t for t, _ in items]) * 1e9
    late = (send_ns - t_start - (schedule - schedule[0])) * 1e-6
    stats = rx.stats()
    return {
        "sent": int(sim_sent),
        "received": int(received),
        "lost": int(sim_sent - received),
        "latency_ms_p50": float(np.percentile(lat, 50)) if lat.size else float("nan"),
        "latency_ms_p99": float(np.percentile(lat, 99)) if lat.size else float("nan"),
        "drops": dict(stats.dropped),
        "send_late_ms_p99": float(np.percentile(late, 99)),
    }


def _send(items: list[tuple[float, bytes]], tx: UdpTransport, on_sent: Any) -> int:
    from mocapkit.suit.recording import paced

    return paced(items, tx.send, 1.0, None, on_sent)
