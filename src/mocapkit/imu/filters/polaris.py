"""``polaris``: mocapkit's most accurate orientation filter (online and offline).

Design (details, equations and the measured value of each part on BROAD in
``docs/design/imu.md``, section *polaris*):

- decoupled like VQF (Laidig and Seel 2023): the gyroscope is integrated into an
  almost-inertial frame I, the inclination ``q_acc = q_E6_I`` and the heading offset
  ``delta`` are estimated separately, so the magnetometer never touches the inclination;
- inclination and gyroscope bias: a 5-state error-state Kalman filter fed with the
  accelerometer low-passed *in I* (linear accelerations average out there, gravity does
  not), with a measurement model that includes the lag of that low-pass behind the tilt a
  bias error causes; rest detection adds direct bias measurements;
- heading: a 6-state extended Kalman filter on the heading offset, the Earth field and a
  hard-iron offset, fed with the block-mean field in E6, with a noise that grows with the
  angular rate (the magnetometer's uncertain timing; its latency ``mag_delay_s`` can also
  be compensated) and a Mahalanobis gate; a field that stays inconsistent makes the filter
  re-learn the hard iron (a magnet attached to the sensor) while the gyroscope carries the
  heading;
- offline (:meth:`Polaris.run_offline`): forward and backward passes fused into a smoothed
  bias, a zero-phase low-pass of the accelerometer in the smoothed strapdown frame, and the
  heading filter forward and backward fused by variances
  (:mod:`mocapkit.imu.filters.polaris_offline`).

Time steps: the gyroscope integration, the drift integrals and the process noises use
each sample's ``dt`` (a few dropped samples are integrated over their true length); the
low-pass coefficients are those of the nominal ``rate_hz``.

Faults (a time gap, a saturated gyroscope): the inclination and, in 9D, the heading are
re-acquired (:mod:`mocapkit.imu.filters.polaris_faults`).

The reference implementation is :mod:`mocapkit.imu.filters.polaris_reference`, the numba
fast path :mod:`mocapkit.imu.filters.polaris_kernels`; parameters and state in
:mod:`mocapkit.imu.filters.polaris_params`.
"""

from __future__ import annotations

import copy
import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray, as_float_array, check_shape
from mocapkit.errors import ConfigError, DataError
from mocapkit.geometry import quat_mul, quat_normalize
from mocapkit.imu.filters import polaris_params as pp
from mocapkit.imu.filters.base import Backend, FilterState, OrientationFilter, register_filter
from mocapkit.imu.filters.inputs import FilterInputs
from mocapkit.imu.filters.polaris_engine import PassResult, initial_linear_acc, run_pass, start
from mocapkit.imu.filters.polaris_faults import (
    reacquire_sample,
    restart_inclination,
    restart_points,
)
from mocapkit.imu.filters.polaris_offline import OfflineResult, smooth
from mocapkit.imu.filters.polaris_params import PolarisCore, PolarisParams
from mocapkit.imu.filters.polaris_reference import reset_heading


@dataclass
class PolarisState(FilterState):
    """Checkpointable state: the base fields (``quat``, ``initialised``, ``dip``), the
    current 6D estimate and the whole filter memory.

    Attributes:
        quat6: (4,) current 6D estimate (heading arbitrary but continuous).
        core: everything else (:class:`~mocapkit.imu.filters.polaris_params.PolarisCore`);
            its ``started`` is 0 until the first samples after (re)initialisation.
    """

    quat6: FloatArray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    core: PolarisCore = field(default_factory=PolarisCore)
    fault_saturated: bool = False  # the last sample processed was saturated
    reacquire_elapsed: float = -1.0  # [s] since a fault whose heading re-acquire is due
    recoveries: int = 0  # faults recovered from since the start (gaps, saturation)

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


GRAVITY = 9.81  # [m/s^2] only to seed the low-pass when a batch has no usable accelerometer


