"""The suit simulator: body motion -> IMU signals -> nodes -> hub -> frames on a real clock.

``SuitSimulator(poses)`` synthesises every sensor's gyroscope, accelerometer and
magnetometer (``mocapkit.imu.simulate``), puts one :class:`SensorNode` per sensor on an
:class:`InProcessBus`, and runs the :class:`Hub` once per round. :meth:`timeline` gives
the frames with their send times; :meth:`stream` sends them on the real clock (or faster)
to any ``send(bytes)`` callable (a UDP or serial transport, or a :class:`RadioLink`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from mocapkit.errors import ConfigError
from mocapkit.imu.filters import make_filter
from mocapkit.imu.simulate import EarthField, ImuErrorModel, MagDisturbance, simulate_imu
from mocapkit.series import ImuRecording, PoseSeries
from mocapkit.suit.bus import Hub, InProcessBus
from mocapkit.suit.motions import suit_poses
from mocapkit.suit.node import NodeMode, SensorNode
from mocapkit.suit.recording import paced


@dataclass(frozen=True)
class SuitSimConfig:
    """How the simulated suit behaves.

    Attributes:
        mode: ``"raw"`` (nodes forward samples; host-side fusion) or ``"orientation"``
            (on-node fusion with ``filter_name``, bundled by the hub).
        filter_name: orientation filter of the nodes (``mocapkit.imu.filters`` registry).
        errors: IMU error model (None: ideal sensors).
        earth: gravity and magnetic field.
        busy_probability: chance that a node misses a poll ("critical section").
        tries: poll attempts per ID per round (the paper: 3).
        round_hz: hub rounds per second (None: the sampling rate).
        random_clocks: give each node a random clock offset (exercises wrap-around).
    """

    mode: NodeMode = "raw"
    filter_name: str = "miller"
    errors: ImuErrorModel | None = None
    earth: EarthField = field(default_factory=EarthField)
    busy_probability: float = 0.0
    tries: int = 3
    round_hz: float | None = None
    random_clocks: bool = True


class SuitSimulator:
    """See the module docstring.

    Args:
        poses: sensor ID (1..15) -> that sensor's pose over time (all on one time base).
        config: :class:`SuitSimConfig`.
        rng: random generator (noise, busy nodes, clock offsets).
        disturbances: magnetic disturbances applied to every sensor.
    """

    def __init__(
        self,
        poses: dict[int, PoseSeries],
        config: SuitSimConfig | None = None,
        rng: np.random.Generator | None = None,
        disturbances: Sequence[MagDisturbance] = (),
    ) -> None:
        if not poses:
            raise ConfigError("poses: the suit needs at least one sensor")
        self.config = cfg = config or SuitSimConfig()
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.recordings: dict[int, ImuRecording] = {}
        self.bus = InProcessBus(cfg.busy_probability, self.rng)
        for sid, pose in sorted(poses.items()):
            rec = simulate_imu(pose, cfg.errors, cfg.earth, disturbances, self.rng, name=pose.name)
            self.recordings[sid] = rec
            filt = make_filter(cfg.filter_name, rec.rate_hz) if cfg.mode == "orientation" else None
            offset = int(self.rng.integers(0, 1 << 32)) if cfg.random_clocks else 0
            self.bus.attach(SensorNode(sid, rec, cfg.mode, filt, clock_offset_us=offset))
        first = next(iter(self.recordings.values()))
        self.time = first.time
        self.rate_hz = first.rate_hz
        self._timeline: list[tuple[float, bytes]] | None = None
        self.hub = Hub(self.bus, max_id=15, tries=cfg.tries, bundle=cfg.mode == "orientation")

    @classmethod
    def from_motion(
        cls,
        motion: str,
        n_sensors: int,
        duration_s: float,
        rate_hz: float,
        config: SuitSimConfig | None = None,
        rng: np.random.Generator | None = None,
    ) -> SuitSimulator:
        """A suit of ``n_sensors`` on a motion of :mod:`mocapkit.suit.motions`."""
        return cls(suit_poses(motion, n_sensors, duration_s, rate_hz), config, rng)

    def timeline(self) -> list[tuple[float, bytes]]:
        """Every frame the hub sends, with its send time [s] (one hub round per tick).

        Computed once (the nodes and the hub advance through the motion), then reused.
        """
        if self._timeline is not None:
            return self._timeline
        round_hz = self.config.round_hz or self.rate_hz
        t_end = float(self.time[-1])
        ticks = np.arange(float(self.time[0]), t_end + 0.5 / round_hz, 1.0 / round_hz)
        out: list[tuple[float, bytes]] = []
        for t in ticks:
            for frame in self.hub.poll_round(float(t) + 1e-9):
                out.append((float(t), frame))
        self._timeline = out
        return out

    def stream(
        self,
        send: Callable[[bytes], None],
        speed: float = 1.0,
        stop: threading.Event | None = None,
        on_sent: Callable[[int, int], None] | None = None,
    ) -> int:
        """Send the timeline on the real clock (``speed`` 1: real time, 0: flat out)."""
        return paced(self.timeline(), send, speed, stop, on_sent)
