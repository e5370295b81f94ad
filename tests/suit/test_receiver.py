"""The host receiver: validation counters and log lines, sequencing, sensor events,
fairness under flooding, consumer API, over real loopback UDP where it matters."""

from __future__ import annotations

import io
import logging
import socket
import struct
import time
from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mocapkit.errors import ConfigError
from mocapkit.suit.protocol import (
    Kind,
    crc16,
    encode_bundle,
    encode_raw,
    encode_status,
    frame,
)
from mocapkit.suit.receiver import Receiver, ReceiverConfig
from mocapkit.suit.transport import Frame, UdpTransport

# runs live processes and sockets against the clock: run serially (see Makefile)
pytestmark = pytest.mark.realtime

_OPEN: list[UdpTransport] = []


@pytest.fixture(autouse=True)
def _close_sockets() -> Iterator[None]:
    yield
    while _OPEN:
        _OPEN.pop().close()


def _rx(**cfg: object) -> Receiver:
    """A receiver on a bound socket nobody sends to: tests feed it through ``handle``."""
    t = UdpTransport.bind("127.0.0.1", 0)
    _OPEN.append(t)
    return Receiver(t, ReceiverConfig(**cfg))  # type: ignore[arg-type]


def _feed(
    rx: Receiver, data: bytes, source: object = ("10.0.0.1", 5000), t_ns: int | None = None
) -> None:
    rx.handle(Frame(data, source, time.perf_counter_ns() if t_ns is None else t_ns))


def _raw(sid: int, seq: int, t_us: int = 0) -> bytes:
    return encode_raw(sid, seq, t_us or seq * 1000, [0.1, 0.2, 0.3], [0, 0, 9.81], [20, 0, -40])


def _drain(rx: Receiver) -> list:
    out = []
    while True:
        b = rx.get_batch(1000, 0.0)
        if not b:
            return out
        out += b


@pytest.mark.parametrize(
    ("data", "reason", "message"),
    [
        (b"\xa5\x12\x02", "truncated", "at least 12"),
        (_raw(1, 0)[:-3], "truncated", "header declares 31"),
        (_raw(1, 0) + bytes(400), "oversized", "at most 267"),
        (_raw(1, 0)[:20] + bytes([_raw(1, 0)[20] ^ 1]) + _raw(1, 0)[21:], "bad_crc", "CRC 0x"),
        (frame(Kind.RAW, 16, 0, 0, bytes(19)), "unknown_sensor", "sensor_id 16 outside 1..15"),
    ],
)
def test_malformed_datagrams_are_counted_and_logged(data, reason, message, caplog) -> None:  # type: ignore[no-untyped-def]
    rx = _rx()
    with caplog.at_level(logging.WARNING, logger="mocapkit.suit.receiver"):
        _feed(rx, data)
    assert rx.stats().dropped == {reason: 1}
    assert any(message in r.message and f"[{reason}]" in r.message for r in caplog.records)
    assert _drain(rx) == []


def test_unsupported_version_is_counted(caplog) -> None:  # type: ignore[no-untyped-def]
    pkt = bytearray(_raw(1, 0))
    pkt[1] = (3 << 4) | 2
    pkt[-2:] = struct.pack("<H", crc16(bytes(pkt[1:-2])))
    rx = _rx()
    with caplog.at_level(logging.WARNING):
        _feed(rx, bytes(pkt))
    assert rx.stats().dropped == {"bad_version": 1}
    assert "protocol version 3, this receiver speaks 1" in caplog.text


def test_allow_list_rejects_other_ids(caplog) -> None:  # type: ignore[no-untyped-def]
    rx = _rx(allowed_ids=frozenset({1, 2}))
    with caplog.at_level(logging.WARNING):
        _feed(rx, _raw(1, 0))
        _feed(rx, _raw(7, 0))
    assert rx.stats().dropped == {"unknown_sensor": 1}
    assert "sensor_id 7 is not in the allow-list [1, 2]" in caplog.text
    assert [s.sensor_id for s in _drain(rx)] == [1]


