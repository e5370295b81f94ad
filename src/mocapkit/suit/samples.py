"""What the receiver hands to the pipeline: samples, sensor events, and statistics."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mocapkit.suit.protocol import Kind


@dataclass(slots=True)
class SuitSample:
    """One sample of one sensor, in sequence order for that sensor.

    Attributes:
        sensor_id: suit ID 1..15 (SlimeVR trackers are given IDs too).
        seq: unwrapped sequence number (per sensor and stream).
        t_sensor_s: the sensor's (or hub's, for bundles) clock [s], unwrapped;
            NaN when the source has no clock (SlimeVR).
        t_arrival_ns: ``time.perf_counter_ns()`` when the datagram was read.
        kind: ORIENTATION for orientations (also from bundles), RAW for IMU samples.
        quat: (4,) ``q_world_sensor`` [w, x, y, z] or None.
        gyr, acc, mag: (3,) sensor frame [rad/s, m/s^2, uT] or None.
        source: ``"suit"`` or ``"slimevr"``.
    """

    sensor_id: int
    seq: int
    t_sensor_s: float
    t_arrival_ns: int
    kind: Kind
    quat: np.ndarray | None = None
    gyr: np.ndarray | None = None
    acc: np.ndarray | None = None
    mag: np.ndarray | None = None
    source: str = "suit"


@dataclass(frozen=True, slots=True)
class SensorEvent:
    """A change in the set of sensors: ``"added"`` (first packet), ``"missing"`` (silent
    for ``missing_after_s``), ``"back"`` (a missing sensor spoke again), ``"stale"``
    (packets arrive but nothing new for ``stale_after_s``), ``"fresh"`` (a stale sensor
    sends new samples again), ``"restarted"`` (its sequence counter restarted)."""

    kind: str
    sensor_id: int
    t_ns: int


@dataclass
class SensorStats:
    """Per-sensor figures at the time of :meth:`Receiver.stats`."""

    sensor_id: int
    state: str = "ok"
    delivered: int = 0
    duplicate: int = 0
    stale: int = 0
    lost: int = 0
    reordered: int = 0
    queue_dropped: int = 0
    rate_hz: float = 0.0
    latency_ms_p50: float = float("nan")
    latency_ms_p99: float = float("nan")
    battery_mv: int | None = None
    last_arrival_ns: int = 0

    @property
    def loss_ratio(self) -> float:
        total = self.delivered + self.lost
        return self.lost / total if total else 0.0


@dataclass
class ReceiverStats:
    """Receiver-wide counters (``dropped`` by reason) and the per-sensor figures.

    ``latency_ms_*`` per sensor is *relative* latency: arrival minus sensor time, minus
    its smallest value seen (the unknown clock offset), so it shows queueing and jitter.
    """

    datagrams: int = 0
    bytes: int = 0
    dropped: dict[str, int] = field(default_factory=dict)
    sensors: dict[int, SensorStats] = field(default_factory=dict)

    @property
    def dropped_total(self) -> int:
        return sum(self.dropped.values())
