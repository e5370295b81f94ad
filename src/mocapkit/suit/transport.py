"""Transports that carry suit frames: UDP (default), serial (pyserial), and a stream deframer.

A transport moves *frames* (bytes objects). :meth:`Transport.recv_batch` returns every
frame readable now (waiting up to ``timeout_s`` for the first), each with its source and
its arrival time ``time.perf_counter_ns()`` taken when it was read, so a receiver drains
a burst in one call (the loop stands in for ``recvmmsg``).
"""

from __future__ import annotations

import errno
import logging
import select
import socket
import time
from abc import ABC, abstractmethod
from typing import Any, NamedTuple

from mocapkit.errors import ConfigError, MissingDependencyError
from mocapkit.suit.protocol import CRC_SIZE, MAX_PACKET, OVERHEAD, SYNC, crc16

log = logging.getLogger(__name__)

# Large enough for a 15 kHz burst of 31-byte datagrams while the receiver is descheduled
# (Linux doubles it and caps it at net.core.rmem_max).
UDP_RCVBUF = 4 * 1024 * 1024
# Every datagram up to this size is read whole, so an oversized one is seen (and dropped).
UDP_READ_SIZE = 2048


class Frame(NamedTuple):
    """A frame as received: the bytes, who sent it, and when it was read [ns, perf_counter]."""

    data: bytes
    source: Any
    t_arrival_ns: int


class Transport(ABC):
    """Moves frames; see the module docstring."""

    name: str = "transport"

    @abstractmethod
    def send(self, data: bytes) -> None:
        """Send one frame to the peer."""

    @abstractmethod
    def recv_batch(self, max_frames: int = 1024, timeout_s: float = 0.05) -> list[Frame]:
        """Frames readable now; waits up to ``timeout_s`` for the first."""

    def reply(self, data: bytes, source: Any) -> None:
        """Send ``data`` back to the ``source`` of a received frame (UDP handshakes)."""
        self.send(data)

    @abstractmethod
    def close(self) -> None:
        """Release the underlying socket or port."""

    def __enter__(self) -> Transport:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class UdpTransport(Transport):
    """A UDP socket: one datagram per frame. Build with :meth:`bind` or :meth:`connect`."""

    def __init__(self, sock: socket.socket, peer: tuple[str, int] | None = None) -> None:
        self.sock = sock
        self.peer = peer
        host, port = peer if peer is not None else sock.getsockname()[:2]
        self.name = f"udp://{host}:{port}"

    @classmethod
    def bind(cls, host: str = "127.0.0.1", port: int = 0) -> UdpTransport:
        """A receiving socket on ``host:port`` (port 0: any free port, see :attr:`port`)."""
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, UDP_RCVBUF)
            sock.bind((host, port))
        except OSError as exc:
            sock.close()
            raise ConfigError(f"port: cannot bind UDP {host}:{port} ({exc})") from exc
        sock.setblocking(False)
        return cls(sock)

    @classmethod
    def connect(cls, host: str, port: int) -> UdpTransport:
        """A sending socket aimed at ``host:port``."""
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, UDP_RCVBUF)
        sock.bind(("0.0.0.0" if host not in ("127.0.0.1", "localhost") else "127.0.0.1", 0))
        sock.setblocking(True)
        return cls(sock, (host, port))

    @property
    def port(self) -> int:
        return int(self.sock.getsockname()[1])

    def send(self, data: bytes) -> None:
        if self.peer is None:
            raise ConfigError("send: this socket was bound for receiving; use connect()")
        try:
            self.sock.sendto(data, self.peer)
        except OSError as exc:  # e.g. ECONNREFUSED from an earlier ICMP: the peer is not up
            if exc.errno not in (errno.ECONNREFUSED, errno.ENOBUFS, errno.EAGAIN):
                raise

    def reply(self, data: bytes, source: Any) -> None:
        try:
            self.sock.sendto(data, source)
        except OSError as exc:
            log.warning("udp: cannot reply to %s (%s)", source, exc)

    def recv_batch(self, max_frames: int = 1024, timeout_s: float = 0.05) -> list[Frame]:
        out: list[Frame] = []
        recv = self.sock.recvfrom
        try:
            ready, _, _ = select.select([self.sock], [], [], timeout_s)
        except (OSError, ValueError):  # closed under us
            return out
        if not ready:
            return out
        clock = time.perf_counter_ns
        while len(out) < max_frames:
            try:
                data, addr = recv(UDP_READ_SIZE)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                break
            out.append(Frame(data, addr, clock()))
        return out

    def close(self) -> None:
        self.sock.close()


