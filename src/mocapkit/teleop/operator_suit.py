"""The simulated operator's suit: segment motion -> sensor poses -> IMU signals -> nodes ->
hub -> the frames a real suit would put on the wire, with their send times.

Real chain (``chain="real"``): each sensor sits on its segment with a mounting the
calibration does not know (a nominal mounting turned by a random ``misalign_deg``) and
10 cm down the segment, so it feels the segment's accelerations;
:func:`mocapkit.imu.simulate.simulate_imu` gives its gyroscope, accelerometer and
magnetometer with a sensor error model (default: consumer grade: noise, constant bias,
bias drift, scale errors). The magnetometer's hard iron (bias) and soft iron (scale) are
drawn once per sensor and distort both the session and, when ``mag_calibration`` is on,
a 20 s rotation "dance" done before the session (the usual magnetometer calibration,
:func:`mocapkit.imu.mag_calibration.fit_mag_calibration`), whose correction the node
applies to every reading; the gyroscope and accelerometer errors are never calibrated
(the still start measures the gyroscope bias at power-up). Then, as in the suit
(:mod:`mocapkit.suit`):

- ``fusion="node"`` (the paper's design): each :class:`~mocapkit.suit.node.SensorNode`
  runs the orientation filter on its own samples, with a still start (the first
  ``still_start_s`` seconds: the operator stands still in the calibration pose while the
  suit powers up, :class:`~mocapkit.imu.still_start.StillStartFilter`); the hub polls every
  node once per sample period and sends one BUNDLE per round;
- ``fusion="host"``: the nodes forward RAW samples (int16 on the wire) and the host fuses.

Ideal chain (``chain="ideal"``, an ablation): the bundles carry the true sensor
orientations: no IMU errors and no filters; everything downstream (wire, receiver, body
model, retargeting, session, robot server) is the same.

A :class:`Dropout` detaches a node from the bus for a while (its cable or radio fails): the
hub polls it in vain and the host sees nothing from it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_exp, quat_mul, quat_rotate
from mocapkit.imu.filters import make_filter
from mocapkit.imu.mag_calibration import fit_mag_calibration
from mocapkit.imu.simulate import ImuErrorModel, SensorErrors, simulate_imu
from mocapkit.imu.still_start import StillStartFilter
from mocapkit.series import ImuRecording, PoseSeries
from mocapkit.suit.bus import Hub, InProcessBus
from mocapkit.suit.node import SensorNode
from mocapkit.suit.protocol import Kind, frame, pack_quat
from mocapkit.teleop.operator import OperatorMotion

#: Where each sensor sits on its segment (segment frame, OpenSim axes) [m]: 10 cm down the
#: segment, on its surface.
SENSOR_OFFSET = np.array([0.03, -0.10, 0.04])


@dataclass(frozen=True)
class SuitSetup:
    """How the simulated suit is built.

    Attributes:
        chain: ``"real"`` (IMU signals, filters) or ``"ideal"`` (true orientations).
        fusion: ``"node"`` (on-node filters, bundles) or ``"host"`` (RAW samples).
        filter_name: the nodes' filter (registry name; host-side fusion uses the pipeline's).
        use_mag: 9D (True) or 6D filters on the nodes.
        errors: the IMU error model (None: ideal sensors).
        mag_calibration: calibrate each magnetometer (hard and soft iron) from a rotation
            dance before the session.
        still_start_s: the nodes' still start [s] (0: none).
        misalign_deg: random mounting error per sensor axis (standard deviation) [deg].
        rate_hz: sampling rate and hub round rate [Hz].
    """

    chain: Literal["real", "ideal"] = "real"
    fusion: Literal["node", "host"] = "node"
    filter_name: str = "miller"
    use_mag: bool = True
    errors: ImuErrorModel | None = field(default_factory=ImuErrorModel.consumer_grade)
    mag_calibration: bool = True
    still_start_s: float = 0.8
    misalign_deg: float = 5.0
    rate_hz: float = 100.0

    def __post_init__(self) -> None:
        if self.chain not in ("real", "ideal"):
            raise ConfigError(f"chain: expected 'real' or 'ideal', got {self.chain!r}")
        if self.fusion not in ("node", "host"):
            raise ConfigError(f"fusion: expected 'node' or 'host', got {self.fusion!r}")


@dataclass(frozen=True)
class Dropout:
    """Sensor ``sensor`` is unreachable from ``t_start`` to ``t_stop`` [s, motion time]."""

    sensor: str
    t_start: float
    t_stop: float


def sensor_poses(
    motion: OperatorMotion, rng: np.random.Generator, misalign_deg: float = 5.0
) -> dict[str, PoseSeries]:
    """Each sensor's pose (``q_world_sensor``, position) over the motion."""
    out = {}
    for i, seg in enumerate(motion.tree.segments):
        q_seg = motion.q_world_segment[:, i]
        mount = quat_exp(0.5 * np.radians(misalign_deg) * rng.normal(size=3))
        q = quat_mul(q_seg, mount)
        p = motion.p_world_segment[:, i] + quat_rotate(q_seg, SENSOR_OFFSET)
        out[seg.sensor] = PoseSeries(motion.time, q, p, name=seg.sensor)
    return out


