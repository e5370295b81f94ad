"""``polaris``: one pass over validated arrays with either backend, from a given state.

Shared by the online filter (:mod:`mocapkit.imu.filters.polaris`) and the offline
smoother (:mod:`mocapkit.imu.filters.polaris_offline`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import DataError
from mocapkit.geometry import quat_from_two_vectors
from mocapkit.imu.filters import polaris_params as pp
from mocapkit.imu.filters.polaris_kernels import polaris_kernel
from mocapkit.imu.filters.polaris_offline_kernels import heading_kernel, strapdown_kernel
from mocapkit.imu.filters.polaris_params import PolarisCore, pack_state, unpack_state
from mocapkit.imu.filters.polaris_reference import (
    heading_pass_reference,
    run_reference,
    start_core,
    strapdown_reference,
)

_UP = np.array([0.0, 0.0, 1.0])
# A reading shorter than this (in its unit) has no direction.
MIN_VECTOR_NORM = 1e-6


class PassResult(NamedTuple):
    """Outputs of one pass: ``q9`` and ``q6`` (N, 4) and ``aux`` (N, 8) or (0, 8)."""

    q9: FloatArray
    q6: FloatArray
    aux: FloatArray


def initial_tilt(acc: FloatArray, use_acc: np.ndarray) -> FloatArray:
    """``q_world_sensor`` at the first usable accelerometer sample: its direction brought
    onto up by the shortest rotation. Any orientation works (upside down included); the
    heading is that of the sensor frame. One sample only, so that a run split anywhere
    starts the same way (the first ``tau_acc`` seconds then average, see (P3))."""
    usable = np.flatnonzero(use_acc)
    if usable.size == 0:
        raise DataError(
            "acc: no usable sample (all zero-norm or saturated) to initialise the "
            "inclination; start the run where the accelerometer works"
        )
    q: FloatArray = quat_from_two_vectors(acc[usable[0]], _UP)
    return q


#: [m] how far a body-worn sensor sits from the joint it turns about (a forearm's length):
#: a sensor turning at ``w`` feels about ``LEVER_ARM * (w^2 + dw/dt)`` of linear acceleration.
LEVER_ARM = 0.3


def initial_linear_acc(acc_window: FloatArray, gyr_window: FloatArray, dt: float) -> float:
    """Mean square linear acceleration [(m/s^2)^2] per axis in the (K, 3) accelerometer
    samples [m/s^2] a start is taken from (gyroscope [rad/s] over the same samples, ``dt``
    [s] apart): 0 for a sensor at rest.

    Along gravity it shows as ``|acc|`` off ``g`` (mean offset and spread); sideways it
    does not, so the rotation bounds it too: a sensor ``LEVER_ARM`` from the joint it turns
    about feels ``LEVER_ARM (w^2 + dw/dt)``.
    """
    norms = np.linalg.norm(acc_window, axis=1)
    if norms.size == 0:
        return 0.0
    lin2 = (float(np.mean(norms)) - pp.GRAVITY) ** 2 + float(np.var(norms))
    turn = float(np.max(np.linalg.norm(gyr_window, axis=1))) ** 2
    if len(gyr_window) > 1:
        turn += float(np.linalg.norm(gyr_window[-1] - gyr_window[0])) / ((len(gyr_window) - 1) * dt)
    return lin2 + (LEVER_ARM * turn) ** 2


def start(
    c: FloatArray,
    core: PolarisCore,
    q_init: FloatArray,
    gyr0: FloatArray,
    acc0: FloatArray,
    lin2: float = 0.0,
    n_window: int = 1,
) -> None:
    """Start ``core`` (same for both backends: the start is plain numpy)."""
    start_core(c, core, q_init, gyr0, acc0, lin2, n_window)


def run_pass(
    c: FloatArray,
    core: PolarisCore,
    backend: str,
    gyr: FloatArray,
    acc: FloatArray,
    mag: FloatArray,
    dt: FloatArray,
    use_acc: np.ndarray,
    use_mag: np.ndarray,
    has_mag: bool,
    want_aux: bool = False,
) -> PassResult:
    """Process the arrays from the started ``core`` (updated in place)."""
    n = gyr.shape[0]
    out9 = np.empty((n, 4))
    out6 = np.empty((n, 4))
    aux = np.empty((n if want_aux else 0, 8))
    if backend == "fast":
        flat = pack_state(core)
        polaris_kernel(c, flat, gyr, acc, mag, dt, use_acc, use_mag, has_mag, out9, out6, aux)
        unpack_state(flat, core)
    else:
        run_reference(c, core, gyr, acc, mag, dt, use_acc, use_mag, has_mag, out9, out6, aux)
    return PassResult(out9, out6, aux)


def strapdown(backend: str, gyr: FloatArray, bias: FloatArray, dt: FloatArray) -> FloatArray:
    """``q_I_S`` (N, 4) from identity with a per-sample bias (N, 3)."""
    out = np.empty((gyr.shape[0], 4))
    if backend == "fast":
        strapdown_kernel(gyr, np.ascontiguousarray(bias), dt, out)
    else:
        strapdown_reference(gyr, bias, dt, out)
    return out


def heading_pass(
    c: FloatArray,
    backend: str,
    q6: FloatArray,
    mag: FloatArray,
    rate2: FloatArray,
    dt: FloatArray,
    use_mag: np.ndarray,
) -> FloatArray:
    """The heading filter alone over a given 6D orientation and squared angular rates:
    (N, 2) ``[delta, var]``."""
    core = PolarisCore()
    out = np.empty((q6.shape[0], 2))
    if backend == "fast":
        flat = pack_state(core)
        heading_kernel(c, flat, np.ascontiguousarray(q6), mag, rate2, dt, use_mag, out)
    else:
        heading_pass_reference(c, core, q6, mag, rate2, dt, use_mag, out)
    return out
