"""SlimeVR ingest: packets built byte by byte from the public layout, fuzzing, and a
tracker talking to the receiver over loopback UDP (handshake answered as the server does)."""

from __future__ import annotations

import contextlib
import socket
import struct
import time

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mocapkit.suit import slimevr
from mocapkit.suit.protocol import Kind
from mocapkit.suit.receiver import Receiver, ReceiverConfig
from mocapkit.suit.slimevr import SlimeVRError, handshake_reply, parse
from mocapkit.suit.transport import UdpTransport

Q = np.array([0.8, 0.2, -0.4, 0.4])  # unit: 0.64 + 0.04 + 0.16 + 0.16


def _header(ptype: int, num: int) -> bytes:
    return ptype.to_bytes(4, "big") + num.to_bytes(8, "big")


def _handshake_bytes() -> bytes:
    fw = b"0.5.3"
    return (
        _header(3, 0)
        + (4).to_bytes(4, "big")  # board
        + (8).to_bytes(4, "big")  # imu
        + (2).to_bytes(4, "big")  # mcu
        + bytes(12)  # imu info
        + (19).to_bytes(4, "big")  # firmware build / protocol version
        + bytes([len(fw)])
        + fw
        + bytes([0x3C, 0x71, 0xBF, 0x00, 0x11, 0x22])
    )


def test_handshake_byte_by_byte() -> None:
    (m,) = parse(_handshake_bytes())
    assert (m.type, m.board, m.imu, m.mcu, m.firmware_build) == (3, 4, 8, 2, 19)
    assert m.firmware == "0.5.3"
    assert m.mac == "3C:71:BF:00:11:22"
    (old,) = parse(_header(3, 0) + (4).to_bytes(4, "big"))  # old firmware: short handshake
    assert old.type == 3
    assert old.board is None


def test_handshake_reply_layout() -> None:
    r = handshake_reply()
    assert len(r) == 64
    assert r[0] == 3
    assert r[1:13] == b"Hey OVR =D 5"
    assert not any(r[13:])


def test_rotation_data_byte_by_byte() -> None:
    w, x, y, z = Q
    data = _header(17, 42) + bytes([2, 1]) + struct.pack(">4f", x, y, z, w) + bytes([3])
    (m,) = parse(data)
    assert (m.type, m.packet_number, m.sensor_id) == (17, 42, 2)
    np.testing.assert_allclose(m.quat, Q, atol=1e-7)  # float32 storage
    (corr,) = parse(_header(17, 43) + bytes([2, 2]) + struct.pack(">4f", x, y, z, w) + b"\0")
    assert corr.quat is None  # correction data is not an orientation


def test_rotation_and_acceleration_byte_by_byte() -> None:
    w, x, y, z = Q
    q15 = [round(c * 32768) for c in (x, y, z, w)]
    acc = [round(c * 128) for c in (1.5, -9.81, 0.25)]
    data = _header(23, 7) + bytes([1]) + struct.pack(">7h", *q15, *acc)
    (m,) = parse(data)
    assert m.sensor_id == 1
    np.testing.assert_allclose(m.quat, Q, atol=1e-4)  # Q15: 3e-5 per component
    np.testing.assert_allclose(m.acc, [1.5, -9.8125, 0.25])  # 1/128 m/s^2 steps


def test_legacy_rotation_accel_battery_sensor_info() -> None:
    w, x, y, z = Q
    (rot,) = parse(_header(1, 1) + struct.pack(">4f", x, y, z, w))
    assert rot.sensor_id == 0
    np.testing.assert_allclose(rot.quat, Q, atol=1e-7)
    (acc,) = parse(_header(4, 2) + struct.pack(">3f", 0.1, 0.2, 9.7) + bytes([1]))
    assert acc.sensor_id == 1
    assert acc.acc is not None
    (bat,) = parse(_header(12, 3) + struct.pack(">2f", 3.9, 0.8))
    assert bat.battery_v == pytest.approx(3.9)
    assert bat.battery_level == pytest.approx(0.8)
    (info,) = parse(_header(15, 4) + bytes([1, 1, 8]))
    assert (info.sensor_id, info.status) == (1, 1)
    (hb,) = parse(_header(0, 5))
    assert hb.type == 0
    assert hb.quat is None


