"""``polaris``: recovery from faults in the data (time gaps, a saturated gyroscope).

After a gap or a saturated burst the strapdown orientation is wrong by an unknown
rotation, and a filter that keeps its small covariances trusts it: the inclination then
takes the accelerometer low-pass's slow pace to come back, and the heading filter, whose
Mahalanobis gate now rejects every magnetometer sample, never does (it even takes the
consistent Earth field for a new hard iron). So at such a sample ``polaris``

1. re-acquires the inclination: the tilt covariance is inflated to
   :data:`FAULT_TILT_SIGMA` (bias and its covariance kept) and the accelerometer
   low-pass restarts its warm-up, so the next Kalman updates take the measured gravity
   direction almost whole;
2. in 9D, re-acquires the heading once the inclination is good again (tilt std below
   :data:`REACQUIRE_TILT_SIGMA`, or :data:`REACQUIRE_MAX_S` after the fault at the
   latest): the heading filter restarts from the next magnetometer sample.

The inputs module detects the faults (:mod:`mocapkit.imu.filters.inputs`: a step longer
than ``gap_factor`` nominal steps, a gyroscope at its range or flat-topped) and warns,
naming the sample. Everything here is plain numpy on the filter's state between kernel
calls, so both backends recover identically, and the moment of the heading re-acquire is
found per sample (a run split anywhere gives the same result).
"""

from __future__ import annotations

import math

import numpy as np

from mocapkit.imu.filters.polaris_params import PolarisCore

_DEG = math.pi / 180.0
#: [rad] tilt std after a fault: the strapdown rotation may be wrong by tens of degrees.
FAULT_TILT_SIGMA = 30.0 * _DEG
#: [rad] the heading is re-acquired once both tilt stds are below this ...
REACQUIRE_TILT_SIGMA = 3.0 * _DEG
#: [s] ... or this long after the fault at the latest.
REACQUIRE_MAX_S = 10.0


def restart_points(gap: np.ndarray, saturated: np.ndarray, carried_saturated: bool) -> np.ndarray:
    """Indices of the samples before which the filter restarts: every sample after a time
    gap, and the first sample after a saturated run (sample 0 when the previous batch
    ended saturated). Sorted, unique."""
    n = gap.shape[0]
    after_sat = np.zeros(n, dtype=bool)
    if n:
        after_sat[1:] = saturated[:-1] & ~saturated[1:]
        after_sat[0] = carried_saturated and not saturated[0]
    return np.flatnonzero(gap | after_sat)


def restart_inclination(core: PolarisCore) -> None:
    """Step 1 above, on ``core`` in place."""
    P = core.tilt_P.reshape(5, 5).copy()
    P[:2, :] = 0.0
    P[:, :2] = 0.0
    P[0, 0] = P[1, 1] = FAULT_TILT_SIGMA**2
    core.tilt_P = P.reshape(-1)
    core.warmup_count = np.zeros(1)
    core.lin_mean = np.zeros(1)
    core.lin_m2 = np.zeros(1)


def reacquire_sample(aux: np.ndarray, dt: np.ndarray, elapsed: float) -> int:
    """The first sample of a pass (``aux`` from :func:`run_pass` with ``want_aux``: its
    columns 0 and 2 are the tilt variances) after which the heading is re-acquired, or -1
    when none is in this pass; ``elapsed`` [s] since the fault at its start."""
    good = (aux[:, 0] < REACQUIRE_TILT_SIGMA**2) & (aux[:, 2] < REACQUIRE_TILT_SIGMA**2)
    late = elapsed + np.cumsum(dt) >= REACQUIRE_MAX_S
    hit = np.flatnonzero(good | late)
    return int(hit[0]) if hit.size else -1