def _dance(rate_hz: float, seconds: float = 20.0) -> PoseSeries:
    """A sensor turned in the hand through every direction (for the magnetometer fit)."""
    t = np.arange(round(seconds * rate_hz)) / rate_hz
    u = t / seconds
    yaw = 2 * np.pi * 3 * u
    pitch = 0.5 * np.pi * np.sin(2 * np.pi * 2.3 * u)
    roll = np.pi * np.sin(2 * np.pi * 1.7 * u)
    q = quat_mul(
        quat_mul(
            quat_exp(np.outer(yaw / 2, [0, 0, 1.0])), quat_exp(np.outer(pitch / 2, [0, 1.0, 0]))
        ),
        quat_exp(np.outer(roll / 2, [1.0, 0, 0])),
    )
    return PoseSeries(t, q, np.tile([0.0, 0.0, 1.0], (len(t), 1)), name="dance")


def sensor_recording(pose: PoseSeries, setup: SuitSetup, rng: np.random.Generator) -> ImuRecording:
    """A sensor's IMU recording for ``pose``, its magnetometer calibrated when asked
    (see the module docstring)."""
    err = setup.errors
    if err is None:
        rec = simulate_imu(pose, None, name=pose.name)
    else:
        m = err.mag
        mag_noise = SensorErrors(noise=m.noise, range=m.range)
        session_err = ImuErrorModel(err.gyr, err.acc, mag_noise, err.time_jitter_s)
        scale = 1.0 + rng.normal(0.0, m.scale_std, 3)
        hard = rng.normal(0.0, m.bias_std, 3) + (np.zeros(3) if m.bias is None else m.bias)
        rec = simulate_imu(pose, session_err, rng=rng, name=pose.name)
        assert rec.mag is not None
        mag = rec.mag * scale + hard
        if setup.mag_calibration:
            dance = simulate_imu(_dance(setup.rate_hz), ImuErrorModel(mag=mag_noise), rng=rng)
            assert dance.mag is not None
            mag = fit_mag_calibration(dance.mag * scale + hard).apply(mag)
        rec = ImuRecording(rec.time, rec.gyr, rec.acc, mag, name=pose.name)
    if not setup.use_mag:
        rec = ImuRecording(rec.time, rec.gyr, rec.acc, None, name=pose.name)
    return rec


def _check_ids(motion: OperatorMotion, sensor_ids: Mapping[str, int]) -> None:
    missing = [s for s in motion.tree.sensor_names if s not in sensor_ids]
    if missing:
        raise ConfigError(f"sensor_ids: no suit ID for {', '.join(missing)}")


def _rounds(
    time: FloatArray,
    dropouts: Sequence[Dropout],
    sensor_ids: Mapping[str, int],
) -> list[tuple[float, set[int]]]:
    """Per hub round: its time and the IDs that are unreachable then."""
    out = []
    for t in time:
        off = {sensor_ids[d.sensor] for d in dropouts if d.t_start <= t < d.t_stop}
        out.append((float(t), off))
    return out


def suit_timeline(
    motion: OperatorMotion,
    setup: SuitSetup,
    sensor_ids: Mapping[str, int],
    rng: np.random.Generator,
    dropouts: Sequence[Dropout] = (),
) -> tuple[list[tuple[float, bytes]], dict[str, PoseSeries]]:
    """The frames the suit sends, ``(t [s], bytes)``, one hub round per sample, and the true
    sensor poses."""
    _check_ids(motion, sensor_ids)
    for d in dropouts:
        if d.sensor not in sensor_ids:
            raise ConfigError(f"dropout: unknown sensor {d.sensor!r}")
    poses = sensor_poses(motion, rng, setup.misalign_deg if setup.chain == "real" else 0.0)
    rounds = _rounds(motion.time, dropouts, sensor_ids)
    if setup.chain == "ideal":
        items = []
        for k, (t, off) in enumerate(rounds):
            entries = b"".join(
                bytes([sid]) + pack_quat(poses[name].quat[k])
                for name, sid in sorted(sensor_ids.items(), key=lambda kv: kv[1])
                if sid not in off
            )
            if entries:
                items.append((t, frame(Kind.BUNDLE, 0, k & 0xFFFF, round(t * 1e6), entries)))
        return items, poses
    bus = InProcessBus()
    nodes: dict[int, SensorNode] = {}
    for name, sid in sensor_ids.items():
        rec = sensor_recording(poses[name], setup, rng)
        if setup.fusion == "node":
            filt = StillStartFilter(
                make_filter(setup.filter_name, setup.rate_hz), setup.still_start_s, label=name
            )
            node = SensorNode(sid, rec, "orientation", filt)
        else:
            node = SensorNode(sid, rec, "raw")
        nodes[sid] = node
        bus.attach(node)
    hub = Hub(bus, max_id=max(sensor_ids.values()), bundle=True)
    items = []
    attached = set(nodes)
    for t, off in rounds:
        for sid in attached - (set(nodes) - off):
            bus.detach(sid)
        for sid in (set(nodes) - off) - attached:
            bus.attach(nodes[sid])
        attached = set(nodes) - off
        for data in hub.poll_round(t + 1e-9):
            items.append((t, data))
    return items, poses
