"""``polaris``: the readable reference implementation (one sample at a time, numpy).

The numba kernel (:mod:`mocapkit.imu.filters.polaris_kernels`) does exactly the same
arithmetic on the flat state vector; tests hold the two to 1e-9 on real data. The
equations (numbered as in ``docs/design/imu.md``, section *polaris*):

Per sample, with the bias-corrected rate ``w = gyr - b``:

- (P1) strapdown: ``q_gyr <- q_gyr * exp(w dt / 2)`` (the almost-inertial frame I);
- (P2) rest detector: deviations of gyr/acc from 1st-order low-passes below thresholds
  for ``rest_min_time``; at rest the gyroscope readings are summed for (P9);
- (P3) accelerometer in I, low-passed (2nd-order Butterworth, ``tau_acc``): ``a_I``
  (for the first ``tau_acc`` seconds the running mean, so the start converges fast);
- (P3a) how much linear acceleration is left in it, read from norms (a rotation, e.g.
  by a bias error, leaves them alone): while warming up, the spread of ``|acc|`` around
  its running mean (less what sensor noise explains) gives the running mean's variance
  ``lin_var``, which then decays with the Butterworth's memory; and a slower average
  ``acc_norm_slow`` of ``|a_I_lp|`` (time constant ``tau_acc / 2``), whose deviation
  from ``|a_I_lp|`` shows the residual that remains while moving;
- (P4) drift integrals for the lag model: ``J += R6[:2] dt`` and ``G += R6[:2] b dt``
  (``R6`` the 6D rotation matrix), both also low-passed with the same Butterworth;
- (P5) magnetometer (9D): the field in E6 using the orientation ``mag_delay`` samples
  earlier, ``y = R6_delayed m / |m_0|``, summed over the block with ``R6_delayed``.

Every ``block_size`` samples (error-state Kalman filter, state
``x = [tilt_x, tilt_y, db_x, db_y, db_z]``, true = ``exp(tilt) * estimate``, ``b_true =
b + db``):

- (P6) propagate ``P <- F P F^T + Q`` with ``F = [[I2, -Phi], [0, I3]]``, ``Phi`` the block's
  ``J`` (a bias error ``db`` tilts the estimate by ``-R6[:2] db dt``);
- (P7) measurement ``z = [n_y, -n_x] * angle / sin(angle)`` from ``n = R(q_acc) a_I /
  |a_I|`` (the rotation that would bring the low-passed vertical onto z);
- (P7a) its noise: ``tilt_noise^2 + lin_var + lin_acc_weight * 2 N (|a_I_lp| -
  acc_norm_slow)^2 / g^2`` (``a_I_lp`` the low-passed accelerometer,
  ``N = 2 motion_corr_time * update rate``; 2: two horizontal axes for the one seen
  along gravity): a residual linear acceleration is shared by the updates within its
  correlation time, and counting each as independent would make the filter explain it
  by a gyroscope bias;
- (P8) lag model: a bias error also tilted the low-pass memory, so ``z = tilt + D db`` with
  ``D = J - LP(J)``; the part due to the bias corrections already applied,
  ``D b - (G - LP(G))``, is known and subtracted;
- (P9) at rest: ``mean(gyr) - b = db + noise`` (sequential scalar updates);
- (P10) apply: ``q_acc <- exp([x0, x1, 0]) * q_acc``, ``b <- b + x[2:]``.

Heading (9D), extended Kalman filter, state ``[delta, f_h, f_v, h_x, h_y, h_z]`` (relative
units): the block-mean field in E6 is modelled as ``[f_h sin delta, f_h cos delta, f_v] +
mean(R6_delayed) h``:

- (P11) propagate: random walks on ``delta`` and the field, plus the heading drift the
  bias uncertainty allows, ``Jz^T P_b Jz`` (``Jz`` the block integral of ``R6[2]``);
- (P12) Mahalanobis gate ``nu^T S^-1 nu <= gate^2`` (the measurement noise is
  ``mag_noise^2 + (mag_timing_sigma_s |w|)^2 + var(tilt)``, ``|w|^2`` the block mean,
  ``var(tilt)`` the mean tilt variance of the inclination filter: a tilt error turns the
  field in E6 by as much); accepted: standard EKF update;
- (P13) rejected for ``mag_reset_time``: the hard-iron covariance is reset to
  ``hard_iron_sigma_reset^2`` (a magnet now moves with the sensor) so it is re-learnt while
  the heading is carried by the gyroscope.

Output: ``q6 = q_acc * q_gyr`` and ``q9 = Rz(delta) * q6``.
"""

