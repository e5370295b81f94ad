"""SlimeVR's tracker UDP protocol, as a second ingest format (our own parser).

Written from the public layout of the SlimeVR server and tracker firmware (no code
copied). All fields are big-endian. A datagram is ``u32 packet type, u64 packet
number`` followed by the packet's data; the server answers a handshake with a fixed
64-byte datagram (type byte 3, ``"Hey OVR =D 5"``, zero padding). Packets parsed here:

====  =====================  ==========================================================
type  name                   data after the 12-byte header
====  =====================  ==========================================================
0     heartbeat              (none)
1     rotation (legacy)      f32 x, y, z, w  (sensor 0)
3     handshake              u32 board, u32 imu, u32 mcu, 3 x i32 imu info,
                             i32 firmware build, u8 n + n bytes firmware name, 6 bytes MAC
                             (every field optional from the end, as the server reads it)
4     acceleration           f32 x, y, z [m/s^2], optional u8 sensor
12    battery                f32 voltage [V], optional f32 level [0..1]
15    sensor info            u8 sensor, u8 status, ...
17    rotation data          u8 sensor, u8 data type (1 normal), f32 x, y, z, w, u8 accuracy
23    rotation + accel       u8 sensor, i16 x, y, z, w (Q15), i16 ax, ay, az (1/128 m/s^2)
100   bundle                 repeated: u16 n, then n bytes: u32 type + data
101   bundle v2              repeated: u8 n, then n bytes: u8 type + data
====  =====================  ==========================================================

Quaternions arrive as x, y, z, w in the tracker's own fusion frame (z up); we return
them as [w, x, y, z] unchanged (the server's y-up axis offset is not applied).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np

from mocapkit.suit.errors import ProtocolError

HEARTBEAT = 0
ROTATION = 1
HANDSHAKE = 3
ACCEL = 4
BATTERY = 12
SENSOR_INFO = 15
ROTATION_DATA = 17
ROTATION_AND_ACCEL = 23
BUNDLE = 100
BUNDLE_V2 = 101
DATA_TYPE_NORMAL = 1
HEADER = struct.Struct(">IQ")
MAX_DATAGRAM = 1472
_F4 = struct.Struct(">4f")
_F3 = struct.Struct(">3f")
_ROT_ACC = struct.Struct(">B7h")
_HANDSHAKE_FIXED = struct.Struct(">3I3ii")


class SlimeVRError(ProtocolError):
    """A datagram that does not parse as a SlimeVR packet."""

    reason = "slimevr_malformed"


@dataclass(slots=True)
class SlimeMessage:
    """One parsed SlimeVR packet (a bundle gives several, sharing ``packet_number``)."""

    type: int
    packet_number: int
    sensor_id: int = 0
    quat: np.ndarray | None = None  # [w, x, y, z]
    acc: np.ndarray | None = None  # m/s^2, tracker frame
    battery_v: float | None = None
    battery_level: float | None = None
    status: int | None = None
    board: int | None = None
    imu: int | None = None
    mcu: int | None = None
    firmware_build: int | None = None
    firmware: str = ""
    mac: str | None = None


def handshake_reply() -> bytes:
    """The server's answer to a handshake: 64 bytes, type byte 3 then ``Hey OVR =D 5``."""
    text = b"Hey OVR =D 5"
    return bytes([HANDSHAKE]) + text + bytes(64 - 1 - len(text))


def _quat_xyzw(x: float, y: float, z: float, w: float) -> np.ndarray:
    q = np.array([w, x, y, z], dtype=np.float64)
    n = math.sqrt(float(np.dot(q, q)))
    if not math.isfinite(n) or n < 1e-6:
        raise SlimeVRError(f"quaternion ({x}, {y}, {z}, {w}) is not a rotation")
    return q / n


def _need(data: bytes | memoryview, p: int, size: int, what: str) -> None:
    if len(data) - p < size:
        raise SlimeVRError(f"{what}: needs {size} bytes at offset {p}, has {len(data) - p}")


def _parse_body(ptype: int, num: int, data: bytes | memoryview, p: int) -> SlimeMessage:
    m = SlimeMessage(ptype, num)
    end = len(data)
    if ptype == ROTATION:
        _need(data, p, 16, "rotation")
        m.quat = _quat_xyzw(*_F4.unpack_from(data, p))
    elif ptype == ROTATION_DATA:
        _need(data, p, 18, "rotation data")
        m.sensor_id = data[p]
        dtype = data[p + 1]
        if dtype == DATA_TYPE_NORMAL:
            m.quat = _quat_xyzw(*_F4.unpack_from(data, p + 2))
    elif ptype == ROTATION_AND_ACCEL:
        _need(data, p, _ROT_ACC.size, "rotation+acceleration")
        sid, x, y, z, w, ax, ay, az = _ROT_ACC.unpack_from(data, p)
        m.sensor_id = sid
        m.quat = _quat_xyzw(x / 32768.0, y / 32768.0, z / 32768.0, w / 32768.0)
        m.acc = np.array([ax, ay, az], dtype=np.float64) / 128.0
    elif ptype == ACCEL:
        _need(data, p, 12, "acceleration")
        acc = np.array(_F3.unpack_from(data, p), dtype=np.float64)
        if not np.all(np.isfinite(acc)):
            raise SlimeVRError(f"acceleration {acc} is not finite")
        m.acc = acc
        m.sensor_id = data[p + 12] if end - p > 12 else 0
    elif ptype == BATTERY:
        _need(data, p, 4, "battery")
        (v,) = struct.unpack_from(">f", data, p)
        if end - p >= 8:
            (level,) = struct.unpack_from(">f", data, p + 4)
            m.battery_v, m.battery_level = v, level
        else:
            m.battery_level = v
    elif ptype == SENSOR_INFO:
        _need(data, p, 2, "sensor info")
        m.sensor_id, m.status = data[p], data[p + 1]
    elif ptype == HANDSHAKE:
        _parse_handshake(m, data, p)
    return m


