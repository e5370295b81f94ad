"""The robot server: a separate process playing the robot (Miller et al., sections 5-6).

It receives 6-DOF end-effector commands (robot-link protocol, UDP), and

- enforces Robonaut's safety gate: a command is accepted only once synchronised, i.e.
  when it lies within ``gate_pos_m`` / ``gate_rot_rad`` of the arm's actual pose; it
  loses synchronisation on a jump beyond those thresholds from the previous accepted
  command, on HOLD, and after ``command_timeout_s`` without commands (it then holds);
- applies an actuation latency (accepted commands become IK targets ``latency_s``
  later);
- solves its own Jacobian IK (one damped-least-squares step per tick, joint position
  and velocity limits);
- reports its actual pose, joints, gate state and reason at ``report_hz`` to the
  address that last sent it a message.

``RobotSim`` is the logic (no sockets, stepped by the caller); ``serve`` runs it on a
UDP socket; ``spawn_robot_server`` starts ``python -m mocapkit.teleop.server`` and
waits for its ``READY <port>`` line.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import select
import signal
import socket
import subprocess
import sys
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError, MocapkitError
from mocapkit.robot.ik import IkParams, ik_step, solve_ik
from mocapkit.robot.model import ArmModel, pose_distance, pose_matrix, pose_parts
from mocapkit.teleop import protocol as proto

if TYPE_CHECKING:
    from mocapkit.teleop.humanoid_sim import HumanoidSim

log = logging.getLogger("mocapkit.teleop.server")

# An IK target still this far away after the arm has stopped moving is unreachable.
_UNREACHABLE_POS_M = 0.01
_UNREACHABLE_ROT_RAD = np.radians(5.0)


@dataclass(frozen=True)
class ServerConfig:
    """Robot-server settings (SI units).

    Attributes:
        robot: registry name of the arm (``mocapkit.robot.available_robots()``), or a
            humanoid (``mocapkit robot list``, or a robot YAML): joint commands.
        rate_hz: control loop rate.
        report_hz: pose report rate.
        latency_s: actuation latency added to every accepted command.
        gate_pos_m, gate_rot_rad: synchronisation thresholds of the safety gate.
        command_timeout_s: without commands for this long the gate drops and the arm holds.
        velocity_scale: fraction of the arm's joint speed limits used.
        q_start: initial joints [rad]; default the arm's ready posture.
        gate_joint_rad: a humanoid's synchronisation threshold, per joint.
    """

    robot: str = "robonaut2-right"
    rate_hz: float = 200.0
    report_hz: float = 100.0
    latency_s: float = 0.03
    gate_pos_m: float = 0.03
    gate_rot_rad: float = float(np.radians(10.0))
    command_timeout_s: float = 0.5
    velocity_scale: float = 1.0
    q_start: tuple[float, ...] | None = None
    gate_joint_rad: float = float(np.radians(6.0))

    def __post_init__(self) -> None:
        for name in ("rate_hz", "report_hz", "gate_pos_m", "gate_rot_rad", "command_timeout_s",
                     "gate_joint_rad"):  # fmt: skip
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"ServerConfig.{name}: expected a positive number, got {v}")
        if not (np.isfinite(self.latency_s) and self.latency_s >= 0):
            raise ConfigError(f"ServerConfig.latency_s: expected >= 0 s, got {self.latency_s}")
        if not (0 < self.velocity_scale <= 1):
            raise ConfigError(
                f"ServerConfig.velocity_scale: expected in (0, 1], got {self.velocity_scale}"
            )


@dataclass
class SimState:
    gate: proto.Gate = proto.Gate.UNSYNCED
    reason: proto.Reason = proto.Reason.STARTUP
    last_command_seq: int = 0
    last_command_t: float = -np.inf
    last_accepted: FloatArray | None = None
    target: Any = None  # an arm's pose (4, 4); a humanoid's (base pos, base quat, joints)
    pending: deque[tuple[float, Any]] = field(default_factory=deque)
    accepted: int = 0
    rejected: int = 0
    malformed: int = 0


class GatedSim:
    """The safety gate's bookkeeping shared by the arm and the humanoid: its state, HOLD,
    the command timeout and the actuation latency queue."""

    state: SimState
    config: ServerConfig

    def _set(self, gate: proto.Gate, reason: proto.Reason) -> None:
        s = self.state
        if (gate, reason) != (s.gate, s.reason):
            log.info("gate", extra={"gate": gate.name, "reason": reason.name, "from": s.gate.name})
        s.gate, s.reason = gate, reason

    def on_hold(self, now: float) -> None:
        s = self.state
        s.pending.clear()
        s.target = None
        s.last_accepted = None
        self._set(proto.Gate.HOLDING, proto.Reason.HOLD_REQUESTED)

    def _jumped(self) -> bool:
        """Refuse a synchronised command that jumped: the gate drops, nothing pending."""
        s = self.state
        s.rejected += 1
        s.pending.clear()
        s.target = None
        self._set(proto.Gate.UNSYNCED, proto.Reason.JUMP)
        return False

    def _too_far(self) -> bool:
        """Refuse an unsynchronised command too far from the robot's actual state."""
        self.state.rejected += 1
        self._set(self.state.gate, proto.Reason.TOO_FAR)
        return False

    def _accept(self, seq: int, now: float, accepted: Any, target: Any) -> bool:
        """Take a command: ``accepted`` is what the next jump check compares with,
        ``target`` acts after the actuation latency."""
        s = self.state
        s.accepted += 1
        s.last_accepted = accepted
        s.last_command_seq = seq
        s.last_command_t = now
        s.pending.append((now + self.config.latency_s, target))
        return True

    def _due(self, now: float) -> None:
        """Drop the gate after ``command_timeout_s`` without commands; the accepted
        commands whose latency has passed become the target."""
        s, c = self.state, self.config
        if s.gate == proto.Gate.SYNCED and now - s.last_command_t > c.command_timeout_s:
            s.pending.clear()
            s.target = None
            s.last_accepted = None
            self._set(proto.Gate.UNSYNCED, proto.Reason.TIMEOUT)
        while s.pending and s.pending[0][0] <= now:
            s.target = s.pending.popleft()[1]


