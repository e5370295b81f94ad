"""Send a suit timeline over UDP from its own process, on the real clock.

The evaluation plays the simulated suit the way a real one behaves: another process (a
suit and a host do not share an interpreter) sends each frame at its time. The parent
writes the frames to the child's stdin, the child answers ``READY``, and the parent picks
the start instant on ``time.perf_counter()`` (CLOCK_MONOTONIC, shared by every process of
the machine), so it knows when each frame leaves. The child is ``python -m
mocapkit.teleop.sender HOST PORT`` and imports only the standard library.

Wire format on stdin: ``u32 count``, then per frame ``f64 t [s], u32 length, bytes``;
then a line ``GO <t_go>``. On stdout: ``READY``, then one JSON line
``{"sent": n, "late_ms_p99": x}``.
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
import time
from typing import Any, BinaryIO

_COUNT = struct.Struct("<I")
_ITEM = struct.Struct("<dI")


def _read_exact(f: BinaryIO, n: int) -> bytes:
    data = f.read(n)
    if len(data) != n:
        raise EOFError(f"expected {n} bytes, got {len(data)}")
    return data


def _child(host: str, port: int) -> int:
    stdin = sys.stdin.buffer
    (count,) = _COUNT.unpack(_read_exact(stdin, _COUNT.size))
    items = []
    for _ in range(count):
        t, n = _ITEM.unpack(_read_exact(stdin, _ITEM.size))
        items.append((t, _read_exact(stdin, n)))
    print("READY", flush=True)
    line = stdin.readline().decode().split()
    if len(line) != 2 or line[0] != "GO":
        return 2
    t_go = float(line[1])
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    late = []
    t0 = items[0][0] if items else 0.0
    try:
        for t, data in items:
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
        payload = [_COUNT.pack(len(items))]
        for t, data in items:
            payload.append(_ITEM.pack(t, len(data)))
            payload.append(data)
        try:
            self.proc.stdin.write(b"".join(payload))
            self.proc.stdin.flush()
        except BrokenPipeError as exc:
            self.stop()
            raise RuntimeError("the suit sender process died on start") from exc
        if self._readline(60.0) != "READY":
            self.stop()
            raise RuntimeError("the suit sender process did not start")
        self.t_go: float | None = None

    def _readline(self, timeout_s: float) -> str:
        assert self.proc.stdout is not None
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout_s)
        return self.proc.stdout.readline().decode().strip() if ready else ""

    def go(self, delay_s: float = 0.2) -> float:
        """Start sending ``delay_s`` from now; returns that instant (``perf_counter``)."""
        assert self.proc.stdin is not None
        self.t_go = time.perf_counter() + delay_s
        self.proc.stdin.write(f"GO {self.t_go!r}\n".encode())
        self.proc.stdin.flush()
        return self.t_go

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
