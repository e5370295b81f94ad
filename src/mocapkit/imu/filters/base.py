"""The contract every orientation filter follows (after vqf's Params / State / update split).

A filter estimates ``q_world_sensor`` [w, x, y, z] in an ENU world (z up, and in 9D
x towards magnetic east, y towards magnetic north). It has

- ``params``: a frozen, validated dataclass (sampling rate, gains, sensor ranges);
- ``state``: a :class:`FilterState` (subclasses add fields) that can be copied out
  (:meth:`~OrientationFilter.get_state`) and put back (:meth:`~OrientationFilter.set_state`),
  so a run can be checkpointed and resumed;
- :meth:`~OrientationFilter.update`: one sample (gyr rad/s, acc m/s^2, optional mag)
  -> quaternion (4,);
- :meth:`~OrientationFilter.run`: a batch (N, 3) -> (N, 4), continuing from the current
  state, so that ``run(a); run(b)`` equals ``run(concat(a, b))`` (the split-run property).
  Row k is the estimate at sample k's time, using the readings up to and including k
  (a gyroscope sample is the rate over the interval ending at its time stamp).
- 6D (``mag=None``) and 9D modes;
- ``backend="reference"`` (readable numpy/Python) and ``backend="fast"`` (numba), which
  agree to 1e-9 on real data.

Initialisation. A new filter is *uninitialised*: the first call to ``run``/``update``
takes the orientation from the first ``params.init_window_s`` seconds of samples (mean
accelerometer and magnetometer directions, :mod:`mocapkit.imu.initialisation`), in any
orientation, instead of starting from the identity. The window's samples are first
turned into one frame with the gyroscope, so a sensor that moves during the window
still starts right. :meth:`~OrientationFilter.reinitialize`
does the same on command at any time without touching the rest of the state (the
paper's wished-for software reset); :meth:`~OrientationFilter.reset` starts over or
from a given quaternion.

Bad input (checked here, once, for every filter; messages name the field and sample):

- wrong shapes, NaN or inf in ``gyr`` or ``acc``, non-positive or non-finite ``dt``:
  :class:`~mocapkit.errors.ShapeError` / :class:`~mocapkit.errors.DataError`;
- magnetometer gaps (all-NaN rows of ``mag``): documented fallback, those samples are
  processed as in 6D (gyroscope integration plus the accelerometer correction; the
  heading is held by the gyroscope). A partly NaN or infinite ``mag`` row is an error;
- a zero-norm (below 1e-6) accelerometer or magnetometer sample has no direction: its
  correction is skipped for that sample (fallback: gyroscope-only for that part);
- saturation, when the sensor's full-scale range is given in the params: a saturated
  accelerometer sample is not used for correction (its direction is wrong); a
  saturated gyroscope sample (at the range, or flat-topped: the same reading above
  4 rad/s three times in a row) is integrated as clipped, which is the only information
  there is, and a :class:`SensorSaturationWarning` names the first such sample;
  ``polaris`` then re-acquires its inclination and heading (its fault recovery);
- time gaps (a step longer than ``params.gap_factor`` nominal steps): held over one
  nominal step, never integrated, with a :class:`TimeGapWarning` naming the sample and
  the length (``last_report.gaps``); ``polaris`` re-acquires after it;
- every run leaves counts of these cases in :attr:`OrientationFilter.last_report`.

Timestamps: ``run`` takes an optional per-sample ``dt``; :meth:`run_recording` passes the
recording's own time steps (so a few dropped packets are integrated over their true
length; longer gaps are held, see above).
The recording's time stamps are validated (strictly increasing) by ``ImuRecording``.
"""

from __future__ import annotations

import copy
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np

from mocapkit._validate import FloatArray, as_float_array, check_shape
from mocapkit.errors import ConfigError, DataError
from mocapkit.imu.filters.inputs import (
    MIN_VECTOR_NORM,
    FilterInputs,
    RunReport,
    SensorSaturationWarning,
    TimeGapWarning,
    prepare_inputs,
)
from mocapkit.imu.initialisation import (
    orientation_from_references,
    reference_vectors,
    rotate_to_first_frame,
)
from mocapkit.series import ImuRecording, OrientationSeries

Backend = Literal["fast", "reference"]

# The recording's rate may differ from params.rate_hz by this fraction (clock drift).
_RATE_TOLERANCE = 0.01


def _check_optional_positive(value: float | None, name: str) -> None:
    if value is not None and not (np.isfinite(value) and value > 0):
        raise ConfigError(f"{name}: expected a positive full-scale range or None, got {value}")