class RobotSim(GatedSim):
    """The robot's behaviour, stepped by the caller with explicit times [s]."""

    def __init__(self, arm: ArmModel, config: ServerConfig) -> None:
        self.arm = arm
        self.config = config
        q0 = arm.q_ref if config.q_start is None else np.asarray(config.q_start, dtype=float)
        self.q = arm.clamp(arm.check_q(q0, "q_start"))
        self.state = SimState()
        self.ik = IkParams()
        self._last_reach_check = -np.inf

    def pose(self) -> FloatArray:
        """Actual end-effector pose T_base_ee (4, 4)."""
        return self.arm.fk(self.q)

    def on_command(self, cmd: proto.Command, now: float) -> bool:
        """Gate a command; returns True when accepted."""
        s = self.state
        ok = np.isfinite(cmd.pos).all() and np.isfinite(cmd.quat).all()
        if not ok or abs(np.linalg.norm(cmd.quat) - 1.0) > 1e-3:
            s.rejected += 1
            self._set(s.gate, proto.Reason.BAD_COMMAND)
            return False
        T = pose_matrix(cmd.pos, cmd.quat / np.linalg.norm(cmd.quat))
        c = self.config
        if s.gate == proto.Gate.SYNCED:
            assert s.last_accepted is not None
            dp, dr = pose_distance(T, s.last_accepted)
            if dp > c.gate_pos_m or dr > c.gate_rot_rad:
                return self._jumped()
        else:
            dp, dr = pose_distance(T, self.pose())
            if dp > c.gate_pos_m or dr > c.gate_rot_rad:
                return self._too_far()
            self._set(proto.Gate.SYNCED, proto.Reason.OK)
        return self._accept(cmd.seq, now, T, T)

    def on_joints(self, cmd: proto.JointsCommand, now: float) -> bool:
        """A joint command: an arm takes end-effector poses (refused, counted)."""
        self.state.rejected += 1
        self._set(self.state.gate, proto.Reason.BAD_COMMAND)
        log.warning("JOINTS command to an arm: send end-effector COMMAND messages")
        return False

    def step(self, now: float, dt: float) -> None:
        """Advance the arm by one control tick of dt [s]."""
        s, c = self.state, self.config
        self._due(now)
        if s.target is None:
            return
        max_dq = self.arm.velocity_limit * c.velocity_scale * dt
        self.q, err, _ = ik_step(self.arm, self.q, s.target, self.ik, max_dq=max_dq)
        far = np.linalg.norm(err[:3]) > _UNREACHABLE_POS_M or np.linalg.norm(err[3:]) > (
            _UNREACHABLE_ROT_RAD
        )
        if s.gate != proto.Gate.SYNCED:
            return
        if far and now - self._last_reach_check >= 0.1:
            # far from the target: is it reachable at all? (full solve, at most 10 Hz)
            self._last_reach_check = now
            reached = solve_ik(self.arm, s.target, self.q, self.ik).reached
            if not reached:
                self._set(s.gate, proto.Reason.UNREACHABLE)
            elif s.reason == proto.Reason.UNREACHABLE:
                self._set(s.gate, proto.Reason.OK)
        elif not far and s.reason == proto.Reason.UNREACHABLE:
            self._set(s.gate, proto.Reason.OK)

    def report(self, seq: int, t_ns: int) -> bytes:
        pos, quat = pose_parts(self.pose())
        s = self.state
        return proto.encode_report(
            seq, t_ns, pos, quat, s.last_command_seq, s.gate, s.reason, self.q
        )


