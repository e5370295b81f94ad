"""Recordings survive the ways a process is stopped: real signals to a real
``mocapkit suit record`` process fed real UDP datagrams.

- SIGTERM / SIGHUP (a service stop, ``timeout``, a closed terminal) stop it like Ctrl-C:
  the file is finished (summary written) and holds every frame sent;
- SIGKILL (or a power cut) leaves a file without its summary: mocapkit reads everything
  up to the last flush (at most ``FLUSH_S`` before the kill), with a warning, and so does
  the ``mcap`` library's own record reader.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mocapkit.io.mcap_recovery import RecoveredRecordingWarning
from mocapkit.suit.protocol import encode_orientation
from mocapkit.suit.recording import read_frames

pytestmark = pytest.mark.realtime

SEND_S = 2.0
RATE_HZ = 200.0


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _start(out: Path, port: int) -> subprocess.Popen[bytes]:
    code = "from mocapkit.cli.main import run; run()"
    argv = [sys.executable, "-c", code, "suit", "record", "--host", "127.0.0.1"]
    argv += ["--port", str(port), "--out", str(out), "--json"]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 30.0
    while not out.exists() or out.stat().st_size == 0:  # the recorder has started
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            raise AssertionError(f"suit record did not start: {proc.communicate()[1]!r}")
        time.sleep(0.05)
    return proc


def _send(port: int) -> int:
    """Send ``SEND_S`` seconds of one sensor's orientation packets; returns how many."""
    n = round(SEND_S * RATE_HZ)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
        t0 = time.monotonic()
        for k in range(n):
            tx.sendto(encode_orientation(1, k, k * 5000, [1.0, 0.0, 0.0, 0.0]), ("127.0.0.1", port))
            delay = t0 + (k + 1) / RATE_HZ - time.monotonic()
            if delay > 0:
                time.sleep(delay)
    return n


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_finish_the_recording(tmp_path: Path, sig: signal.Signals) -> None:
    out = tmp_path / "rec.mcap"
    port = _free_port()
    proc = _start(out, port)
    sent = _send(port)
    time.sleep(0.3)  # the last datagrams reach the receiver
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err  # interrupted, like Ctrl-C
    frames = read_frames(out)  # a finished file: no recovery warning (warnings are errors)
    assert len(frames) == sent


def test_sigkill_leaves_everything_but_the_last_flush_readable(tmp_path: Path) -> None:
    out = tmp_path / "rec.mcap"
    port = _free_port()
    proc = _start(out, port)
    sent = _send(port)
    time.sleep(1.5)  # > FLUSH_S: the recorder has flushed every frame sent
    os.kill(proc.pid, signal.SIGKILL)
    proc.communicate(timeout=30)
    with pytest.warns(RecoveredRecordingWarning, match="was not closed"):
        frames = read_frames(out)
    assert len(frames) == sent
    # the mcap library's own record reader sees the same messages
    from mcap.exceptions import McapError
    from mcap.records import Message
    from mcap.stream_reader import StreamReader

    count = 0
    with open(out, "rb") as f:
        try:
            for record in StreamReader(f).records:
                count += isinstance(record, Message)
        except (McapError, EOFError):  # the cut at the end of a killed file
            pass
    assert count == sent
