"""Host-side fusion: the nodes forward RAW samples, the host runs one filter per sensor.

The alternative to on-node fusion (the paper's design): the host's filter can be any
in the registry (``mocapkit.imu.filters``), it sees every sample, and a better filter
needs no firmware update. Use it between the receiver and the pipeline::

    fusion = HostFusion("miller", rate_hz=1000.0)
    for sample in rx.samples():
        out = fusion.process(sample)     # ORIENTATION samples pass through unchanged
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace
from typing import Any

import numpy as np

from mocapkit.errors import ConfigError
from mocapkit.imu.filters import make_filter
from mocapkit.imu.filters.base import OrientationFilter
from mocapkit.suit.protocol import Kind
from mocapkit.suit.samples import SuitSample


class HostFusion:
    """One orientation filter per sensor, fed with that sensor's RAW samples in order.

    Args:
        filter_name: a registered filter (``available_filters()``).
        rate_hz: the sensors' sampling rate [Hz].
        use_mag: use magnetometer samples when present (9D), else 6D.
        params: extra filter parameters (gains).
    """

    def __init__(
        self, filter_name: str, rate_hz: float, use_mag: bool = True, **params: Any
    ) -> None:
        if not rate_hz > 0:
            raise ConfigError(f"rate_hz: expected > 0, got {rate_hz}")
        self.filter_name = filter_name
        self.rate_hz = rate_hz
        self.use_mag = use_mag
        self.params = params
        make_filter(filter_name, rate_hz, **params)  # fail early on a bad name or gain
        self.filters: dict[int, OrientationFilter] = {}

    def _filter(self, sensor_id: int) -> OrientationFilter:
        f = self.filters.get(sensor_id)
        if f is None:
            f = self.filters[sensor_id] = make_filter(self.filter_name, self.rate_hz, **self.params)
        return f

    def reset(self, sensor_id: int) -> None:
        """Forget a sensor's filter state (e.g. after a "back" or "restarted" event)."""
        self.filters.pop(sensor_id, None)

    def process(self, sample: SuitSample) -> SuitSample:
        """An ORIENTATION sample for a RAW one (same seq and times); others unchanged."""
        if sample.kind is not Kind.RAW or sample.gyr is None or sample.acc is None:
            return sample
        mag = sample.mag if self.use_mag else None
        q = self._filter(sample.sensor_id).update(sample.gyr, sample.acc, mag)
        return replace(sample, kind=Kind.ORIENTATION, quat=q)

    def process_batch(self, samples: Iterable[SuitSample]) -> list[SuitSample]:
        """Like :meth:`process` over a batch, running each filter once on its run of
        samples (``filter.run`` on (n, 3) arrays); the output keeps the input order."""
        items = list(samples)
        out: list[SuitSample] = list(items)
        by_sensor: dict[int, list[int]] = {}
        for i, s in enumerate(items):
            if s.kind is Kind.RAW and s.gyr is not None and s.acc is not None:
                by_sensor.setdefault(s.sensor_id, []).append(i)
        for sid, idx in by_sensor.items():
            gyr = np.array([items[i].gyr for i in idx])
            acc = np.array([items[i].acc for i in idx])
            mags = [items[i].mag for i in idx]
            mag = None
            if self.use_mag and all(m is not None for m in mags):
                mag = np.array(mags)
            q = self._filter(sid).run(gyr, acc, mag)
            for row, i in enumerate(idx):
                out[i] = replace(items[i], kind=Kind.ORIENTATION, quat=q[row])
        return out
