"""Wire protocol v1: layout byte by byte, round trips, every validation path, fuzzing."""

from __future__ import annotations

import contextlib
import struct

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mocapkit.suit.errors import (
    BadSyncError,
    CrcMismatchError,
    OversizedPacketError,
    ProtocolError,
    TruncatedPacketError,
    UnknownKindError,
    UnknownSensorError,
    UnsupportedVersionError,
)
from mocapkit.suit.protocol import (
    ACC_LSB,
    GYR_LSB,
    MAG_LSB,
    Kind,
    crc16,
    decode,
    encode_bundle,
    encode_orientation,
    encode_raw,
    encode_status,
    frame,
    pack_quat,
    unpack_quat,
)
from tests.strategies import same_rotation, unit_quats

# Smallest-three with 15 bits per component over [-1/sqrt2, 1/sqrt2]: each sent component
# is off by at most half a step h = 2.16e-5; the rebuilt largest one (>= 1/2) by at most
# 3h; so |dq| <= sqrt(12) h and the angle (~2|dq|) by at most 7h = 1.5e-4 rad.
QUAT_ANGLE_TOL = 1.6e-4


def _angle(q1: np.ndarray, q2: np.ndarray) -> float:
    return float(2 * np.arccos(min(1.0, abs(float(np.dot(q1, q2))))))


def test_crc16_check_value() -> None:
    # The catalogued check value of CRC-16/CCITT-FALSE for the ASCII digits 1..9.
    assert crc16(b"123456789") == 0x29B1


def test_orientation_layout_byte_by_byte() -> None:
    pkt = encode_orientation(3, 0x0102, 0x0A0B0C0D, [1.0, 0.0, 0.0, 0.0])
    # identity: largest index 0 (w); x, y, z = 0 -> mid-scale 16384 (round(0.5 * 32767))
    value = 0 | (16384 << 2) | (16384 << 17) | (16384 << 32)
    body = bytes([0x11, 3, 6, 0x02, 0x01, 0x0D, 0x0C, 0x0B, 0x0A]) + value.to_bytes(6, "little")
    expected = b"\xa5" + body + struct.pack("<H", crc16(body))
    assert pkt == expected
    assert len(pkt) == 18


@given(unit_quats())
def test_orientation_round_trip(q: np.ndarray) -> None:
    p = decode(encode_orientation(7, 42, 123, q))
    assert (p.kind, p.sensor_id, p.seq, p.t_us) == (Kind.ORIENTATION, 7, 42, 123)
    assert p.quat is not None
    assert _angle(p.quat, q) < QUAT_ANGLE_TOL


@given(unit_quats())
def test_pack_unpack_quat(q: np.ndarray) -> None:
    out = unpack_quat(pack_quat(q))
    assert abs(np.linalg.norm(out) - 1.0) < 1e-12  # renormalised exactly
    assert same_rotation(out, q, 1e-8)  # 1 - |dot| ~ angle^2 / 8 < 2e-9


def test_pack_quat_rejects_non_finite() -> None:
    with pytest.raises(ValueError, match="finite non-zero"):
        pack_quat([np.nan, 0, 0, 0])
    with pytest.raises(ValueError, match="finite non-zero"):
        pack_quat([0, 0, 0, 0])


def test_raw_round_trip_within_half_lsb() -> None:
    rng = np.random.default_rng(1)
    gyr, acc, mag = rng.normal(0, 3, 3), rng.normal(0, 20, 3), rng.normal(0, 50, 3)
    p = decode(encode_raw(15, 65535, 2**32 - 1, gyr, acc, mag))
    assert (p.kind, p.sensor_id, p.seq, p.t_us, p.saturated) == (
        Kind.RAW,
        15,
        65535,
        2**32 - 1,
        False,
    )
    assert p.gyr is not None
    assert p.acc is not None
    assert p.mag is not None
    # quantisation: at most half a least-significant bit per axis (plus float rounding)
    np.testing.assert_array_less(np.abs(p.gyr - gyr), GYR_LSB / 2 + 1e-12)
    np.testing.assert_array_less(np.abs(p.acc - acc), ACC_LSB / 2 + 1e-12)
    np.testing.assert_array_less(np.abs(p.mag - mag), MAG_LSB / 2 + 1e-12)


def test_raw_saturation_and_missing_mag() -> None:
    p = decode(encode_raw(1, 0, 0, [100.0, 0, 0], [0, 0, 9.81]))
    assert p.saturated
    assert p.gyr is not None
    assert p.gyr[0] == pytest.approx(32767 * GYR_LSB)
    assert p.mag is None


def test_raw_rejects_non_finite() -> None:
    with pytest.raises(ValueError, match="non-finite"):
        encode_raw(1, 0, 0, [np.nan, 0, 0], [0, 0, 0])


