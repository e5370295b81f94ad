"""``polaris``: the numba kernels of the heading filter (P11-P13) and its start.

The same arithmetic as ``_heading_update`` and ``_start_heading`` of the reference,
:mod:`mocapkit.imu.filters.polaris_reference`, on the flat state vector; used by
:mod:`mocapkit.imu.filters.polaris_kernels` and the offline heading pass.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from mocapkit.imu.filters.polaris_params import (
    C_FIELD_PROCESS,
    C_FIELD_SIGMA_INIT,
    C_HARD_IRON_INIT,
    C_HARD_IRON_RESET,
    C_HEADING_PROCESS,
    C_HEADING_SIGMA_INIT,
    C_MAG_GATE,
    C_MAG_NOISE,
    C_MAG_RESET_TIME,
    C_MAG_TIMING,
    S_BLOCK_TIME,
    S_DRIFT_JZ,
    S_MAG_COUNT,
    S_MAG_DIST_TIME,
    S_MAG_P,
    S_MAG_R_SUM,
    S_MAG_RATE2_SUM,
    S_MAG_READY,
    S_MAG_SCALE,
    S_MAG_X,
    S_MAG_Y_SUM,
    S_TILT_P,
)


@njit(cache=True)
def invert3(S: np.ndarray, out: np.ndarray) -> bool:
    """``out = inv(S)`` for a 3x3 matrix by cofactors; False (out untouched) unless the
    determinant is positive (S is a covariance)."""
    c00 = S[1, 1] * S[2, 2] - S[1, 2] * S[2, 1]
    c01 = S[1, 2] * S[2, 0] - S[1, 0] * S[2, 2]
    c02 = S[1, 0] * S[2, 1] - S[1, 1] * S[2, 0]
    det = S[0, 0] * c00 + S[0, 1] * c01 + S[0, 2] * c02
    if not det > 0.0:
        return False
    out[0, 0] = c00 / det
    out[0, 1] = (S[0, 2] * S[2, 1] - S[0, 1] * S[2, 2]) / det
    out[0, 2] = (S[0, 1] * S[1, 2] - S[0, 2] * S[1, 1]) / det
    out[1, 0] = c01 / det
    out[1, 1] = (S[0, 0] * S[2, 2] - S[0, 2] * S[2, 0]) / det
    out[1, 2] = (S[0, 2] * S[1, 0] - S[0, 0] * S[1, 2]) / det
    out[2, 0] = c02 / det
    out[2, 1] = (S[0, 1] * S[2, 0] - S[0, 0] * S[2, 1]) / det
    out[2, 2] = (S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]) / det
    return True


@njit(cache=True)
def heading_update(
    c: np.ndarray, s: np.ndarray, P: np.ndarray, H: np.ndarray, PHt: np.ndarray,
    S: np.ndarray, Si: np.ndarray, nu: np.ndarray,
) -> None:  # fmt: skip
    """(P11)-(P13) on the flat state; the matrix arguments are scratch arrays."""
    T = s[S_BLOCK_TIME]
    for i in range(36):
        P[i // 6, i % 6] = s[S_MAG_P + i]
    q_bias = 0.0
    for r in range(3):
        for col in range(3):
            q_bias += s[S_DRIFT_JZ + r] * s[S_TILT_P + 5 * (2 + r) + 2 + col] * s[S_DRIFT_JZ + col]
    P[0, 0] += c[C_HEADING_PROCESS] * c[C_HEADING_PROCESS] * T + q_bias
    P[1, 1] += c[C_FIELD_PROCESS] * c[C_FIELD_PROCESS] * T
    P[2, 2] += c[C_FIELD_PROCESS] * c[C_FIELD_PROCESS] * T
    count = s[S_MAG_COUNT]
    x = S_MAG_X
    if count > 0.0:
        sd = math.sin(s[x])
        cd = math.cos(s[x])
        for i in range(3):
            rm0 = s[S_MAG_R_SUM + 3 * i] / count
            rm1 = s[S_MAG_R_SUM + 3 * i + 1] / count
            rm2 = s[S_MAG_R_SUM + 3 * i + 2] / count
            H[i, 3] = rm0
            H[i, 4] = rm1
            H[i, 5] = rm2
            predicted = rm0 * s[x + 3] + rm1 * s[x + 4] + rm2 * s[x + 5]
            if i == 0:
                predicted = s[x + 1] * sd + predicted
            elif i == 1:
                predicted = s[x + 1] * cd + predicted
            else:
                predicted = s[x + 2] + predicted
            nu[i] = s[S_MAG_Y_SUM + i] / count - predicted
        H[0, 0], H[0, 1], H[0, 2] = s[x + 1] * cd, sd, 0.0
        H[1, 0], H[1, 1], H[1, 2] = -s[x + 1] * sd, cd, 0.0
        H[2, 0], H[2, 1], H[2, 2] = 0.0, 0.0, 1.0
        for r in range(6):
            for col in range(3):
                acc = 0.0
                for t in range(6):
                    acc += P[r, t] * H[col, t]
                PHt[r, col] = acc
        r_mag = c[C_MAG_NOISE] * c[C_MAG_NOISE] + (
            c[C_MAG_TIMING] * c[C_MAG_TIMING] * (s[S_MAG_RATE2_SUM] / count)
        )
        r_mag = r_mag + 0.5 * (s[S_TILT_P] + s[S_TILT_P + 6])
        for r in range(3):
            for col in range(3):
                acc = 0.0
                for t in range(6):
                    acc += H[r, t] * PHt[t, col]
                S[r, col] = acc + (r_mag if r == col else 0.0)
        d2 = math.inf  # a broken-down state (S not positive definite) counts as rejected
        if invert3(S, Si):
            d2 = 0.0
            for r in range(3):
                for col in range(3):
                    d2 += nu[r] * Si[r, col] * nu[col]
        gate = c[C_MAG_GATE]
        if d2 <= gate * gate:
            for r in range(6):
                k0 = PHt[r, 0] * Si[0, 0] + PHt[r, 1] * Si[1, 0] + PHt[r, 2] * Si[2, 0]
                k1 = PHt[r, 0] * Si[0, 1] + PHt[r, 1] * Si[1, 1] + PHt[r, 2] * Si[2, 1]
                k2 = PHt[r, 0] * Si[0, 2] + PHt[r, 1] * Si[1, 2] + PHt[r, 2] * Si[2, 2]
                s[x + r] += k0 * nu[0] + k1 * nu[1] + k2 * nu[2]
                for col in range(6):
                    P[r, col] -= k0 * PHt[col, 0] + k1 * PHt[col, 1] + k2 * PHt[col, 2]
            s[S_MAG_DIST_TIME] = 0.0
        else:
            dist = s[S_MAG_DIST_TIME] + T
            if dist >= c[C_MAG_RESET_TIME]:
                for r in range(6):
                    for col in range(3, 6):
                        P[r, col] = 0.0
                        P[col, r] = 0.0
                reset = c[C_HARD_IRON_RESET] * c[C_HARD_IRON_RESET]
                P[3, 3] = reset
                P[4, 4] = reset
                P[5, 5] = reset
                dist = 0.0
            s[S_MAG_DIST_TIME] = dist
    s[x] = math.atan2(math.sin(s[x]), math.cos(s[x]))
    for r in range(6):
        for col in range(6):
            s[S_MAG_P + 6 * r + col] = 0.5 * (P[r, col] + P[col, r])
    for i in range(3):
        s[S_MAG_Y_SUM + i] = 0.0
    for i in range(9):
        s[S_MAG_R_SUM + i] = 0.0
    s[S_MAG_COUNT] = 0.0
    s[S_MAG_RATE2_SUM] = 0.0


@njit(cache=True)
def start_heading(c: np.ndarray, s: np.ndarray, R: np.ndarray, mx: float, my: float,
                   mz: float) -> None:  # fmt: skip
    """First magnetometer sample: scale, heading and field from it; hard iron 0."""
    scale = math.sqrt(mx * mx + my * my + mz * mz)
    fx = R[0, 0] * (mx / scale) + R[0, 1] * (my / scale) + R[0, 2] * (mz / scale)
    fy = R[1, 0] * (mx / scale) + R[1, 1] * (my / scale) + R[1, 2] * (mz / scale)
    fz = R[2, 0] * (mx / scale) + R[2, 1] * (my / scale) + R[2, 2] * (mz / scale)
    s[S_MAG_SCALE] = scale
    s[S_MAG_X] = math.atan2(fx, fy)
    s[S_MAG_X + 1] = math.hypot(fx, fy)
    s[S_MAG_X + 2] = fz
    for i in range(3, 6):
        s[S_MAG_X + i] = 0.0
    for i in range(36):
        s[S_MAG_P + i] = 0.0
    s[S_MAG_P] = c[C_HEADING_SIGMA_INIT] * c[C_HEADING_SIGMA_INIT]
    s[S_MAG_P + 7] = c[C_FIELD_SIGMA_INIT] * c[C_FIELD_SIGMA_INIT]
    s[S_MAG_P + 14] = c[C_FIELD_SIGMA_INIT] * c[C_FIELD_SIGMA_INIT]
    hi = c[C_HARD_IRON_INIT] * c[C_HARD_IRON_INIT]
    s[S_MAG_P + 21] = hi
    s[S_MAG_P + 28] = hi
    s[S_MAG_P + 35] = hi
    s[S_MAG_READY] = 1.0
