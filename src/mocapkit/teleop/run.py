"""``mocapkit teleop run``: a live session from a suit stream, with operator controls.

:func:`run_live` starts the robot server (or uses a running one), the
:class:`~mocapkit.teleop.live.LiveSession` on the suit's UDP port, the control socket and
the keyboard, runs scheduled commands (``[(t, "calibrate"), (t, "engage")]``, seconds from
the start: scripted sessions and tests), and returns a summary when the time is up or
the operator quits.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from mocapkit.errors import ConfigError
from mocapkit.teleop.control import Controls, ControlSocket, read_keys
from mocapkit.teleop.live import LiveConfig, LiveSession
from mocapkit.teleop.server import RobotServerProcess, ServerConfig, spawn_robot_server

log = logging.getLogger("mocapkit.teleop.run")


@dataclass(frozen=True)
class Ros2RobotOptions:
    """The robot is a ROS 2 machine's (:mod:`mocapkit.teleop.ros2_link`), over the
    ``ros2_zenoh`` endpoints. A humanoid: joint targets to ``command_topic``, its
    ``state_topic`` back. An arm: end-effector poses to ``pose_topic`` (in ``frame_id``),
    its ``pose_state_topic`` back."""

    command_topic: str = "/forward_position_controller/commands"
    state_topic: str = "/joint_states"
    controller_joints: tuple[str, ...] | None = None
    pose_topic: str = "/target_pose"  # an arm: end-effector targets for the robot's IK
    pose_state_topic: str = "/current_pose"
    frame_id: str = "base"


@dataclass(frozen=True)
class RunOptions:
    """How a live run is set up.

    Attributes:
        server: robot server ``(host, port)``, or None to start one (``spawn``).
        spawn: the settings of the robot server to start when ``server`` is None.
        seconds: end after this long (None: until ``quit``).
        commands: scheduled operator commands ``(t [s from the start], command)``.
        control_port: UDP control socket port on loopback (None: no socket, 0: any).
        keys: a text stream of commands, one per line (the terminal), or None.
        record: an MCAP file for the session.
        foxglove_port: serve the session to Foxglove (WebSocket) on this loopback port
            (0: any free one), or None.
        lsl: LSL outlets of the joint angles, the sensor orientations and, with host-side
            fusion, each sensor's raw samples
            (:mod:`mocapkit.io.lsl`).
        ros2_zenoh: Zenoh endpoints of a ROS 2 (rmw_zenoh) router to publish the joint
            states to (:mod:`mocapkit.io.ros2_zenoh`; empty: Zenoh's scouting), or None.
        ros2_robot: drive a ROS 2 robot over those endpoints instead of mocapkit's robot
            server (no server is started), or None.
    """

    server: tuple[str, int] | None = None
    spawn: ServerConfig | None = None
    seconds: float | None = None
    commands: tuple[tuple[float, str], ...] = ()
    control_port: int | None = None
    keys: IO[str] | None = None
    record: Path | None = None
    foxglove_port: int | None = None
    lsl: bool = False
    ros2_zenoh: tuple[str, ...] | None = None
    ros2_robot: Ros2RobotOptions | None = None


def parse_commands(text: str) -> tuple[tuple[float, str], ...]:
    """``"1.0:calibrate,3.5:engage"`` -> ((1.0, "calibrate"), (3.5, "engage"))."""
    out = []
    for part in filter(None, (p.strip() for p in text.split(","))):
        t, sep, cmd = part.partition(":")
        try:
            when = float(t)
        except ValueError:
            when = float("nan")
        if not sep or not cmd or not when >= 0:
            raise ConfigError(
                f"commands: expected 'seconds:command' items like '1.0:calibrate,3.5:engage', "
                f"got {part!r}"
            )
        out.append((when, cmd.strip()))
    return tuple(sorted(out))


@contextlib.contextmanager
def _robot(options: RunOptions, config: LiveConfig) -> Iterator[tuple[str, int] | None]:
    if options.ros2_robot is not None:  # the robot is a ROS 2 machine's, reached over Zenoh
        yield None
        return
    if options.server is not None:
        yield options.server
        return
    cfg = options.spawn or ServerConfig(robot=config.pipeline.robot)
    srv: RobotServerProcess = spawn_robot_server(cfg, max_seconds=(options.seconds or 86400) + 60)
    with srv:
        yield srv.address


def run_live(
    config: LiveConfig,
    options: RunOptions,
    on_start: Callable[[LiveSession], None] | None = None,
) -> dict[str, Any]:
    """Run a live session (see the module docstring); returns the final summary:
    the snapshot plus ``pipeline_ms_p50/p99`` over the whole run and every transition."""
    done = threading.Event()
    make_link = None
    if options.ros2_robot is not None:
        from mocapkit.teleop.ros2_link import Ros2RobotLink

        ros = options.ros2_robot
        endpoints = options.ros2_zenoh or ()

        def make_link(pipeline: Any) -> Any:
            if pipeline.humanoid is None:  # an arm: end-effector poses for the robot's IK
                return Ros2RobotLink((), endpoints, pose_topic=ros.pose_topic,
                                     pose_state_topic=ros.pose_state_topic,
                                     frame_id=ros.frame_id)  # fmt: skip
            return Ros2RobotLink(pipeline.robot_joint_names, endpoints,
                                 command_topic=ros.command_topic, state_topic=ros.state_topic,
                                 controller_joints=ros.controller_joints)  # fmt: skip

    with (
        _robot(options, config) as address,
        LiveSession(config, address, options.record, make_link=make_link) as live,
    ):
        controls = Controls(live, done.set)
        log.info("suit stream expected on UDP port %d", live.suit_port)
        with contextlib.ExitStack() as stack:
            if options.control_port is not None:
                sock = stack.enter_context(ControlSocket(controls, port=options.control_port))
                log.info("control socket on UDP 127.0.0.1:%d", sock.port)
            if options.foxglove_port is not None:
                from mocapkit.teleop.foxglove_live import FoxgloveLive

                humanoid = live.pipeline.humanoid
                fox = FoxgloveLive(live.snapshot, port=options.foxglove_port,
                                   robot=None if humanoid is None else humanoid.robot)  # fmt: skip
                stack.enter_context(fox.start())
                print(f"teleop run: Foxglove: open a WebSocket connection to {fox.url}",
                      file=sys.stderr, flush=True)  # fmt: skip
            if options.lsl:
                _lsl_outlets(live)
            if options.ros2_zenoh is not None:
                stack.enter_context(_ros2_topics(live, options.ros2_zenoh))
            if options.keys is not None:
                threading.Thread(
                    target=read_keys, args=(controls, options.keys, done), daemon=True
                ).start()
            if on_start is not None:
                on_start(live)
            start = time.monotonic()
            pending = list(options.commands)
            while not done.is_set():
                now = time.monotonic() - start
                while pending and pending[0][0] <= now:
                    _, cmd = pending.pop(0)
                    reply = controls.apply(cmd)
                    log.info("scheduled %s: %s", cmd, reply)
                if options.seconds is not None and now >= options.seconds:
                    break
                wait = 0.1 if not pending else min(0.1, max(0.0, pending[0][0] - now))
                done.wait(wait)
        summary = live.snapshot()
        lat = live.pipeline.latency_ms()
        summary["pipeline_ms_p50"] = float(_percentile(lat, 50))
        summary["pipeline_ms_p99"] = float(_percentile(lat, 99))
        summary["commands_sent"] = int(live.pipeline.n_latencies)
        summary["transitions"] = [
            {"t": tr.t, "from": tr.source.value, "to": tr.target.value, "reason": tr.reason}
            for tr in live.session.transitions
        ]
    return summary


def _lsl_outlets(live: LiveSession) -> None:
    """LSL outlets fed by every frame of the session (``mocapkit.io.lsl``)."""
    from mocapkit.io.lsl import SessionOutlets

    tree = live.pipeline.tree
    outlets = SessionOutlets(tree.coordinate_names, tree.sensor_names,
                             live.config.pipeline.rate_hz)  # fmt: skip
    live.frame_listeners.append(lambda f: outlets.push(f.angles, live.pipeline.q_sensor))
    names = ["mocapkit-joint-angles", "mocapkit-orientations"]
    cfg = live.config.pipeline
    if cfg.fusion == "host":  # the suit sends raw samples: each sensor's to its own outlet
        from mocapkit.io.lsl import RawOutlets

        ids = live.pipeline.sensor_ids
        raw = RawOutlets({sid: name for name, sid in ids.items()}, cfg.rate_hz, cfg.use_mag)
        live.batch_listeners.append(raw.push)
        names.append(f"mocapkit-imu-<sensor> ({', '.join(ids)})")
    print(f"teleop run: LSL outlets {', '.join(names)}", file=sys.stderr, flush=True)


def _ros2_topics(live: LiveSession, connect: tuple[str, ...]) -> Any:
    """Every frame's joint angles and robot joints as ROS 2 JointState over Zenoh."""
    from mocapkit.io.ros2_zenoh import Ros2ZenohPublisher

    pub = Ros2ZenohPublisher(connect=connect)
    coords = live.pipeline.tree.coordinate_names
    robot = live.pipeline.robot_joint_names

    def on_frame(f: Any) -> None:
        try:
            if f.angles is not None:
                pub.joint_state("/mocapkit/joint_states", coords, f.angles)
            if f.q_robot is not None:
                pub.joint_state("/mocapkit/robot/joint_states", robot, f.q_robot)
        except Exception as exc:  # a Zenoh peer that disappears must not stop the session
            log.warning("ROS 2 over Zenoh: %s", exc)

    live.frame_listeners.append(on_frame)
    where = ", ".join(connect) or "scouting"
    print(f"teleop run: ROS 2 topics /mocapkit/joint_states, /mocapkit/robot/joint_states "
          f"over Zenoh ({where})", file=sys.stderr, flush=True)  # fmt: skip
    return pub


def _percentile(values: Sequence[float] | Any, q: float) -> float:
    import numpy as np

    a = np.asarray(values, dtype=float)
    return float(np.percentile(a, q)) if a.size else float("nan")