from __future__ import annotations

import math
from dataclasses import fields

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.geometry import quat_mul, quat_to_matrix
from mocapkit.imu.filters import polaris_params as pp
from mocapkit.imu.filters.polaris_params import PolarisCore

_UP = np.array([0.0, 0.0, 1.0])


def _exp_rotvec(v: FloatArray) -> FloatArray:
    """Unit quaternion of the rotation vector ``v`` [rad] (identity below 1e-15 rad)."""
    angle = math.sqrt(float(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]))
    if angle <= 1e-15:
        return np.array([1.0, 0.0, 0.0, 0.0])
    s = math.sin(0.5 * angle) / angle
    return np.array([math.cos(0.5 * angle), s * v[0], s * v[1], s * v[2]])


def _normalized(q: FloatArray) -> FloatArray:
    return q / math.sqrt(float(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]))


def _butterworth_step(c: FloatArray, x: FloatArray, state: FloatArray) -> FloatArray:
    """One step of the (vectorised) 2nd-order low-pass in transposed direct form II.

    ``state`` is (k, 2) ``[s1, s2]`` per channel, updated in place; returns the output (k,).
    """
    b0, b1, b2, a1, a2 = c[pp.C_B0], c[pp.C_B1], c[pp.C_B2], c[pp.C_A1], c[pp.C_A2]
    y = b0 * x + state[:, 0]
    state[:, 0] = b1 * x - a1 * y + state[:, 1]
    state[:, 1] = b2 * x - a2 * y
    return y


def _lowpass_step(
    c: FloatArray, x: FloatArray, y: FloatArray, state: FloatArray, warmup: float
) -> FloatArray:
    """The low-pass of (P3)/(P4): while ``warmup`` (the sample count, 0 when done) runs,
    the running mean ``y + (x - y) / warmup``, whose last value seeds the Butterworth
    memory; then the Butterworth. ``state`` (k, 2) is updated in place."""
    if warmup > 0.0:
        out = y + (x - y) / warmup
        if warmup >= c[pp.C_WARMUP]:
            state[:, :] = butterworth_steady_state(c, out)
        return out
    return _butterworth_step(c, x, state)


def butterworth_steady_state(c: FloatArray, value: FloatArray) -> FloatArray:
    """Low-pass memory (k, 2) whose output stays at ``value`` (k,) for a constant input."""
    b1, b2, a1, a2 = c[pp.C_B1], c[pp.C_B2], c[pp.C_A1], c[pp.C_A2]
    s2 = (b2 - a2) * value
    s1 = (b1 - a1) * value + s2
    return np.stack([s1, s2], axis=-1)


