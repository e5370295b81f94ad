"""``polaris``: the numba fast path.

Exactly the arithmetic of :mod:`mocapkit.imu.filters.polaris_reference` (equations P1-P13
there), written on scalars and one flat state vector (offsets ``S_*`` and coefficients
``C_*`` from :mod:`mocapkit.imu.filters.polaris_params`) so that nothing is allocated per
sample. Tests hold it to the reference to 1e-9 on real data.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from mocapkit.geometry.kernels import qmul, rotation_matrix, rotation_matrix_into, strapdown_step
from mocapkit.imu.filters.polaris_heading_kernels import heading_update, start_heading
from mocapkit.imu.filters.polaris_params import (
    C_A1,
    C_A2,
    C_AC_ALPHA,
    C_AC_GAIN,
    C_B0,
    C_B1,
    C_B2,
    C_BIAS_NOISE_REST,
    C_BIAS_PROCESS,
    C_BLOCK,
    C_LAG,
    C_LIN_DEADBAND,
    C_LIN_DECAY,
    C_LIN_WARM,
    C_MAG_DELAY,
    C_REST_ALPHA,
    C_REST_MIN_TIME,
    C_REST_TH_ACC,
    C_REST_TH_GYR,
    C_TILT_NOISE,
    C_TILT_NOISE_REST,
    C_TILT_PROCESS,
    C_WARMUP,
    HISTORY_LEN,
    S_ACC_LP,
    S_ACC_LP_STATE,
    S_ACC_NORM_SLOW,
    S_BIAS,
    S_BLOCK_COUNT,
    S_BLOCK_TIME,
    S_DRIFT_G,
    S_DRIFT_G_LP,
    S_DRIFT_G_LP_STATE,
    S_DRIFT_J,
    S_DRIFT_J_LP,
    S_DRIFT_J_LP_STATE,
    S_DRIFT_JZ,
    S_HISTORY,
    S_HISTORY_POS,
    S_LIN_M2,
    S_LIN_MEAN,
    S_LIN_VAR,
    S_MAG_COUNT,
    S_MAG_P,
    S_MAG_R_SUM,
    S_MAG_RATE2_SUM,
    S_MAG_READY,
    S_MAG_SCALE,
    S_MAG_X,
    S_MAG_Y_SUM,
    S_Q_ACC,
    S_Q_GYR,
    S_REST_ACC_LP,
    S_REST_COUNT,
    S_REST_GYR_LP,
    S_REST_GYR_SUM,
    S_REST_TIME,
    S_TILT_P,
    S_WARMUP_COUNT,
)


@njit(cache=True, inline="always")
def _lp_step(c: np.ndarray, value: float, s: np.ndarray, i: int) -> float:
    """One Butterworth step of channel with memory ``s[i], s[i + 1]``; returns the output."""
    y = c[C_B0] * value + s[i]
    s[i] = c[C_B1] * value - c[C_A1] * y + s[i + 1]
    s[i + 1] = c[C_B2] * value - c[C_A2] * y
    return y


@njit(cache=True, inline="always")
def _lowpass(c: np.ndarray, value: float, s: np.ndarray, out: int, mem: int, warm: float) -> float:
    """(P3)/(P4) low-pass of one channel: running mean while ``warm`` > 0 (seeding the
    Butterworth memory ``s[mem:mem + 2]`` at its end), then the Butterworth."""
    if warm > 0.0:
        y = s[out] + (value - s[out]) / warm
        if warm >= c[C_WARMUP]:
            st2 = (c[C_B2] - c[C_A2]) * y
            s[mem] = (c[C_B1] - c[C_A1]) * y + st2
            s[mem + 1] = st2
        return y
    return _lp_step(c, value, s, mem)


@njit(cache=True)
def _tilt_update(c: np.ndarray, s: np.ndarray, P: np.ndarray, R: np.ndarray, v: np.ndarray) -> None:
    """(P6)-(P10) on the flat state; ``P`` (5, 5), ``R`` (3, 3), ``v`` (15,) are scratch."""
    T = s[S_BLOCK_TIME]
    for i in range(25):
        P[i // 5, i % 5] = s[S_TILT_P + i]
    # (P6) P <- F P F^T + Q with F = [[I2, -Phi], [0, I3]], Phi = J (2x3).
    j = S_DRIFT_J
    for col in range(5):
        r0 = s[j] * P[2, col] + s[j + 1] * P[3, col] + s[j + 2] * P[4, col]
        r1 = s[j + 3] * P[2, col] + s[j + 4] * P[3, col] + s[j + 5] * P[4, col]
        P[0, col] -= r0
        P[1, col] -= r1
    for row in range(5):
        c0 = P[row, 2] * s[j] + P[row, 3] * s[j + 1] + P[row, 4] * s[j + 2]
        c1 = P[row, 2] * s[j + 3] + P[row, 3] * s[j + 4] + P[row, 4] * s[j + 5]
        P[row, 0] -= c0
        P[row, 1] -= c1
    q_tilt = c[C_TILT_PROCESS] * c[C_TILT_PROCESS] * T
    q_bias = c[C_BIAS_PROCESS] * c[C_BIAS_PROCESS] * T
    P[0, 0] += q_tilt
    P[1, 1] += q_tilt
    P[2, 2] += q_bias
    P[3, 3] += q_bias
    P[4, 4] += q_bias
    x0 = x1 = x2 = x3 = x4 = 0.0
    # (P9) rest: sequential scalar bias updates.
    if s[S_REST_COUNT] >= c[C_BLOCK]:
        r_rest = c[C_BIAS_NOISE_REST] * c[C_BIAS_NOISE_REST]
        for i in range(3):
            xi = x2 if i == 0 else (x3 if i == 1 else x4)
            innovation = s[S_REST_GYR_SUM + i] / s[S_REST_COUNT] - (s[S_BIAS + i] + xi)
            sv = P[2 + i, 2 + i] + r_rest
            k0 = P[0, 2 + i] / sv
            k1 = P[1, 2 + i] / sv
            k2 = P[2, 2 + i] / sv
            k3 = P[3, 2 + i] / sv
            k4 = P[4, 2 + i] / sv
            x0 += k0 * innovation
            x1 += k1 * innovation
            x2 += k2 * innovation
            x3 += k3 * innovation
            x4 += k4 * innovation
            for r in range(5):
                kr = (
                    k0 if r == 0 else (k1 if r == 1 else (k2 if r == 2 else (k3 if r == 3 else k4)))
                )
                P[r, 0] -= kr * k0 * sv
                P[r, 1] -= kr * k1 * sv
                P[r, 2] -= kr * k2 * sv
                P[r, 3] -= kr * k3 * sv
                P[r, 4] -= kr * k4 * sv
    # (P7) tilt measurement.
    rotation_matrix_into(s[S_Q_ACC], s[S_Q_ACC + 1], s[S_Q_ACC + 2], s[S_Q_ACC + 3], R)
    ax, ay, az = s[S_ACC_LP], s[S_ACC_LP + 1], s[S_ACC_LP + 2]
    ex = R[0, 0] * ax + R[0, 1] * ay + R[0, 2] * az
    ey = R[1, 0] * ax + R[1, 1] * ay + R[1, 2] * az
    ez = R[2, 0] * ax + R[2, 1] * ay + R[2, 2] * az
    norm = math.sqrt(ex * ex + ey * ey + ez * ez)
    if norm > 1e-6:
        nx, ny, nz = ex / norm, ey / norm, ez / norm
        sin_angle = math.sqrt(nx * nx + ny * ny)
        factor = math.atan2(sin_angle, nz) / sin_angle if sin_angle > 1e-12 else 1.0
        z0 = ny * factor
        z1 = -nx * factor
        # (P8) lag model.
        d0 = d1 = d2 = d3 = d4 = d5 = 0.0
        if c[C_LAG] > 0.0:
            d0 = s[S_DRIFT_J] - s[S_DRIFT_J_LP]
            d1 = s[S_DRIFT_J + 1] - s[S_DRIFT_J_LP + 1]
            d2 = s[S_DRIFT_J + 2] - s[S_DRIFT_J_LP + 2]
            d3 = s[S_DRIFT_J + 3] - s[S_DRIFT_J_LP + 3]
            d4 = s[S_DRIFT_J + 4] - s[S_DRIFT_J_LP + 4]
            d5 = s[S_DRIFT_J + 5] - s[S_DRIFT_J_LP + 5]
            bx, by, bz = s[S_BIAS], s[S_BIAS + 1], s[S_BIAS + 2]
            z0 -= d0 * bx + d1 * by + d2 * bz - (s[S_DRIFT_G] - s[S_DRIFT_G_LP])
            z1 -= d3 * bx + d4 * by + d5 * bz - (s[S_DRIFT_G + 1] - s[S_DRIFT_G_LP + 1])
        at_rest = s[S_REST_TIME] >= c[C_REST_MIN_TIME]
        sigma = c[C_TILT_NOISE_REST] if at_rest else c[C_TILT_NOISE]
        # (P7a) the linear acceleration left in the low-pass.
        dev = (
            math.sqrt(s[S_ACC_LP] ** 2 + s[S_ACC_LP + 1] ** 2 + s[S_ACC_LP + 2] ** 2)
            - s[S_ACC_NORM_SLOW]
        )
        var = sigma * sigma + (s[S_LIN_VAR] + c[C_AC_GAIN] * dev * dev)
        i0 = z0 - (x0 + d0 * x2 + d1 * x3 + d2 * x4)
        i1 = z1 - (x1 + d3 * x2 + d4 * x3 + d5 * x4)
        # PHt (5x2) = P H^T with H = [[1, 0, d0, d1, d2], [0, 1, d3, d4, d5]].
        ph0 = v[0:5]
        ph1 = v[5:10]
        for r in range(5):
            ph0[r] = P[r, 0] + P[r, 2] * d0 + P[r, 3] * d1 + P[r, 4] * d2
            ph1[r] = P[r, 1] + P[r, 2] * d3 + P[r, 3] * d4 + P[r, 4] * d5
        s00 = ph0[0] + d0 * ph0[2] + d1 * ph0[3] + d2 * ph0[4] + var
        s01 = ph1[0] + d0 * ph1[2] + d1 * ph1[3] + d2 * ph1[4]
        s10 = ph0[1] + d3 * ph0[2] + d4 * ph0[3] + d5 * ph0[4]
        s11 = ph1[1] + d3 * ph1[2] + d4 * ph1[3] + d5 * ph1[4] + var
        det = s00 * s11 - s01 * s10
        if det > 0.0:  # S is positive definite unless the state has broken down
            v00, v01, v10, v11 = s11 / det, -s01 / det, -s10 / det, s00 / det
            xs = v[10:15]
            xs[0], xs[1], xs[2], xs[3], xs[4] = x0, x1, x2, x3, x4
            for r in range(5):
                k0 = ph0[r] * v00 + ph1[r] * v10
                k1 = ph0[r] * v01 + ph1[r] * v11
                xs[r] += k0 * i0 + k1 * i1
                for col in range(5):
                    P[r, col] -= k0 * ph0[col] + k1 * ph1[col]
            x0, x1, x2, x3, x4 = xs[0], xs[1], xs[2], xs[3], xs[4]
    # (P10) apply.
    angle = math.sqrt(x0 * x0 + x1 * x1)
    if angle > 1e-15:
        sh = math.sin(0.5 * angle) / angle
        w, qx, qy, qz = qmul(
            math.cos(0.5 * angle), sh * x0, sh * x1, 0.0,
            s[S_Q_ACC], s[S_Q_ACC + 1], s[S_Q_ACC + 2], s[S_Q_ACC + 3],
        )  # fmt: skip
    else:
        w, qx, qy, qz = qmul(
            1.0, 0.0, 0.0, 0.0, s[S_Q_ACC], s[S_Q_ACC + 1], s[S_Q_ACC + 2], s[S_Q_ACC + 3]
        )
    n = math.sqrt(w * w + qx * qx + qy * qy + qz * qz)
    s[S_Q_ACC], s[S_Q_ACC + 1], s[S_Q_ACC + 2], s[S_Q_ACC + 3] = w / n, qx / n, qy / n, qz / n
    s[S_BIAS] += x2
    s[S_BIAS + 1] += x3
    s[S_BIAS + 2] += x4
    # Symmetrise (see the reference): rounding asymmetry would otherwise grow.
    for r in range(5):
        for col in range(5):
            s[S_TILT_P + 5 * r + col] = 0.5 * (P[r, col] + P[col, r])
    # Rebase the drift integrals (see the reference).
    b1m_a1 = c[C_B1] - c[C_A1]
    b2m_a2 = c[C_B2] - c[C_A2]
    for i in range(6):
        v = s[S_DRIFT_J + i]
        st2 = b2m_a2 * v
        s[S_DRIFT_J_LP_STATE + 2 * i] -= b1m_a1 * v + st2
        s[S_DRIFT_J_LP_STATE + 2 * i + 1] -= st2
        s[S_DRIFT_J_LP + i] -= v
        s[S_DRIFT_J + i] = 0.0
    for i in range(2):
        v = s[S_DRIFT_G + i]
        st2 = b2m_a2 * v
        s[S_DRIFT_G_LP_STATE + 2 * i] -= b1m_a1 * v + st2
        s[S_DRIFT_G_LP_STATE + 2 * i + 1] -= st2
        s[S_DRIFT_G_LP + i] -= v
        s[S_DRIFT_G + i] = 0.0
    s[S_REST_GYR_SUM] = 0.0
    s[S_REST_GYR_SUM + 1] = 0.0
    s[S_REST_GYR_SUM + 2] = 0.0
    s[S_REST_COUNT] = 0.0


@njit(cache=True, inline="always")
def _lp(
    value: float, y: float, m0: float, m1: float, warm: float, warmup: float,
    b0: float, b1: float, b2: float, a1: float, a2: float,
) -> tuple[float, float, float]:  # fmt: skip
    """:func:`_lowpass` on locals: one channel with previous output ``y`` and Butterworth
    memory ``m0, m1``; returns the new ``(y, m0, m1)``."""
    if warm > 0.0:
        y = y + (value - y) / warm
        if warm >= warmup:
            st2 = (b2 - a2) * y
            m0 = (b1 - a1) * y + st2
            m1 = st2
        return y, m0, m1
    y = b0 * value + m0
    return y, b1 * value - a1 * y + m1, b2 * value - a2 * y


@njit(cache=True)
def polaris_kernel(
    c: np.ndarray,
    s: np.ndarray,
    gyr: np.ndarray,
    acc: np.ndarray,
    mag: np.ndarray,
    dt: np.ndarray,
    use_acc: np.ndarray,
    use_mag: np.ndarray,
    has_mag: bool,
    out9: np.ndarray,
    out6: np.ndarray,
    aux: np.ndarray,
) -> None:
    """Process N samples from the started flat state ``s`` (in place); see
    :func:`mocapkit.imu.filters.polaris_reference.run_reference` for the arguments.

    The state that changes every sample lives in locals for the whole loop (loads and
    stores through ``s`` cannot be kept in registers: numba cannot tell that ``s`` and the
    output arrays do not overlap); it is written to ``s`` before a block update reads it,
    read back after the update changed it, and written at the end."""
    block = c[C_BLOCK]
    delay = int(c[C_MAG_DELAY])
    alpha = c[C_REST_ALPHA]
    th_gyr2 = c[C_REST_TH_GYR] * c[C_REST_TH_GYR]
    th_acc2 = c[C_REST_TH_ACC] * c[C_REST_TH_ACC]
    rest_min_time = c[C_REST_MIN_TIME]
    warmup = c[C_WARMUP]
    lin_decay = c[C_LIN_DECAY]
    lin_deadband = c[C_LIN_DEADBAND]
    lin_warm = c[C_LIN_WARM]
    ac_alpha = c[C_AC_ALPHA]
    b0, b1, b2, a1, a2 = c[C_B0], c[C_B1], c[C_B2], c[C_A1], c[C_A2]
    want_aux = aux.shape[0] > 0
    R = np.empty((3, 3))
    Pt = np.empty((5, 5))
    Pm = np.empty((6, 6))
    Hm = np.empty((3, 6))
    PHm = np.empty((6, 3))
    Sm = np.empty((3, 3))
    Sim = np.empty((3, 3))
    nu = np.empty(3)
    scratch = np.empty(15)
    hc, hs = math.cos(0.5 * s[S_MAG_X]), math.sin(0.5 * s[S_MAG_X])  # Rz(delta), cached
    # -- the per-sample state in locals ------------------------------------------------------
    w, x, y, z = s[S_Q_GYR], s[S_Q_GYR + 1], s[S_Q_GYR + 2], s[S_Q_GYR + 3]
    pos = int(s[S_HISTORY_POS])
    lgx, lgy, lgz = s[S_REST_GYR_LP], s[S_REST_GYR_LP + 1], s[S_REST_GYR_LP + 2]
    lax, lay, laz = s[S_REST_ACC_LP], s[S_REST_ACC_LP + 1], s[S_REST_ACC_LP + 2]
    rest_time = s[S_REST_TIME]
    rsx, rsy, rsz = s[S_REST_GYR_SUM], s[S_REST_GYR_SUM + 1], s[S_REST_GYR_SUM + 2]
    rest_count = s[S_REST_COUNT]
    warmup_count = s[S_WARMUP_COUNT]
    lin_var, lin_mean, lin_m2 = s[S_LIN_VAR], s[S_LIN_MEAN], s[S_LIN_M2]
    alp0, alp1, alp2 = s[S_ACC_LP], s[S_ACC_LP + 1], s[S_ACC_LP + 2]
    am00, am01 = s[S_ACC_LP_STATE], s[S_ACC_LP_STATE + 1]
    am10, am11 = s[S_ACC_LP_STATE + 2], s[S_ACC_LP_STATE + 3]
    am20, am21 = s[S_ACC_LP_STATE + 4], s[S_ACC_LP_STATE + 5]
    acc_norm_slow = s[S_ACC_NORM_SLOW]
    jz0, jz1, jz2 = s[S_DRIFT_JZ], s[S_DRIFT_JZ + 1], s[S_DRIFT_JZ + 2]
    mag_ready = s[S_MAG_READY] != 0.0
    scale = s[S_MAG_SCALE]
    my0, my1, my2 = s[S_MAG_Y_SUM], s[S_MAG_Y_SUM + 1], s[S_MAG_Y_SUM + 2]
    mr00, mr01, mr02 = s[S_MAG_R_SUM], s[S_MAG_R_SUM + 1], s[S_MAG_R_SUM + 2]
    mr10, mr11, mr12 = s[S_MAG_R_SUM + 3], s[S_MAG_R_SUM + 4], s[S_MAG_R_SUM + 5]
    mr20, mr21, mr22 = s[S_MAG_R_SUM + 6], s[S_MAG_R_SUM + 7], s[S_MAG_R_SUM + 8]
    mag_count, mag_rate2 = s[S_MAG_COUNT], s[S_MAG_RATE2_SUM]
    block_count, block_time = s[S_BLOCK_COUNT], s[S_BLOCK_TIME]
    # ... and the state a block update changes (read again after each update)
    qa0, qa1, qa2, qa3 = s[S_Q_ACC], s[S_Q_ACC + 1], s[S_Q_ACC + 2], s[S_Q_ACC + 3]
    bx, by, bz = s[S_BIAS], s[S_BIAS + 1], s[S_BIAS + 2]
    j0, j1, j2 = s[S_DRIFT_J], s[S_DRIFT_J + 1], s[S_DRIFT_J + 2]
    j3, j4, j5 = s[S_DRIFT_J + 3], s[S_DRIFT_J + 4], s[S_DRIFT_J + 5]
    jl0, jl1, jl2 = s[S_DRIFT_J_LP], s[S_DRIFT_J_LP + 1], s[S_DRIFT_J_LP + 2]
    jl3, jl4, jl5 = s[S_DRIFT_J_LP + 3], s[S_DRIFT_J_LP + 4], s[S_DRIFT_J_LP + 5]
    jm00, jm01 = s[S_DRIFT_J_LP_STATE], s[S_DRIFT_J_LP_STATE + 1]
    jm10, jm11 = s[S_DRIFT_J_LP_STATE + 2], s[S_DRIFT_J_LP_STATE + 3]
    jm20, jm21 = s[S_DRIFT_J_LP_STATE + 4], s[S_DRIFT_J_LP_STATE + 5]
    jm30, jm31 = s[S_DRIFT_J_LP_STATE + 6], s[S_DRIFT_J_LP_STATE + 7]
    jm40, jm41 = s[S_DRIFT_J_LP_STATE + 8], s[S_DRIFT_J_LP_STATE + 9]
    jm50, jm51 = s[S_DRIFT_J_LP_STATE + 10], s[S_DRIFT_J_LP_STATE + 11]
    g0, g1 = s[S_DRIFT_G], s[S_DRIFT_G + 1]
    gl0, gl1 = s[S_DRIFT_G_LP], s[S_DRIFT_G_LP + 1]
    gm00, gm01 = s[S_DRIFT_G_LP_STATE], s[S_DRIFT_G_LP_STATE + 1]
    gm10, gm11 = s[S_DRIFT_G_LP_STATE + 2], s[S_DRIFT_G_LP_STATE + 3]
    for k in range(gyr.shape[0]):
        step = dt[k]
        gx, gy, gz = gyr[k, 0], gyr[k, 1], gyr[k, 2]
        ax, ay, az = acc[k, 0], acc[k, 1], acc[k, 2]
        # (P1) strapdown.
        rx, ry, rz = gx - bx, gy - by, gz - bz
        wx, wy, wz = rx * step, ry * step, rz * step
        w, x, y, z = strapdown_step(w, x, y, z, wx, wy, wz)
        h = S_HISTORY + 4 * pos
        s[h], s[h + 1], s[h + 2], s[h + 3] = w, x, y, z
        pos_now = pos
        pos = (pos + 1) % HISTORY_LEN
        # (P2) rest detector.
        dgx, dgy, dgz = gx - lgx, gy - lgy, gz - lgz
        dax, day, daz = ax - lax, ay - lay, az - laz
        lgx += alpha * dgx
        lgy += alpha * dgy
        lgz += alpha * dgz
        lax += alpha * dax
        lay += alpha * day
        laz += alpha * daz
        still = (
            use_acc[k]
            and dgx * dgx + dgy * dgy + dgz * dgz < th_gyr2
            and dax * dax + day * day + daz * daz < th_acc2
            and lgx * lgx + lgy * lgy + lgz * lgz < th_gyr2
        )
        rest_time = rest_time + step if still else 0.0
        if rest_time >= rest_min_time:
            rsx += gx
            rsy += gy
            rsz += gz
            rest_count += 1.0
        # (P3) accelerometer in I, low-passed.
        warm = 0.0
        if warmup_count < warmup:
            warm = warmup_count + 1.0
            warmup_count = warm
        if warm == 0.0:  # (P3a) the Butterworth forgets the warm-up's running mean
            lin_var *= lin_decay
        if use_acc[k]:
            r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_matrix(w, x, y, z)
            e0 = r00 * ax + r01 * ay + r02 * az
            e1 = r10 * ax + r11 * ay + r12 * az
            e2 = r20 * ax + r21 * ay + r22 * az
            alp0, am00, am01 = _lp(e0, alp0, am00, am01, warm, warmup, b0, b1, b2, a1, a2)
            alp1, am10, am11 = _lp(e1, alp1, am10, am11, warm, warmup, b0, b1, b2, a1, a2)
            alp2, am20, am21 = _lp(e2, alp2, am20, am21, warm, warmup, b0, b1, b2, a1, a2)
            if warm > 0.0:  # (P3a) spread of |acc| while warming up (Welford)
                a_n = math.sqrt(ax * ax + ay * ay + az * az)
                d = a_n - lin_mean
                lin_mean += d / warm
                lin_m2 += d * (a_n - lin_mean)
                lin_var = max(0.0, lin_m2 / warm - lin_deadband) * lin_warm
            lp_n = math.sqrt(alp0**2 + alp1**2 + alp2**2)
            acc_norm_slow += ac_alpha * (lp_n - acc_norm_slow)
        # (P4) drift integrals.
        q0, q1, q2, q3 = qmul(qa0, qa1, qa2, qa3, w, x, y, z)
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_matrix(q0, q1, q2, q3)
        j0 += r00 * step
        j1 += r01 * step
        j2 += r02 * step
        g0 += (r00 * bx + r01 * by + r02 * bz) * step
        j3 += r10 * step
        j4 += r11 * step
        j5 += r12 * step
        g1 += (r10 * bx + r11 * by + r12 * bz) * step
        jz0 += r20 * step
        jz1 += r21 * step
        jz2 += r22 * step
        jl0, jm00, jm01 = _lp(j0, jl0, jm00, jm01, warm, warmup, b0, b1, b2, a1, a2)
        jl1, jm10, jm11 = _lp(j1, jl1, jm10, jm11, warm, warmup, b0, b1, b2, a1, a2)
        jl2, jm20, jm21 = _lp(j2, jl2, jm20, jm21, warm, warmup, b0, b1, b2, a1, a2)
        jl3, jm30, jm31 = _lp(j3, jl3, jm30, jm31, warm, warmup, b0, b1, b2, a1, a2)
        jl4, jm40, jm41 = _lp(j4, jl4, jm40, jm41, warm, warmup, b0, b1, b2, a1, a2)
        jl5, jm50, jm51 = _lp(j5, jl5, jm50, jm51, warm, warmup, b0, b1, b2, a1, a2)
        gl0, gm00, gm01 = _lp(g0, gl0, gm00, gm01, warm, warmup, b0, b1, b2, a1, a2)
        gl1, gm10, gm11 = _lp(g1, gl1, gm10, gm11, warm, warmup, b0, b1, b2, a1, a2)
        # (P5) magnetometer.
        if has_mag and use_mag[k]:
            if delay > 0:  # else R6 = R(q_acc * q_gyr) above, the same numbers
                hp = S_HISTORY + 4 * ((pos_now - delay) % HISTORY_LEN)
                m0, m1, m2, m3 = qmul(qa0, qa1, qa2, qa3, s[hp], s[hp + 1], s[hp + 2], s[hp + 3])
                r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_matrix(m0, m1, m2, m3)
            mx, my, mz = mag[k, 0], mag[k, 1], mag[k, 2]
            if not mag_ready:
                R[0, 0], R[0, 1], R[0, 2] = r00, r01, r02
                R[1, 0], R[1, 1], R[1, 2] = r10, r11, r12
                R[2, 0], R[2, 1], R[2, 2] = r20, r21, r22
                start_heading(c, s, R, mx, my, mz)
                mag_ready = True
                scale = s[S_MAG_SCALE]
                hc, hs = math.cos(0.5 * s[S_MAG_X]), math.sin(0.5 * s[S_MAG_X])
            ux, uy, uz = mx / scale, my / scale, mz / scale
            my0 += r00 * ux + r01 * uy + r02 * uz
            mr00 += r00
            mr01 += r01
            mr02 += r02
            my1 += r10 * ux + r11 * uy + r12 * uz
            mr10 += r10
            mr11 += r11
            mr12 += r12
            my2 += r20 * ux + r21 * uy + r22 * uz
            mr20 += r20
            mr21 += r21
            mr22 += r22
            mag_count += 1.0
            mag_rate2 += rx * rx + ry * ry + rz * rz
        block_count += 1.0
        block_time += step
        if block_count >= block:
            # the state the updates read
            s[S_BLOCK_TIME] = block_time
            s[S_REST_TIME] = rest_time
            s[S_REST_GYR_SUM], s[S_REST_GYR_SUM + 1], s[S_REST_GYR_SUM + 2] = rsx, rsy, rsz
            s[S_REST_COUNT] = rest_count
            s[S_ACC_LP], s[S_ACC_LP + 1], s[S_ACC_LP + 2] = alp0, alp1, alp2
            s[S_ACC_NORM_SLOW] = acc_norm_slow
            s[S_LIN_VAR] = lin_var
            s[S_DRIFT_J], s[S_DRIFT_J + 1], s[S_DRIFT_J + 2] = j0, j1, j2
            s[S_DRIFT_J + 3], s[S_DRIFT_J + 4], s[S_DRIFT_J + 5] = j3, j4, j5
            s[S_DRIFT_J_LP], s[S_DRIFT_J_LP + 1], s[S_DRIFT_J_LP + 2] = jl0, jl1, jl2
            s[S_DRIFT_J_LP + 3], s[S_DRIFT_J_LP + 4], s[S_DRIFT_J_LP + 5] = jl3, jl4, jl5
            s[S_DRIFT_J_LP_STATE], s[S_DRIFT_J_LP_STATE + 1] = jm00, jm01
            s[S_DRIFT_J_LP_STATE + 2], s[S_DRIFT_J_LP_STATE + 3] = jm10, jm11
            s[S_DRIFT_J_LP_STATE + 4], s[S_DRIFT_J_LP_STATE + 5] = jm20, jm21
            s[S_DRIFT_J_LP_STATE + 6], s[S_DRIFT_J_LP_STATE + 7] = jm30, jm31
            s[S_DRIFT_J_LP_STATE + 8], s[S_DRIFT_J_LP_STATE + 9] = jm40, jm41
            s[S_DRIFT_J_LP_STATE + 10], s[S_DRIFT_J_LP_STATE + 11] = jm50, jm51
            s[S_DRIFT_G], s[S_DRIFT_G + 1] = g0, g1
            s[S_DRIFT_G_LP], s[S_DRIFT_G_LP + 1] = gl0, gl1
            s[S_DRIFT_G_LP_STATE], s[S_DRIFT_G_LP_STATE + 1] = gm00, gm01
            s[S_DRIFT_G_LP_STATE + 2], s[S_DRIFT_G_LP_STATE + 3] = gm10, gm11
            _tilt_update(c, s, Pt, R, scratch)
            if has_mag and mag_ready:
                s[S_DRIFT_JZ], s[S_DRIFT_JZ + 1], s[S_DRIFT_JZ + 2] = jz0, jz1, jz2
                s[S_MAG_Y_SUM], s[S_MAG_Y_SUM + 1], s[S_MAG_Y_SUM + 2] = my0, my1, my2
                s[S_MAG_R_SUM], s[S_MAG_R_SUM + 1], s[S_MAG_R_SUM + 2] = mr00, mr01, mr02
                s[S_MAG_R_SUM + 3], s[S_MAG_R_SUM + 4], s[S_MAG_R_SUM + 5] = mr10, mr11, mr12
                s[S_MAG_R_SUM + 6], s[S_MAG_R_SUM + 7], s[S_MAG_R_SUM + 8] = mr20, mr21, mr22
                s[S_MAG_COUNT], s[S_MAG_RATE2_SUM] = mag_count, mag_rate2
                heading_update(c, s, Pm, Hm, PHm, Sm, Sim, nu)
                hc, hs = math.cos(0.5 * s[S_MAG_X]), math.sin(0.5 * s[S_MAG_X])
                my0 = my1 = my2 = 0.0
                mr00 = mr01 = mr02 = mr10 = mr11 = mr12 = mr20 = mr21 = mr22 = 0.0
                mag_count = mag_rate2 = 0.0
            # what the tilt update changed
            qa0, qa1, qa2, qa3 = s[S_Q_ACC], s[S_Q_ACC + 1], s[S_Q_ACC + 2], s[S_Q_ACC + 3]
            bx, by, bz = s[S_BIAS], s[S_BIAS + 1], s[S_BIAS + 2]
            rsx = rsy = rsz = rest_count = 0.0
            j0 = j1 = j2 = j3 = j4 = j5 = g0 = g1 = 0.0
            jl0, jl1, jl2 = s[S_DRIFT_J_LP], s[S_DRIFT_J_LP + 1], s[S_DRIFT_J_LP + 2]
            jl3, jl4, jl5 = s[S_DRIFT_J_LP + 3], s[S_DRIFT_J_LP + 4], s[S_DRIFT_J_LP + 5]
            jm00, jm01 = s[S_DRIFT_J_LP_STATE], s[S_DRIFT_J_LP_STATE + 1]
            jm10, jm11 = s[S_DRIFT_J_LP_STATE + 2], s[S_DRIFT_J_LP_STATE + 3]
            jm20, jm21 = s[S_DRIFT_J_LP_STATE + 4], s[S_DRIFT_J_LP_STATE + 5]
            jm30, jm31 = s[S_DRIFT_J_LP_STATE + 6], s[S_DRIFT_J_LP_STATE + 7]
            jm40, jm41 = s[S_DRIFT_J_LP_STATE + 8], s[S_DRIFT_J_LP_STATE + 9]
            jm50, jm51 = s[S_DRIFT_J_LP_STATE + 10], s[S_DRIFT_J_LP_STATE + 11]
            gl0, gl1 = s[S_DRIFT_G_LP], s[S_DRIFT_G_LP + 1]
            gm00, gm01 = s[S_DRIFT_G_LP_STATE], s[S_DRIFT_G_LP_STATE + 1]
            gm10, gm11 = s[S_DRIFT_G_LP_STATE + 2], s[S_DRIFT_G_LP_STATE + 3]
            q0, q1, q2, q3 = qmul(qa0, qa1, qa2, qa3, w, x, y, z)
            jz0 = jz1 = jz2 = 0.0
            block_count = block_time = 0.0
        # q6 = q_acc * q_gyr: from (P4), or recomputed above after a block update.
        out6[k, 0], out6[k, 1], out6[k, 2], out6[k, 3] = q0, q1, q2, q3
        if mag_ready:
            h0, h1, h2, h3 = qmul(hc, 0.0, 0.0, hs, q0, q1, q2, q3)
            out9[k, 0], out9[k, 1], out9[k, 2], out9[k, 3] = h0, h1, h2, h3
        else:
            out9[k, 0], out9[k, 1], out9[k, 2], out9[k, 3] = q0, q1, q2, q3
        if want_aux:
            aux[k, 0] = s[S_TILT_P]
            aux[k, 1] = s[S_TILT_P + 1]
            aux[k, 2] = s[S_TILT_P + 6]
            aux[k, 3] = s[S_MAG_P]
            aux[k, 4] = bx
            aux[k, 5] = by
            aux[k, 6] = bz
            aux[k, 7] = (s[S_TILT_P + 12] + s[S_TILT_P + 18] + s[S_TILT_P + 24]) / 3.0
    # -- write the locals back ---------------------------------------------------------------
    s[S_Q_GYR], s[S_Q_GYR + 1], s[S_Q_GYR + 2], s[S_Q_GYR + 3] = w, x, y, z
    s[S_HISTORY_POS] = float(pos)
    s[S_REST_GYR_LP], s[S_REST_GYR_LP + 1], s[S_REST_GYR_LP + 2] = lgx, lgy, lgz
    s[S_REST_ACC_LP], s[S_REST_ACC_LP + 1], s[S_REST_ACC_LP + 2] = lax, lay, laz
    s[S_REST_TIME] = rest_time
    s[S_REST_GYR_SUM], s[S_REST_GYR_SUM + 1], s[S_REST_GYR_SUM + 2] = rsx, rsy, rsz
    s[S_REST_COUNT] = rest_count
    s[S_WARMUP_COUNT] = warmup_count
    s[S_LIN_VAR], s[S_LIN_MEAN], s[S_LIN_M2] = lin_var, lin_mean, lin_m2
    s[S_ACC_LP], s[S_ACC_LP + 1], s[S_ACC_LP + 2] = alp0, alp1, alp2
    s[S_ACC_LP_STATE], s[S_ACC_LP_STATE + 1] = am00, am01
    s[S_ACC_LP_STATE + 2], s[S_ACC_LP_STATE + 3] = am10, am11
    s[S_ACC_LP_STATE + 4], s[S_ACC_LP_STATE + 5] = am20, am21
    s[S_ACC_NORM_SLOW] = acc_norm_slow
    s[S_DRIFT_JZ], s[S_DRIFT_JZ + 1], s[S_DRIFT_JZ + 2] = jz0, jz1, jz2
    s[S_MAG_Y_SUM], s[S_MAG_Y_SUM + 1], s[S_MAG_Y_SUM + 2] = my0, my1, my2
    s[S_MAG_R_SUM], s[S_MAG_R_SUM + 1], s[S_MAG_R_SUM + 2] = mr00, mr01, mr02
    s[S_MAG_R_SUM + 3], s[S_MAG_R_SUM + 4], s[S_MAG_R_SUM + 5] = mr10, mr11, mr12
    s[S_MAG_R_SUM + 6], s[S_MAG_R_SUM + 7], s[S_MAG_R_SUM + 8] = mr20, mr21, mr22
    s[S_MAG_COUNT], s[S_MAG_RATE2_SUM] = mag_count, mag_rate2
    s[S_BLOCK_COUNT], s[S_BLOCK_TIME] = block_count, block_time
    s[S_DRIFT_J], s[S_DRIFT_J + 1], s[S_DRIFT_J + 2] = j0, j1, j2
    s[S_DRIFT_J + 3], s[S_DRIFT_J + 4], s[S_DRIFT_J + 5] = j3, j4, j5
    s[S_DRIFT_J_LP], s[S_DRIFT_J_LP + 1], s[S_DRIFT_J_LP + 2] = jl0, jl1, jl2
    s[S_DRIFT_J_LP + 3], s[S_DRIFT_J_LP + 4], s[S_DRIFT_J_LP + 5] = jl3, jl4, jl5
    s[S_DRIFT_J_LP_STATE], s[S_DRIFT_J_LP_STATE + 1] = jm00, jm01
    s[S_DRIFT_J_LP_STATE + 2], s[S_DRIFT_J_LP_STATE + 3] = jm10, jm11
    s[S_DRIFT_J_LP_STATE + 4], s[S_DRIFT_J_LP_STATE + 5] = jm20, jm21
    s[S_DRIFT_J_LP_STATE + 6], s[S_DRIFT_J_LP_STATE + 7] = jm30, jm31
    s[S_DRIFT_J_LP_STATE + 8], s[S_DRIFT_J_LP_STATE + 9] = jm40, jm41
    s[S_DRIFT_J_LP_STATE + 10], s[S_DRIFT_J_LP_STATE + 11] = jm50, jm51
    s[S_DRIFT_G], s[S_DRIFT_G + 1] = g0, g1
    s[S_DRIFT_G_LP], s[S_DRIFT_G_LP + 1] = gl0, gl1
    s[S_DRIFT_G_LP_STATE], s[S_DRIFT_G_LP_STATE + 1] = gm00, gm01
    s[S_DRIFT_G_LP_STATE + 2], s[S_DRIFT_G_LP_STATE + 3] = gm10, gm11