def test_status_and_bundle_round_trip() -> None:
    p = decode(encode_status(4, 9, 1000, 3712, 36.51, flags=5, rssi_dbm=-70))
    assert (p.battery_mv, p.temperature_c, p.status_flags, p.rssi_dbm) == (3712, 36.51, 5, -70)
    rng = np.random.default_rng(2)
    qs = [q / np.linalg.norm(q) for q in rng.normal(size=(15, 4))]
    pkt = encode_bundle(77, 5, list(zip(range(1, 16), qs, strict=True)))
    assert len(pkt) == 12 + 7 * 15
    b = decode(pkt)
    assert b.kind is Kind.BUNDLE
    assert b.sensor_id == 0
    assert b.seq == 77
    assert [sid for sid, _ in b.entries] == list(range(1, 16))
    for (_, q), ref in zip(b.entries, qs, strict=True):
        assert _angle(q, ref) < QUAT_ANGLE_TOL


def _good() -> bytes:
    return encode_raw(2, 1, 1, [0, 0, 1], [0, 0, 9.81])


def _with_crc(pkt: bytearray) -> bytes:
    pkt[-2:] = struct.pack("<H", crc16(bytes(pkt[1:-2])))
    return bytes(pkt)


@pytest.mark.parametrize(
    ("mutate", "error", "message"),
    [
        (lambda p: p[:5], TruncatedPacketError, "at least 12"),
        (lambda p: p[:-1], TruncatedPacketError, "header declares 31"),
        (lambda p: p + b"\x00", OversizedPacketError, "header declares 31"),
        (lambda p: p + bytes(300), OversizedPacketError, "at most 267"),
        (lambda p: b"\x5a" + p[1:], BadSyncError, "first byte 0x5A"),
        (lambda p: p[:12] + bytes([p[12] ^ 0x40]) + p[13:], CrcMismatchError, "CRC 0x"),
    ],
)
def test_framing_errors(mutate, error, message) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(error, match=message):
        decode(mutate(_good()))


def test_unsupported_version() -> None:
    pkt = bytearray(_good())
    pkt[1] = (2 << 4) | int(Kind.RAW)
    with pytest.raises(UnsupportedVersionError, match="version 2, this receiver speaks 1"):
        decode(_with_crc(pkt))


def test_unknown_kind_and_wrong_length() -> None:
    pkt = bytearray(_good())
    pkt[1] = (1 << 4) | 9
    with pytest.raises(UnknownKindError, match="kind 9 is not defined"):
        decode(_with_crc(pkt))
    short = frame(Kind.ORIENTATION, 1, 0, 0, bytes(5))
    with pytest.raises(UnknownKindError, match="ORIENTATION payload of 5 bytes, expected 6"):
        decode(short)
    bad_bundle = frame(Kind.BUNDLE, 0, 0, 0, bytes(8))
    with pytest.raises(UnknownKindError, match="multiple of 7"):
        decode(bad_bundle)


@pytest.mark.parametrize("sensor_id", [0, 16, 255])
def test_unknown_sensor_id(sensor_id: int) -> None:
    pkt = frame(Kind.RAW, sensor_id, 0, 0, bytes(19))
    with pytest.raises(UnknownSensorError, match=f"sensor_id {sensor_id} outside 1..15"):
        decode(pkt)


def test_bundle_entry_with_unknown_sensor() -> None:
    payload = bytes([3]) + pack_quat([1, 0, 0, 0]) + bytes([20]) + pack_quat([1, 0, 0, 0])
    with pytest.raises(UnknownSensorError, match="bundle entry 1: sensor_id 20"):
        decode(frame(Kind.BUNDLE, 0, 0, 0, payload))


@given(st.binary(max_size=300))
def test_fuzz_random_bytes_raise_only_protocol_errors(data: bytes) -> None:
    with contextlib.suppress(ProtocolError):
        decode(data)


@given(st.binary(min_size=1, max_size=40), st.integers(0, 40), st.sampled_from(list(Kind)))
def test_fuzz_valid_header_random_payload(payload: bytes, cut: int, kind: Kind) -> None:
    pkt = frame(kind, 0 if kind is Kind.BUNDLE else 5, 1, 2, payload)
    for data in (pkt, pkt[:cut]):
        try:
            p = decode(data)
        except ProtocolError:
            continue
        assert p.kind is kind


@given(st.integers(0, 30), st.integers(1, 255))
def test_fuzz_single_byte_corruption_never_passes_silently(pos: int, xor: int) -> None:
    pkt = bytearray(_good())
    pkt[pos] ^= xor
    # CRC-16 detects every single-byte error; a corrupted sync byte is a sync error
    with pytest.raises(ProtocolError):
        decode(bytes(pkt))
