"""A still start for any orientation filter: gyroscope bias and orientation from the
first seconds, while the sensor is held still (Miller et al., section 3).

The paper initialises each sensor by holding it in a known posture and cycling the
power: the node averages the accelerometer and magnetometer for ``g_ref`` and ``m_init``.
:class:`StillStartFilter` does the same and also averages the gyroscope, whose mean at
rest is its bias: after ``still_s`` seconds of samples the bias is that mean, the wrapped
filter's orientation is re-resolved from the window's mean directions
(:meth:`OrientationFilter.reinitialize`), and from then on every gyroscope sample has the
bias removed; a filter that estimates the bias itself is told
(:meth:`OrientationFilter.gyr_bias_removed`, with the window's standard error). Neither
miller nor bachmann estimates a gyroscope bias: uncorrected, a consumer-grade bias of
0.01 rad/s turns into several degrees of slowly varying error (the filters' time constants
are 6-9 s), which teleoperation sees as drift.

If the gyroscope moved during the window (its mean rate above ``max_motion_rad_s``, more
than any plausible bias, or any sample that far from the mean), the window is not a
rest: no bias is
applied (a warning names the sensor) and :attr:`StillStartFilter.bias_ok` stays False.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray, as_float_array, check_shape
from mocapkit.errors import ConfigError
from mocapkit.imu.filters.base import FilterState, OrientationFilter
from mocapkit.imu.filters.inputs import FilterInputs

log = logging.getLogger(__name__)

#: A gyroscope sample further than this from the window's mean rate [rad/s] means the
#: sensor moved (noise of a consumer-grade gyroscope is ~0.005 rad/s per sample).
MAX_MOTION_RAD_S = 0.1


class StillStartFilter(OrientationFilter):
    """Wraps ``inner`` (see the module docstring).

    Args:
        inner: the filter to run (``make_filter(name, rate_hz)``).
        still_s: duration of the still start [s] (0: pass everything through unchanged).
        max_motion_rad_s: motion threshold of the window [rad/s].
        label: sensor name used in messages.
    """

    name = "still-start"

    def __init__(
        self,
        inner: OrientationFilter,
        still_s: float = 1.0,
        max_motion_rad_s: float = MAX_MOTION_RAD_S,
        label: str = "sensor",
    ) -> None:
        if not (np.isfinite(still_s) and still_s >= 0):
            raise ConfigError(f"still_s: expected a duration >= 0 in seconds, got {still_s}")
        super().__init__(inner.params, inner.backend)
        self.inner = inner
        self.label = label
        self.max_motion_rad_s = float(max_motion_rad_s)
        self.n_still = round(still_s * inner.params.rate_hz)
        self.bias = np.zeros(3)
        """Gyroscope bias removed from every sample after the window [rad/s] (3,)."""
        self.bias_ok = False
        self.done = self.n_still == 0
        self._gyr: list[FloatArray] = []
        self._acc: list[FloatArray] = []
        self._mag: list[FloatArray] = []

    # the wrapped filter owns the orientation state
    @property
    def quat(self) -> FloatArray:
        return self.inner.quat

    @property
    def initialised(self) -> bool:
        return self.inner.initialised

    def get_state(self) -> FilterState:
        return self.inner.get_state()

    def set_state(self, state: FilterState) -> None:
        self.inner.set_state(state)

    def reset(self, quat: Any = None, dip: float | None = None) -> None:
        """Start over, including the still start."""
        self.inner.reset(quat, dip)
        self.bias = np.zeros(3)
        self.bias_ok = False
        self.done = self.n_still == 0
        self._gyr, self._acc, self._mag = [], [], []

    def reinitialize(self, acc_window: Any, mag_window: Any = None) -> FloatArray:
        return self.inner.reinitialize(acc_window, mag_window)

    def _run_reference(self, inputs: FilterInputs) -> FloatArray:  # pragma: no cover
        return self.inner._run_reference(inputs)

    def _run_fast(self, inputs: FilterInputs) -> FloatArray:  # pragma: no cover
        return self.inner._run_fast(inputs)

    def run(self, gyr: Any, acc: Any, mag: Any = None, dt: Any = None) -> FloatArray:
        """Like :meth:`OrientationFilter.run`; the bias is removed once the window is full."""
        if self.done:
            if self.bias_ok:
                gyr = as_float_array(gyr, "gyr") - self.bias
            return self.inner.run(gyr, acc, mag, dt)
        g = as_float_array(gyr, "gyr")
        check_shape(g, "gyr", None, 3)
        a = np.asarray(acc, dtype=np.float64)
        m = None if mag is None else np.asarray(mag, dtype=np.float64)
        k = min(len(g), self.n_still - len(self._gyr))
        d = None if dt is None or np.ndim(dt) == 0 else np.asarray(dt, dtype=np.float64)
        m_k = None if m is None else m[:k]
        first = self.inner.run(g[:k], a[:k], m_k, dt if d is None else d[:k])
        self._gyr.extend(g[:k])
        self._acc.extend(a[:k])
        if m is not None:
            self._mag.extend(m[:k])
        if len(self._gyr) < self.n_still:
            return first
        self._finish()
        rest = self.run(g[k:], a[k:], None if m is None else m[k:], dt if d is None else d[k:])
        return np.concatenate([first, rest]) if len(rest) else first

    def _finish(self) -> None:
        gyr = np.array(self._gyr)
        mean = gyr.mean(axis=0)
        spread = float(np.max(np.linalg.norm(gyr - mean, axis=1)))
        self.done = True
        motion = max(spread, float(np.linalg.norm(mean)))
        if motion > self.max_motion_rad_s:
            log.warning(
                "%s: moved during the still start (gyroscope %.3f rad/s, more than %.3f): no "
                "gyroscope bias removed; hold the sensor still for the first %.1f s",
                self.label,
                motion,
                self.max_motion_rad_s,
                self.n_still / self.params.rate_hz,
            )
        else:
            self.bias = mean
            self.bias_ok = True
            # a filter that estimates the bias itself must know its input moves by -mean
            # (its estimate shifts; the window's spread is a measurement of what is left)
            sigma = float(np.mean(np.std(gyr, axis=0))) / np.sqrt(len(gyr))
            self.inner.gyr_bias_removed(mean, sigma if sigma > 0 else None)
            mag = np.array(self._mag) if self._mag else None
            if mag is not None and np.isnan(mag).all():
                mag = None
            self.inner.reinitialize(np.array(self._acc), mag)
        self._gyr, self._acc, self._mag = [], [], []
