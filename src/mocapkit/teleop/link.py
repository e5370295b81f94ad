"""Client side of the robot link: send end-effector or joint commands, collect reports."""

from __future__ import annotations

import logging
import socket
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.teleop import _kernels
from mocapkit.teleop import protocol as proto

log = logging.getLogger("mocapkit.teleop.link")


#: [s] silence of the server after which the link sends a HOLD to be heard again.
KEEPALIVE_S = 0.5


class ReportedRobot:
    """What every robot link shares: the latest report, its age, the reported end-effector
    pose, waiting for a first report, and use as a context manager. A subclass sets
    ``latest``/``latest_t`` in ``poll`` and says whether its reports carry a pose."""

    reports_pose = True
    latest: proto.Report | None
    latest_t: float

    def __init__(self) -> None:
        self.latest = None
        self.latest_t = -np.inf
        self._pose = np.eye(4)
        self._pose_of: proto.Report | None = None

    def poll(self) -> int:  # pragma: no cover (every link has its own)
        raise NotImplementedError

    def close(self) -> None:  # pragma: no cover
        raise NotImplementedError

    def robot_pose(self) -> FloatArray | None:
        """The latest reported pose T_base_ee (4, 4), or None. Computed once per report
        into one buffer: copy it to keep it."""
        latest = self.latest
        if latest is None or not self.reports_pose:
            return None
        if self._pose_of is not latest:
            if not np.isfinite(latest.quat).all() or not latest.quat.any():
                return None  # a report with a broken pose: as good as none
            _kernels.pose_from_parts(latest.pos, latest.quat, self._pose)
            self._pose_of = latest
        return self._pose

    def report_age(self, now: float | None = None) -> float:
        """Seconds since the latest report (inf when none)."""
        return (time.monotonic() if now is None else now) - self.latest_t

    def wait_for_report(self, timeout_s: float = 5.0) -> bool:
        """Poll until a report arrives, sending nothing."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if self.poll():
                return True
            time.sleep(0.005)
        return False

    def __enter__(self) -> Any:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class RobotLink(ReportedRobot):
    """A UDP client of the robot server (loopback or LAN), non-blocking; with ``key`` every
    datagram is signed and every report checked (:func:`~mocapkit.teleop.protocol.sign`).

    Attributes:
        latest: the newest :class:`~mocapkit.teleop.protocol.Report` or None.
        latest_t: ``time.monotonic()`` when it arrived [s].
    """

    def __init__(
        self,
        address: tuple[str, int],
        on_report: Callable[[float, proto.Report], None] | None = None,
        key: bytes | None = None,
    ) -> None:
        super().__init__()
        self.address = address
        self.key = key
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.sock.connect(address)
        self.seq = 0
        self.on_report = on_report
        self.malformed = 0
        self.send_errors = 0
        self._quat = np.empty(4)
        self._last_ping = -np.inf

    def close(self) -> None:
        self.sock.close()

    def _send(self, data: bytes) -> bool:
        if self.key is not None:
            data = proto.sign(data, self.key)
        try:
            self.sock.send(data)
            return True
        except OSError as exc:  # ECONNREFUSED after an ICMP "port unreachable": server gone
            self.send_errors += 1
            log.debug("send to %s failed: %s", self.address, exc)
            return False

    def send_command(self, T_base_ee: Any) -> int:
        """Send a pose (4, 4) [m]; returns its sequence number."""
        self.seq += 1
        T = np.asarray(T_base_ee, dtype=np.float64)
        _kernels.mat_to_quat(T, self._quat)
        self._send(proto.encode_command(self.seq, time.monotonic_ns(), T[:3, 3], self._quat))
        return self.seq

    def send_joints(self, base_pos: Any, base_quat: Any, q: Any) -> int:
        """Send a humanoid's base pose and joint positions [rad]; returns the sequence."""
        self.seq += 1
        self._send(proto.encode_joints(self.seq, time.monotonic_ns(), base_pos, base_quat, q))
        return self.seq

    def send_hold(self) -> None:
        self.seq += 1
        self._send(proto.encode_hold(self.seq, time.monotonic_ns()))

    def poll(self) -> int:
        """Read every report waiting; returns how many arrived."""
        n = 0
        while True:
            try:
                data = self.sock.recv(4096)
            except (BlockingIOError, InterruptedError):
                return n
            except OSError:  # ECONNREFUSED: nobody listens (yet)
                return n
            try:
                msg = proto.decode(data if self.key is None else proto.open_signed(data, self.key))
            except proto.LinkProtocolError as exc:
                self.malformed += 1
                log.warning("dropped report: %s", exc)
                continue
            last = self.latest
            if self.key is not None and last is not None and msg.seq <= last.seq:
                self.malformed += 1
                log.warning("dropped report %d: not newer than %d (a replay?)", msg.seq, last.seq)
                continue
            if isinstance(msg, proto.Report):
                t = time.monotonic()
                self.latest, self.latest_t = msg, t
                n += 1
                if self.on_report is not None:
                    self.on_report(t, msg)

    def keepalive(self, now: float | None = None) -> bool:
        """When the server has been silent for ``KEEPALIVE_S`` (killed and restarted, or
        not started yet), send a HOLD at most every ``KEEPALIVE_S``: a server reports to
        the client it last heard from, so a session on hold (which sends no commands)
        would otherwise never hear from a restarted server. A HOLD cannot move the robot.
        Returns whether one was sent."""
        now = time.monotonic() if now is None else now
        if now - self.latest_t < KEEPALIVE_S or now - self._last_ping < KEEPALIVE_S:
            return False
        self._last_ping = now
        self.send_hold()
        return True

    def wait_for_report(self, timeout_s: float = 5.0) -> bool:
        """Send nothing, poll until a report arrives (the server reports to its last
        sender, so send a HOLD first if it has never heard from us)."""
        return super().wait_for_report(timeout_s)