def start_core(
    c: FloatArray,
    core: PolarisCore,
    q_init: FloatArray,
    gyr0: FloatArray,
    acc0: FloatArray,
    lin2: float = 0.0,
    n_window: int = 1,
) -> None:
    """Initialise ``core`` from an initial ``q_world_sensor`` and the first readings.

    The almost-inertial frame I starts at the sensor frame (``q_gyr = 1``), so
    ``q_acc = q_init``. The accelerometer low-pass starts at the gravity direction that
    ``q_init`` implies (with the first reading's norm), the rest low-passes at the first
    readings; the heading filter waits for the first magnetometer sample.

    ``lin2`` [(m/s^2)^2]: the linear acceleration per axis in the ``n_window`` samples
    ``q_init`` was taken from (:func:`mocapkit.imu.filters.polaris_engine.initial_linear_acc`;
    0 at rest). It widens the initial tilt uncertainty (to at most 45 deg) and seeds the
    warm-up's spread (P3a) as ``n_window`` samples' worth, so the first running means,
    over too few samples to show their own spread, are not trusted as if at rest.
    """
    fresh = PolarisCore()
    for f in fields(PolarisCore):
        setattr(core, f.name, getattr(fresh, f.name))
    core.q_acc = _normalized(np.asarray(q_init, dtype=np.float64).copy())
    a_norm = math.sqrt(float(acc0 @ acc0))
    a_I = quat_to_matrix(core.q_acc).T @ (_UP * a_norm)
    core.acc_lp = a_I.copy()
    core.acc_norm_slow = np.array([a_norm])
    core.lin_mean = np.array([a_norm])
    core.lin_m2 = np.array([lin2 * n_window])
    core.lin_var = np.array([max(0.0, lin2 - c[pp.C_LIN_DEADBAND]) * c[pp.C_LIN_WARM]])
    core.acc_lp_state = butterworth_steady_state(c, a_I).reshape(-1)
    core.warmup_count = np.array([1.0])  # q_init counts as the first sample of the mean
    core.drift_J_lp = np.zeros(6)
    core.drift_G_lp = np.zeros(2)
    core.rest_gyr_lp = np.asarray(gyr0, dtype=np.float64).copy()
    core.rest_acc_lp = np.asarray(acc0, dtype=np.float64).copy()
    P = np.zeros((5, 5))
    tilt_var = c[pp.C_TILT_SIGMA_INIT] ** 2 + lin2 / pp.GRAVITY**2
    P[0, 0] = P[1, 1] = min(tilt_var, (0.25 * math.pi) ** 2)
    P[2, 2] = P[3, 3] = P[4, 4] = c[pp.C_BIAS_SIGMA_INIT] ** 2
    core.tilt_P = P.reshape(-1)
    core.started = np.array([1.0])


def reset_heading(core: PolarisCore) -> None:
    """Forget the heading filter (it restarts from the next magnetometer sample)."""
    core.mag_ready = np.array([0.0])
    core.mag_x = np.zeros(6)
    core.mag_P = np.zeros(36)
    core.mag_y_sum = np.zeros(3)
    core.mag_R_sum = np.zeros(9)
    core.mag_count = np.array([0.0])
    core.mag_dist_time = np.array([0.0])


def heading_quat(delta: float) -> FloatArray:
    """``Rz(delta)`` as a quaternion."""
    return np.array([math.cos(0.5 * delta), 0.0, 0.0, math.sin(0.5 * delta)])


def _rest_detector(
    c: FloatArray, core: PolarisCore, gyr: FloatArray, acc: FloatArray, dt: float, acc_ok: bool
) -> None:
    """(P2) update the rest low-passes and timer; sum gyroscope readings while at rest."""
    alpha = c[pp.C_REST_ALPHA]
    d_gyr = gyr - core.rest_gyr_lp
    d_acc = acc - core.rest_acc_lp
    core.rest_gyr_lp = core.rest_gyr_lp + alpha * d_gyr
    core.rest_acc_lp = core.rest_acc_lp + alpha * d_acc
    th_gyr2 = c[pp.C_REST_TH_GYR] ** 2
    still = (
        acc_ok
        and float(d_gyr @ d_gyr) < th_gyr2
        and float(d_acc @ d_acc) < c[pp.C_REST_TH_ACC] ** 2
        and float(core.rest_gyr_lp @ core.rest_gyr_lp) < th_gyr2
    )
    core.rest_time = np.array([core.rest_time[0] + dt if still else 0.0])
    if core.rest_time[0] >= c[pp.C_REST_MIN_TIME]:
        core.rest_gyr_sum = core.rest_gyr_sum + gyr
        core.rest_count = core.rest_count + 1.0


def _track_linear_acc(c: FloatArray, core: PolarisCore, acc: FloatArray, warmup: float) -> None:
    """(P3a) after the low-pass step of a usable sample ``acc``. While warming up
    (``warmup`` samples in the running mean) Welford's running mean and sum of squared
    deviations of ``|acc|`` give its spread; less the deadband of sensor noise, times
    ``C_LIN_WARM``, it is the running mean's tilt variance [rad^2]. Then the slower average
    of ``|a_I_lp|``."""
    if warmup > 0.0:
        a = math.sqrt(float(acc @ acc))
        d = a - core.lin_mean[0]
        core.lin_mean = np.array([core.lin_mean[0] + d / warmup])
        core.lin_m2 = np.array([core.lin_m2[0] + d * (a - core.lin_mean[0])])
        spread = max(0.0, core.lin_m2[0] / warmup - c[pp.C_LIN_DEADBAND])
        core.lin_var = np.array([spread * c[pp.C_LIN_WARM]])
    norm = math.sqrt(float(core.acc_lp @ core.acc_lp))
    core.acc_norm_slow = core.acc_norm_slow + c[pp.C_AC_ALPHA] * (norm - core.acc_norm_slow)


