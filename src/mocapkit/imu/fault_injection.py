"""Faults injected into an IMU recording, to test what a filter does after them.

Used by ``benchmarks/polaris_faults.py`` and the recovery tests; useful to anyone who
wants to know how their pipeline behaves when a sensor misbehaves. Each fault starts at
sample ``at`` and returns a new :class:`Faulted` (the inputs are not modified):

=================  ==========================================================  =========
kind               what happens                                                 size
=================  ==========================================================  =========
gyr_saturation     every gyroscope axis pinned at +-``gyr_range`` (a shock)     seconds
time_jump          the clock jumps forward: every later stamp + ``size``        seconds
missing            ``size`` seconds of samples lost (stamps keep their time)    seconds
duplicate_stamp    sample ``at`` carries the previous sample's stamp           --
backwards_stamp    sample ``at`` is stamped one step before the previous one    --
mag_dropout        magnetometer rows NaN (the documented gap marker)            seconds
mag_spike          a field three times the Earth's added along the sensor x     seconds
acc_impact         16 g added along the sensor's x axis                         seconds
=================  ==========================================================  =========
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError

FAULT_KINDS = (
    "gyr_saturation",
    "time_jump",
    "missing",
    "duplicate_stamp",
    "backwards_stamp",
    "mag_dropout",
    "mag_spike",
    "acc_impact",
)
#: [rad/s] the range most MEMS gyroscopes in body-worn sensors are set to (2000 deg/s).
DEFAULT_GYR_RANGE = np.radians(2000.0)
G = 9.81


@dataclass(frozen=True)
class Faulted:
    """A recording with a fault: ``time`` [s], ``gyr``, ``acc``, ``mag`` (N, 3) and
    ``source`` (N,), the index of each row in the clean recording (rows lost to a
    ``missing`` fault are absent); ``end`` is the first row after the fault."""

    time: FloatArray
    gyr: FloatArray
    acc: FloatArray
    mag: FloatArray
    source: np.ndarray
    end: int

    @property
    def dt(self) -> FloatArray:
        """Per-sample time steps (the first one the median step)."""
        steps = np.diff(self.time)
        return np.concatenate([[float(np.median(steps))], steps])


def inject(
    kind: str,
    time: FloatArray,
    gyr: FloatArray,
    acc: FloatArray,
    mag: FloatArray,
    at: int,
    size: float = 0.0,
    gyr_range: float = DEFAULT_GYR_RANGE,
    rng: np.random.Generator | None = None,
) -> Faulted:
    """``kind`` (see the module docstring) at sample ``at`` lasting ``size`` seconds."""
    if kind not in FAULT_KINDS:
        raise ConfigError(f"kind: unknown fault {kind!r}; expected one of {', '.join(FAULT_KINDS)}")
    n = time.shape[0]
    if not 1 <= at < n:
        raise ConfigError(f"at: sample {at} is outside 1..{n - 1}")
    rate = 1.0 / float(np.median(np.diff(time)))
    m = max(1, round(size * rate))
    t, g, a, b = time.copy(), gyr.copy(), acc.copy(), mag.copy()
    source = np.arange(n)
    end = min(n, at + m)
    if kind == "gyr_saturation":
        signs = np.where((rng or np.random.default_rng(0)).random(3) < 0.5, -1.0, 1.0)
        g[at:end] = signs * gyr_range
    elif kind == "time_jump":
        t[at:] += size
        end = at
    elif kind == "missing":
        keep = np.ones(n, dtype=bool)
        keep[at:end] = False
        return Faulted(t[keep], g[keep], a[keep], b[keep], source[keep], at)
    elif kind == "duplicate_stamp":
        t[at] = t[at - 1]
        end = at + 1
    elif kind == "backwards_stamp":
        t[at] = t[at - 1] - 1.0 / rate
        end = at + 1
    elif kind == "mag_dropout":
        b[at:end] = np.nan
    elif kind == "mag_spike":
        norm = float(np.median(np.linalg.norm(mag, axis=1)))
        b[at:end, 0] += 3.0 * norm
    else:  # acc_impact
        a[at:end, 0] += 16.0 * G
    return Faulted(t, g, a, b, source, end)
