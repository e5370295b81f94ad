"""``polaris``: mocapkit's most accurate orientation filter (online and offline).

Design (details, equations and the measured value of each part on BROAD in
``docs/architecture.md``, section *polaris*):

- decoupled like VQF (Laidig and Seel 2023): the gyroscope is integrated into an
  almost-inertial frame I, the inclination ``q_acc = q_E6_I`` and the heading offset
  ``delta`` are estimated separately, so the magnetometer never touches the inclination;
- inclination and gyroscope bias: a 5-state error-state Kalman filter fed with the
  accelerometer low-passed *in I* (linear accelerations average out there, gravity does
  not), with a measurement model that includes the lag of that low-pass behind the tilt a
  bias error causes; rest detection adds direct bias measurements;
- heading: a 6-state extended Kalman filter on the heading offset, the Earth field and a
  hard-iron offset, fed with the block-mean field in E6 compared with the orientation
  ``mag_delay_s`` earlier (the magnetometer's latency), with a Mahalanobis gate; a field
  that stays inconsistent makes the filter re-learn the hard iron (a magnet attached to
  the sensor) while the gyroscope carries the heading;
- offline (:meth:`Polaris.run_offline`): forward and backward passes, their biases and
  headings fused by their variances, and a zero-phase low-pass of the accelerometer in the
  smoothed strapdown frame (:mod:`mocapkit.imu.filters.polaris_offline`).

The reference implementation is :mod:`mocapkit.imu.filters.polaris_reference`, the numba
fast path :mod:`mocapkit.imu.filters.polaris_kernels`; parameters and state in
:mod:`mocapkit.imu.filters.polaris_params`.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray, as_float_array, check_finite, check_shape
from mocapkit.errors import ConfigError, DataError
from mocapkit.imu.filters import polaris_params as pp
from mocapkit.imu.filters.base import Backend, OrientationFilter, register_filter
from mocapkit.imu.filters.polaris_engine import (
    MIN_VECTOR_NORM,
    initial_tilt,
    run_pass,
    start,
)
from mocapkit.imu.filters.polaris_offline import OfflineResult, smooth
from mocapkit.imu.filters.polaris_params import PolarisCore, PolarisParams
from mocapkit.imu.filters.polaris_reference import reset_heading


@dataclass
class PolarisState:
    """Checkpointable state: the current estimates and the whole filter memory.

    Attributes:
        quat: (4,) current ``q_world_sensor`` (9D once the heading is known, else 6D).
        quat6: (4,) current 6D estimate (heading arbitrary but continuous).
        core: everything else (:class:`~mocapkit.imu.filters.polaris_params.PolarisCore`).
    """

    quat: FloatArray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    quat6: FloatArray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    core: PolarisCore = field(default_factory=PolarisCore)

    @property
    def started(self) -> bool:
        return bool(self.core.started[0])

    @property
    def bias(self) -> FloatArray:
        """Gyroscope bias estimate [rad/s] (3,)."""
        return self.core.bias.copy()

    @property
    def hard_iron(self) -> FloatArray:
        """Hard-iron estimate (3,), in the magnetometer's unit (zero until 9D starts)."""
        return self.core.mag_x[3:6] * self.core.mag_scale[0]

    @property
    def heading_offset(self) -> float:
        """``delta`` [rad]: ``q9 = Rz(delta) * q6``."""
        return float(self.core.mag_x[0])


def _check_output(q: FloatArray) -> None:
    """A kernel bug must never reach the user as a NaN quaternion."""
    bad = ~np.isfinite(q).all(axis=1)
    if bad.any():
        raise DataError(
            f"polaris: non-finite orientation at sample {int(np.flatnonzero(bad)[0])}; "
            "this is a bug, please report it with the input"
        )


