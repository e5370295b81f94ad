"""Serial transport through pyserial over a pseudo-terminal pair, and the stream deframer."""

from __future__ import annotations

import os
import threading
import time
import tty
from collections.abc import Iterator

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.suit.protocol import encode_orientation, encode_raw
from mocapkit.suit.receiver import Receiver
from mocapkit.suit.simulator import SuitSimConfig, SuitSimulator
from mocapkit.suit.transport import SerialTransport, StreamDeframer, UdpTransport


@pytest.fixture
def pty_pair() -> Iterator[tuple[int, str]]:
    """(master fd, slave device path) of a raw pseudo-terminal."""
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    name = os.ttyname(slave)
    yield master, name
    os.close(master)
    os.close(slave)


def _frames() -> list[bytes]:
    return [encode_raw(1 + i % 3, i, i * 1000, [0, 0, 1], [0, 0, 9.81]) for i in range(50)]


def test_deframer_resynchronises_after_garbage_and_corruption() -> None:
    frames = _frames()
    bad = bytearray(frames[10])
    bad[15] ^= 0xFF
    stream = b"\xa5\x00junk" + b"".join(frames[:10]) + bytes(bad) + b"".join(frames[11:])
    d = StreamDeframer()
    assert d.feed(stream) == frames[:10] + frames[11:]
    # fed one byte at a time, the result is the same
    d1 = StreamDeframer()
    out: list[bytes] = []
    for i in range(len(stream)):
        out += d1.feed(stream[i : i + 1])
    assert out == frames[:10] + frames[11:]
    assert d1.skipped_bytes == d.skipped_bytes == 6 + len(bad)


def test_serial_transport_over_pty(pty_pair: tuple[int, str]) -> None:
    master, name = pty_pair
    frames = _frames()
    with SerialTransport(name) as rx:
        os.write(master, b"\x00\x01" + b"".join(frames))
        got: list[bytes] = []
        deadline = time.monotonic() + 3.0
        while len(got) < len(frames) and time.monotonic() < deadline:
            got += [f.data for f in rx.recv_batch(7, 0.05)]
        assert got == frames
        # the other direction: pyserial writes, the master end reads
        rx.send(frames[0])
        time.sleep(0.05)
        assert os.read(master, 100) == frames[0]


def test_simulated_suit_streams_over_serial_to_the_receiver(pty_pair: tuple[int, str]) -> None:
    master, name = pty_pair
    sim = SuitSimulator.from_motion(
        "wave", 3, 0.2, 100.0, SuitSimConfig(mode="raw"), np.random.default_rng(0)
    )
    with SerialTransport(name) as port:
        rx = Receiver(port).start()
        n = sim.stream(lambda b: os.write(master, b), speed=0)
        got = []
        deadline = time.monotonic() + 5.0
        while len(got) < n and time.monotonic() < deadline:
            got += rx.get_batch(1000, 0.05)
        rx.stop()
    assert n == 3 * 21
    assert len(got) == n
    assert rx.stats().dropped == {}


def test_serial_bad_port_message() -> None:
    with pytest.raises(ConfigError, match="cannot open serial port '/nonexistent/tty'"):
        SerialTransport("/nonexistent/tty")


def test_udp_bind_conflict_message() -> None:
    a = UdpTransport.bind("127.0.0.1", 0)
    try:
        with pytest.raises(ConfigError, match=f"cannot bind UDP 127.0.0.1:{a.port}"):
            UdpTransport.bind("127.0.0.1", a.port)
        with pytest.raises(ConfigError, match="bound for receiving; use connect"):
            a.send(b"x")
    finally:
        a.close()


def test_udp_batch_drain() -> None:
    rx = UdpTransport.bind("127.0.0.1", 0)
    tx = UdpTransport.connect("127.0.0.1", rx.port)
    try:
        frames = [encode_orientation(1, i, i, [1, 0, 0, 0]) for i in range(100)]
        for f in frames:
            tx.send(f)
        got: list[bytes] = []
        t = threading.Event()
        deadline = time.monotonic() + 3.0
        while len(got) < 100 and time.monotonic() < deadline and not t.is_set():
            got += [f.data for f in rx.recv_batch(1000, 0.05)]
        assert got == frames
    finally:
        rx.close()
        tx.close()
