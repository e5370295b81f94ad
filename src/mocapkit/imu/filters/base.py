"""The contract every orientation filter follows (after vqf's Params / State / update split).

A filter estimates ``q_world_sensor`` [w, x, y, z] in an ENU world (z up, and in 9D
x towards magnetic east, y towards magnetic north). It has

- ``params``: a frozen, validated dataclass (sampling rate and gains);
- ``state``: a dataclass that can be copied out (:meth:`get_state`) and put back
  (:meth:`set_state`), so a run can be checkpointed and resumed;
- :meth:`update`: one sample (gyr rad/s, acc m/s^2, optional mag) -> quaternion (4,);
- :meth:`run`: a batch (N, 3) -> (N, 4), continuing from the current state, so that
  ``run(a); run(b)`` equals ``run(concat(a, b))`` (the split-run property);
- 6D (``mag=None``) and 9D modes;
- ``backend="reference"`` (readable numpy/Python) and ``backend="fast"`` (numba), which
  agree to 1e-9 on real data.
"""

from __future__ import annotations

import copy
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import numpy as np

from mocapkit._validate import FloatArray, as_float_array, check_finite, check_shape
from mocapkit.errors import ConfigError
from mocapkit.series import ImuRecording, OrientationSeries

Backend = Literal["fast", "reference"]


@dataclass(frozen=True)
class FilterParams:
    """Base parameters: the sampling rate [Hz]. Filters subclass and add gains."""

    rate_hz: float

    def __post_init__(self) -> None:
        if not (np.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise ConfigError(
                f"rate_hz: expected a positive sampling rate in Hz, got {self.rate_hz}"
            )

    @property
    def dt(self) -> float:
        """Sample interval [s]."""
        return 1.0 / self.rate_hz


class OrientationFilter(ABC):
    """Abstract orientation filter; see the module docstring for the contract."""

    name: ClassVar[str]

    def __init__(self, params: FilterParams, backend: Backend = "fast") -> None:
        if backend not in ("fast", "reference"):
            raise ConfigError(f"backend: expected 'fast' or 'reference', got {backend!r}")
        self.params = params
        self.backend: Backend = backend

    # -- state -----------------------------------------------------------------------------
    @abstractmethod
    def get_state(self) -> Any:
        """A deep copy of the state (checkpoint)."""

    @abstractmethod
    def set_state(self, state: Any) -> None:
        """Restore a checkpoint taken with :meth:`get_state`."""

    @property
    @abstractmethod
    def quat(self) -> FloatArray:
        """Current estimate ``q_world_sensor`` (4,)."""

    # -- processing ------------------------------------------------------------------------
    @abstractmethod
    def _run(self, gyr: FloatArray, acc: FloatArray, mag: FloatArray | None) -> FloatArray:
        """Process validated (N, 3) arrays from the current state; return (N, 4)."""

    def update(self, gyr: Any, acc: Any, mag: Any = None) -> FloatArray:
        """Process one sample; returns the new ``q_world_sensor`` (4,)."""
        g = as_float_array(gyr, "gyr").reshape(1, -1)
        a = as_float_array(acc, "acc").reshape(1, -1)
        m = None if mag is None else as_float_array(mag, "mag").reshape(1, -1)
        return self.run(g, a, m)[0]

    def run(self, gyr: Any, acc: Any, mag: Any = None) -> FloatArray:
        """Process a batch (N, 3) from the current state; returns (N, 4) quaternions."""
        g = as_float_array(gyr, "gyr")
        check_shape(g, "gyr", None, 3)
        a = as_float_array(acc, "acc")
        check_shape(a, "acc", g.shape[0], 3)
        fix = "Interpolate or drop the sample (ImuRecording.with_gaps_interpolated)."
        check_finite(g, "gyr", fix)
        check_finite(a, "acc", fix)
        m = None
        if mag is not None:
            m = as_float_array(mag, "mag")
            check_shape(m, "mag", g.shape[0], 3)
            check_finite(m, "mag", fix)
        return self._run(np.ascontiguousarray(g), np.ascontiguousarray(a), m)

    def run_recording(self, rec: ImuRecording, use_mag: bool = True) -> OrientationSeries:
        """Run over a whole recording (9D when it has a magnetometer and ``use_mag``)."""
        mag = rec.mag if use_mag else None
        q = self.run(rec.gyr, rec.acc, mag)
        return OrientationSeries(rec.time, q, name=rec.name)

    def copy(self) -> OrientationFilter:
        return copy.deepcopy(self)


FilterFactory = Callable[..., OrientationFilter]
_REGISTRY: dict[str, FilterFactory] = {}


def register_filter(name: str) -> Callable[[FilterFactory], FilterFactory]:
    """Class decorator adding a filter to the registry under ``name``."""

    def deco(factory: FilterFactory) -> FilterFactory:
        _REGISTRY[name] = factory
        return factory

    return deco


def available_filters() -> list[str]:
    """Names accepted by :func:`make_filter`."""
    import mocapkit.imu.filters  # noqa: F401  (registers the built-in filters)

    return sorted(_REGISTRY)


def make_filter(
    name: str, rate_hz: float, backend: Backend = "fast", **params: Any
) -> OrientationFilter:
    """Build a registered filter by name, e.g. ``make_filter("miller", 100.0, alpha=0.5)``."""
    names = available_filters()
    if name not in _REGISTRY:
        raise ConfigError(f"filter: unknown name {name!r}; choose one of {', '.join(names)}")
    return _REGISTRY[name](rate_hz=rate_hz, backend=backend, **params)