def _check_output(q: FloatArray) -> None:
    """A kernel bug must never reach the user as a NaN quaternion."""
    if np.isfinite(q).all():  # one flat pass (the per-row reduction costs ~15 ns/sample)
        return
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
        params: :class:`PolarisParams`; or give ``rate_hz`` and parameter keywords.
        backend: ``"fast"`` (numba) or ``"reference"`` (readable numpy); they agree to 1e-9.

    Initialisation follows the filter contract (:mod:`mocapkit.imu.filters.base`): the
    first ``init_window_s`` of samples give the starting orientation in any orientation;
    after that the accelerometer low-pass averages over ``tau_acc`` and, in 9D, the heading
    filter starts from the first magnetometer sample. :meth:`reinitialize` re-resolves the
    orientation on command and keeps the bias estimate.
    """

    name = "polaris"
    state_type = PolarisState

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
        self.state: PolarisState = PolarisState()
        self._c = pp.coefficients(params)
        self._mode_9d = False
        self._last_q6 = np.zeros((0, 4))

    @property
    def at_rest(self) -> bool:
        """Whether the rest detector currently reports rest."""
        return bool(self.state.core.rest_time[0] >= self.params.rest_min_time)

    def reset_heading(self) -> None:
        """Re-initialise the heading from the next magnetometer sample (keeps the rest)."""
        reset_heading(self.state.core)

    def gyr_bias_removed(self, bias: Any, sigma: float | None = None) -> None:
        """The caller now subtracts ``bias`` [rad/s] (3,) from every gyroscope reading: the
        bias estimate and the rest detector's memory of the readings move by ``-bias`` (so
        nothing sees a step; only whether the rate is small enough for rest may differ);
        with ``sigma`` [rad/s], the caller's measurement leaves ``0 +- sigma`` of bias, which
        is fused with the estimate by one Kalman update of the bias states (P9's form)."""
        b = as_float_array(bias, "bias")
        check_shape(b, "bias", 3)
        core = self.state.core
        core.bias = core.bias - b
        # the rest detector's memory of the readings moves with them
        core.rest_gyr_lp = core.rest_gyr_lp - b
        core.rest_gyr_sum = core.rest_gyr_sum - b * core.rest_count[0]
        # (P8) the lag model's record of the corrections applied, G = int R6[:2] b dt, as if
        # the new estimate had always been used (the low-pass is linear: shift its memory)
        J = core.drift_J.reshape(2, 3)
        core.drift_G = core.drift_G - J @ b
        core.drift_G_lp = core.drift_G_lp - core.drift_J_lp.reshape(2, 3) @ b
        j_state = core.drift_J_lp_state.reshape(2, 3, 2)
        core.drift_G_lp_state = (
            core.drift_G_lp_state.reshape(2, 2) - np.einsum("rjm,j->rm", j_state, b)
        ).reshape(-1)
        if sigma is None or not self.state.started:
            return
        if not (np.isfinite(sigma) and sigma > 0.0):
            raise ConfigError(f"sigma: expected a positive bias uncertainty in rad/s, got {sigma}")
        P = core.tilt_P.reshape(5, 5).copy()
        x = np.zeros(5)
        for i in range(3):
            s = P[2 + i, 2 + i] + sigma * sigma
            k = P[:, 2 + i] / s
            x = x + k * (0.0 - (core.bias[i] + x[2 + i]))
            P = P - np.outer(k, k) * s
        core.bias = core.bias + x[2:5]
        q_fix = np.array([1.0, 0.5 * x[0], 0.5 * x[1], 0.0])
        core.q_acc = quat_normalize(quat_mul(q_fix, core.q_acc))
        core.tilt_P = (0.5 * (P + P.T)).reshape(-1)

    def _after_reinitialize(self) -> None:
        """A new ``state.quat``: restart the inclination and heading filters from it (the
        low-passes from the rest detector's memory of the readings), keep the gyroscope
        bias and its uncertainty."""
        core = self.state.core
        if not self.state.started:
            return  # the next run starts from state.quat anyway
        bias = core.bias.copy()
        bias_P = core.tilt_P.reshape(5, 5)[2:5, 2:5].copy()
        start(self._c, core, self.state.quat, core.rest_gyr_lp.copy(), core.rest_acc_lp.copy())
        core.bias = bias
        P = core.tilt_P.reshape(5, 5).copy()
        P[2:5, 2:5] = bias_P
        core.tilt_P = P.reshape(-1)
        self.state.quat6 = self.state.quat.copy()

    # -- processing ------------------------------------------------------------------------
    def run(self, gyr: Any, acc: Any, mag: Any = None, dt: Any = None) -> FloatArray:
        self._mode_9d = mag is not None
        return super().run(gyr, acc, mag, dt)

    def _run_fast(self, inputs: FilterInputs) -> FloatArray:
        return self._process(inputs, "fast")

    def _run_reference(self, inputs: FilterInputs) -> FloatArray:
        return self._process(inputs, "reference")

    def _process(self, inputs: FilterInputs, backend: str) -> FloatArray:
        core = self.state.core
        if not self.state.started:
            usable = np.flatnonzero(inputs.use_acc)
            acc0 = inputs.acc[usable[0]] if usable.size else np.array([0.0, 0.0, GRAVITY])
            # the linear acceleration at the start, from the first sample only (so that a run
            # split anywhere, or sample by sample, starts the same), weighted as the
            # initialisation window the start was taken from
            first = usable[0] if usable.size else 0
            lin2 = initial_linear_acc(acc0[None, :], inputs.gyr[first : first + 1], self.params.dt)
            start(
                self._c, core, self.state.quat, inputs.gyr[0], acc0, lin2, self.params.init_samples
            )
        restarts = restart_points(inputs.gap, inputs.saturated, self.state.fault_saturated)
        self.state.fault_saturated = bool(inputs.saturated[-1])
        if restarts.size == 0 and self.state.reacquire_elapsed < 0.0:
            result = self._pass(inputs, 0, inputs.gyr.shape[0], backend)
        else:
            result = self._recovering(inputs, restarts, backend)
        _check_output(result.q9)
        self.state.quat = result.q9[-1].copy()
        self.state.quat6 = result.q6[-1].copy()
        self._last_q6 = result.q6
        return result.q9

    def _pass(
        self, inputs: FilterInputs, a: int, b: int, backend: str, aux: bool = False
    ) -> PassResult:
        """One kernel pass over samples ``[a, b)`` from the current state."""
        return run_pass(
            self._c,
            self.state.core,
            backend,
            inputs.gyr[a:b],
            inputs.acc[a:b],
            inputs.mag[a:b],
            inputs.dt[a:b],
            inputs.use_acc[a:b],
            inputs.use_mag[a:b],
            self._mode_9d,
            aux,
        )

    def _recovering(self, inputs: FilterInputs, restarts: np.ndarray, backend: str) -> PassResult:
        """The pass split at the fault restarts, with the heading re-acquire found per
        sample (:mod:`mocapkit.imu.filters.polaris_faults`)."""
        n = inputs.gyr.shape[0]
        bounds = [0, *[int(r) for r in restarts if r > 0], n]
        parts: list[PassResult] = []
        state = self.state
        for a, b in itertools.pairwise(bounds):
            if a in restarts:
                restart_inclination(state.core)
                state.recoveries += 1
                if self._mode_9d:
                    state.reacquire_elapsed = 0.0
            while a < b:
                if state.reacquire_elapsed < 0.0 or not self._mode_9d:
                    parts.append(self._pass(inputs, a, b, backend))
                    break
                saved = copy.deepcopy(state.core)
                probe = self._pass(inputs, a, b, backend, aux=True)
                k = reacquire_sample(probe.aux, inputs.dt[a:b], state.reacquire_elapsed)
                if k < 0:
                    state.reacquire_elapsed += float(inputs.dt[a:b].sum())
                    parts.append(PassResult(probe.q9, probe.q6, np.zeros((0, 8))))
                    break
                state.core = saved
                parts.append(self._pass(inputs, a, a + k + 1, backend))
                reset_heading(state.core)
                state.reacquire_elapsed = -1.0
                a += k + 1
        return PassResult(
            np.concatenate([p.q9 for p in parts]),
            np.concatenate([p.q6 for p in parts]),
            np.zeros((0, 8)),
        )

    def run_both(
        self, gyr: Any, acc: Any, mag: Any, dt: Any = None
    ) -> tuple[FloatArray, FloatArray]:
        """A 9D :meth:`run` that also returns the 6D estimate: ``(q9, q6)``, each (N, 4)."""
        if mag is None:
            raise ConfigError("mag: run_both needs magnetometer samples (N, 3)")
        q9 = self.run(gyr, acc, mag, dt)
        return q9, self._last_q6.copy()

    def run_offline(self, gyr: Any, acc: Any, mag: Any = None, dt: Any = None) -> FloatArray:
        """Smooth a whole recording with the forward-backward mode; returns (N, 4)
        ``q_world_sensor`` (9D with ``mag``, else 6D). The filter's own state is untouched.

        See :mod:`mocapkit.imu.filters.polaris_offline` for the method.
        """
        result = self.smooth(gyr, acc, mag, dt)
        return result.q9 if result.q9 is not None else result.q6

    def smooth(self, gyr: Any, acc: Any, mag: Any = None, dt: Any = None) -> OfflineResult:
        """Like :meth:`run_offline` but returns the smoothed 6D and 9D estimates and bias.

        Inputs are validated like :meth:`run` (gaps, zero-norm and saturated samples are
        skipped the same way)."""
        inputs, _ = self._prepare(gyr, acc, mag, dt)
        n = inputs.gyr.shape[0]
        if n == 0:
            empty = np.zeros((0, 4))
            return OfflineResult(empty, None if mag is None else empty, np.zeros((0, 3)))
        result = smooth(
            self.params,
            self.backend,
            inputs.gyr,
            inputs.acc,
            inputs.mag,
            inputs.dt,
            inputs.use_acc,
            inputs.use_mag,
            mag is not None,
        )
        _check_output(result.q6 if result.q9 is None else result.q9)
        return result


@register_filter("polaris-body")
def polaris_body(rate_hz: float, backend: Backend = "fast", **gains: Any) -> Polaris:
    """``polaris`` with :data:`~mocapkit.imu.filters.polaris_params.BODY_PROFILE` (sensors
    worn on limbs; keywords override it). The default of the suit, teleop and demo."""
    return Polaris(rate_hz=rate_hz, backend=backend, **{**pp.BODY_PROFILE, **gains})