def test_bundles_v1_and_v2_byte_by_byte() -> None:
    w, x, y, z = Q
    body0 = bytes([0, 1]) + struct.pack(">4f", x, y, z, w) + b"\0"
    body1 = bytes([1, 1]) + struct.pack(">4f", -x, -y, -z, -w) + b"\0"
    v1 = _header(100, 9)
    for body in (body0, body1):
        inner = (17).to_bytes(4, "big") + body
        v1 += len(inner).to_bytes(2, "big") + inner
    v2 = _header(101, 9)
    for body in (body0, body1):
        inner = bytes([17]) + body
        v2 += bytes([len(inner)]) + inner
    for data in (v1, v2):
        msgs = parse(data)
        assert [(m.type, m.sensor_id, m.packet_number) for m in msgs] == [(17, 0, 9), (17, 1, 9)]
    assert v2 == slimevr.build_bundle(9, [(17, body0), (17, body1)], v2=True)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"\x00\x00", "a SlimeVR packet has at least 12"),
        (_header(17, 1) + b"\x01", "rotation data: needs 18 bytes"),
        (_header(17, 1) + bytes([0, 1]) + bytes(17), r"is not a rotation"),
        (_header(100, 1) + b"\x00\x40" + bytes(5), "bundle entry of 64 bytes"),
        (_header(101, 1) + b"\x0d" + bytes([100]) + bytes(12), "a bundle inside a bundle"),
        (_header(4, 1) + struct.pack(">3f", float("nan"), 0, 0), "not finite"),
        (bytes(1500), "more than a SlimeVR datagram"),
    ],
)
def test_malformed_slimevr(data: bytes, message: str) -> None:
    with pytest.raises(SlimeVRError, match=message):
        parse(data)


@given(st.binary(max_size=200))
def test_fuzz_parse_raises_only_its_error(data: bytes) -> None:
    for d in (data, _header(100, 1) + data, _header(101, 1) + data, _header(23, 1) + data):
        with contextlib.suppress(SlimeVRError):
            parse(d)


def test_tracker_over_udp() -> None:
    rx_t = UdpTransport.bind("127.0.0.1", 0)
    rx = Receiver(rx_t, ReceiverConfig(protocols="slimevr")).start()
    tracker = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tracker.settimeout(2.0)
    addr = ("127.0.0.1", rx_t.port)
    try:
        tracker.sendto(slimevr.build_handshake(0), addr)
        reply, _ = tracker.recvfrom(100)
        assert reply == handshake_reply()
        tracker.sendto(slimevr.build_heartbeat(1), addr)
        for n in range(2, 12):
            tracker.sendto(slimevr.build_rotation_data(n, 0, Q), addr)
        tracker.sendto(slimevr.build_rotation_and_accel(12, 1, Q, np.array([0.0, 0.0, 1.0])), addr)
        got = []
        deadline = time.monotonic() + 3.0
        while len(got) < 11 and time.monotonic() < deadline:
            got += rx.get_batch(100, 0.05)
    finally:
        rx.stop()
        tracker.close()
        rx_t.close()
    by_sensor: dict[int, list] = {}
    for s in got:
        by_sensor.setdefault(s.sensor_id, []).append(s)
    assert sorted(by_sensor) == [1, 2]  # tracker sensors 0 and 1 got suit IDs 1 and 2
    assert [s.seq for s in by_sensor[1]] == list(range(10))
    assert all(s.kind is Kind.ORIENTATION and s.source == "slimevr" for s in got)
    np.testing.assert_allclose(by_sensor[1][0].quat, Q, atol=1e-7)
    np.testing.assert_allclose(by_sensor[2][0].acc, [0, 0, 1.0])


def test_device_packet_numbers_interleave_sensors_without_false_loss() -> None:
    """Packet numbers count the device's packets: two sensors interleaved leave no gaps
    per sensor; an old or repeated number is dropped (as the SlimeVR server does)."""
    from mocapkit.suit.transport import Frame

    t = UdpTransport.bind("127.0.0.1", 0)
    rx = Receiver(t, ReceiverConfig(protocols="slimevr"))
    src = ("10.0.0.7", 6969)
    now = time.perf_counter_ns()
    for n in range(1, 21):
        rx.handle(Frame(slimevr.build_rotation_data(n, n % 2, Q), src, now))
    rx.handle(Frame(slimevr.build_rotation_data(20, 0, Q), src, now))  # repeated
    rx.handle(Frame(slimevr.build_rotation_data(3, 1, Q), src, now))  # replayed
    got = rx.get_batch(100, 0.0)  # all delivered at once: nothing waits for a "gap"
    st_ = rx.stats()
    t.close()
    assert len(got) == 20
    assert {sid: s.lost for sid, s in st_.sensors.items()} == {1: 0, 2: 0}
    assert st_.dropped == {"duplicate": 1, "stale": 1}


def test_a_malformed_packet_number_is_dropped_alone() -> None:
    """A datagram with a garbage packet number must not silence the tracker: before, it
    was taken as the newest and every real packet after it was "stale" until the next
    handshake."""
    from mocapkit.suit.transport import Frame

    t = UdpTransport.bind("127.0.0.1", 0)
    rx = Receiver(t, ReceiverConfig(protocols="slimevr"))
    src = ("10.0.0.7", 6969)
    now = time.perf_counter_ns()
    for n in range(1, 6):
        rx.handle(Frame(slimevr.build_rotation_data(n, 0, Q), src, now))
    rx.handle(Frame(slimevr.build_rotation_data(2**62, 0, Q), src, now))  # garbage number
    for n in range(6, 11):
        rx.handle(Frame(slimevr.build_rotation_data(n, 0, Q), src, now))
    got = rx.get_batch(100, 0.0)
    st_ = rx.stats()
    t.close()
    assert len(got) == 10
    assert st_.dropped == {"bad_sequence": 1}