def _accumulate_drift(
    c: FloatArray, core: PolarisCore, R6: FloatArray, dt: float, warmup: float
) -> None:
    """(P4) ``J += R6[:2] dt``, ``G += R6[:2] b dt`` and their low-passes (the same filter
    as the accelerometer's, warm-up included, so the lag model stays exact)."""
    core.drift_J = core.drift_J + R6[:2, :].reshape(-1) * dt
    core.drift_G = core.drift_G + (R6[:2, :] @ core.bias) * dt
    core.drift_Jz = core.drift_Jz + R6[2, :] * dt
    j_state = core.drift_J_lp_state.reshape(6, 2)
    core.drift_J_lp = _lowpass_step(c, core.drift_J, core.drift_J_lp, j_state, warmup)
    core.drift_J_lp_state = j_state.reshape(-1)
    g_state = core.drift_G_lp_state.reshape(2, 2)
    core.drift_G_lp = _lowpass_step(c, core.drift_G, core.drift_G_lp, g_state, warmup)
    core.drift_G_lp_state = g_state.reshape(-1)


def _start_heading(c: FloatArray, core: PolarisCore, R_mag: FloatArray, mag: FloatArray) -> None:
    """First magnetometer sample: scale, heading and field from it; hard iron 0."""
    scale = math.sqrt(float(mag @ mag))
    f = R_mag @ (mag / scale)
    core.mag_scale = np.array([scale])
    core.mag_x = np.array([math.atan2(f[0], f[1]), math.hypot(f[0], f[1]), f[2], 0.0, 0.0, 0.0])
    P = np.zeros((6, 6))
    P[0, 0] = c[pp.C_HEADING_SIGMA_INIT] ** 2
    P[1, 1] = P[2, 2] = c[pp.C_FIELD_SIGMA_INIT] ** 2
    P[3, 3] = P[4, 4] = P[5, 5] = c[pp.C_HARD_IRON_INIT] ** 2
    core.mag_P = P.reshape(-1)
    core.mag_ready = np.array([1.0])