def serve(
    sim: RobotSim | HumanoidSim,
    sock: socket.socket,
    max_seconds: float | None = None,
    parent_pid: int | None = None,
    key: bytes | None = None,
) -> dict[str, Any]:
    """Run the robot on a bound UDP socket until SIGTERM/SIGINT, ``max_seconds``, or the
    parent process (``parent_pid``) going away; returns what happened (seconds served,
    the paired client, commands accepted and refused by the gate, datagrams dropped,
    reports sent, the gate's last state).

    The first client whose datagram is valid is paired: datagrams from any other address
    are dropped until the paired one has been silent for ``PAIR_TIMEOUT_S`` (a restarted
    host session then pairs anew). With ``key`` every datagram must be signed and newer
    than the last one accepted (:func:`~mocapkit.teleop.protocol.open_signed`), and the
    reports are signed."""
    stop = False

    def _stop(*_: object) -> None:
        nonlocal stop
        stop = True

    signal.signal(signal.SIGTERM, _stop)
    signal.signal(signal.SIGINT, _stop)
    sock.setblocking(False)
    period = 1.0 / sim.config.rate_hz
    report_period = 1.0 / sim.config.report_hz
    start = time.monotonic()
    next_tick = start
    next_report = start
    client: tuple[str, int] | None = None
    client_seen = -math.inf
    last_seq = -1
    seq = 0
    sent = 0
    while not stop:
        now = time.monotonic()
        if max_seconds is not None and now - start > max_seconds:
            break
        if parent_pid is not None and os.getppid() != parent_pid:
            break
        wait = max(0.0, next_tick - now)
        readable, _, _ = select.select([sock], [], [], wait)
        if readable:
            while True:
                try:
                    data, addr = sock.recvfrom(2048)
                except BlockingIOError:
                    break
                t = time.monotonic()
                if client is not None and addr != client and t - client_seen < PAIR_TIMEOUT_S:
                    sim.state.malformed += 1
                    log.warning("dropped datagram from %s: not the paired client %s", addr, client)
                    continue
                try:
                    msg = proto.decode(data if key is None else proto.open_signed(data, key))
                except proto.LinkProtocolError as exc:
                    sim.state.malformed += 1
                    log.warning("dropped datagram from %s: %s", addr, exc)
                    continue
                if addr != client:  # a new (or the first) client: pair with it
                    client, last_seq = addr, -1
                elif key is not None and msg.seq <= last_seq:
                    sim.state.malformed += 1
                    log.warning("dropped datagram %d from %s: a replay", msg.seq, addr)
                    continue
                client_seen, last_seq = t, msg.seq
                if isinstance(msg, proto.Command):
                    sim.on_command(msg, t)
                elif isinstance(msg, proto.JointsCommand):
                    sim.on_joints(msg, t)
                elif isinstance(msg, proto.Hold):
                    sim.on_hold(t)
        now = time.monotonic()
        if now >= next_tick:
            sim.step(now, period)
            next_tick += period
            if next_tick < now:  # fell behind (loaded machine): do not burst
                next_tick = now + period
        if client is not None and now >= next_report:
            seq += 1
            try:
                report = sim.report(seq, time.monotonic_ns())
                sock.sendto(report if key is None else proto.sign(report, key), client)
                sent += 1
            except OSError as exc:  # the client went away: keep serving
                log.debug("report to %s failed: %s", client, exc)
            next_report = max(next_report + report_period, now)
    st = sim.state
    return {
        "seconds": round(time.monotonic() - start, 3),
        "client": None if client is None else f"{client[0]}:{client[1]}",
        "commands_accepted": st.accepted,
        "commands_refused": st.rejected,
        "datagrams_dropped": st.malformed,
        "reports_sent": sent,
        "gate": st.gate.name.lower(),
        "reason": st.reason.name.lower(),
    }


#: [s] the paired client may be replaced by another address after this much silence.
PAIR_TIMEOUT_S = 1.0


