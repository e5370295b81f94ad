"""The sensor bus and the hub that polls it (paper section 4).

The hub (the "capture subject interface") is the bus master. Each round it polls IDs
1..max_id in turn; a node that does not answer is asked ``tries - 1`` more times (the
paper: "tries two additional times in case the sensor is in a critical section"), then
the hub moves on. It keeps only packets whose structure and CRC are valid, and sends
orientation packets of one round as one BUNDLE (far fewer bytes on the radio).

The bus is pluggable: anything with :meth:`Bus.request`. :class:`InProcessBus` hosts
:class:`~mocapkit.suit.node.SensorNode` objects; a node may be "busy" with a given
probability (seeded), which is what the retries are for.
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from mocapkit.errors import ConfigError
from mocapkit.suit.node import SensorNode
from mocapkit.suit.protocol import (
    HEADER_SIZE,
    MAX_SENSOR_ID,
    OVERHEAD,
    Kind,
    crc16,
    frame,
)

log = logging.getLogger(__name__)


class Bus(ABC):
    """A master-slave bus: the hub addresses one sensor ID at a time."""

    @abstractmethod
    def request(self, sensor_id: int, t: float) -> list[bytes] | None:
        """Poll ``sensor_id`` at bus time ``t`` [s]: its packets, or None if nobody answered."""


class InProcessBus(Bus):
    """Nodes in this process; each request to a busy node goes unanswered."""

    def __init__(self, busy_probability: float = 0.0, rng: np.random.Generator | None = None):
        if not 0.0 <= busy_probability < 1.0:
            raise ConfigError(f"busy_probability: expected [0, 1), got {busy_probability}")
        if busy_probability > 0 and rng is None:
            raise ConfigError("rng: a bus with busy nodes draws; pass np.random.default_rng(seed)")
        self.busy_probability = busy_probability
        self.rng = rng
        self.nodes: dict[int, SensorNode] = {}

    def attach(self, node: SensorNode) -> None:
        """Plug a node in (before or during a session)."""
        if node.sensor_id in self.nodes:
            raise ConfigError(f"sensor_id {node.sensor_id}: already on the bus")
        self.nodes[node.sensor_id] = node

    def detach(self, sensor_id: int) -> None:
        """Unplug a node."""
        self.nodes.pop(sensor_id, None)

    def request(self, sensor_id: int, t: float) -> list[bytes] | None:
        node = self.nodes.get(sensor_id)
        if node is None:
            return None
        busy = self.busy_probability and self.rng is not None
        if busy and self.rng is not None and self.rng.random() < self.busy_probability:
            return None
        return node.answer(t)


@dataclass
class HubStats:
    rounds: int = 0
    polls: int = 0
    retries: int = 0
    silent: int = 0
    invalid: int = 0
    forwarded: int = 0


class Hub:
    """Bus master: polls IDs 1..max_id, ``tries`` attempts each, buffers valid packets.

    Args:
        bus: the bus to poll.
        max_id: highest ID polled (the paper: 15).
        tries: attempts per ID per round (the paper: 1 + 2 retries).
        bundle: pack a round's ORIENTATION packets into one BUNDLE.
        clock_offset_us: the hub clock at bus time 0 [us] (stamps bundles).
    """

    def __init__(
        self,
        bus: Bus,
        max_id: int = MAX_SENSOR_ID,
        tries: int = 3,
        bundle: bool = True,
        clock_offset_us: int = 0,
    ) -> None:
        if not 1 <= max_id <= MAX_SENSOR_ID:
            raise ConfigError(f"max_id: expected 1..{MAX_SENSOR_ID}, got {max_id}")
        if tries < 1:
            raise ConfigError(f"tries: expected >= 1, got {tries}")
        self.bus = bus
        self.max_id = max_id
        self.tries = tries
        self.bundle = bundle
        self.clock_offset_us = clock_offset_us
        self.stats = HubStats()
        self._round_seq = 0

    @staticmethod
    def _valid(pkt: bytes) -> bool:
        if len(pkt) < OVERHEAD or len(pkt) != OVERHEAD + pkt[3]:
            return False
        return crc16(pkt[1:-2]) == (pkt[-2] | (pkt[-1] << 8))

    def poll_round(self, t: float) -> list[bytes]:
        """One round at bus time ``t`` [s]: the frames to send to the host, in order."""
        s = self.stats
        s.rounds += 1
        out: list[bytes] = []
        entries: list[bytes] = []
        for sid in range(1, self.max_id + 1):
            answer = None
            for attempt in range(self.tries):
                s.polls += 1
                s.retries += attempt > 0
                answer = self.bus.request(sid, t)
                if answer is not None:
                    break
            if answer is None:
                s.silent += 1
                continue
            for pkt in answer:
                if not self._valid(pkt):
                    s.invalid += 1
                    log.warning("hub: dropped an invalid packet from sensor %d", sid)
                    continue
                if self.bundle and pkt[1] & 0x0F == Kind.ORIENTATION:
                    entries.append(bytes([sid]) + pkt[HEADER_SIZE : HEADER_SIZE + 6])
                else:
                    out.append(pkt)
        if entries:
            out.append(frame(Kind.BUNDLE, 0, self._round_seq, self._t_us(t), b"".join(entries)))
            self._round_seq = (self._round_seq + 1) & 0xFFFF
        s.forwarded += len(out)
        return out

    def _t_us(self, t: float) -> int:
        return (round(t * 1e6) + self.clock_offset_us) & 0xFFFFFFFF