def test_log_lines_are_rate_limited(caplog) -> None:  # type: ignore[no-untyped-def]
    rx = _rx()
    with caplog.at_level(logging.WARNING):
        for _ in range(500):
            _feed(rx, b"\xa5\x00")
    assert rx.stats().dropped == {"truncated": 500}
    assert len([r for r in caplog.records if "[truncated]" in r.message]) == 1


def test_duplicates_reordering_replay_and_fields() -> None:
    rx = _rx()
    for seq in (0, 1, 3, 2, 2, 1, 4):
        _feed(rx, _raw(5, seq))
    samples = _drain(rx)
    assert [s.seq for s in samples] == [0, 1, 2, 3, 4]
    s = rx.stats().sensors[5]
    assert (s.delivered, s.duplicate, s.reordered, s.lost) == (5, 2, 1, 0)
    first = samples[0]
    assert first.kind is Kind.RAW
    assert first.sensor_id == 5
    np.testing.assert_allclose(first.gyr, [0.1, 0.2, 0.3])
    np.testing.assert_allclose(first.mag, [20, 0, -40])
    assert first.t_sensor_s == pytest.approx(0.0)
    assert samples[3].t_sensor_s == pytest.approx(0.003)


def test_gap_counted_lost_after_window() -> None:
    rx = _rx(reorder_window_s=0.01)
    t = time.perf_counter_ns()
    _feed(rx, _raw(1, 0), t_ns=t)
    _feed(rx, _raw(1, 5), t_ns=t)
    assert [s.seq for s in _drain(rx)] == [0]
    rx._housekeeping(t + 20_000_000)
    assert [s.seq for s in _drain(rx)] == [5]
    assert rx.stats().sensors[1].lost == 4


def test_bundle_and_status() -> None:
    rx = _rx()
    q = np.array([0.5, 0.5, 0.5, 0.5])
    _feed(rx, encode_bundle(9, 123_000, [(1, q), (2, -q)]))
    _feed(rx, encode_status(2, 0, 0, 3650, 31.0))
    samples = _drain(rx)
    assert [(s.sensor_id, s.seq, s.kind) for s in samples] == [
        (1, 9, Kind.ORIENTATION),
        (2, 9, Kind.ORIENTATION),
    ]
    assert samples[0].t_sensor_s == pytest.approx(0.123)
    assert rx.stats().sensors[2].battery_mv == 3650


def test_sensor_events_added_missing_back() -> None:
    rx = _rx(missing_after_s=0.1)
    t = time.perf_counter_ns()
    _feed(rx, _raw(3, 0), t_ns=t)
    rx._housekeeping(t + 200_000_000)
    assert rx.stats().sensors[3].state == "missing"
    _feed(rx, _raw(3, 900), t_ns=t + 300_000_000)  # back, with its counter elsewhere
    assert [(e.kind, e.sensor_id) for e in rx.events()] == [
        ("added", 3),
        ("missing", 3),
        ("back", 3),
    ]
    assert [s.seq for s in _drain(rx)] == [0, 900]


def test_round_robin_consumer_and_bounded_queues() -> None:
    rx = _rx(queue_per_sensor=100)
    for seq in range(300):
        _feed(rx, _raw(1, seq))
    for seq in range(5):
        _feed(rx, _raw(2, seq))
    batch = rx.get_batch(12, 0.0)
    # sensor 1 flooded its own queue (oldest dropped) but sensor 2 still gets its turn
    assert sum(s.sensor_id == 2 for s in batch) == 5
    st_ = rx.stats()
    assert st_.sensors[1].queue_dropped == 200
    assert st_.dropped["queue_full"] == 200


def test_listener_is_called() -> None:
    rx = _rx()
    seen: list[int] = []
    rx.add_listener(lambda s: seen.append(s.seq))
    for seq in range(3):
        _feed(rx, _raw(1, seq))
    assert seen == [0, 1, 2]