class StreamDeframer:
    """Cuts a byte stream (serial, a raw capture) into frames.

    It hunts for the sync byte, reads the declared length, and keeps a frame only if its
    CRC matches; otherwise it drops one byte and hunts again, so one corrupted byte costs
    at most one frame. ``skipped_bytes`` counts what was thrown away.
    """

    def __init__(self) -> None:
        self.buffer = bytearray()
        self.skipped_bytes = 0
        self.frames = 0

    def feed(self, data: bytes) -> list[bytes]:
        buf = self.buffer
        buf += data
        out: list[bytes] = []
        i = 0
        n = len(buf)
        while True:
            j = buf.find(SYNC, i)
            if j < 0:
                self.skipped_bytes += n - i
                i = n
                break
            self.skipped_bytes += j - i
            i = j
            if n - i < 4:
                break
            total = OVERHEAD + buf[i + 3]
            if n - i < total:
                break
            body = buf[i + 1 : i + total - CRC_SIZE]
            crc = buf[i + total - 2] | (buf[i + total - 1] << 8)
            if crc16(body) == crc:
                out.append(bytes(buf[i : i + total]))
                i += total
            else:
                self.skipped_bytes += 1
                i += 1
        del buf[:i]
        self.frames += len(out)
        return out


class SerialTransport(Transport):
    """Frames over a serial line (pyserial); works on a real port or a pseudo-terminal.

    Args:
        port: device path (``/dev/ttyUSB0``, a pty slave) or a pyserial URL.
        baudrate: line speed [bit/s] (ignored by pseudo-terminals).
    """

    def __init__(self, port: str, baudrate: int = 921_600) -> None:
        try:
            import serial
        except ImportError as exc:  # pragma: no cover - pyserial is a core dependency
            raise MissingDependencyError("pyserial is missing: pip install pyserial") from exc
        try:
            self.serial = serial.serial_for_url(port, baudrate=baudrate, timeout=0)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise ConfigError(f"port: cannot open serial port {port!r} ({exc})") from exc
        self.deframer = StreamDeframer()
        self.name = f"serial://{port}"
        self._pending: list[Frame] = []

    def send(self, data: bytes) -> None:
        self.serial.write(data)

    def recv_batch(self, max_frames: int = 1024, timeout_s: float = 0.05) -> list[Frame]:
        if self._pending:
            out, self._pending = self._pending[:max_frames], self._pending[max_frames:]
            return out
        fd = self.serial.fileno() if hasattr(self.serial, "fileno") else None
        if fd is not None:
            ready, _, _ = select.select([fd], [], [], timeout_s)
            if not ready:
                return []
        else:  # pragma: no cover - URL handlers without a file descriptor
            time.sleep(timeout_s)
        data = self.serial.read(max(1, self.serial.in_waiting) if fd is None else 65536)
        now = time.perf_counter_ns()
        frames = [Frame(f, self.name, now) for f in self.deframer.feed(data)]
        out, self._pending = frames[:max_frames], frames[max_frames:]
        return out

    def close(self) -> None:
        self.serial.close()


def max_frame_size() -> int:
    """The largest valid frame [bytes]."""
    return MAX_PACKET