@dataclass(frozen=True)
class FilterParams:
    """Base parameters. Filters subclass and add gains (all with defaults).

    Attributes:
        rate_hz: nominal sampling rate [Hz]; ``dt = 1 / rate_hz`` unless ``run`` is given ``dt``.
        init_window_s: duration [s] of the first samples averaged for the automatic
            initialisation (at least one sample).
        acc_range: accelerometer full-scale range [m/s^2], or None (unknown).
        gyr_range: gyroscope full-scale range [rad/s], or None (unknown; a flat-topped
            gyroscope axis is still detected as clipped).
        gap_factor: a time step longer than this many nominal steps (and than
            ``max_integrated_gap_s``) is a time gap (missing samples, a clock jump): held
            over one nominal step and warned about, never integrated; ``polaris``
            re-acquires its orientation after it. Shorter steps (a few dropped packets)
            are integrated over their true length, at the mean of the readings either
            side (the trapezoidal rule).
        max_integrated_gap_s: lost packets up to this long [s] are integrated with the
            next reading rather than held (a limb's rate hardly changes in a quarter of a
            second; holding loses the rotation, for good without a magnetometer).
    """

    rate_hz: float
    init_window_s: float = 0.1
    acc_range: float | None = None
    gyr_range: float | None = None
    gap_factor: float = 5.0
    max_integrated_gap_s: float = 0.25

    def __post_init__(self) -> None:
        if not (np.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise ConfigError(
                f"rate_hz: expected a positive sampling rate in Hz, got {self.rate_hz}"
            )
        if not (np.isfinite(self.init_window_s) and self.init_window_s >= 0):
            raise ConfigError(
                f"init_window_s: expected a duration >= 0 in seconds, got {self.init_window_s}"
            )
        _check_optional_positive(self.acc_range, "acc_range")
        _check_optional_positive(self.gyr_range, "gyr_range")
        if not self.gap_factor > 1.0:  # inf switches the check off
            raise ConfigError(
                f"gap_factor: expected a number of nominal steps > 1, got {self.gap_factor}"
            )

    @property
    def dt(self) -> float:
        """Sample interval [s]."""
        return 1.0 / self.rate_hz

    @property
    def init_samples(self) -> int:
        """Number of samples averaged for the automatic initialisation."""
        return max(1, round(self.init_window_s * self.rate_hz))


@dataclass(frozen=True)
class GainParams(FilterParams):
    """Parameters of a filter with one correction gain ``alpha`` [1/s] (time constant
    ``1/alpha``), applied once per sample as ``alpha dt``; ``0 <= alpha dt < 1``."""

    alpha: float = 0.1

    def __post_init__(self) -> None:
        super().__post_init__()
        if not (np.isfinite(self.alpha) and 0.0 <= self.alpha * self.dt < 1.0):
            raise ConfigError(
                f"alpha: expected 0 <= alpha < rate_hz ({self.rate_hz:g}) in 1/s, got "
                f"{self.alpha}; larger gains overshoot every step"
            )


@dataclass
class FilterState:
    """What a filter carries from one sample to the next. Subclasses add fields.

    Attributes:
        quat: (4,) current ``q_world_sensor``.
        initialised: False until the first samples (or :meth:`OrientationFilter.reset`
            with a quaternion, or :meth:`OrientationFilter.reinitialize`) set ``quat``.
        dip: magnetic dip [rad] measured at initialisation (NaN until known).
        last_gyr: (3,) the last gyroscope reading [rad/s] (None before the first): a step
            over lost samples at the start of the next batch is integrated with it (the
            trapezoidal rule), as in one run over both batches.
    """

    quat: FloatArray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    initialised: bool = False
    dip: float = float("nan")
    last_gyr: FloatArray | None = None


class OrientationFilter(ABC):
    """Abstract orientation filter; see the module docstring for the contract.

    Subclasses set ``name``, ``state_type`` and implement :meth:`_run_reference`
    and :meth:`_run_fast`, which process validated :class:`FilterInputs` from
    ``self.state`` (initialised) and leave the final state in ``self.state``.
    """

    name: ClassVar[str]
    state_type: ClassVar[type[FilterState]] = FilterState

    def __init__(self, params: FilterParams, backend: Backend = "fast") -> None:
        if backend not in ("fast", "reference"):
            raise ConfigError(f"backend: expected 'fast' or 'reference', got {backend!r}")
        self.params = params
        self.backend: Backend = backend
        self.state: FilterState = self.state_type()
        self.last_report = RunReport(0)

    # -- state -----------------------------------------------------------------------------
    def get_state(self) -> FilterState:
        """A deep copy of the state (checkpoint)."""
        return copy.deepcopy(self.state)

    def set_state(self, state: FilterState) -> None:
        """Restore a checkpoint taken with :meth:`get_state` (copied, never shared)."""
        if not isinstance(state, self.state_type):
            raise ConfigError(
                f"state: expected a {self.state_type.__name__} for filter {self.name!r}, "
                f"got {type(state).__name__}"
            )
        self.state = copy.deepcopy(state)

    @property
    def quat(self) -> FloatArray:
        """Current estimate ``q_world_sensor`` (4,) (a copy)."""
        return np.array(self.state.quat, dtype=np.float64)

    @property
    def initialised(self) -> bool:
        return self.state.initialised

    def reset(self, quat: Any = None, dip: float | None = None) -> None:
        """Start over: uninitialised (``quat=None``, initialise from the next samples) or
        from a given ``q_world_sensor`` (and optionally the magnetic dip [rad])."""
        self.state = self.state_type()
        if quat is not None:
            q = as_float_array(quat, "quat")
            check_shape(q, "quat", 4)
            norm = float(np.linalg.norm(q))
            if not (np.isfinite(norm) and norm > 0.5):
                raise DataError(f"quat: expected a unit quaternion [w, x, y, z], got {q}")
            self.state.quat = q / norm
            self.state.initialised = True
        if dip is not None:
            self.state.dip = float(dip)

    def reinitialize(self, acc_window: Any, mag_window: Any = None) -> FloatArray:
        """Re-resolve the orientation from (stationary) samples, without restarting.

        Args:
            acc_window: (K, 3) accelerometer samples [m/s^2].
            mag_window: (K', 3) magnetometer samples, or None (6D: the inclination is
                reset, the current heading is kept).

        Returns the new ``q_world_sensor`` (4,). Other state (e.g. a bias estimate) is kept.
        """
        refs = reference_vectors(acc_window, mag_window)
        prior = self.state.quat if self.state.initialised else None
        self.state.quat = orientation_from_references(refs, prior)
        if refs.m_ref is not None:
            self.state.dip = refs.dip
        self.state.initialised = True
        self._after_reinitialize()
        return self.quat

    def gyr_bias_removed(self, bias: Any, sigma: float | None = None) -> None:  # noqa: B027
        """Tell the filter that the caller subtracts ``bias`` [rad/s] (3,) from every later
        gyroscope reading (a bias measured at rest, e.g. in a calibration pose), with
        uncertainty ``sigma`` [rad/s] if known. A filter that estimates the bias shifts its
        estimate by ``-bias`` (and may take ``sigma`` as a measurement of what is left);
        the others have nothing to do (this default)."""

    def _after_reinitialize(self) -> None:  # noqa: B027  (an optional hook)
        """Hook for subclasses that keep more state tied to the orientation."""

    # -- processing ------------------------------------------------------------------------
    @abstractmethod
    def _run_reference(self, inputs: FilterInputs) -> FloatArray:
        """Readable implementation: process ``inputs`` from ``self.state``; return (N, 4)."""

    @abstractmethod
    def _run_fast(self, inputs: FilterInputs) -> FloatArray:
        """Compiled implementation with the same result as :meth:`_run_reference`."""

    def update(self, gyr: Any, acc: Any, mag: Any = None, dt: float | None = None) -> FloatArray:
        """Process one sample (each of shape (3,)); returns the new ``q_world_sensor`` (4,)."""
        arrays = {}
        for key, value in (("gyr", gyr), ("acc", acc), ("mag", mag)):
            if value is None:
                continue
            arr = as_float_array(value, key)
            check_shape(arr, key, 3)
            arrays[key] = arr[None, :]
        return self.run(arrays["gyr"], arrays["acc"], arrays.get("mag"), dt=dt)[0]

    def run(self, gyr: Any, acc: Any, mag: Any = None, dt: Any = None) -> FloatArray:
        """Process a batch from the current state; returns (N, 4) quaternions.

        Args:
            gyr: (N, 3) angular rate [rad/s], sensor frame.
            acc: (N, 3) specific force [m/s^2], sensor frame.
            mag: (N, 3) magnetic field (any unit) or None (6D). All-NaN rows are gaps.
            dt: time step [s] per sample, scalar or (N,); ``params.dt`` when None.
        """
        inputs, report = self._prepare(gyr, acc, mag, dt, self.state.last_gyr)
        n = inputs.gyr.shape[0]
        if n == 0:
            self.last_report = report
            return np.zeros((0, 4))
        last_gyr = np.array(as_float_array(gyr, "gyr").reshape(-1, 3)[-1])
        initialised_here = False
        if not self.state.initialised:
            self._initialise_from(inputs)
            initialised_here = True
        elif mag is not None and not np.isfinite(self.state.dip):
            self._measure_dip(inputs)
        out = self._run_fast(inputs) if self.backend == "fast" else self._run_reference(inputs)
        self.state.last_gyr = last_gyr
        if not np.isfinite(out).all():  # a kernel bug must never reach the user as NaN
            i = int(np.flatnonzero(~np.isfinite(out).all(axis=1))[0])
            raise DataError(f"{self.name}: non-finite orientation at sample {i}; please report")
        self.last_report = RunReport(
            n,
            report.acc_rejected,
            report.mag_gaps,
            report.mag_rejected,
            report.gyr_saturated,
            initialised_here,
            report.gaps,
        )
        return out

    def _prepare(
        self, gyr: Any, acc: Any, mag: Any, dt: Any, last_gyr: FloatArray | None = None
    ) -> tuple[FilterInputs, RunReport]:
        p = self.params
        return prepare_inputs(
            gyr, acc, mag, dt, p.dt, p.acc_range, p.gyr_range, p.gap_factor,
            p.max_integrated_gap_s, last_gyr,
        )  # fmt: skip

    def _initialise_from(self, inputs: FilterInputs) -> None:
        k = min(self.params.init_samples, inputs.gyr.shape[0])
        acc_ok = inputs.use_acc[:k]
        if not acc_ok.any():
            raise DataError(
                f"acc: no usable sample among the first {k} samples to initialise the "
                "orientation (all zero-norm or saturated); start the run where the "
                "accelerometer works, or call reset(quat) with a known orientation"
            )
        # the window's samples turned into the frame before the first sample, so motion
        # during the window does not bias the start
        acc = rotate_to_first_frame(inputs.gyr[:k], inputs.dt[:k], inputs.acc[:k])
        both = acc_ok & inputs.use_mag[:k]
        if both.any():
            mag = rotate_to_first_frame(inputs.gyr[:k], inputs.dt[:k], inputs.mag[:k])
            self.reinitialize(acc[both], mag[both])
        else:
            self.reinitialize(acc[acc_ok])

    def _measure_dip(self, inputs: FilterInputs) -> None:
        """Dip from the first usable (acc, mag) pairs: it does not depend on the orientation."""
        both = np.flatnonzero(inputs.use_acc & inputs.use_mag)[: self.params.init_samples]
        if both.size:
            self.state.dip = reference_vectors(inputs.acc[both], inputs.mag[both]).dip

    def run_recording(
        self, rec: ImuRecording, use_mag: bool = True, use_timestamps: bool = True
    ) -> OrientationSeries:
        """Run over a whole recording (9D when it has a magnetometer and ``use_mag``).

        With ``use_timestamps`` the time steps come from ``rec.time`` (the first sample
        uses the nominal step), so dropped samples are integrated over their true length.
        """
        if rec.n_samples > 1:
            rate = rec.rate_hz
            if abs(rate - self.params.rate_hz) > _RATE_TOLERANCE * self.params.rate_hz:
                raise ConfigError(
                    f"rate_hz: the filter expects {self.params.rate_hz:g} Hz but "
                    f"{rec.name} is sampled at {rate:.4g} Hz; build the filter with "
                    f"rate_hz={rate:.6g}"
                )
        dt = recording_steps(rec, self.params.dt) if use_timestamps else None
        mag = rec.mag if use_mag else None
        q = self.run(rec.gyr, rec.acc, mag, dt=dt)
        return OrientationSeries(rec.time, q, name=rec.name)

    def copy(self) -> OrientationFilter:
        return copy.deepcopy(self)


def recording_steps(rec: ImuRecording, nominal_dt: float) -> FloatArray | None:
    """Per-sample time steps of a recording from its time stamps (the first sample's is
    the nominal step), or None for fewer than two samples."""
    if rec.n_samples < 2:
        return None
    return np.concatenate([[nominal_dt], np.diff(rec.time)])


FilterFactory = Callable[..., OrientationFilter]
_REGISTRY: dict[str, FilterFactory] = {}


def register_filter(name: str) -> Callable[[FilterFactory], FilterFactory]:
    """Decorator adding a filter (class or factory taking ``rate_hz``, ``backend`` and
    parameter keywords) to the registry under ``name``."""

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
    try:
        return _REGISTRY[name](rate_hz=rate_hz, backend=backend, **params)
    except TypeError as exc:
        raise ConfigError(f"filter {name!r}: bad parameter ({exc})") from exc


__all__ = [
    "MIN_VECTOR_NORM",
    "Backend",
    "FilterInputs",
    "FilterParams",
    "FilterState",
    "OrientationFilter",
    "RunReport",
    "SensorSaturationWarning",
    "TimeGapWarning",
    "available_filters",
    "make_filter",
    "register_filter",
]