def _tilt_update(c: FloatArray, core: PolarisCore) -> None:
    """(P6)-(P10): one Kalman step of the tilt/bias filter over the finished block."""
    T = float(core.block_time[0])
    P = core.tilt_P.reshape(5, 5).copy()
    # (P6) propagation; the block started with J = 0, so Phi = J.
    F = np.eye(5)
    F[0:2, 2:5] = -core.drift_J.reshape(2, 3)
    P = F @ P @ F.T
    P[0, 0] += c[pp.C_TILT_PROCESS] ** 2 * T
    P[1, 1] += c[pp.C_TILT_PROCESS] ** 2 * T
    for i in range(2, 5):
        P[i, i] += c[pp.C_BIAS_PROCESS] ** 2 * T
    x = np.zeros(5)
    block = c[pp.C_BLOCK]
    # (P9) bias measurements at rest (the whole block at rest).
    if core.rest_count[0] >= block:
        r_rest = c[pp.C_BIAS_NOISE_REST] ** 2
        for i in range(3):
            innovation = core.rest_gyr_sum[i] / core.rest_count[0] - (core.bias[i] + x[2 + i])
            s = P[2 + i, 2 + i] + r_rest
            k = P[:, 2 + i] / s
            x = x + k * innovation
            P = P - np.outer(k, k) * s
    # (P7) tilt measurement from the low-passed accelerometer.
    a_E = quat_to_matrix(core.q_acc) @ core.acc_lp
    norm = math.sqrt(float(a_E @ a_E))
    if norm > 1e-6:
        n = a_E / norm
        sin_angle = math.sqrt(float(n[0] * n[0] + n[1] * n[1]))
        factor = math.atan2(sin_angle, n[2]) / sin_angle if sin_angle > 1e-12 else 1.0
        z = np.array([n[1] * factor, -n[0] * factor])
        # (P8) lag model.
        D = np.zeros((2, 3))
        if c[pp.C_LAG] > 0.0:
            D = (core.drift_J - core.drift_J_lp).reshape(2, 3)
            z = z - (D @ core.bias - (core.drift_G - core.drift_G_lp))
        H = np.zeros((2, 5))
        H[0, 0] = H[1, 1] = 1.0
        H[:, 2:5] = D
        at_rest = core.rest_time[0] >= c[pp.C_REST_MIN_TIME]
        sigma = c[pp.C_TILT_NOISE_REST] if at_rest else c[pp.C_TILT_NOISE]
        # (P7a) the linear acceleration left in the low-pass.
        deviation = math.sqrt(float(core.acc_lp @ core.acc_lp)) - core.acc_norm_slow[0]
        r_lin = core.lin_var[0] + c[pp.C_AC_GAIN] * deviation * deviation
        innovation = z - H @ x
        PHt = P @ H.T
        S = H @ PHt + np.eye(2) * (sigma * sigma + r_lin)
        if np.linalg.det(S) > 0.0:  # positive definite unless the state has broken down
            K = PHt @ np.linalg.inv(S)
            x = x + K @ innovation
            P = P - K @ PHt.T
    # (P10) apply the correction; the error state returns to zero.
    correction = _exp_rotvec(np.array([x[0], x[1], 0.0]))
    core.q_acc = _normalized(quat_mul(correction, core.q_acc))
    core.bias = core.bias + x[2:5]
    # Symmetrise: rounding makes P slightly asymmetric and the asymmetry would grow.
    core.tilt_P = (0.5 * (P + P.T)).reshape(-1)
    # Rebase the drift integrals (only differences to their low-passes matter): subtracting
    # a constant from the input and the steady state of that constant from the memory
    # shifts the low-pass output by exactly that constant.
    j_state = core.drift_J_lp_state.reshape(6, 2) - butterworth_steady_state(c, core.drift_J)
    core.drift_J_lp_state = j_state.reshape(-1)
    core.drift_J_lp = core.drift_J_lp - core.drift_J
    core.drift_J = np.zeros(6)
    g_state = core.drift_G_lp_state.reshape(2, 2) - butterworth_steady_state(c, core.drift_G)
    core.drift_G_lp_state = g_state.reshape(-1)
    core.drift_G_lp = core.drift_G_lp - core.drift_G
    core.drift_G = np.zeros(2)
    core.rest_gyr_sum = np.zeros(3)
    core.rest_count = np.array([0.0])