@register_filter("polaris")
class Polaris(OrientationFilter):
    """The ``polaris`` filter; see the module docstring.

    Args:
        params: :class:`PolarisParams` (or build with ``Polaris.create(rate_hz, **gains)``).
        backend: ``"fast"`` (numba) or ``"reference"`` (readable numpy); they agree to 1e-9.

    A new filter starts from its first samples (inclination from the first accelerometer
    sample, any orientation, then averaged over ``tau_acc``; in 9D the heading from the first
    magnetometer sample, refined by the heading filter).
    """

    name = "polaris"

    def __init__(
        self,
        params: PolarisParams | None = None,
        backend: Backend = "fast",
        rate_hz: float | None = None,
        **gains: Any,
    ) -> None:
        if params is None:
            if rate_hz is None:
                raise ConfigError("rate_hz: required when no PolarisParams are given")
            params = PolarisParams(rate_hz=rate_hz, **gains)
        elif rate_hz is not None or gains:
            raise ConfigError("pass either params or rate_hz and gains, not both")
        super().__init__(params, backend)
        self.params: PolarisParams = params
        self._c = pp.coefficients(params)
        self.state = PolarisState()

    # -- state -----------------------------------------------------------------------------
    def get_state(self) -> PolarisState:
        return copy.deepcopy(self.state)

    def set_state(self, state: Any) -> None:
        if not isinstance(state, PolarisState):
            raise ConfigError(
                f"state: expected a PolarisState from Polaris.get_state(), got "
                f"{type(state).__name__}"
            )
        self.state = copy.deepcopy(state)

    @property
    def quat(self) -> FloatArray:
        return self.state.quat.copy()

    @property
    def at_rest(self) -> bool:
        """Whether the rest detector currently reports rest."""
        return bool(self.state.core.rest_time[0] >= self.params.rest_min_time)

    def reset(self) -> None:
        """Start over from the next samples."""
        self.state = PolarisState()

    def reset_heading(self) -> None:
        """Re-initialise the heading from the next magnetometer sample (keeps the rest)."""
        reset_heading(self.state.core)

    # -- processing ------------------------------------------------------------------------
    def _run(self, gyr: FloatArray, acc: FloatArray, mag: FloatArray | None) -> FloatArray:
        q9, q6 = self._process(gyr, acc, mag, None)
        return q9 if mag is not None else q6

    def _process(
        self, gyr: FloatArray, acc: FloatArray, mag: FloatArray | None, dt: FloatArray | None
    ) -> tuple[FloatArray, FloatArray]:
        n = gyr.shape[0]
        steps = np.full(n, self.params.dt) if dt is None else dt
        use_acc = np.linalg.norm(acc, axis=1) > MIN_VECTOR_NORM
        has_mag = mag is not None
        if mag is None:
            mag_arr = np.zeros((n, 3))
            use_mag = np.zeros(n, dtype=bool)
        else:
            mag_arr = mag
            use_mag = np.linalg.norm(mag, axis=1) > MIN_VECTOR_NORM
        if n == 0:
            return np.zeros((0, 4)), np.zeros((0, 4))
        core = self.state.core
        if not self.state.started:
            q_init = initial_tilt(acc, use_acc)
            first = int(np.flatnonzero(use_acc)[0])
            start(self._c, core, q_init, gyr[0], acc[first])
        result = run_pass(
            self._c, core, self.backend, gyr, acc, mag_arr, steps, use_acc, use_mag, has_mag
        )
        _check_output(result.q9)
        self.state.quat = result.q9[-1].copy()
        self.state.quat6 = result.q6[-1].copy()
        return result.q9, result.q6

    def run_both(self, gyr: Any, acc: Any, mag: Any) -> tuple[FloatArray, FloatArray]:
        """9D run that also returns the 6D estimate: ``(q9, q6)``, each (N, 4)."""
        g, a, m = self._validated(gyr, acc, mag)
        if m is None:
            raise ConfigError("mag: run_both needs magnetometer samples (N, 3)")
        return self._process(g, a, m, None)

    def run_offline(self, gyr: Any, acc: Any, mag: Any = None) -> FloatArray:
        """Smooth a whole recording with the forward-backward mode; returns (N, 4)
        ``q_world_sensor`` (9D with ``mag``, else 6D). The filter's own state is untouched.

        See :mod:`mocapkit.imu.filters.polaris_offline` for the method.
        """
        result = self.smooth(gyr, acc, mag)
        return result.q9 if result.q9 is not None else result.q6

    def smooth(self, gyr: Any, acc: Any, mag: Any = None) -> OfflineResult:
        """Like :meth:`run_offline` but returns the smoothed 6D and 9D estimates and bias."""
        g, a, m = self._validated(gyr, acc, mag)
        n = g.shape[0]
        if n == 0:
            empty = np.zeros((0, 4))
            return OfflineResult(empty, None if m is None else empty, np.zeros((0, 3)))
        use_acc = np.linalg.norm(a, axis=1) > MIN_VECTOR_NORM
        has_mag = m is not None
        mag_arr = np.zeros((n, 3)) if m is None else m
        use_mag = np.linalg.norm(mag_arr, axis=1) > MIN_VECTOR_NORM
        dt = np.full(n, self.params.dt)
        result = smooth(self.params, self.backend, g, a, mag_arr, dt, use_acc, use_mag, has_mag)
        _check_output(result.q6 if result.q9 is None else result.q9)
        return result

    def _validated(
        self, gyr: Any, acc: Any, mag: Any
    ) -> tuple[FloatArray, FloatArray, FloatArray | None]:
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
            m = np.ascontiguousarray(m)
        return np.ascontiguousarray(g), np.ascontiguousarray(a), m