def _parse_handshake(m: SlimeMessage, data: bytes | memoryview, p: int) -> None:
    end = len(data)
    if end - p >= _HANDSHAKE_FIXED.size:
        board, imu, mcu, _, _, _, build = _HANDSHAKE_FIXED.unpack_from(data, p)
        m.board, m.imu, m.mcu, m.firmware_build = board, imu, mcu, build
        p += _HANDSHAKE_FIXED.size
    else:
        return
    if p < end:
        n = data[p]
        p += 1
        raw = bytes(data[p : min(end, p + n)])
        m.firmware = raw.split(b"\0")[0].decode("ascii", errors="replace")
        p += n
    if end - p >= 6:
        mac = bytes(data[p : p + 6])
        if any(mac):
            m.mac = ":".join(f"{b:02X}" for b in mac)


def parse(data: bytes | memoryview) -> list[SlimeMessage]:
    """Parse one datagram; raises only :class:`SlimeVRError` (a :class:`ProtocolError`)."""
    n = len(data)
    if n < HEADER.size:
        raise SlimeVRError(f"{n} bytes, a SlimeVR packet has at least {HEADER.size}")
    if n > MAX_DATAGRAM:
        raise SlimeVRError(f"{n} bytes, more than a SlimeVR datagram ({MAX_DATAGRAM})")
    ptype, num = HEADER.unpack_from(data, 0)
    p = HEADER.size
    if ptype not in (BUNDLE, BUNDLE_V2):
        return [_parse_body(ptype, num, data, p)]
    out = []
    wide = ptype == BUNDLE
    while p < n:
        size_len = 2 if wide else 1
        _need(data, p, size_len, "bundle entry length")
        length = struct.unpack_from(">H", data, p)[0] if wide else data[p]
        p += size_len
        if length == 0:
            continue
        if n - p < length:
            raise SlimeVRError(f"bundle entry of {length} bytes at offset {p}, only {n - p} left")
        inner = memoryview(bytes(data[p : p + length]))
        type_len = 4 if wide else 1
        _need(inner, 0, type_len, "bundle entry type")
        itype = struct.unpack_from(">I", inner, 0)[0] if wide else inner[0]
        if itype in (BUNDLE, BUNDLE_V2):
            raise SlimeVRError("a bundle inside a bundle")
        out.append(_parse_body(itype, num, inner, type_len))
        p += length
    return out


# -- builders (a tracker's side: the simulator and the tests) --------------------------------


def build_heartbeat(num: int) -> bytes:
    return HEADER.pack(HEARTBEAT, num)


def build_handshake(
    num: int,
    mac: bytes = b"\x02\x00\x00\x00\x00\x01",
    firmware: str = "mocapkit-sim",
    board: int = 0,
    imu: int = 0,
    mcu: int = 0,
    build: int = 19,
) -> bytes:
    fw = firmware.encode("ascii")
    return (
        HEADER.pack(HANDSHAKE, num)
        + _HANDSHAKE_FIXED.pack(board, imu, mcu, 0, 0, 0, build)
        + bytes([len(fw)])
        + fw
        + mac
    )


def _rotation_data_body(sensor_id: int, quat_wxyz: np.ndarray) -> bytes:
    w, x, y, z = (float(c) for c in quat_wxyz)
    return bytes([sensor_id, DATA_TYPE_NORMAL]) + _F4.pack(x, y, z, w) + b"\x00"


def _rot_acc_body(sensor_id: int, quat_wxyz: np.ndarray, acc: np.ndarray) -> bytes:
    w, x, y, z = (max(-32768, min(32767, round(float(c) * 32768))) for c in quat_wxyz)
    a = [max(-32768, min(32767, round(float(c) * 128))) for c in acc]
    return _ROT_ACC.pack(sensor_id, x, y, z, w, *a)


def build_rotation_data(num: int, sensor_id: int, quat_wxyz: np.ndarray) -> bytes:
    return HEADER.pack(ROTATION_DATA, num) + _rotation_data_body(sensor_id, quat_wxyz)


def build_rotation_and_accel(
    num: int, sensor_id: int, quat_wxyz: np.ndarray, acc: np.ndarray
) -> bytes:
    return HEADER.pack(ROTATION_AND_ACCEL, num) + _rot_acc_body(sensor_id, quat_wxyz, acc)


def build_bundle(num: int, entries: list[tuple[int, bytes]], v2: bool = False) -> bytes:
    """A bundle of ``(type, body)`` entries (body = the data after the header)."""
    out = bytearray(HEADER.pack(BUNDLE_V2 if v2 else BUNDLE, num))
    for ptype, body in entries:
        inner = (bytes([ptype]) if v2 else struct.pack(">I", ptype)) + body
        out += bytes([len(inner)]) if v2 else struct.pack(">H", len(inner))
        out += inner
    return bytes(out)


def rotation_body(sensor_id: int, quat_wxyz: np.ndarray) -> bytes:
    """Body of a rotation-data (17) packet, for :func:`build_bundle`."""
    return _rotation_data_body(sensor_id, quat_wxyz)