def build_sim(config: ServerConfig) -> RobotSim | HumanoidSim:
    """An arm of the registry, or a humanoid (a packaged name or a robot YAML)."""
    from mocapkit.robot.registry import available_robots, robot_arm

    if config.robot in available_robots():
        return RobotSim(robot_arm(config.robot), config)
    from mocapkit.retarget.robot_model import build_humanoid
    from mocapkit.retarget.robot_spec import load_robot_spec
    from mocapkit.teleop.humanoid_sim import HumanoidSim

    sim = HumanoidSim(build_humanoid(load_robot_spec(config.robot)), config)
    if config.q_start is not None:
        q0 = np.asarray(config.q_start, dtype=float)
        if q0.shape != sim.joints.shape:
            raise ConfigError(
                f"--q-start-deg: {q0.size} values, robot {config.robot} has "
                f"{sim.joints.size} joints ({', '.join(sim.joint_names)})"
            )
        sim.joints = np.clip(q0, sim.lo, sim.hi)
    return sim


def config_args(parser: argparse.ArgumentParser) -> None:
    """Add the server's options to a parser (shared with ``mocapkit teleop server``)."""
    d = ServerConfig()
    parser.add_argument("--host", default="127.0.0.1", help="bind address (default loopback)")
    from mocapkit.cli.boundary import port

    parser.add_argument("--port", type=port, default=9870, help="UDP port (0: any free port)")
    parser.add_argument(
        "--robot",
        default=d.robot,
        help="robot arm name, or a humanoid (mocapkit robot list) or robot YAML: joint commands",
    )
    parser.add_argument(
        "--rate-hz", type=float, default=d.rate_hz, help="the robot's control rate [Hz]"
    )
    parser.add_argument(
        "--report-hz", type=float, default=d.report_hz, help="pose reports sent back per second"
    )
    parser.add_argument(
        "--latency-ms",
        type=float,
        default=d.latency_s * 1e3,
        help="simulated actuation latency [ms]",
    )
    parser.add_argument(
        "--gate-mm",
        type=float,
        default=d.gate_pos_m * 1e3,
        help="safety gate: a command farther than this from the actual pose is refused [mm]",
    )
    parser.add_argument(
        "--gate-deg",
        type=float,
        default=float(np.degrees(d.gate_rot_rad)),
        help="safety gate: the same for rotation [deg]",
    )
    parser.add_argument(
        "--command-timeout-s",
        type=float,
        default=d.command_timeout_s,
        help="no command for this long: the robot holds [s]",
    )
    parser.add_argument(
        "--velocity-scale",
        type=float,
        default=d.velocity_scale,
        help="fraction of the arm's joint velocity limits the robot may use",
    )
    parser.add_argument(
        "--q-start-deg",
        default=None,
        help="initial joints, comma-separated degrees (default: the arm's ready posture)",
    )
    parser.add_argument(
        "--gate-joint-deg",
        type=float,
        default=float(np.degrees(d.gate_joint_rad)),
        help="humanoids: a joint command farther than this from the actual joint (or, "
        "synchronised, from the last command) is refused [deg]",
    )
    parser.add_argument("--max-seconds", type=float, default=None, help="stop after this long")
    parser.add_argument(
        "--json",
        action="store_true",
        help="on exit, one JSON object on stdout: seconds, the paired client, commands "
        "accepted and refused by the gate, datagrams dropped, reports sent (READY goes to "
        "stderr)",
    )
    parser.add_argument(
        "--key-file",
        default=None,
        help="shared key for signed datagrams (required off loopback; the host's "
        "teleop run --robot-key-file must name the same key)",
    )


def config_from_args(args: argparse.Namespace) -> ServerConfig:
    return ServerConfig(
        robot=args.robot,
        rate_hz=args.rate_hz,
        report_hz=args.report_hz,
        latency_s=args.latency_ms / 1e3,
        gate_pos_m=args.gate_mm / 1e3,
        gate_rot_rad=float(np.radians(args.gate_deg)),
        command_timeout_s=args.command_timeout_s,
        velocity_scale=args.velocity_scale,
        q_start=_q_start(args.q_start_deg),
        gate_joint_rad=float(np.radians(args.gate_joint_deg)),
    )


def _q_start(text: str | None) -> tuple[float, ...] | None:
    if text is None:
        return None
    try:
        return tuple(float(np.radians(float(v))) for v in text.split(","))
    except ValueError as exc:
        raise ConfigError(
            f"--q-start-deg: expected comma-separated degrees like 10,-80,90,-60,-90,0,0, "
            f"got {text!r}"
        ) from exc


