"""A sensor node: one IMU with its own microcontroller (paper section 4).

In ``"orientation"`` mode the node runs an orientation filter on its own samples (on-node
fusion, as in the paper) and answers a poll with its latest ORIENTATION packet; in
``"raw"`` mode it answers with every RAW sample it has not sent yet (host-side fusion).
Its clock is the recording's time plus ``clock_offset_us`` (a node does not know the
host's time).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from mocapkit.errors import ConfigError
from mocapkit.imu.filters.base import OrientationFilter
from mocapkit.series import ImuRecording
from mocapkit.suit.batch import encode_raw_many
from mocapkit.suit.protocol import MAX_SENSOR_ID, encode_orientation, encode_status

NodeMode = Literal["orientation", "raw"]


class SensorNode:
    """One sensor with ID 1..15 replaying an IMU recording on the bus's clock.

    Args:
        sensor_id: bus address 1..15.
        recording: the samples this node's IMU produces (e.g. from ``simulate_imu``).
        mode: ``"orientation"`` (needs ``orientation_filter``) or ``"raw"``.
        orientation_filter: the on-node filter (``make_filter(name, rate_hz)``).
        clock_offset_us: the node clock at recording time 0 [us].
        max_raw_per_poll: at most this many RAW packets per answer (the rest wait).
    """

    def __init__(
        self,
        sensor_id: int,
        recording: ImuRecording,
        mode: NodeMode = "raw",
        orientation_filter: OrientationFilter | None = None,
        clock_offset_us: int = 0,
        max_raw_per_poll: int = 64,
    ) -> None:
        if not 1 <= sensor_id <= MAX_SENSOR_ID:
            raise ConfigError(f"sensor_id: expected 1..{MAX_SENSOR_ID}, got {sensor_id}")
        if mode not in ("orientation", "raw"):
            raise ConfigError(f"mode: expected 'orientation' or 'raw', got {mode!r}")
        if mode == "orientation" and orientation_filter is None:
            raise ConfigError(
                "orientation_filter: on-node fusion needs a filter, e.g. "
                "make_filter('miller', rate_hz)"
            )
        self.sensor_id = sensor_id
        self.recording = recording
        self.mode: NodeMode = mode
        self.filter = orientation_filter
        self.max_raw_per_poll = max_raw_per_poll
        self.t_us = (np.round(recording.time * 1e6).astype(np.int64) + clock_offset_us) & (
            0xFFFFFFFF
        )
        self._next = 0  # first sample not yet processed
        self._sent = 0  # first RAW sample not yet sent
        self._seq = 0
        self._status_seq = 0
        self._raw: list[bytes] = []
        if mode == "raw":
            self._raw = encode_raw_many(
                sensor_id, 0, self.t_us, recording.gyr, recording.acc, recording.mag
            )
        self.quat: np.ndarray | None = None

    @property
    def finished(self) -> bool:
        n = self.recording.n_samples
        return self._next >= n and (self.mode != "raw" or self._sent >= n)

    def _advance(self, t: float) -> bool:
        """Process the samples with time <= t; True if there was a new one."""
        stop = int(np.searchsorted(self.recording.time, t, side="right"))
        if stop <= self._next:
            return False
        if self.mode == "orientation":
            assert self.filter is not None
            rec = self.recording
            mag = None if rec.mag is None else rec.mag[self._next : stop]
            q = self.filter.run(rec.gyr[self._next : stop], rec.acc[self._next : stop], mag)
            self.quat = q[-1]
        self._next = stop
        return True

    def answer(self, t: float) -> list[bytes]:
        """The node's answer to a poll at bus time ``t`` [s] (may be empty: nothing new)."""
        fresh = self._advance(t)
        if self.mode == "raw":
            stop = min(self._next, self._sent + self.max_raw_per_poll)
            out = self._raw[self._sent : stop]
            self._sent = stop
            return out
        if not fresh or self.quat is None:
            return []
        pkt = encode_orientation(
            self.sensor_id, self._seq, int(self.t_us[self._next - 1]), self.quat
        )
        self._seq += 1
        return [pkt]

    def status(self, t: float, battery_mv: int = 3900, temperature_c: float = 30.0) -> bytes:
        """A STATUS packet at bus time ``t``."""
        i = max(0, min(self._next, self.recording.n_samples) - 1)
        pkt = encode_status(
            self.sensor_id, self._status_seq, int(self.t_us[i]), battery_mv, temperature_c
        )
        self._status_seq += 1
        return pkt
