"""``polaris`` parameters (frozen, validated) and state (copyable, checkpointable).

The algorithm is described in :mod:`mocapkit.imu.filters.polaris` and in
``docs/design/imu.md`` (section *polaris*). This module only holds numbers:

- :class:`PolarisParams`: the tuning, in SI units (radians, seconds), each with a
  physical meaning and a default (see the field comments for how it was chosen);
- :func:`coefficients`: the derived per-run constants, packed into one float vector
  shared by the readable reference and the numba kernel (index names ``C_*``);
- :class:`PolarisState`: every quantity carried from one sample to the next, with
  named fields; :func:`pack_state` / :func:`unpack_state` convert it to the flat vector
  the kernel works on (index names ``S_*``), so both implementations share one state.

Frames: ``S`` sensor, ``I`` the almost-inertial frame of the bias-corrected gyroscope
strapdown integration, ``E6`` the 6D world (z up, arbitrary heading), ``E`` the 9D world
(ENU, y magnetic north). ``q_gyr = q_I_S``, ``q_acc = q_E6_I``, ``q6 = q_acc * q_gyr``,
``q9 = Rz(delta) * q6``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError
from mocapkit.imu.filters.base import FilterParams

_DEG = math.pi / 180.0
# Longest magnetometer delay the ring buffer of past strapdown orientations holds [samples].
MAX_MAG_DELAY_SAMPLES = 63


@dataclass(frozen=True)
class PolarisParams(FilterParams):
    """Tuning of the ``polaris`` filter (all SI; angles in rad).

    How the defaults were chosen (``benchmarks/polaris_cv.py``): ``tau_acc``,
    ``tilt_process``, ``bias_process``, ``tilt_noise_rest``, ``bias_noise_rest``,
    ``heading_process``, ``field_process`` and ``offline_tau_acc`` by a fixed selection
    procedure (coordinate descent on the error relative to VQF) run on the 8 BROAD trials
    in ``../shared/data``; docs/benchmarks.md gives that procedure's leave-one-trial-out
    figures and the defaults' figures on 22 BROAD trials never used for any choice. All
    the other parameters are set from the physics of a MEMS IMU (comments below).

    Inclination (6D), a 5-state Kalman filter on the tilt of the almost-inertial frame and
    the gyroscope bias, updated at ``update_rate_hz`` from the accelerometer low-passed in
    that frame:

    Attributes:
        tau_acc: time constant [s] of the 2nd-order Butterworth low-pass applied to the
            accelerometer in the almost-inertial frame (cut-off ``1 / (2 pi tau_acc)``).
        update_rate_hz: rate [Hz] of the Kalman updates; samples are grouped in blocks of
            ``round(rate_hz / update_rate_hz)`` (at least 1).
        tilt_noise: std [rad] of one low-passed tilt measurement while moving (it is mostly
            residual linear acceleration, not sensor noise).
        tilt_noise_rest: the same at rest.
        tilt_process: random walk [rad/sqrt(s)] of the inclination (gyroscope noise and
            scale errors the bias does not explain).
        bias_process: random walk [rad/s/sqrt(s)] of the gyroscope bias.
        bias_sigma_init: initial bias uncertainty [rad/s] (a MEMS gyroscope: 0.5 deg/s).
        bias_noise_rest: std [rad/s] of a block-mean gyroscope reading as a measurement of
            the bias at rest.
        rest_tau: time constant [s] of the rest detector's low-passes.
        rest_th_gyr: rest when the gyroscope deviates less than this [rad/s] from its
            low-pass, and that low-pass is below it too (2 deg/s).
        rest_th_acc: ... and the accelerometer deviates less than this [m/s^2].
        rest_min_time: ... for at least this long [s].
        lag_compensation: model the lag of the low-passed measurement behind the tilt that a
            bias error causes (the ``D`` term of the measurement model).
        motion_corr_time: correlation time [s] of a body segment's linear acceleration
            (human motion of about 1 Hz: ``1 / (2 pi)`` s). The low-passed accelerometer is
            gravity plus the low-passed linear acceleration; that residual changes slowly,
            so the ``update_rate_hz`` measurements a second share it. Its variance per
            update is therefore counted ``2 motion_corr_time update_rate`` times (the
            number of updates that see the same error), see (P7a).
        lin_acc_weight: weight of the residual seen in the low-passed accelerometer
            itself (its deviation from a slower average, (P7a)); 0 uses only the
            warm-up term.

    Heading (9D), a 6-state extended Kalman filter on the heading offset ``delta`` of E6
    from E, the Earth field (horizontal and vertical parts, relative to the first sample's
    norm) and a hard-iron offset, with a Mahalanobis gate:

    Attributes:
        mag_noise: std of the block-mean field in E6 (relative to the field norm).
        heading_process: random walk [rad/sqrt(s)] of ``delta`` (the 6D heading drifts);
            the bias uncertainty of the inclination filter adds ``Jz^T P_b Jz`` per update
            (``Jz`` the block integral of the vertical row of ``R6``).
        field_process: random walk [1/sqrt(s)] of the relative field components.
        hard_iron_sigma_init: prior std of the hard-iron offset (relative): small, the
            magnetometer is assumed calibrated.
        hard_iron_sigma_reset: std the hard-iron offset is reset to when the field stays
            inconsistent for ``mag_reset_time`` (a magnet attached to the sensor).
        mag_gate: an update is rejected when its Mahalanobis distance exceeds this.
        mag_reset_time: [s] of consecutive rejections before the hard iron is re-learnt.
        mag_delay_s: magnetometer latency [s] behind the gyroscope (see
            :func:`mocapkit.imu.filters.polaris_timing.estimate_mag_delay`); the field is
            compared with the orientation that many samples earlier.

    Offline (:meth:`Polaris.run_offline`):

    Attributes:
        offline_tau_acc: time constant [s] of the zero-phase low-pass of the accelerometer
            in the inertial frame of the smoothed-bias strapdown integration.
    """

    tau_acc: float = 1.5  # chosen by LOO-CV
    update_rate_hz: float = 50.0  # far above the filters' bandwidths (< 1 Hz)
    tilt_noise: float = 0.125 * _DEG  # the scale: the filter depends on noise ratios
    tilt_noise_rest: float = 0.025 * _DEG  # chosen by LOO-CV
    tilt_process: float = 0.0224 * _DEG  # chosen by LOO-CV
    bias_process: float = 0.00035 * _DEG  # chosen by LOO-CV
    bias_sigma_init: float = 0.5 * _DEG  # a MEMS gyroscope's turn-on bias
    bias_noise_rest: float = 0.28 * _DEG  # chosen by LOO-CV
    rest_tau: float = 0.5  # rest detector as VQF's published defaults
    rest_th_gyr: float = 2.0 * _DEG
    rest_th_acc: float = 0.5
    rest_min_time: float = 1.5
    lag_compensation: bool = True
    motion_corr_time: float = 1.0 / (2.0 * math.pi)  # a 1 Hz motion
    lin_acc_weight: float = 0.5  # BROAD 6D 0.646 (0: 0.630), synthetic limbs better
    mag_noise: float = 0.02  # 0.7 uT of 44 per axis, block-averaged, plus field roughness
    heading_process: float = 0.05 * _DEG  # chosen by LOO-CV
    field_process: float = 0.064  # chosen by LOO-CV
    hard_iron_sigma_init: float = 1e-3  # a calibrated magnetometer
    hard_iron_sigma_reset: float = 1.0  # a magnet can be as strong as the Earth's field
    mag_gate: float = 3.0  # a 3-sigma gate
    mag_reset_time: float = 1.0  # a field rejected for 1 s is a new hard iron to learn
    mag_delay_s: float = 0.0  # unknown sensor: not compensated, covered by the next line
    mag_timing_sigma_s: float = 0.01  # ~10 ms latency/jitter of an uncharacterised sensor
    offline_tau_acc: float = 2.5  # chosen by LOO-CV

    def __post_init__(self) -> None:
        super().__post_init__()
        positive = (
            "tau_acc",
            "update_rate_hz",
            "tilt_noise",
            "tilt_noise_rest",
            "bias_sigma_init",
            "bias_noise_rest",
            "rest_tau",
            "rest_th_gyr",
            "rest_th_acc",
            "mag_noise",
            "hard_iron_sigma_init",
            "hard_iron_sigma_reset",
            "mag_gate",
            "offline_tau_acc",
            "motion_corr_time",
        )
        non_negative = (
            "lin_acc_weight",
            "tilt_process",
            "bias_process",
            "rest_min_time",
            "heading_process",
            "field_process",
            "mag_reset_time",
            "mag_delay_s",
            "mag_timing_sigma_s",
        )
        for name in positive:
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(f"{name}: expected a positive finite number, got {value}")
        for name in non_negative:
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value >= 0.0):
                raise ConfigError(f"{name}: expected a finite number >= 0, got {value}")
        if self.mag_delay_samples > MAX_MAG_DELAY_SAMPLES:
            raise ConfigError(
                f"mag_delay_s: {self.mag_delay_s} s is {self.mag_delay_samples} samples at "
                f"{self.rate_hz:g} Hz; at most {MAX_MAG_DELAY_SAMPLES} samples are supported"
            )
        # The low-pass must be slower than the sampling (bilinear transform below Nyquist).
        for name in ("tau_acc", "offline_tau_acc", "rest_tau"):
            if getattr(self, name) * self.rate_hz < 1.0:
                raise ConfigError(
                    f"{name}: {getattr(self, name)} s is shorter than one sample at "
                    f"{self.rate_hz:g} Hz; use at least {1.0 / self.rate_hz:.3g} s"
                )

    @property
    def block_size(self) -> int:
        """Samples per Kalman update."""
        return max(1, round(self.rate_hz / self.update_rate_hz))

    @property
    def mag_delay_samples(self) -> int:
        """Magnetometer delay in whole samples at the nominal rate."""
        return round(self.mag_delay_s * self.rate_hz)


def butterworth2(tau: float, dt: float) -> tuple[float, float, float, float, float]:
    """2nd-order Butterworth low-pass ``(b0, b1, b2, a1, a2)``, cut-off ``1 / (2 pi tau)``
    [Hz], by the bilinear transform with pre-warping; unit DC gain."""
    k = math.tan(math.pi * dt / (2.0 * math.pi * tau))
    norm = 1.0 / (1.0 + math.sqrt(2.0) * k + k * k)
    b0 = k * k * norm
    return b0, 2.0 * b0, b0, 2.0 * (k * k - 1.0) * norm, (1.0 - math.sqrt(2.0) * k + k * k) * norm


# -- coefficient vector (shared by both implementations) -------------------------------------
C_B0, C_B1, C_B2, C_A1, C_A2 = 0, 1, 2, 3, 4  # acc low-pass (tau_acc, nominal dt)
C_REST_ALPHA = 5  # 1st-order low-pass factor of the rest detector
C_BLOCK = 6  # samples per update
C_TILT_NOISE = 7
C_TILT_NOISE_REST = 8
C_TILT_PROCESS = 9
C_BIAS_PROCESS = 10
C_BIAS_SIGMA_INIT = 11
C_BIAS_NOISE_REST = 12
C_REST_TH_GYR = 13
C_REST_TH_ACC = 14
C_REST_MIN_TIME = 15
C_LAG = 16  # 1.0 or 0.0
C_MAG_NOISE = 17
C_HEADING_PROCESS = 18
C_FIELD_PROCESS = 19
C_HARD_IRON_INIT = 20
C_HARD_IRON_RESET = 21
C_MAG_GATE = 22
C_MAG_RESET_TIME = 23
C_MAG_DELAY = 24  # samples
C_TILT_SIGMA_INIT = 25
C_HEADING_SIGMA_INIT = 26
C_FIELD_SIGMA_INIT = 27
C_WARMUP = 28  # samples of running mean before the low-pass takes over
C_MAG_TIMING = 29
C_LIN_WARM = 30  # warm-up: tilt variance [rad^2] per (m/s^2)^2 of spread of |acc|
C_LIN_DECAY = 31  # per-sample decay of that variance once the Butterworth has taken over
C_LIN_DEADBAND = 32  # spread [(m/s^2)^2] that is sensor noise, not motion
C_AC_ALPHA = 33  # 1st-order factor (tau_acc / 2) of the slower average of |low-pass|
C_AC_GAIN = 34  # tilt variance [rad^2] per (m/s^2)^2 of deviation from that average
N_COEFFICIENTS = 35

# Initial uncertainties the user does not tune: the first tilt comes from a short average
# of the accelerometer (2 deg covers linear acceleration in it), the first heading from a
# single magnetometer sample (10 deg covers its noise and a moderate disturbance).
TILT_SIGMA_INIT = 2.0 * _DEG
# Gravity [m/s^2], only to turn a linear acceleration into the tilt angle it causes.
GRAVITY = 9.81
HEADING_SIGMA_INIT = 10.0 * _DEG
FIELD_SIGMA_INIT = 0.05


def coefficients(params: PolarisParams) -> FloatArray:
    """The derived constants of one run, as a float vector indexed by the ``C_*`` names."""
    c = np.zeros(N_COEFFICIENTS)
    c[C_B0 : C_A2 + 1] = butterworth2(params.tau_acc, params.dt)
    c[C_REST_ALPHA] = 1.0 - math.exp(-params.dt / params.rest_tau)
    c[C_BLOCK] = params.block_size
    c[C_TILT_NOISE] = params.tilt_noise
    c[C_TILT_NOISE_REST] = params.tilt_noise_rest
    c[C_TILT_PROCESS] = params.tilt_process
    c[C_BIAS_PROCESS] = params.bias_process
    c[C_BIAS_SIGMA_INIT] = params.bias_sigma_init
    c[C_BIAS_NOISE_REST] = params.bias_noise_rest
    c[C_REST_TH_GYR] = params.rest_th_gyr
    c[C_REST_TH_ACC] = params.rest_th_acc
    c[C_REST_MIN_TIME] = params.rest_min_time
    c[C_LAG] = 1.0 if params.lag_compensation else 0.0
    c[C_MAG_NOISE] = params.mag_noise
    c[C_HEADING_PROCESS] = params.heading_process
    c[C_FIELD_PROCESS] = params.field_process
    c[C_HARD_IRON_INIT] = params.hard_iron_sigma_init
    c[C_HARD_IRON_RESET] = params.hard_iron_sigma_reset
    c[C_MAG_GATE] = params.mag_gate
    c[C_MAG_RESET_TIME] = params.mag_reset_time
    c[C_MAG_DELAY] = params.mag_delay_samples
    c[C_TILT_SIGMA_INIT] = TILT_SIGMA_INIT
    c[C_HEADING_SIGMA_INIT] = HEADING_SIGMA_INIT
    c[C_FIELD_SIGMA_INIT] = FIELD_SIGMA_INIT
    c[C_WARMUP] = max(1, round(params.tau_acc * params.rate_hz))
    c[C_MAG_TIMING] = params.mag_timing_sigma_s
    # (P7a) linear acceleration in the tilt measurement: a residual with correlation time
    # motion_corr_time is seen by 2 * motion_corr_time * update rate updates. Its size is
    # read from the norm of the accelerometer (a rotation, e.g. by a bias error, leaves
    # the norm alone), i.e. along gravity; the two horizontal axes that tilt the
    # measurement carry as much again each (a body's linear acceleration has no preferred
    # direction): hence the factor 2.
    updates_per_s = params.rate_hz / params.block_size
    shared = 2.0 * 2.0 * params.motion_corr_time * updates_per_s / GRAVITY**2
    c[C_LIN_WARM] = shared
    c[C_LIN_DECAY] = math.exp(-2.0 * params.dt / params.tau_acc)
    c[C_LIN_DEADBAND] = (params.rest_th_acc / 3.0) ** 2
    c[C_AC_ALPHA] = 1.0 - math.exp(-2.0 * params.dt / params.tau_acc)
    c[C_AC_GAIN] = params.lin_acc_weight * shared
    return c


# -- state ---------------------------------------------------------------------------------
def _zeros(n: int) -> FloatArray:
    return np.zeros(n)


@dataclass
class PolarisCore:
    """Everything ``polaris`` carries between samples (named; see :data:`STATE_LAYOUT`).

    ``started`` is 0 until the first sample has set the tilt (``q_acc``) and the low-pass
    memories; for the first ``tau_acc`` seconds (``warmup_count`` samples) the low-passes
    are running means of all samples so far, so the start does not stay biased towards
    the first reading; ``mag_ready`` is 0 until the first magnetometer sample has set the
    heading filter. Matrices are stored row-major in flat arrays (``tilt_P`` is 5x5 over
    ``[tilt_x, tilt_y, bias_x, bias_y, bias_z]``, ``mag_P`` 6x6 over
    ``[delta, field_h, field_v, iron_x, iron_y, iron_z]``).
    """

    q_gyr: FloatArray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    q_acc: FloatArray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    bias: FloatArray = field(default_factory=lambda: _zeros(3))
    tilt_P: FloatArray = field(default_factory=lambda: _zeros(25))
    acc_lp_state: FloatArray = field(default_factory=lambda: _zeros(6))
    acc_lp: FloatArray = field(default_factory=lambda: _zeros(3))
    acc_norm_slow: FloatArray = field(default_factory=lambda: _zeros(1))
    lin_mean: FloatArray = field(default_factory=lambda: _zeros(1))
    lin_m2: FloatArray = field(default_factory=lambda: _zeros(1))
    lin_var: FloatArray = field(default_factory=lambda: _zeros(1))
    drift_J: FloatArray = field(default_factory=lambda: _zeros(6))
    drift_J_lp_state: FloatArray = field(default_factory=lambda: _zeros(12))
    drift_J_lp: FloatArray = field(default_factory=lambda: _zeros(6))
    drift_G: FloatArray = field(default_factory=lambda: _zeros(2))
    drift_G_lp_state: FloatArray = field(default_factory=lambda: _zeros(4))
    drift_G_lp: FloatArray = field(default_factory=lambda: _zeros(2))
    drift_Jz: FloatArray = field(default_factory=lambda: _zeros(3))
    rest_gyr_lp: FloatArray = field(default_factory=lambda: _zeros(3))
    rest_acc_lp: FloatArray = field(default_factory=lambda: _zeros(3))
    rest_time: FloatArray = field(default_factory=lambda: _zeros(1))
    rest_gyr_sum: FloatArray = field(default_factory=lambda: _zeros(3))
    rest_count: FloatArray = field(default_factory=lambda: _zeros(1))
    block_count: FloatArray = field(default_factory=lambda: _zeros(1))
    block_time: FloatArray = field(default_factory=lambda: _zeros(1))
    mag_x: FloatArray = field(default_factory=lambda: _zeros(6))
    mag_P: FloatArray = field(default_factory=lambda: _zeros(36))
    mag_y_sum: FloatArray = field(default_factory=lambda: _zeros(3))
    mag_R_sum: FloatArray = field(default_factory=lambda: _zeros(9))
    mag_count: FloatArray = field(default_factory=lambda: _zeros(1))
    mag_rate2_sum: FloatArray = field(default_factory=lambda: _zeros(1))
    mag_scale: FloatArray = field(default_factory=lambda: _zeros(1))
    mag_dist_time: FloatArray = field(default_factory=lambda: _zeros(1))
    mag_ready: FloatArray = field(default_factory=lambda: _zeros(1))
    started: FloatArray = field(default_factory=lambda: _zeros(1))
    warmup_count: FloatArray = field(default_factory=lambda: _zeros(1))
    history_pos: FloatArray = field(default_factory=lambda: _zeros(1))
    q_gyr_history: FloatArray = field(
        default_factory=lambda: np.tile([1.0, 0.0, 0.0, 0.0], (MAX_MAG_DELAY_SAMPLES + 1, 1))
    )


def _layout() -> list[tuple[str, int]]:
    core = PolarisCore()
    return [(f.name, int(np.asarray(getattr(core, f.name)).size)) for f in fields(PolarisCore)]


STATE_LAYOUT = _layout()
_OFFSETS: dict[str, int] = {}
_pos = 0
for _name, _size in STATE_LAYOUT:
    _OFFSETS[_name] = _pos
    _pos += _size
STATE_SIZE = _pos

# Offsets for the kernel (module-level ints are compile-time constants in numba).
S_Q_GYR = _OFFSETS["q_gyr"]
S_Q_ACC = _OFFSETS["q_acc"]
S_BIAS = _OFFSETS["bias"]
S_TILT_P = _OFFSETS["tilt_P"]
S_ACC_LP_STATE = _OFFSETS["acc_lp_state"]
S_ACC_LP = _OFFSETS["acc_lp"]
S_ACC_NORM_SLOW = _OFFSETS["acc_norm_slow"]
S_LIN_MEAN = _OFFSETS["lin_mean"]
S_LIN_M2 = _OFFSETS["lin_m2"]
S_LIN_VAR = _OFFSETS["lin_var"]
S_DRIFT_J = _OFFSETS["drift_J"]
S_DRIFT_J_LP_STATE = _OFFSETS["drift_J_lp_state"]
S_DRIFT_J_LP = _OFFSETS["drift_J_lp"]
S_DRIFT_G = _OFFSETS["drift_G"]
S_DRIFT_G_LP_STATE = _OFFSETS["drift_G_lp_state"]
S_DRIFT_G_LP = _OFFSETS["drift_G_lp"]
S_DRIFT_JZ = _OFFSETS["drift_Jz"]
S_REST_GYR_LP = _OFFSETS["rest_gyr_lp"]
S_REST_ACC_LP = _OFFSETS["rest_acc_lp"]
S_REST_TIME = _OFFSETS["rest_time"]
S_REST_GYR_SUM = _OFFSETS["rest_gyr_sum"]
S_REST_COUNT = _OFFSETS["rest_count"]
S_BLOCK_COUNT = _OFFSETS["block_count"]
S_BLOCK_TIME = _OFFSETS["block_time"]
S_MAG_X = _OFFSETS["mag_x"]
S_MAG_P = _OFFSETS["mag_P"]
S_MAG_Y_SUM = _OFFSETS["mag_y_sum"]
S_MAG_R_SUM = _OFFSETS["mag_R_sum"]
S_MAG_COUNT = _OFFSETS["mag_count"]
S_MAG_RATE2_SUM = _OFFSETS["mag_rate2_sum"]
S_MAG_SCALE = _OFFSETS["mag_scale"]
S_MAG_DIST_TIME = _OFFSETS["mag_dist_time"]
S_MAG_READY = _OFFSETS["mag_ready"]
S_STARTED = _OFFSETS["started"]
S_WARMUP_COUNT = _OFFSETS["warmup_count"]
S_HISTORY_POS = _OFFSETS["history_pos"]
S_HISTORY = _OFFSETS["q_gyr_history"]
HISTORY_LEN = MAX_MAG_DELAY_SAMPLES + 1


def pack_state(core: PolarisCore) -> FloatArray:
    """The named state as one flat float vector (a copy)."""
    out = np.empty(STATE_SIZE)
    for name, size in STATE_LAYOUT:
        out[_OFFSETS[name] : _OFFSETS[name] + size] = np.asarray(getattr(core, name)).reshape(-1)
    return out


def unpack_state(flat: FloatArray, core: PolarisCore) -> None:
    """Write a flat vector back into the named fields of ``core`` (copies)."""
    for name, size in STATE_LAYOUT:
        current = np.asarray(getattr(core, name))
        value = flat[_OFFSETS[name] : _OFFSETS[name] + size].reshape(current.shape).copy()
        setattr(core, name, value)


#: ``polaris-body``: the parameters that differ from :class:`PolarisParams`' defaults for
#: sensors worn on limbs (chosen on the teleoperation chain's simulated operator by
#: ``benchmarks/polaris_body_profile.py``, on seeds not used for the figures): a longer
#: accelerometer low-pass, so a limb's linear acceleration at every movement start tilts
#: the estimate less.
BODY_PROFILE: dict[str, float] = {"tau_acc": 4.0}