def test_config_validation() -> None:
    with pytest.raises(ConfigError, match="protocols: expected suit, slimevr or auto"):
        ReceiverConfig(protocols="tcp")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="reorder_window_s: expected > 0"):
        ReceiverConfig(reorder_window_s=0)
    with pytest.raises(ConfigError, match="allowed_ids: expected IDs in 1..15"):
        ReceiverConfig(allowed_ids=frozenset({0}))


@given(st.binary(max_size=120))
def test_fuzz_receiver_never_raises(data: bytes) -> None:
    rx = _rx()
    _feed(rx, data)
    _feed(rx, b"\xa5" + data)
    _feed(rx, struct.pack(">IQ", 17, 1) + data)
    assert rx.stats().datagrams == 3


def test_udp_stream_with_a_flooding_sender() -> None:
    """A flooding source is rate-limited; the legitimate sensors lose nothing."""
    rx_t = UdpTransport.bind("127.0.0.1", 0)
    # the good source sends 400 packets, within its burst allowance; the flood sends 2000
    rx = Receiver(rx_t, ReceiverConfig(source_rate_hz=2000, source_burst=600)).start()
    good = UdpTransport.connect("127.0.0.1", rx_t.port)
    flood = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        junk = _raw(3, 0)
        for i in range(200):
            good.send(_raw(1, i))
            good.send(_raw(2, i))
            for _ in range(10):  # 10 flood datagrams (replays of one packet) per good pair
                flood.sendto(junk, ("127.0.0.1", rx_t.port))
            if i % 10 == 0:  # bursts of 120 datagrams fit even a default 208 KiB socket buffer
                time.sleep(0.002)
        got: dict[int, int] = {}
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline and (got.get(1, 0) < 200 or got.get(2, 0) < 200):
            for s in rx.get_batch(1000, 0.05):
                got[s.sensor_id] = got.get(s.sensor_id, 0) + 1
    finally:
        rx.stop()
        good.close()
        flood.close()
        rx_t.close()
    st_ = rx.stats()
    assert got.get(1) == 200
    assert got.get(2) == 200
    assert st_.sensors[1].lost == 0
    assert st_.sensors[2].lost == 0
    assert st_.dropped.get("rate_limited", 0) > 0
    assert st_.sensors[3].duplicate > 0  # the admitted replays were caught as duplicates


def test_stale_sensor_detected_and_fresh_again(caplog: pytest.LogCaptureFixture) -> None:
    rx = _rx(stale_after_s=0.1, missing_after_s=1.0)
    t = time.perf_counter_ns()
    _feed(rx, _raw(4, 0, 1000), t_ns=t)
    # a frozen node: new sequence numbers but its clock does not advance
    for k in range(1, 5):
        _feed(rx, _raw(4, k, 1000), t_ns=t + k * 50_000_000)
    with caplog.at_level(logging.WARNING):
        rx._housekeeping(t + 200_000_000)
    assert rx.stats().sensors[4].state == "stale"
    assert "sensor 4 stale" in caplog.text
    _feed(rx, _raw(4, 5, 2000), t_ns=t + 250_000_000)
    assert rx.stats().sensors[4].state == "ok"
    assert [e.kind for e in rx.events()] == ["added", "stale", "fresh"]


def test_replayed_old_traffic_is_stale_while_the_sensor_is_live() -> None:
    rx = _rx()
    t = time.perf_counter_ns()
    for seq in range(400):
        _feed(rx, _raw(2, seq), t_ns=t + seq * 1_000_000)
    for k, seq in enumerate(range(0, 30)):  # an attacker replays a captured run
        _feed(rx, _raw(2, seq), t_ns=t + (400 + k) * 1_000_000)
        _feed(rx, _raw(2, 400 + k), t_ns=t + (400 + k) * 1_000_000)
    got = [s.seq for s in _drain(rx)]
    assert got == list(range(430))
    st_ = rx.stats().sensors[2]
    assert st_.stale == 30
    assert st_.lost == 0


