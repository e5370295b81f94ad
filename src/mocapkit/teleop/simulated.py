"""A live teleoperation session driven by a simulated operator, for as long as wanted: the
live viewer's session (``mocapkit viewer``), through the real chain.

::

  operator_cycle (truth: the body model tracing the shapes in a loop)
    -> the sensors' poses (mountings 5 deg off) -> IMU signals (consumer-grade errors,
       magnetometers calibrated by a rotation dance) for one period of the cycle
    -> RAW datagrams, period after period (sequence numbers and sensor clocks continue;
       the period's samples, noise included, repeat), streamed a few seconds ahead to
    -> a sender process (the suit's hardware), which sends them over UDP on the real clock
    -> LiveSession: receiver thread, host-side fusion (a filter bank with a still start),
       body model, heading refinement, eq. 16, session, robot link
    -> a robot-server process (own IK, joint and speed limits, latency, safety gate)

The operator API (:meth:`SimulatedSession.calibrate`, ``engage``, ``disengage``,
``reindex``, ``clutch``, ``snapshot``) is the live session's: it satisfies the viewer's
protocol (:class:`mocapkit.viz.live_api.LiveSession`). The session calibrates itself in
the first shape's N-pose window unless told not to; the operator engages.

The filter preference of the simulated chains (:data:`PREFERRED_FILTERS`,
:func:`best_filter`) lives here: the demo (:mod:`mocapkit.demo.teleop_section`) and the
viewer use it.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from mocapkit.body.calibration import BodyCalibration
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError, MocapkitError
from mocapkit.imu.filters import available_filters
from mocapkit.imu.simulate import ImuErrorModel
from mocapkit.suit.batch import encode_raw_many
from mocapkit.teleop.live import LiveConfig, LiveSession
from mocapkit.teleop.operator import SHAPES
from mocapkit.teleop.operator_cycle import OperatorCycle, operator_cycle
from mocapkit.teleop.operator_suit import SuitSetup, sensor_poses, sensor_recording
from mocapkit.teleop.pipeline import PipelineConfig
from mocapkit.teleop.sender import TimelineSender
from mocapkit.teleop.server import RobotServerProcess, ServerConfig, spawn_robot_server

log = logging.getLogger("mocapkit.teleop.simulated")

#: Host-side filters in order of preference for the simulated chains, by the measured
#: end-effector error through the live session (six shapes, right_arm_2, fused on the
#: host with a still start, consumer-grade errors; seeds 0 and 1; docs/benchmarks.md,
#: "Polaris in the teleoperation chain"): bachmann 2.47 mm, polaris-body 2.81 mm,
#: polaris 6.25 mm. polaris-body moves first once it wins there.
PREFERRED_FILTERS = ("bachmann", "polaris-body", "polaris", "miller")
_AHEAD_S = 8.0  # frames handed to the sender ahead of the clock [s]
_CHUNK_S = 2.0  # ... in chunks of this much motion [s]


def best_filter() -> str:
    """The most accurate registered orientation filter for the simulated chains."""
    names = available_filters()
    return next(f for f in (*PREFERRED_FILTERS, *names) if f in names)


@dataclass(frozen=True)
class SimulatedConfig:
    """What the simulated session does.

    Attributes:
        shapes: the shapes the operator traces, in a loop.
        shape_s: duration of one shape [s].
        preset: the body's sensor tree (``right_arm_torso_3``: upper arm, forearm and the
            section-6 torso sensor).
        filter_name: host-side filter (None: :func:`best_filter`).
        sensor_noise: consumer-grade IMU errors (or ideal sensors).
        seed: noise and mounting seed.
        duration_s: how long the suit streams [s] (None: until stopped); afterwards its
            sensors go silent and the session holds, as with a suit switched off.
        auto_calibrate: calibrate in the first shape's N-pose window.
        auto_engage: engage when the hand first reaches the working point.
        rate_hz: sample rate [Hz].
        heading_rad: where the operator faces [rad from world x].
        server: the robot server's settings.
        robot: the robot: an arm (end-effector commands) or a humanoid name or robot YAML
            (whole-body joint commands); the server runs the same robot.
        record: an MCAP file to record the session to (None: no recording).
        send_port: send the suit's datagrams to this loopback port instead of the
            session's own (a relay in front of it, e.g. to inject network faults).
    """

    shapes: tuple[str, ...] = SHAPES
    shape_s: float = 6.0
    preset: str = "right_arm_torso_3"
    filter_name: str | None = None
    sensor_noise: bool = True
    seed: int = 0
    duration_s: float | None = None
    auto_calibrate: bool = True
    auto_engage: bool = False
    rate_hz: float = 100.0
    heading_rad: float = 0.0
    server: ServerConfig = field(default_factory=ServerConfig)
    robot: str = "robonaut2-right"
    record: str | None = None
    send_port: int | None = None

    def __post_init__(self) -> None:
        if self.duration_s is not None and not self.duration_s > 0:
            raise ConfigError(
                f"duration_s: expected a positive duration or None, got {self.duration_s}"
            )


class _SuitStream:
    """The suit's RAW datagrams, period after period of the operator's cycle."""

    def __init__(self, cycle: OperatorCycle, setup: SuitSetup, ids: dict[str, int], seed: int):
        rng = np.random.default_rng(seed)
        motion = cycle.motion
        poses = sensor_poses(motion, rng, setup.misalign_deg)
        self.recs = {ids[name]: sensor_recording(poses[name], setup, rng) for name in ids}
        self.time = motion.time
        self.period = cycle.period_s
        self.n = len(motion.time)

    def frames(self, k0: int, k1: int) -> list[tuple[float, bytes]]:
        """Frames of the global samples ``k0 <= k < k1`` (sample k is in period k // n)."""
        out: list[tuple[float, bytes]] = []
        while k0 < k1:
            period, j0 = divmod(k0, self.n)
            j1 = min(self.n, j0 + (k1 - k0))
            t = self.time[j0:j1] + period * self.period
            t_us = np.round(t * 1e6).astype(np.int64) & 0xFFFFFFFF
            per_sensor = [
                encode_raw_many(sid, k0, t_us, r.gyr[j0:j1], r.acc[j0:j1],
                                None if r.mag is None else r.mag[j0:j1])
                for sid, r in sorted(self.recs.items())
            ]  # fmt: skip
            for j in range(j1 - j0):
                out.extend((float(t[j]), frames[j]) for frames in per_sensor)
            k0 += j1 - j0
        return out


class SimulatedSession:
    """See the module docstring. Use as a context manager (it owns two processes, threads
    and sockets)."""

    def __init__(self, config: SimulatedConfig | None = None) -> None:
        self.config = c = config or SimulatedConfig()
        self.filter_name = c.filter_name or best_filter()
        tree = SensorTree.preset(c.preset)
        self.cycle = operator_cycle(c.shapes, tree, c.rate_hz, c.shape_s, heading_rad=c.heading_rad)
        self.pipeline_config = PipelineConfig(
            preset=c.preset, fusion="host", filter_name=self.filter_name, rate_hz=c.rate_hz,
            robot=c.robot,
        )  # fmt: skip
        setup = SuitSetup(
            fusion="host",
            errors=ImuErrorModel.consumer_grade() if c.sensor_noise else None,
            rate_hz=c.rate_hz,
        )
        ids = {n: i + 1 for i, n in enumerate(tree.sensor_names)}
        self._stream = _SuitStream(self.cycle, setup, ids, c.seed)
        self._n_total = None if c.duration_s is None else round(c.duration_s * c.rate_hz)
        self.server: RobotServerProcess | None = None
        self.live: LiveSession | None = None
        self.sender: TimelineSender | None = None
        self.t_go: float | None = None
        self._fed = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None

    # -- lifecycle ----------------------------------------------------------------------------
    def start(self) -> SimulatedSession:
        c = self.config
        horizon = 1e6 if c.duration_s is None else c.duration_s + 120.0
        try:
            self.server = spawn_robot_server(replace(c.server, robot=c.robot), max_seconds=horizon)
            self.live = LiveSession(
                LiveConfig(pipeline=self.pipeline_config), self.server.address, record=c.record
            )
            self.live.start()
            end = time.monotonic() + 10.0  # (the receiver thread polls the link)
            while self.live.link.latest is None:
                if time.monotonic() > end:
                    raise MocapkitError("the robot server did not report within 10 s")
                time.sleep(0.01)
            first = self._take(round(_AHEAD_S * c.rate_hz))
            port = self.live.suit_port if c.send_port is None else c.send_port
            self.sender = TimelineSender(first, "127.0.0.1", port)
            self.t_go = self.sender.go(stream=True)
        except BaseException:
            self.stop()
            raise
        self._thread = threading.Thread(target=self._operate, name="simulated-operator",
                                        daemon=True)  # fmt: skip
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
            self._thread = None
        if self.sender is not None:
            self.sender.stop()
            self.sender = None
        if self.live is not None:
            self.live.stop()
        if self.server is not None:
            self.server.stop()
            self.server = None

    def __enter__(self) -> SimulatedSession:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- the operator's side ------------------------------------------------------------------
    @property
    def motion_time(self) -> float:
        """Time on the operator's clock [s] (0 when the suit starts sending)."""
        return 0.0 if self.t_go is None else max(0.0, time.perf_counter() - self.t_go)

    def _take(self, n: int) -> list[tuple[float, bytes]]:
        k1 = self._fed + n if self._n_total is None else min(self._n_total, self._fed + n)
        items = self._stream.frames(self._fed, k1)
        self._fed = k1
        return items

    def _operate(self) -> None:
        """Feed the sender ahead of the clock; calibrate and engage when due."""
        c = self.config
        span = self.cycle.spans[0]
        w0, w1 = span.calib_window
        todo = []
        if c.auto_calibrate:
            todo.append((w0, "calibrate"))
        if c.auto_engage:
            todo.append((span.engage_t, "engage"))
        assert self.sender is not None
        live = self.live
        assert live is not None
        try:
            while not self._stop.wait(0.05):
                t = self.motion_time
                while todo and t >= todo[0][0]:
                    _, what = todo.pop(0)
                    if what == "calibrate":
                        live.calibrate(w1 - w0, wait=False)
                    else:
                        self._try(live.engage)
                if self._n_total is not None and self._fed >= self._n_total:
                    self.sender.end()
                    if not todo:
                        return
                elif self._fed / c.rate_hz < t + _AHEAD_S:
                    self.sender.feed(self._take(round(_CHUNK_S * c.rate_hz)))
        except BaseException as exc:  # surfaced by snapshot()
            self._error = exc
            log.exception("simulated operator failed")

    @staticmethod
    def _try(fn: Any) -> None:
        try:
            fn()
        except MocapkitError as exc:
            log.warning("simulated operator: %s", exc)

    # -- operator API (the viewer's protocol) -------------------------------------------------
    def _live(self) -> LiveSession:
        if self.live is None:
            raise MocapkitError("the simulated session is not started")
        if self._error is not None:
            raise MocapkitError(f"the simulated suit failed: {self._error}") from self._error
        return self.live

    def calibrate(self, duration_s: float | None = None) -> str:
        """The operator holds the N-pose for ``duration_s`` (default 1 s): calibrate.
        Raises :class:`~mocapkit.body.calibration.CalibrationError` saying why not."""
        calib: BodyCalibration | None = self._live().calibrate(duration_s)
        heading = 0.0 if calib is None else np.degrees(calib.heading_rad)
        return f"calibrated (heading {heading:.1f} deg)"

    def engage(self) -> str:
        return self._live().engage()

    def disengage(self) -> str:
        return self._live().disengage()

    def reindex(self) -> str:
        return self._live().reindex()

    def clutch(self, pressed: bool) -> str:
        return self._live().clutch(pressed)

    def snapshot(self) -> dict[str, Any]:
        """The live session's snapshot; ``t`` is the operator's clock [s], ``shape`` the
        shape being traced (or None)."""
        snap = self._live().snapshot()
        t = self.motion_time
        span = self.cycle.span_at(t)
        snap["t"] = t
        snap["shape"] = None if span is None else span.shape
        return snap
