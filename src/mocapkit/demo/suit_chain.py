"""A live teleoperation session from a simulated suit, through the real chain.

::

  operator_cycle (truth) -> SuitSimulator nodes + Hub (raw IMU packets, real clock)
    -> UDP on loopback -> Receiver thread -> HostFusion (orientation filter per sensor)
    -> BodyStream (calibrated body model: segment orientations, joint angles)
    -> ArmTeleop (eq. 16 retargeting onto Robonaut 2, intermediate model, session)
    -> RobotLink (UDP) -> robot-server process (own IK, latency, safety gate) -> reports

It implements :class:`mocapkit.viz.live_api.LiveSession` (calibrate, engage, disengage,
reindex, snapshot), so the live viewer can drive it, and records a :class:`ChainHistory`
for the demo's report. Operator commands may come from any thread: they are queued and
run on the pipeline thread between two packets, so the pipeline needs no locks.

This is the viewer's and the demo's session until the teleoperation package's own live
session (``mocapkit teleop run``) lands; both satisfy the same protocol.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass, field, replace
from typing import Any, TypeVar

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.calibration import HeadingFixed, calibrate_pose
from mocapkit.body.kinematics import BodyStream
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.demo.chain_history import ChainHistory, HistoryRecorder
from mocapkit.demo.operator_cycle import SENSORS, TREE, OperatorCycle, operator_cycle
from mocapkit.errors import DataError, MocapkitError
from mocapkit.imu.filters import available_filters
from mocapkit.imu.simulate import ImuErrorModel
from mocapkit.robot.robonaut2 import robonaut2_arm
from mocapkit.robot.segment_retarget import (
    SegmentRetargeter,
    robonaut2_groups,
    robonaut2_init_posture,
)
from mocapkit.series import OrientationSeries
from mocapkit.suit.fusion import HostFusion
from mocapkit.suit.receiver import Receiver
from mocapkit.suit.receiver_state import ReceiverConfig
from mocapkit.suit.samples import SuitSample
from mocapkit.suit.simulator import SuitSimConfig, SuitSimulator
from mocapkit.suit.transport import UdpTransport
from mocapkit.teleop.arm_pipeline import ArmTeleop, OrientationSample
from mocapkit.teleop.link import RobotLink
from mocapkit.teleop.operator import SHAPES
from mocapkit.teleop.server import RobotServerProcess, ServerConfig, spawn_robot_server
from mocapkit.teleop.session import SessionConfig, State, TeleopSession
from mocapkit.viz.geometry import skeleton_segments
from mocapkit.viz.live_api import LiveSnapshot, SensorPose, percentile_or_nan

log = logging.getLogger("mocapkit.demo.chain")
T = TypeVar("T")

#: filters in order of preference for the simulated suit chain, by measured accuracy on
#: it (`mocapkit demo --sections teleop`, consumer-grade noise, 100 Hz): bachmann 7.8 mm
#: end-effector RMSE (sensors 1.07 / 1.92 / 2.55 deg: upper arm, forearm, chest), polaris
#: 19.2 mm (1.14 / 3.22 / 2.85 deg; 28.3 mm before the linear-acceleration terms and the
#: gyr_bias_removed hand-over), miller 13.8 mm. polaris wins on BROAD and on the longer
#: simulated motions (docs/benchmarks.md, "Orientation filters on simulated suits") but
#: not yet on this 10 s run's forearm, whose reach starts 1 s after power-up; it moves
#: first once it does.
PREFERRED_FILTERS = ("bachmann", "polaris", "miller")
_SEGMENT_IDS = {"humerus_r": 1, "radius_r": 2, "torso": 3}


def best_filter() -> str:
    """The most accurate registered orientation filter."""
    names = available_filters()
    return next(f for f in (*PREFERRED_FILTERS, *names) if f in names)


@dataclass(frozen=True)
class ChainConfig:
    """What the simulated session does.

    Attributes:
        shapes: the shapes the operator traces, in order (then again).
        shape_s: duration of one shape [s].
        duration_s: how long the suit streams [s] (afterwards its sensors go silent and
            the session holds, as with a real suit switched off).
        rate_hz: IMU sampling and hub polling rate.
        filter_name: host-side orientation filter (None: :func:`best_filter`).
        sensor_noise: consumer-grade IMU errors (noise, bias, drift, scale) or ideal ones.
        seed: noise and mounting seed.
        auto_calibrate_at_s: take the body calibration at this motion time (the operator
            rests in the initialisation posture for the first second), or None.
        auto_engage: engage at the first shape's engage instant and disengage when the
            shape has been held (before the operator lowers the arm), as in the demo; or
            leave both to the operator (the viewer).
        record: keep a :class:`ChainHistory` (the demo's report).
        server: the robot server's settings.
    """

    shapes: tuple[str, ...] = SHAPES
    shape_s: float = 6.0
    duration_s: float = 600.0
    rate_hz: float = 100.0
    filter_name: str | None = None
    sensor_noise: bool = True
    seed: int = 0
    auto_calibrate_at_s: float | None = 0.7
    auto_engage: bool = False
    record: bool = False
    server: ServerConfig = field(default_factory=ServerConfig)


class SuitTeleopChain:
    """See the module docstring. Use as a context manager (it owns threads, sockets and
    the robot-server process)."""

    def __init__(self, config: ChainConfig | None = None) -> None:
        self.config = c = config or ChainConfig()
        self.filter_name = c.filter_name or best_filter()
        self.motion: OperatorCycle = operator_cycle(
            c.shapes, c.rate_hz, c.shape_s, repeat_until_s=c.duration_s, seed=c.seed
        )
        errors = ImuErrorModel.consumer_grade() if c.sensor_noise else None
        self.suit = SuitSimulator(
            self.motion.sensor_poses,
            SuitSimConfig(mode="raw", errors=errors, random_clocks=False),
            rng=np.random.default_rng(c.seed + 1),
        )
        self.tree = SensorTree.preset(TREE)
        self.arm = robonaut2_arm("right")
        self.history = HistoryRecorder(self.motion, self.arm) if c.record else None
        self.server: RobotServerProcess | None = None
        self.link: RobotLink | None = None
        self.rx: Receiver | None = None
        self.body: BodyStream | None = None
        self.teleop: ArmTeleop | None = None
        self.session = TeleopSession(SessionConfig())
        self.fusion = HostFusion(self.filter_name, c.rate_hz)
        self._latest: dict[int, FloatArray] = {}
        window = round(1.5 * c.rate_hz)
        self._recent: dict[int, deque[tuple[float, FloatArray]]] = {
            sid: deque(maxlen=window) for sid in SENSORS
        }
        self._recent_gyr: dict[int, deque[tuple[float, FloatArray]]] = {
            sid: deque(maxlen=window) for sid in SENSORS
        }
        self._gyr_bias: dict[int, FloatArray] = {}
        self._t_sensor = -np.inf
        self._t0 = time.monotonic()
        self._latency_ms: deque[float] = deque(maxlen=300)
        self._requests: queue.Queue[tuple[Callable[[], str], Future[str]]] = queue.Queue()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._snapshot = LiveSnapshot.empty()
        self._snap_lock = threading.Lock()
        self._last_snap = 0.0
        self._message = ""
        self._engaged_once = False
        self._calibrated_at: float | None = None
        self._error: BaseException | None = None
        self._last_cmd: FloatArray | None = None

    # -- lifecycle --------------------------------------------------------------------------
    def start(self) -> SuitTeleopChain:
        c = self.config
        self.server = spawn_robot_server(c.server, max_seconds=c.duration_s + 120.0)
        self.link = RobotLink(self.server.address, on_report=self._on_report)
        self.link.send_hold()
        if not self.link.wait_for_report(10.0):
            self.stop()
            raise MocapkitError("the robot server did not report within 10 s")
        self.rx = Receiver(
            UdpTransport.bind("127.0.0.1", 0),
            ReceiverConfig(allowed_ids=frozenset(SENSORS), protocols="suit"),
        ).start()
        port = self.rx.transport.port  # type: ignore[attr-defined]
        self._t0 = time.monotonic()
        for target, name in ((self._pipeline_loop, "chain-pipeline"),
                             (lambda: self._send_loop(port), "chain-suit")):  # fmt: skip
            th = threading.Thread(target=target, name=name, daemon=True)
            th.start()
            self._threads.append(th)
        return self

    def stop(self) -> None:
        self._stop.set()
        for th in self._threads:
            th.join(5.0)
        self._threads.clear()
        if self.link is not None:
            self.link.send_hold()
            self.link.close()
            self.link = None
        if self.rx is not None:
            self.rx.stop()
            self.rx.transport.close()
            self.rx = None
        if self.server is not None:
            self.server.stop()
            self.server = None

    def __enter__(self) -> SuitTeleopChain:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def motion_time(self) -> float:
        """Sensor time of the newest sample processed [s] (the motion's clock)."""
        return float(self._t_sensor)

    def wait_motion_time(
        self, t: float, timeout_s: float, on_progress: Callable[[float], None] | None = None
    ) -> bool:
        """Block until the pipeline has processed the motion up to ``t`` [s]."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if self._error is not None:
                raise MocapkitError(f"the pipeline thread failed: {self._error}") from self._error
            if on_progress is not None:
                on_progress(max(0.0, self.motion_time))
            if self.motion_time >= t:
                return True
            time.sleep(0.05)
        return False

    # -- the suit's side ----------------------------------------------------------------------
    def _send_loop(self, port: int) -> None:
        """The hub polls its nodes once per sample period on the real clock and sends what
        it gets over UDP (the simulator's rounds, computed as time goes on)."""
        tx = UdpTransport.connect("127.0.0.1", port)
        hub = self.suit.hub
        period = 1.0 / self.config.rate_hz
        start = time.perf_counter()
        try:
            for k in range(len(self.motion.time)):
                if self._stop.is_set():
                    return
                wait = start + k * period - time.perf_counter()
                if wait > 0:
                    time.sleep(wait)
                for frame in hub.poll_round(k * period + 1e-9):
                    tx.send(frame)
        finally:
            tx.close()

    # -- operator commands (any thread) -------------------------------------------------------
    def _call(self, fn: Callable[[], str], timeout_s: float = 5.0) -> str:
        if not self._threads:  # not started: run here
            return fn()
        fut: Future[str] = Future()
        self._requests.put((fn, fut))
        return fut.result(timeout_s)

    def calibrate(self) -> str:
        """Take the body calibration from the last 0.5 s (the operator must hold the
        initialisation posture: standing, arms hanging, palms to the thighs)."""
        return self._call(self._do_calibrate)

    def engage(self) -> str:
        return self._call(self._do_engage)

    def disengage(self) -> str:
        return self._call(lambda: self._do_session("disable"))

    def reindex(self) -> str:
        return self._call(lambda: self._do_session("reindex"))

    # -- pipeline thread ----------------------------------------------------------------------
    def _do_calibrate(self, t_end: float | None = None) -> str:
        """Calibrate on the 0.5 s before ``t_end`` (sensor time; default: the newest)."""
        t_end = self._t_sensor if t_end is None else t_end
        window = (t_end - 0.5, t_end)
        series = {}
        for sid, (name, _seg, _frame) in SENSORS.items():
            rows = [(t, q) for t, q in self._recent[sid] if window[0] - 0.05 <= t <= t_end]
            if len(rows) < 10:
                raise DataError(
                    f"calibrate: sensor {sid} ({name}) has {len(rows)} samples in the last "
                    "0.5 s; wait until the suit streams"
                )
            series[name] = OrientationSeries(
                np.array([r[0] for r in rows]), np.array([r[1] for r in rows]), name=name
            )
        calib = calibrate_pose(self.tree, series, window, pose="npose", heading=HeadingFixed(0.0))
        # the operator holds still: the gyroscopes' mean is their bias (paper, section 3)
        for sid in SENSORS:
            prev = self._gyr_bias.get(sid, np.zeros(3))
            gyr = [g for t, g in self._recent_gyr[sid] if window[0] <= t <= t_end]
            if gyr:
                g = np.stack(gyr)
                step = np.mean(g, axis=0)
                self._gyr_bias[sid] = prev + step
                # a filter that estimates the bias itself must know its input moved
                f = self.fusion.filters.get(sid)
                if f is not None:
                    f.gyr_bias_removed(step, float(np.mean(np.std(g, axis=0))) / np.sqrt(len(g)))
        body = BodyStream(self.tree, calib, dropout="hold", max_hold_s=0.2)
        body.update({SENSORS[sid][0]: q for sid, q in self._latest.items()}, t_end)
        q_seg = {sid: body.q_world_segment[i].copy() for i, sid in enumerate(self._seg_ids())}
        if self.teleop is None:
            arm = robonaut2_arm("right")
            groups = robonaut2_groups("right")[:2]  # the paper's two arm sensors: 5 joints
            self.teleop = ArmTeleop(
                arm,
                SegmentRetargeter(arm, groups, robonaut2_init_posture("right")),
                {1: "humerus_r", 2: "radius_r"},
                self.session,
                self.link,
                root_sensor=3,
                stale_after_s=0.2,
            )
            self.teleop.keep_frames = False
        self.teleop.calibrate(q_seg)
        self.body = body
        self._calibrated_at = t_end
        if self.history is not None:
            self.history.calibrated(t_end, calib)
        self.session.reindex(time.monotonic())
        self._message = f"calibrated at t = {t_end:.1f} s (N-pose)"
        log.info(self._message)
        return self._message

    def _seg_ids(self) -> list[int]:
        return [_SEGMENT_IDS[s] for s in self.tree.segment_names]

    def _do_engage(self) -> str:
        if self.teleop is None:
            raise DataError("engage: calibrate first (the operator in the N-pose)")
        self.session.engage(time.monotonic())
        self._message = f"engage: {self.session.state.value}"
        return self._message

    def _do_session(self, what: str) -> str:
        now = time.monotonic()
        if what == "disable":
            self.session.disable(now)
        else:
            self.session.reindex(now)
        self._message = f"{what}: {self.session.state.value}"
        return self._message

    def _serve_requests(self) -> None:
        while True:
            try:
                fn, fut = self._requests.get_nowait()
            except queue.Empty:
                return
            try:
                fut.set_result(fn())
            except MocapkitError as exc:
                self._message = str(exc)
                fut.set_exception(exc)

    def _on_report(self, t: float, report: Any) -> None:
        if self.history is not None:
            self.history.report(t - self._t0, report)

    def _pipeline_loop(self) -> None:
        try:
            while not self._stop.is_set():
                self._step()
        except BaseException as exc:  # surfaced by wait_motion_time / snapshot
            self._error = exc
            log.exception("pipeline thread failed")

    def _auto(self) -> None:
        c = self.config
        due = c.auto_calibrate_at_s
        if due is not None and self._calibrated_at is None and self._t_sensor >= due:
            try:
                # the window ends at the due time, even if the pipeline got there late
                self._do_calibrate(due)
            except MocapkitError as exc:
                self._message = f"automatic calibration failed: {exc}"
                self._calibrated_at = -1.0
        if c.auto_engage and self.teleop is not None:
            span = self.motion.spans[0]
            if not self._engaged_once and self._t_sensor >= span.t_engage:
                self._do_engage()
                self._engaged_once = True
            elif (
                self._engaged_once
                and self._t_sensor >= span.t_end + 0.8
                and self.session.state != State.DISABLED
            ):
                self._do_session("disable")

    def _debias(self, batch: list[SuitSample]) -> list[SuitSample]:
        """Keep the recent gyroscope samples (for the rest calibration) and subtract each
        sensor's gyroscope bias once it is known."""
        out = []
        for s in batch:
            if s.gyr is not None:
                self._recent_gyr[s.sensor_id].append((s.t_sensor_s, s.gyr))
                b = self._gyr_bias.get(s.sensor_id)
                if b is not None:
                    s = replace(s, gyr=s.gyr - b)
            out.append(s)
        return out

    def _step(self) -> None:
        assert self.rx is not None
        batch = self.rx.get_batch(1024, timeout_s=0.01)
        self._serve_requests()
        arrival = None
        if batch:
            batch = self._debias(batch)
            for s in self.fusion.process_batch(batch):
                if s.quat is None:
                    continue
                self._latest[s.sensor_id] = s.quat
                self._recent[s.sensor_id].append((s.t_sensor_s, s.quat))
                self._t_sensor = max(self._t_sensor, s.t_sensor_s)
                if self.history is not None:
                    self.history.orientation(s.sensor_id, s.t_sensor_s, s.quat)
            arrival = min(s.t_arrival_ns for s in batch)
        self._auto()
        now = time.monotonic()
        if self.body is not None and self.teleop is not None:
            samples = []
            if batch:
                quats = {SENSORS[sid][0]: q for sid, q in self._latest.items()}
                angles = self.body.update(quats, self._t_sensor)
                if self.history is not None:
                    self.history.angles(self._t_sensor, angles, self.body.q_world_segment)
                samples = [
                    OrientationSample(sid, arrival or 0, self.body.q_world_segment[i])
                    for i, sid in enumerate(self._seg_ids())
                ]
            frame = self.teleop.process(samples, now)
            if frame.out.command is not None:
                self._last_cmd = frame.out.command.copy()
                if frame.latency_ns is not None:
                    self._latency_ms.append(frame.latency_ns / 1e6)
            if self.history is not None and frame.out.command is not None:
                self.history.command(now - self._t0, self._t_sensor, frame)
        elif self.link is not None:
            self.link.poll()
        if now - self._last_snap > 1 / 30:
            self._last_snap = now
            snap = self._make_snapshot(now)
            with self._snap_lock:
                self._snapshot = snap

    # -- snapshot -------------------------------------------------------------------------------
    def snapshot(self) -> LiveSnapshot:
        if self._error is not None:
            raise MocapkitError(f"the pipeline thread failed: {self._error}") from self._error
        with self._snap_lock:
            snap = self._snapshot
        # the operator-facing message changes on commands: the current one, not the one
        # of the last publication
        return snap if snap.message == self._message else replace(snap, message=self._message)

    def _safety(self) -> str:
        parts = [self.session.fault] if self.session.fault else []
        rep = None if self.link is None else self.link.latest
        if rep is not None:
            parts.append(f"robot gate {rep.gate.name.lower()} ({rep.reason.name.lower()})")
        return "; ".join(parts) or "no robot report yet"

    def _make_snapshot(self, now: float) -> LiveSnapshot:
        lat = np.array(self._latency_ms)
        loss, delivered = 0.0, 0
        if self.rx is not None:
            st = self.rx.stats()
            delivered = sum(s.delivered for s in st.sensors.values())
            lost = sum(s.lost for s in st.sensors.values())
            loss = lost / (delivered + lost) if delivered + lost else 0.0
        segments: tuple[Any, ...] = ()
        if self.body is not None:
            segments = skeleton_segments(
                self.tree, self.body.q_world_segment, self.body.calib.q_world_ground
            )
        by_segment = {s.name: s for s in segments}
        sensors = []
        for sid, (name, seg, _frame) in SENSORS.items():
            q = self._latest.get(sid)
            if q is None:
                continue
            sp = by_segment.get(seg)
            pos = (
                np.array([0.0, -0.4 - 0.15 * sid, 0.2]) if sp is None else 0.5 * (sp.start + sp.end)
            )
            sensors.append(SensorPose(name, pos, np.array(q)))
        rep = None if self.link is None else self.link.latest
        cmd = self._last_cmd if self.session.state == State.ENGAGED else None
        ee_actual = None if self.link is None else self.link.robot_pose()
        return LiveSnapshot(
            t_s=now - self._t0,
            state=self.session.state.value,
            safety=self._safety(),
            calibrated=self.body is not None,
            latency_ms_p50=percentile_or_nan(lat, 50),
            latency_ms_p99=percentile_or_nan(lat, 99),
            packet_loss=loss,
            packets=delivered,
            segments=segments,
            sensors=tuple(sensors),
            robot_name=self.config.server.robot,
            robot_q=None if rep is None else np.array(rep.q),
            ee_command=cmd,
            ee_actual=ee_actual,
            message=self._message,
            transitions=tuple(
                f"{t.source.value} -> {t.target.value}: {t.reason}"
                for t in self.session.transitions[-5:]
            ),
        )

    def result(self) -> ChainHistory:
        """The recorded history (``record=True``)."""
        if self.history is None:
            raise MocapkitError("this session was started with record=False")
        h = self.history.finish(self.session, self.motion)
        h.filter_name = self.filter_name
        return h