def run_from_args(args: argparse.Namespace, parent_pid: int | None = None) -> int:
    """Bind, print ``READY <port>`` on stdout, serve."""
    from mocapkit.cli.boundary import is_loopback

    key = read_key(args.key_file)
    if key is None and not is_loopback(args.host):
        raise ConfigError(
            f"--host {args.host}: the robot port moves a robot; off loopback it needs a shared "
            "key (--key-file, the same file as the host's --robot-key-file), or bind 127.0.0.1"
        )
    sim = build_sim(config_from_args(args))
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind((args.host, args.port))
        # with --json stdout holds only the summary: READY goes to stderr
        out = sys.stderr if getattr(args, "json", False) else sys.stdout
        print(f"READY {sock.getsockname()[1]}", file=out, flush=True)
        summary = serve(sim, sock, args.max_seconds, parent_pid, key)
    finally:
        sock.close()
    if getattr(args, "json", False):
        from mocapkit.cli.common import print_json

        print_json({"robot": args.robot, **summary})
    return 0


def read_key(path: str | None) -> bytes | None:
    """The shared key in a file (its bytes, surrounding whitespace removed), or None."""
    if path is None:
        return None
    key = Path(path).read_bytes().strip()
    if len(key) < 16:
        raise ConfigError(f"--key-file {path}: the key has {len(key)} bytes; use at least 16")
    return key


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m mocapkit.teleop.server")
    config_args(parser)
    parser.add_argument("--parent-pid", type=int, default=None)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr)
    try:
        return run_from_args(args, args.parent_pid)
    except MocapkitError as exc:
        print(f"robot server: error: {exc}", file=sys.stderr)
        return 1


class RobotServerProcess:
    """A robot server running in its own process; use as a context manager."""

    def __init__(self, proc: subprocess.Popen[str], port: int) -> None:
        self.proc = proc
        self.port = port
        self.address = ("127.0.0.1", port)

    def stop(self, timeout_s: float = 5.0) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout_s)
        if self.proc.stdout is not None:
            self.proc.stdout.close()

    def pause(self) -> None:
        """Freeze the process (SIGSTOP): a server that stops answering."""
        self.proc.send_signal(signal.SIGSTOP)

    def resume(self) -> None:
        self.proc.send_signal(signal.SIGCONT)

    def __enter__(self) -> RobotServerProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def spawn_robot_server(
    config: ServerConfig | None = None,
    max_seconds: float = 600.0,
    ready_timeout_s: float = 30.0,
    nice: int = 0,
    port: int = 0,
    key_file: str | None = None,
) -> RobotServerProcess:
    """Start ``python -m mocapkit.teleop.server`` on a loopback port (``port``, 0: a free
    one; a restarted server takes its predecessor's) and wait until it is ready. The
    process exits by itself after ``max_seconds`` or if we die. ``nice`` lowers its
    scheduling priority (the evaluation runs it at 10: it stands in for the
    robot's own computer, and on a shared machine must not preempt the host pipeline)."""
    c = config or ServerConfig()
    argv = [
        sys.executable,
        "-m",
        "mocapkit.teleop.server",
        "--port",
        str(port),
        "--robot",
        c.robot,
        "--rate-hz",
        str(c.rate_hz),
        "--report-hz",
        str(c.report_hz),
        "--latency-ms",
        str(c.latency_s * 1e3),
        "--gate-mm",
        str(c.gate_pos_m * 1e3),
        "--gate-deg",
        str(np.degrees(c.gate_rot_rad)),
        "--command-timeout-s",
        str(c.command_timeout_s),
        "--velocity-scale",
        str(c.velocity_scale),
        "--max-seconds",
        str(max_seconds),
        *(
            ["--q-start-deg", ",".join(str(float(np.degrees(v))) for v in c.q_start)]
            if c.q_start is not None
            else []
        ),
        "--parent-pid",
        str(os.getpid()),
        *(["--key-file", key_file] if key_file is not None else []),
    ]

    def lower_priority() -> None:  # pragma: no cover (runs in the child)
        os.nice(nice)

    proc = subprocess.Popen(
        argv, stdout=subprocess.PIPE, text=True, preexec_fn=lower_priority if nice else None
    )
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], ready_timeout_s)
    line = proc.stdout.readline() if ready else ""
    if not line.startswith("READY "):
        proc.kill()
        proc.wait()
        raise MocapkitError(
            f"robot server did not start (exit code {proc.returncode}, said {line!r})"
        )
    return RobotServerProcess(proc, int(line.split()[1]))


if __name__ == "__main__":
    sys.exit(main())