def _heading_update(c: FloatArray, core: PolarisCore) -> None:
    """(P11)-(P13): one step of the heading / field / hard-iron filter over the block."""
    T = float(core.block_time[0])
    P = core.mag_P.reshape(6, 6).copy()
    x = core.mag_x.copy()
    # (P11) random walks; the heading also inherits the bias uncertainty of (P6)-(P10).
    jz = core.drift_Jz
    P_bias = core.tilt_P.reshape(5, 5)[2:5, 2:5]
    P[0, 0] += c[pp.C_HEADING_PROCESS] ** 2 * T + float(jz @ P_bias @ jz)
    P[1, 1] += c[pp.C_FIELD_PROCESS] ** 2 * T
    P[2, 2] += c[pp.C_FIELD_PROCESS] ** 2 * T
    count = float(core.mag_count[0])
    if count > 0.0:
        y = core.mag_y_sum / count
        R_mean = core.mag_R_sum.reshape(3, 3) / count
        sd, cd = math.sin(x[0]), math.cos(x[0])
        predicted = np.array([x[1] * sd, x[1] * cd, x[2]]) + R_mean @ x[3:6]
        nu = y - predicted
        H = np.zeros((3, 6))
        H[0, 0], H[0, 1] = x[1] * cd, sd
        H[1, 0], H[1, 1] = -x[1] * sd, cd
        H[2, 2] = 1.0
        H[:, 3:6] = R_mean
        PHt = P @ H.T
        rate2 = float(core.mag_rate2_sum[0]) / count
        # the field in E6 also turns with the tilt error of the 6D estimate
        tilt_var = 0.5 * (core.tilt_P[0] + core.tilt_P[6])
        r_mag = c[pp.C_MAG_NOISE] ** 2 + c[pp.C_MAG_TIMING] ** 2 * rate2 + tilt_var
        S = H @ PHt + np.eye(3) * r_mag
        # A broken-down state (S not positive definite) counts as rejected.
        positive = np.linalg.det(S) > 0.0
        S_inv = np.linalg.inv(S) if positive else np.zeros((3, 3))
        d2 = float(nu @ S_inv @ nu) if positive else math.inf
        # (P12) gate.
        if d2 <= c[pp.C_MAG_GATE] ** 2:
            K = PHt @ S_inv
            x = x + K @ nu
            P = P - K @ PHt.T
            core.mag_dist_time = np.array([0.0])
        else:
            # (P13) persistent inconsistency: re-learn the hard iron.
            dist = core.mag_dist_time[0] + T
            if dist >= c[pp.C_MAG_RESET_TIME]:
                P[3:6, :] = 0.0
                P[:, 3:6] = 0.0
                for i in range(3, 6):
                    P[i, i] = c[pp.C_HARD_IRON_RESET] ** 2
                dist = 0.0
            core.mag_dist_time = np.array([dist])
    x[0] = math.atan2(math.sin(x[0]), math.cos(x[0]))
    core.mag_x = x
    core.mag_P = (0.5 * (P + P.T)).reshape(-1)
    core.mag_y_sum = np.zeros(3)
    core.mag_R_sum = np.zeros(9)
    core.mag_count = np.array([0.0])
    core.mag_rate2_sum = np.array([0.0])


def run_reference(
    c: FloatArray,
    core: PolarisCore,
    gyr: FloatArray,
    acc: FloatArray,
    mag: FloatArray,
    dt: FloatArray,
    use_acc: np.ndarray,
    use_mag: np.ndarray,
    has_mag: bool,
    out9: FloatArray,
    out6: FloatArray,
    aux: FloatArray,
) -> None:
    """Process N samples from a started ``core`` (updated in place).

    Args:
        c: coefficient vector (:func:`polaris_params.coefficients`).
        gyr, acc, mag: (N, 3) readings [rad/s], [m/s^2], [any unit].
        dt: (N,) time steps [s]; use_acc, use_mag: (N,) bool, which readings to use.
        has_mag: 9D mode.
        out9, out6: (N, 4) outputs ``q9`` (equals ``q6`` until the heading is known, and in
            6D) and ``q6``.
        aux: (N, 8) or (0, 8): per sample ``[P_tilt_xx, P_tilt_xy, P_tilt_yy, P_delta,
            b_x, b_y, b_z, trace(P_bias) / 3]`` for the offline smoother.
    """
    block = c[pp.C_BLOCK]
    delay = int(c[pp.C_MAG_DELAY])
    hist_len = pp.HISTORY_LEN
    want_aux = aux.shape[0] > 0
    for k in range(gyr.shape[0]):
        step = float(dt[k])
        # (P1) strapdown integration in the almost-inertial frame.
        rate = gyr[k] - core.bias
        core.q_gyr = _normalized(quat_mul(core.q_gyr, _exp_rotvec(rate * step)))
        pos = int(core.history_pos[0])
        core.q_gyr_history[pos] = core.q_gyr
        core.history_pos = np.array([float((pos + 1) % hist_len)])
        # (P2) rest detector.
        _rest_detector(c, core, gyr[k], acc[k], step, bool(use_acc[k]))
        # (P3) accelerometer in I, low-passed (a running mean while warming up).
        count = core.warmup_count[0] + 1.0 if core.warmup_count[0] < c[pp.C_WARMUP] else 0.0
        if count > 0.0:
            core.warmup_count = np.array([count])
        if count == 0.0:  # the Butterworth forgets the warm-up's running mean
            core.lin_var = core.lin_var * c[pp.C_LIN_DECAY]
        if use_acc[k]:
            a_I = quat_to_matrix(core.q_gyr) @ acc[k]
            state = core.acc_lp_state.reshape(3, 2)
            core.acc_lp = _lowpass_step(c, a_I, core.acc_lp, state, count)
            core.acc_lp_state = state.reshape(-1)
            _track_linear_acc(c, core, acc[k], count)
        # (P4) drift integrals.
        q6 = quat_mul(core.q_acc, core.q_gyr)
        _accumulate_drift(c, core, quat_to_matrix(q6), step, count)
        # (P5) magnetometer, compared with the orientation `delay` samples earlier.
        if has_mag and use_mag[k]:
            q_past = core.q_gyr_history[(pos - delay) % hist_len]
            R_mag = quat_to_matrix(quat_mul(core.q_acc, q_past))
            if core.mag_ready[0] == 0.0:
                _start_heading(c, core, R_mag, mag[k])
            core.mag_y_sum = core.mag_y_sum + R_mag @ (mag[k] / core.mag_scale[0])
            core.mag_R_sum = core.mag_R_sum + R_mag.reshape(-1)
            core.mag_count = core.mag_count + 1.0
            core.mag_rate2_sum = core.mag_rate2_sum + float(rate @ rate)
        core.block_count = core.block_count + 1.0
        core.block_time = core.block_time + step
        if core.block_count[0] >= block:
            _tilt_update(c, core)
            if has_mag and core.mag_ready[0] != 0.0:
                _heading_update(c, core)
            core.drift_Jz = np.zeros(3)
            core.block_count = np.array([0.0])
            core.block_time = np.array([0.0])
        q6 = quat_mul(core.q_acc, core.q_gyr)
        out6[k] = q6
        out9[k] = quat_mul(heading_quat(core.mag_x[0]), q6) if core.mag_ready[0] != 0.0 else q6
        if want_aux:
            P = core.tilt_P
            aux[k] = [P[0], P[1], P[6], core.mag_P[0], *core.bias, (P[12] + P[18] + P[24]) / 3.0]


