"""Receiver configuration and per-sensor state (split from ``receiver.py``)."""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any, Literal, Protocol

from mocapkit.errors import ConfigError
from mocapkit.suit.protocol import MAX_SENSOR_ID
from mocapkit.suit.samples import SensorStats, SuitSample
from mocapkit.suit.tracks import SensorTrack

_WRAP_US = 1 << 32


class FrameRecorder(Protocol):
    """What the receiver needs from a recorder (``recording.McapRecorder``)."""

    def write_frame(self, data: bytes, t_arrival_ns: int, source: Any) -> None: ...

    def write_sample(self, sample: SuitSample) -> None: ...


@dataclass(frozen=True)
class ReceiverConfig:
    """Receiver settings.

    Attributes:
        allowed_ids: sensor IDs to accept (None: any of 1..15, new ones are "added").
        protocols: ``"suit"``, ``"slimevr"`` or ``"auto"`` (by the first byte).
        reorder_window_s: how long an out-of-order packet may wait for a gap to fill [s].
        missing_after_s: a sensor silent this long is "missing" [s].
        stale_after_s: a sensor that keeps sending but brings nothing new this long (only
            duplicates, or a sensor clock that does not advance: a frozen node) is "stale" [s].
        source_rate_hz, source_burst: token bucket per source address [packets/s, packets];
            ``math.inf`` turns it off (a file replayed as fast as possible is one source
            far above any live rate).
        queue_per_sensor: bounded queue length per sensor (oldest dropped when full).
    """

    allowed_ids: frozenset[int] | None = None
    protocols: Literal["suit", "slimevr", "auto"] = "auto"
    reorder_window_s: float = 0.02
    missing_after_s: float = 0.5
    stale_after_s: float = 0.5
    source_rate_hz: float = 60_000.0
    source_burst: float = 20_000.0
    queue_per_sensor: int = 8192

    def __post_init__(self) -> None:
        if self.protocols not in ("suit", "slimevr", "auto"):
            raise ConfigError(f"protocols: expected suit, slimevr or auto, got {self.protocols!r}")
        for name in (
            "reorder_window_s",
            "missing_after_s",
            "stale_after_s",
            "source_rate_hz",
            "source_burst",
        ):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected > 0, got {getattr(self, name)}")
        if self.queue_per_sensor < 1:
            raise ConfigError(f"queue_per_sensor: expected >= 1, got {self.queue_per_sensor}")
        if self.allowed_ids is not None and not all(
            1 <= i <= MAX_SENSOR_ID for i in self.allowed_ids
        ):
            raise ConfigError(f"allowed_ids: expected IDs in 1..{MAX_SENSOR_ID}")


class SensorState:
    """Receiver-side state of one sensor."""

    def __init__(self, sensor_id: int, cfg: ReceiverConfig) -> None:
        self.stats = SensorStats(sensor_id)
        self.tracks: dict[object, SensorTrack] = {}
        self.cfg = cfg
        self.queue: deque[SuitSample] = deque()
        self.t_wraps = 0
        self.t_last_us: int | None = None
        self.offset_min = math.inf
        self.latencies: deque[float] = deque(maxlen=4096)
        self.window_start = 0
        self.window_count = 0
        self.t_sensor_max = -math.inf
        self.slime_seq = -1  # SlimeVR: per-sensor count of accepted samples
        self.last_fresh_ns = 0

    def track(self, key: object) -> SensorTrack:
        tr = self.tracks.get(key)
        if tr is None:
            tr = self.tracks[key] = SensorTrack(self.cfg.reorder_window_s)
        return tr

    def unwrap_time(self, t_us: int) -> float:
        if self.t_last_us is not None and t_us < self.t_last_us - (_WRAP_US >> 1):
            self.t_wraps += 1
        elif self.t_last_us is not None and t_us > self.t_last_us + (_WRAP_US >> 1):
            return (self.t_wraps - 1) * 4294.967296 + t_us * 1e-6  # late, before a wrap
        self.t_last_us = t_us
        return self.t_wraps * 4294.967296 + t_us * 1e-6
