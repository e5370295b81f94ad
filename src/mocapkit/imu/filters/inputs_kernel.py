"""The common case of :func:`mocapkit.imu.filters.inputs.prepare_inputs` in one numba pass.

Clean batches (finite gyroscope and accelerometer, magnetometer rows finite or all-NaN
gaps, no saturated gyroscope) are the rule; for them one pass over the samples gives the
masks and counts that the numpy checks give in several passes (``np.linalg.norm`` and
axis reductions cost about 100 ns per sample). Anything else is left to the numpy path,
which raises or warns with the message that names the sample.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def scan_inputs(
    g: np.ndarray,
    a: np.ndarray,
    m: np.ndarray,
    has_mag: bool,
    min_norm: float,
    acc_limit: float,
    gyr_limit: float,
    use_acc: np.ndarray,
    use_mag: np.ndarray,
) -> tuple[bool, int, int, int]:
    """One pass over (N, 3) ``g``, ``a`` and (N, 3) ``m`` (used when ``has_mag``).

    Fills ``use_acc`` (norm above ``min_norm`` and no component at or above
    ``acc_limit``) and ``use_mag`` (not a gap, norm above ``min_norm``) and sets the gap
    rows of ``m`` to zero (in place: ``m`` is the caller's copy). Returns ``(clean,
    acc_rejected, mag_gaps, mag_rejected)``; ``clean`` is False, and the rest meaningless,
    when a gyroscope or accelerometer value is not finite, a gyroscope component reaches
    ``gyr_limit``, or a magnetometer row is partly NaN or holds an infinity.
    """
    acc_rejected = mag_gaps = mag_rejected = 0
    for k in range(g.shape[0]):
        g0, g1, g2 = g[k, 0], g[k, 1], g[k, 2]
        a0, a1, a2 = a[k, 0], a[k, 1], a[k, 2]
        finite = (
            math.isfinite(g0) and math.isfinite(g1) and math.isfinite(g2)
            and math.isfinite(a0) and math.isfinite(a1) and math.isfinite(a2)
        )  # fmt: skip
        if not finite:
            return False, 0, 0, 0
        if abs(g0) >= gyr_limit or abs(g1) >= gyr_limit or abs(g2) >= gyr_limit:
            return False, 0, 0, 0
        ok = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2) > min_norm
        if abs(a0) >= acc_limit or abs(a1) >= acc_limit or abs(a2) >= acc_limit:
            ok = False
        use_acc[k] = ok
        if not ok:
            acc_rejected += 1
        if has_mag:
            m0, m1, m2 = m[k, 0], m[k, 1], m[k, 2]
            if math.isnan(m0) and math.isnan(m1) and math.isnan(m2):
                m[k, 0] = m[k, 1] = m[k, 2] = 0.0
                use_mag[k] = False
                mag_gaps += 1
                continue
            if not (math.isfinite(m0) and math.isfinite(m1) and math.isfinite(m2)):
                return False, 0, 0, 0
            ok = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2) > min_norm
            use_mag[k] = ok
            if not ok:
                mag_rejected += 1
        else:
            use_mag[k] = False
    return True, acc_rejected, mag_gaps, mag_rejected