def strapdown_reference(gyr: FloatArray, bias: FloatArray, dt: FloatArray, out: FloatArray) -> None:
    """``out[k] = q_I_S`` integrating ``(gyr - bias) dt`` from identity, as (P1)."""
    q = np.array([1.0, 0.0, 0.0, 0.0])
    for k in range(gyr.shape[0]):
        q = _normalized(quat_mul(q, _exp_rotvec((gyr[k] - bias[k]) * dt[k])))
        out[k] = q


def heading_pass_reference(
    c: FloatArray,
    core: PolarisCore,
    q6: FloatArray,
    mag: FloatArray,
    rate2: FloatArray,
    dt: FloatArray,
    use_mag: np.ndarray,
    out: FloatArray,
) -> None:
    """The heading filter (P5, P11-P13) alone on a given 6D orientation ``q6`` (N, 4) and
    squared angular rates ``rate2`` (N,) (no delay; ``core.tilt_P`` and ``drift_Jz`` are
    zero, so no bias term); ``out`` (N, 2) receives ``[delta, var(delta)]``."""
    block = c[pp.C_BLOCK]
    for k in range(q6.shape[0]):
        if use_mag[k]:
            R = quat_to_matrix(q6[k])
            if core.mag_ready[0] == 0.0:
                _start_heading(c, core, R, mag[k])
            core.mag_y_sum = core.mag_y_sum + R @ (mag[k] / core.mag_scale[0])
            core.mag_R_sum = core.mag_R_sum + R.reshape(-1)
            core.mag_count = core.mag_count + 1.0
            core.mag_rate2_sum = core.mag_rate2_sum + float(rate2[k])
        core.block_count = core.block_count + 1.0
        core.block_time = core.block_time + float(dt[k])
        if core.block_count[0] >= block:
            if core.mag_ready[0] != 0.0:
                _heading_update(c, core)
            core.block_count = np.array([0.0])
            core.block_time = np.array([0.0])
        out[k, 0] = core.mag_x[0]
        out[k, 1] = core.mag_P[0] if core.mag_ready[0] != 0.0 else 0.0