def test_samples_iterator_ends_after_timeout() -> None:
    rx = _rx()
    for seq in range(3):
        _feed(rx, _raw(1, seq))
    assert [s.seq for s in rx.samples(timeout_s=0.01)] == [0, 1, 2]
    assert rx.pending == 0


def test_live_table_renders() -> None:
    from rich.console import Console

    from mocapkit.cli.suit_cmd import _table

    rx = _rx()
    for seq in (0, 1, 3):
        _feed(rx, _raw(2, seq))
    _feed(rx, b"\xa5")
    console = Console(width=160, record=True, file=io.StringIO())
    console.print(_table(rx))
    text = console.export_text()
    assert "suit receiver: 4 datagrams, 1 dropped {'truncated': 1}" in text
    assert "latency p50 ms" in text


def test_many_sources_do_not_grow_memory_without_bound() -> None:
    rx = _rx()
    t = time.perf_counter_ns()
    for i in range(10_000):
        _feed(rx, b"\xa5\x00", source=("10.0.0.1", i), t_ns=t + i * 1_000_000)
    assert len(rx._buckets) <= 4096
    assert rx.stats().dropped == {"truncated": 10_000}


def test_bundle_entry_outside_the_allow_list_drops_only_that_entry() -> None:
    rx = _rx(allowed_ids=frozenset({1, 2}))
    q = np.array([1.0, 0.0, 0.0, 0.0])
    _feed(rx, encode_bundle(0, 0, [(1, q), (9, q), (2, q)]))
    assert [s.sensor_id for s in _drain(rx)] == [1, 2]
    assert rx.stats().dropped == {"unknown_sensor": 1}


def test_rate_limit_can_be_turned_off_for_fast_replays() -> None:
    import math

    limited = _rx(queue_per_sensor=30_000)
    free = _rx(source_rate_hz=math.inf, queue_per_sensor=30_000)
    for seq in range(21_000):
        pkt = _raw(1, seq)
        _feed(limited, pkt, t_ns=0)
        _feed(free, pkt, t_ns=0)
    assert limited.stats().dropped == {"rate_limited": 1_000}  # the 20 000 burst, then none
    assert free.stats().dropped == {}
    assert free.stats().sensors[1].delivered == 21_000


def test_direct_consumer_runs_on_the_receiver_thread(caplog) -> None:  # type: ignore[no-untyped-def]
    """on_batch gets every delivered sample on the receiver thread, ticks when idle, and
    a failing consumer costs one call, never the thread."""
    import threading

    rx_t = UdpTransport.bind("127.0.0.1", 0)
    _OPEN.append(rx_t)
    seen: list[tuple[int, int, str]] = []
    ticks = [0]
    fail = [True]

    def consume(samples: list, now_ns: int) -> None:  # type: ignore[type-arg]
        ticks[0] += 1
        for s in samples:
            seen.append((s.sensor_id, s.seq, threading.current_thread().name))
        if samples and fail[0]:
            fail[0] = False
            raise RuntimeError("consumer bug")

    tx = UdpTransport.connect("127.0.0.1", rx_t.port)
    _OPEN.append(tx)
    with caplog.at_level(logging.ERROR, logger="mocapkit.suit.receiver"):
        rx = Receiver(rx_t, on_batch=consume).start()
        try:
            for seq in range(5):
                tx.send(_raw(3, seq))
                time.sleep(0.01)
            end = time.monotonic() + 5.0
            while len(seen) < 5 and time.monotonic() < end:
                time.sleep(0.01)
            time.sleep(0.05)  # idle: empty ticks (every 5 ms at most)
        finally:
            rx.stop()
    assert [(sid, seq) for sid, seq, _ in seen] == [(3, k) for k in range(5)]
    assert {name for *_, name in seen} == {"suit-receiver"}
    assert ticks[0] > 5 + 5  # more calls than batches: the idle ticks
    assert rx.get_batch(10, 0.0) == []  # nothing queued
    assert rx.stats().dropped == {"consumer_error": 1}
    assert "the direct consumer (on_batch) failed" in caplog.text
