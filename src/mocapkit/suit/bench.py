"""The loopback benchmark behind ``mocapkit suit bench``: simulator -> UDP -> receiver.

The simulator's nodes forward raw samples (host-side fusion), so 15 sensors at 1 kHz are
15,000 datagrams per second. The sender stamps ``perf_counter_ns`` right before each
``sendto``; the receiver stamps each datagram when it reads it; *added latency* is the
difference (``CLOCK_MONOTONIC``: the same clock in every process of the machine). A
consumer thread drains the sample stream as the pipeline would.

By default the simulator runs in its own process (as a suit and a host do), so sender
and receiver do not share one interpreter lock; ``sender="thread"`` keeps them in one
process (harder: every 5 ms the two threads trade the lock).
"""

from __future__ import annotations

import multiprocessing as mp
import threading
import time
from typing import Any, Literal

import numpy as np

from mocapkit.errors import ConfigError
from mocapkit.suit.receiver import Receiver, ReceiverConfig
from mocapkit.suit.recording import paced
from mocapkit.suit.simulator import SuitSimConfig, SuitSimulator
from mocapkit.suit.transport import UdpTransport


def _timeline(
    motion: str, n_sensors: int, seconds: float, rate_hz: float, seed: int
) -> list[tuple[float, bytes]]:
    sim = SuitSimulator.from_motion(
        motion, n_sensors, seconds, rate_hz, SuitSimConfig(mode="raw"), np.random.default_rng(seed)
    )
    return sim.timeline()


def _send_all(items: list[tuple[float, bytes]], host: str, port: int) -> tuple[np.ndarray, int]:
    """Send on the real clock; returns (send time per item [ns], start time [ns])."""
    send_ns = np.zeros(len(items), dtype=np.int64)

    def on_sent(i: int, t_ns: int) -> None:
        send_ns[i] = t_ns

    tx = UdpTransport.connect(host, port)
    t_start = time.perf_counter_ns()
    try:
        paced(items, tx.send, 1.0, None, on_sent)
    finally:
        tx.close()
    return send_ns, t_start


def _sender_process(
    conn: Any, motion: str, n: int, seconds: float, rate_hz: float, seed: int, host: str, port: int
) -> None:
    items = _timeline(motion, n, seconds, rate_hz, seed)
    conn.send("ready")
    conn.recv()  # go
    send_ns, t_start = _send_all(items, host, port)
    conn.send((send_ns, t_start))
    conn.close()


def run_loopback_bench(
    n_sensors: int = 15,
    rate_hz: float = 1000.0,
    seconds: float = 10.0,
    motion: str = "walk",
    seed: int = 0,
    host: str = "127.0.0.1",
    sender: Literal["process", "thread"] = "process",
) -> dict[str, Any]:
    """Stream a simulated suit over loopback UDP to a receiver; return the figures.

    Returns ``{"sent", "received", "lost", "latency_ms_p50", "latency_ms_p99"}`` plus
    ``"drops"`` (receiver drop counters), ``"send_late_ms_p99"`` (how late the sender
    was against its schedule: a loaded machine shows here, not in the latency) and
    ``"sender"``.
    """
    if sender not in ("process", "thread"):
        raise ConfigError(f"sender: expected 'process' or 'thread', got {sender!r}")
    items = _timeline(motion, n_sensors, seconds, rate_hz, seed)
    index: dict[tuple[int, int], int] = {}
    for i, (_, frame) in enumerate(items):
        index[(frame[2], frame[4] | (frame[5] << 8))] = i
    arrival_ns = np.zeros(len(items), dtype=np.int64)

    rx_transport = UdpTransport.bind(host, 0)
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
    proc = None
    try:
        if sender == "process":
            ctx = mp.get_context("spawn")
            parent, child = ctx.Pipe()
            args = (child, motion, n_sensors, seconds, rate_hz, seed, host, rx_transport.port)
            proc = ctx.Process(target=_sender_process, args=args, daemon=True)
            proc.start()
            if not parent.poll(120.0) or parent.recv() != "ready":
                raise ConfigError("bench: the sender process did not start")
        rx.start()
        consumer.start()
        if proc is not None:
            parent.send("go")
            send_ns, t_start = parent.recv()
            proc.join(timeout=10.0)
        else:
            send_ns, t_start = _send_all(items, host, rx_transport.port)
        deadline = time.perf_counter() + 2.0
        while received < len(items) and time.perf_counter() < deadline:
            time.sleep(0.01)
    finally:
        rx.stop()
        done.set()
        if consumer.is_alive():
            consumer.join(timeout=5.0)
        rx_transport.close()
        if proc is not None and proc.is_alive():
            proc.terminate()
            proc.join(timeout=5.0)
    ok = arrival_ns > 0
    lat = (arrival_ns[ok] - send_ns[ok]) * 1e-6
    schedule = np.array([t for t, _ in items]) * 1e9
    late = (send_ns - t_start - (schedule - schedule[0])) * 1e-6
    return {
        "sent": len(items),
        "received": int(received),
        "lost": int(len(items) - received),
        "latency_ms_p50": float(np.percentile(lat, 50)) if lat.size else float("nan"),
        "latency_ms_p99": float(np.percentile(lat, 99)) if lat.size else float("nan"),
        "drops": dict(rx.stats().dropped),
        "send_late_ms_p99": float(np.percentile(late, 99)),
        "sender": sender,
    }
