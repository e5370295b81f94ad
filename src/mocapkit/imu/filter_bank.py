"""Many sensors' orientation filters advanced together, sample by sample (host-side fusion).

A suit's host fuses S sensors at once: every round brings one new sample per sensor. Run
one filter object per sensor and each sample costs a Python call (validation, state
handling around the numba kernel: 50-100 us); a :class:`FilterBank` keeps every sensor's
state in arrays and advances all of a round's samples in one numba call (a few us per
sample), for the filters that have a bank kernel (:mod:`mocapkit.imu.filter_bank_kernels`:
``miller``, ``bachmann``, ``polaris``). Others run per sensor, unchanged.

The result is exactly that of one ``StillStartFilter(make_filter(name, rate_hz),
still_s)`` per sensor fed sample by sample (tested to 1e-12): each sensor starts on its
own filter object (initialisation from its first sample, then the still start: gyroscope
bias and orientation from the first ``still_s``), and once that is done (and, for a
filter that needs it, its magnetic dip is known) its state moves into the bank's arrays
and the object is no longer used. Per-sample time step: the filter's nominal ``dt``. A
filter with a gyroscope range (saturation warnings) runs per sensor.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError, MocapkitError
from mocapkit.imu import filter_bank_kernels as bk
from mocapkit.imu.filters import make_filter
from mocapkit.imu.filters.bachmann import BachmannFilter
from mocapkit.imu.filters.miller import MillerFilter
from mocapkit.imu.filters.polaris import Polaris
from mocapkit.imu.filters.polaris_params import pack_state
from mocapkit.imu.still_start import StillStartFilter

log = logging.getLogger(__name__)

_STATUS = {
    bk.BAD_GYR: "gyr: non-finite value",
    bk.BAD_ACC: "acc: non-finite value",
    bk.BAD_MAG: "mag: non-finite value (mark a gap with all three components NaN)",
    bk.BAD_OUTPUT: "non-finite orientation; please report",
}


@dataclass(frozen=True)
class _Spec:
    """How a filter class runs in the bank: its kernel, its state and parameters as flat
    rows, and when a started filter object can hand its state over."""

    kernel: Callable[..., None]
    state: Callable[[Any], FloatArray]
    params: Callable[[Any], FloatArray]
    ready: Callable[[Any, bool], bool]


def _quat(f: Any) -> FloatArray:
    return np.array(f.state.quat, dtype=np.float64)


def _miller_params(f: MillerFilter) -> FloatArray:
    return np.array([f.params.alpha])


def _bachmann_params(f: BachmannFilter) -> FloatArray:
    m_ref, ok = f._field()
    return np.array([f.params.alpha, *m_ref, 1.0 if ok else 0.0])


def _always(f: Any, use_mag: bool) -> bool:
    return True


def _bachmann_ready(f: BachmannFilter, use_mag: bool) -> bool:
    """The reference field needs the dip: until it is known the object measures it."""
    return not use_mag or bool(np.isfinite(f.state.dip))


def _polaris_state(f: Polaris) -> FloatArray:
    return pack_state(f.state.core)


def _polaris_params(f: Polaris) -> FloatArray:
    return np.asarray(f._c, dtype=np.float64)


def _polaris_ready(f: Polaris, use_mag: bool) -> bool:
    return f.state.started


_SPECS: dict[type, _Spec] = {
    MillerFilter: _Spec(bk.miller_bank_kernel, _quat, _miller_params, _always),
    BachmannFilter: _Spec(bk.bachmann_bank_kernel, _quat, _bachmann_params, _bachmann_ready),
    Polaris: _Spec(bk.polaris_bank_kernel, _polaris_state, _polaris_params, _polaris_ready),
}


def has_bank_kernel(name: str, rate_hz: float = 100.0) -> bool:
    """Whether the registered filter ``name`` runs in the bank (else per sensor)."""
    return type(make_filter(name, rate_hz)) in _SPECS


class FilterBank:
    """See the module docstring.

    Args:
        name: registered filter name (``make_filter``).
        rate_hz: sample rate [Hz].
        n_sensors: sensors, addressed by slot 0..n-1.
        still_s: each sensor's still start [s] (0: none).
        use_mag: 9D (the magnetometer rows are used) or 6D.
        labels: per-slot sensor names for messages.
    """

    def __init__(
        self,
        name: str,
        rate_hz: float,
        n_sensors: int,
        still_s: float = 0.8,
        use_mag: bool = True,
        labels: Sequence[str] | None = None,
    ) -> None:
        if n_sensors < 1:
            raise ConfigError(f"n_sensors: expected at least 1, got {n_sensors}")
        self.name = name
        self.rate_hz = rate_hz
        self.use_mag = use_mag
        self.labels = list(labels) if labels else [f"sensor {i}" for i in range(n_sensors)]
        probe = make_filter(name, rate_hz)
        spec = _SPECS.get(type(probe))
        if probe.params.gyr_range is not None:  # saturation warnings: the object path
            spec = None
        self._spec = spec
        self._dt = probe.params.dt
        acc_range = probe.params.acc_range
        self._acc_range = np.inf if acc_range is None else float(acc_range)
        if spec is not None:  # the state's and parameters' sizes: from a started filter
            probe.update([0.0, 0.0, 0.0], [0.0, 0.0, 9.81], [0.0, 20.0, -40.0])
        L = 0 if spec is None else len(spec.state(probe))
        k = 0 if spec is None else len(spec.params(probe))
        self.X = np.zeros((n_sensors, L))
        """(S, L) the filter state of the sensors in the bank (rows of the others: unused)."""
        self.P = np.zeros((n_sensors, k))
        self.bias = np.zeros((n_sensors, 3))
        """(S, 3) gyroscope bias removed before the bank's kernel [rad/s]."""
        self.in_bank = np.zeros(n_sensors, dtype=bool)
        self.objects: list[StillStartFilter | None] = [None] * n_sensors
        self._still_s = still_s
        if spec is not None:  # compile (or load) the kernel now, not on a sample
            self._run_kernel(np.zeros(1, np.int64), np.zeros((1, 3)), np.ones((1, 3)), None,
                             np.zeros(1, bool))  # fmt: skip

    @property
    def batched(self) -> bool:
        """Whether this filter runs in the bank (else per sensor)."""
        return self._spec is not None

    def _object(self, slot: int) -> StillStartFilter:
        f = self.objects[slot]
        if f is None:
            inner = make_filter(self.name, self.rate_hz)
            f = self.objects[slot] = StillStartFilter(inner, self._still_s, label=self.labels[slot])
        return f

    def _maybe_move_in(self, slot: int, f: StillStartFilter) -> None:
        spec = self._spec
        if spec is None or not f.done or not f.initialised or not spec.ready(f.inner, self.use_mag):
            return
        self.X[slot] = spec.state(f.inner)
        self.P[slot] = spec.params(f.inner)
        self.bias[slot] = f.bias if f.bias_ok else 0.0
        self.in_bank[slot] = True
        self.objects[slot] = None

    def _run_kernel(
        self, slots: np.ndarray, gyr: FloatArray, acc: FloatArray, mag: FloatArray | None,
        take: np.ndarray,
    ) -> tuple[FloatArray, np.ndarray]:  # fmt: skip
        m = len(slots)
        out = np.full((m, 4), np.nan)
        status = np.zeros(m, dtype=np.int8)
        has_mag = self.use_mag and mag is not None
        mag_arr = mag if mag is not None else np.zeros((m, 3))
        assert self._spec is not None
        self._spec.kernel(self.X, self.P, self.bias, slots, take, gyr, acc, mag_arr, has_mag,
                          self._dt, self._acc_range, out, status)  # fmt: skip
        return out, status

    def update(
        self, slots: Any, gyr: Any, acc: Any, mag: Any = None
    ) -> tuple[FloatArray, dict[int, str]]:
        """Advance the sensors by the batch's samples, in order.

        Args:
            slots: (M,) the sensor (0..S-1) of each sample.
            gyr, acc: (M, 3) [rad/s], [m/s^2], sensor frame.
            mag: (M, 3) (all-NaN rows: gaps) or None (6D).

        Returns:
            ``(q_world_sensor (M, 4), errors)``: ``errors`` maps a sample's index to the
            reason it could not be used (its row is NaN; the sensor's state is unchanged).
        """
        sl = np.asarray(slots, dtype=np.int64)
        g = np.ascontiguousarray(gyr, dtype=np.float64)
        a = np.ascontiguousarray(acc, dtype=np.float64)
        m = None if mag is None or not self.use_mag else np.ascontiguousarray(mag, np.float64)
        take = self.in_bank[sl]
        errors: dict[int, str] = {}
        if take.all():
            out, status = self._run_kernel(sl, g, a, m, take)
        else:
            out = np.full((len(sl), 4), np.nan)
            status = np.zeros(len(sl), dtype=np.int8)
            for i in np.flatnonzero(~take):
                s = int(sl[i])
                if self.in_bank[s]:  # moved in earlier in this batch
                    take[i] = True
                    continue
                f = self._object(s)
                try:
                    out[i] = f.update(g[i], a[i], None if m is None else m[i])
                except MocapkitError as exc:
                    errors[int(i)] = str(exc)
                    continue
                self._maybe_move_in(s, f)
            if take.any():
                out_b, status = self._run_kernel(sl, g, a, m, take)
                out[take] = out_b[take]
        if status.any():
            for i in np.flatnonzero(status):
                errors[int(i)] = _STATUS[int(status[i])]
        return out, errors
