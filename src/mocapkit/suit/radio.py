"""The paper's radio: its byte budget (update-rate table) and a radio model for the simulator.

The Linx TR-916-SC is a transparent UART radio at 33,600 bit/s. A UART sends 10 bits per
byte (start bit, 8 data bits, stop bit: 8N1), so it carries 3,360 bytes/s.

The paper does not give its packet layout. Its *naive packet* here is the obvious one for
a Mega32 that holds its orientation as four floats: sync byte, sensor ID, 4 x float32
quaternion, one checksum byte = 19 bytes per sensor per update. Ours is a BUNDLE per hub
round: 12 + 7 n bytes for n sensors.
"""

from __future__ import annotations

import heapq
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mocapkit.errors import ConfigError
from mocapkit.suit.protocol import BUNDLE_ENTRY, ORIENTATION_PAYLOAD, OVERHEAD

PAPER_RADIO_BPS = 33_600
UART_BITS_PER_BYTE = 10
NAIVE_PACKET_BYTES = 1 + 1 + 16 + 1  # sync, id, 4 x float32, checksum
ORIENTATION_PACKET_BYTES = OVERHEAD + ORIENTATION_PAYLOAD


def naive_round_bytes(n_sensors: int) -> int:
    """Bytes on the radio per update of all sensors with the paper's naive packet."""
    return NAIVE_PACKET_BYTES * n_sensors


def ours_round_bytes(n_sensors: int) -> int:
    """Bytes per update of all sensors with our protocol: one BUNDLE per hub round."""
    return OVERHEAD + BUNDLE_ENTRY * n_sensors


def update_rate_hz(round_bytes: int, bps: float = PAPER_RADIO_BPS) -> float:
    """Highest per-sensor update rate [Hz] when each update of all sensors takes
    ``round_bytes`` on a UART radio of ``bps`` bit/s."""
    return bps / (UART_BITS_PER_BYTE * round_bytes)


def radio_rate_table(max_sensors: int = 15, bps: float = PAPER_RADIO_BPS) -> list[dict[str, float]]:
    """Rows ``{n_sensors, naive_hz, ours_hz, ratio}`` for 1..max_sensors."""
    rows = []
    for n in range(1, max_sensors + 1):
        naive = update_rate_hz(naive_round_bytes(n), bps)
        ours = update_rate_hz(ours_round_bytes(n), bps)
        rows.append({"n_sensors": n, "naive_hz": naive, "ours_hz": ours, "ratio": ours / naive})
    return rows


def radio_rate_markdown(max_sensors: int = 15, bps: float = PAPER_RADIO_BPS) -> str:
    """The table printed in docs/protocol.md (a test keeps the two equal)."""
    lines = [
        f"| sensors | naive packet ({NAIVE_PACKET_BYTES} B each) [Hz] | ours [Hz] | ours / naive |",
        "|---:|---:|---:|---:|",
    ]
    for r in radio_rate_table(max_sensors, bps):
        lines.append(
            f"| {r['n_sensors']:d} | {r['naive_hz']:.1f} | {r['ours_hz']:.1f} | {r['ratio']:.2f} |"
        )
    return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class RadioParams:
    """A one-way radio link.

    Attributes:
        bps: raw bit rate [bit/s] (10 bits per byte on the air).
        latency_s: fixed propagation and processing delay [s].
        jitter_s: standard deviation of an extra |normal| delay [s].
        loss: probability that a packet is lost.
        reorder: probability that a packet is held back by ``reorder_delay_s``.
        reorder_delay_s: the hold-back delay [s] of a reordered packet.
        queue_bytes: transmit buffer [bytes]; a packet that does not fit is dropped.
    """

    bps: float = PAPER_RADIO_BPS
    latency_s: float = 0.002
    jitter_s: float = 0.0
    loss: float = 0.0
    reorder: float = 0.0
    reorder_delay_s: float = 0.005
    queue_bytes: int = 1024

    def __post_init__(self) -> None:
        checks = {
            "bps": self.bps > 0,
            "latency_s": self.latency_s >= 0,
            "jitter_s": self.jitter_s >= 0,
            "loss": 0 <= self.loss <= 1,
            "reorder": 0 <= self.reorder <= 1,
            "reorder_delay_s": self.reorder_delay_s >= 0,
            "queue_bytes": self.queue_bytes > 0,
        }
        for name, ok in checks.items():
            if not ok:
                raise ConfigError(f"radio.{name}: out of range ({getattr(self, name)})")


class RadioModel:
    """Computes when (and whether) each packet arrives; seeded, so runs repeat exactly.

    The transmitter sends one packet at a time (serialisation at ``bps``); a packet
    arriving at a full buffer is dropped ("overflow"); then loss, latency, jitter and
    reordering apply.
    """

    def __init__(self, params: RadioParams, rng: np.random.Generator) -> None:
        self.params = params
        self.rng = rng
        self.busy_until = -np.inf
        self.counts = {"sent": 0, "lost": 0, "overflow": 0, "reordered": 0}

    def deliver_time(self, t_send: float, size: int) -> float | None:
        """Arrival time [s] of a packet of ``size`` bytes sent at ``t_send``, or None if lost."""
        p = self.params
        self.counts["sent"] += 1
        start = max(t_send, self.busy_until)
        backlog_bytes = (start - t_send) * p.bps / UART_BITS_PER_BYTE
        if backlog_bytes + size > p.queue_bytes:
            self.counts["overflow"] += 1
            return None
        self.busy_until = start + size * UART_BITS_PER_BYTE / p.bps
        if p.loss and self.rng.random() < p.loss:
            self.counts["lost"] += 1
            return None
        t = self.busy_until + p.latency_s
        if p.jitter_s:
            t += abs(self.rng.normal(0.0, p.jitter_s))
        if p.reorder and self.rng.random() < p.reorder:
            self.counts["reordered"] += 1
            t += p.reorder_delay_s
        return t


class RadioLink:
    """A live radio: ``send(packet)`` now, ``deliver(packet)`` called at its arrival time.

    A background thread releases packets in arrival order on the real clock
    (``time.perf_counter``). :meth:`close` waits for the packets in flight to arrive
    on time (``drain=True``) or discards them.
    """

    def __init__(
        self, deliver: Callable[[bytes], None], params: RadioParams, rng: np.random.Generator
    ) -> None:
        self.model = RadioModel(params, rng)
        self._deliver = deliver
        self._heap: list[tuple[float, int, bytes]] = []
        self._count = 0
        self._cv = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._loop, name="radio-link", daemon=True)
        self._thread.start()

    def send(self, packet: bytes) -> None:
        with self._cv:
            t = self.model.deliver_time(time.perf_counter(), len(packet))
            if t is None:
                return
            self._count += 1
            heapq.heappush(self._heap, (t, self._count, bytes(packet)))
            self._cv.notify()

    def _loop(self) -> None:
        while True:
            with self._cv:
                while not self._heap and not self._closed:
                    self._cv.wait()
                if not self._heap and self._closed:
                    return
                due, _, pkt = self._heap[0]
                wait = due - time.perf_counter()
                if wait > 0:
                    self._cv.wait(timeout=wait)
                    continue
                heapq.heappop(self._heap)
            self._deliver(pkt)

    def close(self, drain: bool = True) -> None:
        """Stop the link after the packets in flight arrived (``drain``) or drop them."""
        with self._cv:
            self._closed = True
            if not drain:
                self._heap.clear()
            self._cv.notify()
        self._thread.join(timeout=10.0)
