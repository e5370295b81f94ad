"""Send a suit timeline over UDP from its own process, on the real clock.

The evaluation plays the simulated suit the way a real one behaves: another process (a
suit and a host do not share an interpreter) sends each frame at its time. The parent
writes the frames to the child's stdin, the child answers ``READY``, and the parent picks
the start instant on ``time.perf_counter()`` (CLOCK_MONOTONIC, shared by every process of
the machine), so it knows when each frame leaves. The child is ``python -m
mocapkit.teleop.sender HOST PORT`` and imports only the standard library.

Wire format on stdin: ``u32 count``, then per frame ``f64 t [s], u32 length, bytes``;
then a line ``GO <t_go>`` (or ``GO <t_go> STREAM``: more chunks follow, each ``u32 count``
and its frames, until a chunk of count 0 or the end of stdin; a live session that runs for
ever is fed this way, a little ahead of the clock). On stdout: ``READY``, then one JSON
line ``{"sent": n, "late_ms_p99": x}``.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import socket
import struct
import subprocess
import sys
import threading
import time
from collections import deque
from typing import Any, BinaryIO

_COUNT = struct.Struct("<I")
_ITEM = struct.Struct("<dI")


def _read_exact(f: BinaryIO, n: int) -> bytes:
    data = f.read(n)
    if len(data) != n:
        raise EOFError(f"expected {n} bytes, got {len(data)}")
    return data


def _read_chunk(f: BinaryIO) -> list[tuple[float, bytes]]:
    """One chunk: ``u32 count`` and its frames (an empty list at the end)."""
    head = f.read(_COUNT.size)
    if len(head) != _COUNT.size:
        return []
    (count,) = _COUNT.unpack(head)
    items = []
    for _ in range(count):
        t, n = _ITEM.unpack(_read_exact(f, _ITEM.size))
        items.append((t, _read_exact(f, n)))
    return items


class _Feed:
    """Frames still to send; in stream mode a reader thread appends the chunks that come."""

    def __init__(self, items: list[tuple[float, bytes]]) -> None:
        self.items: deque[tuple[float, bytes]] = deque(items)
        self.more = False
        self.cond = threading.Condition()

    def stream_from(self, f: BinaryIO) -> None:
        self.more = True

        def read() -> None:
            try:
                while chunk := _read_chunk(f):
                    with self.cond:
                        self.items.extend(chunk)
                        self.cond.notify()
            finally:
                with self.cond:
                    self.more = False
                    self.cond.notify()

        threading.Thread(target=read, daemon=True).start()

    def next(self) -> tuple[float, bytes] | None:
        with self.cond:
            while not self.items and self.more:
                self.cond.wait()
            return self.items.popleft() if self.items else None


def _child(host: str, port: int) -> int:
    stdin = sys.stdin.buffer
    feed = _Feed(_read_chunk(stdin))
    print("READY", flush=True)
    line = stdin.readline().decode().split()
    if len(line) not in (2, 3) or line[0] != "GO":
        return 2
    t_go = float(line[1])
    if len(line) == 3 and line[2] == "STREAM":
        feed.stream_from(stdin)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    late = []
    t0: float | None = None
    try:
        while (item := feed.next()) is not None:
            t, data = item
            if t0 is None:
                t0 = t
            due = t_go + (t - t0)
            wait = due - time.perf_counter()
            if wait > 0:
                time.sleep(wait)  # never spin: the machine is shared
            late.append(time.perf_counter() - due)
            with contextlib.suppress(OSError):  # nobody listens (any more): keep the schedule
                sock.sendto(data, (host, port))
    finally:
        sock.close()
    late.sort()
    p99 = 1e3 * late[int(0.99 * (len(late) - 1))] if late else 0.0
    print(json.dumps({"sent": len(late), "late_ms_p99": p99}), flush=True)
    return 0


def _chunk(items: list[tuple[float, bytes]]) -> bytes:
    payload = [_COUNT.pack(len(items))]
    for t, data in items:
        payload.append(_ITEM.pack(t, len(data)))
        payload.append(data)
    return b"".join(payload)


class TimelineSender:
    """``(t, bytes)`` items sent from a child process; :meth:`go` starts them at an instant.
    ``nice`` lowers the child's priority (it stands in for the suit's own hardware)."""

    def __init__(
        self, items: list[tuple[float, bytes]], host: str, port: int, nice: int = 0
    ) -> None:
        def lower_priority() -> None:  # pragma: no cover (runs in the child)
            os.nice(nice)

        self.proc = subprocess.Popen(
            [sys.executable, "-m", "mocapkit.teleop.sender", host, str(port)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            preexec_fn=lower_priority if nice else None,
        )
        assert self.proc.stdin is not None
        assert self.proc.stdout is not None
        try:
            self.proc.stdin.write(_chunk(items))
            self.proc.stdin.flush()
        except BrokenPipeError as exc:
            self.stop()
            raise RuntimeError("the suit sender process died on start") from exc
        if self._readline(60.0) != "READY":
            self.stop()
            raise RuntimeError("the suit sender process did not start")
        self.t_go: float | None = None
        self._streaming = False

    def _readline(self, timeout_s: float) -> str:
        assert self.proc.stdout is not None
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout_s)
        return self.proc.stdout.readline().decode().strip() if ready else ""

    def go(self, delay_s: float = 0.2, stream: bool = False) -> float:
        """Start sending ``delay_s`` from now; returns that instant (``perf_counter``).
        With ``stream``, more frames may follow (:meth:`feed`) until :meth:`end`."""
        assert self.proc.stdin is not None
        self.t_go = time.perf_counter() + delay_s
        self.proc.stdin.write(f"GO {self.t_go!r}{' STREAM' if stream else ''}\n".encode())
        self.proc.stdin.flush()
        self._streaming = stream
        return self.t_go

    def feed(self, items: list[tuple[float, bytes]]) -> None:
        """More frames, after those already given (times on the same clock); only after
        ``go(stream=True)``. An empty list is ignored (:meth:`end` ends the stream)."""
        from mocapkit.errors import ConfigError, MocapkitError  # (the child: stdlib only)

        stdin = self.proc.stdin
        if stdin is None or stdin.closed or self.proc.poll() is not None:
            raise MocapkitError("the suit sender process has stopped; start a new one")
        if not self._streaming:
            raise ConfigError(
                "feed: start the sender with go(stream=True) first (and before end())"
            )
        if not items:
            return
        try:
            stdin.write(_chunk(items))
            stdin.flush()
        except BrokenPipeError as exc:
            raise MocapkitError("the suit sender process has stopped; start a new one") from exc

    def end(self) -> None:
        """No more frames: the child sends what it has and reports."""
        if self._streaming and self.proc.stdin is not None and not self.proc.stdin.closed:
            with contextlib.suppress(BrokenPipeError):
                self.proc.stdin.write(_COUNT.pack(0))
                self.proc.stdin.flush()
            self._streaming = False

    def wait(self, timeout_s: float) -> dict[str, Any]:
        """Wait for the last frame; returns ``{"sent", "late_ms_p99"}``."""
        line = self._readline(timeout_s)
        if not line:
            self.stop()
            raise RuntimeError("the suit sender process did not finish in time")
        result: dict[str, Any] = json.loads(line)
        self.proc.wait(5.0)
        return result

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5.0)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5.0)
        for f in (self.proc.stdin, self.proc.stdout):
            if f is not None:
                f.close()

    def __enter__(self) -> TimelineSender:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


if __name__ == "__main__":
    sys.exit(_child(sys.argv[1], int(sys.argv[2])))
