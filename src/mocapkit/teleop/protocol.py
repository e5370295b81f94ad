"""Robot-link protocol v1: end-effector or joint commands and reports over UDP.

Little-endian, one message per datagram (see docs/design/teleop.md, "Robot link")::

    0-3   magic b"MKRL"          4  version (1)         5  kind (1 COMMAND, 2 HOLD, 3 REPORT,
                                                                  4 JOINTS)
    6-7   flags u16              8-11 seq u32           12-19 t_send_ns u64 (CLOCK_MONOTONIC)
    COMMAND: 20-43 position xyz f64 [m], 44-75 quaternion wxyz f64 (chest frame)
    HOLD:    header only
    REPORT:  20-75 actual pose, 76-79 last accepted command seq u32, 80 gate u8,
             81 reason u8, 82 n u8, then n f64 joint angles [rad]
    JOINTS:  20-75 base pose (position, quaternion wxyz; a humanoid's floating base),
             76 n u8, then n f64 joint positions [rad] (the robot's one-DOF joints in
             model order); a humanoid's REPORT carries its base pose and its joints

Decoding raises :class:`LinkProtocolError` (a ``DataError``) with the reason; the server
counts and drops such datagrams.

Signed datagrams (a link that leaves the machine: the server refuses a non-loopback
address without a key): flag bit 0 set and the first 16 bytes of the HMAC-SHA256 of the
message under the shared key appended (:func:`sign`, :func:`open_signed`); the receiver
also refuses a sequence number that is not newer than the last one it accepted from its
peer (a replayed datagram).
"""

from __future__ import annotations

import hashlib
import hmac
import struct
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import DataError

MAGIC = b"MKRL"
VERSION = 1
_HEADER = struct.Struct("<4sBBHIQ")  # 20 bytes
_POSE = struct.Struct("<7d")  # 56 bytes
_REPORT_TAIL = struct.Struct("<IBBB")  # 7 bytes
MAX_JOINTS = 64
_COUNT = struct.Struct("<B")
FLAG_SIGNED = 0x1
MAC_LEN = 16


class Kind(IntEnum):
    COMMAND = 1
    HOLD = 2
    REPORT = 3
    JOINTS = 4


class Gate(IntEnum):
    """Robot-server safety gate (Robonaut: commands only once synchronised)."""

    UNSYNCED = 0
    SYNCED = 1
    HOLDING = 2


class Reason(IntEnum):
    """Why the gate is in its state (sent in every report)."""

    OK = 0
    STARTUP = 1  # no command accepted yet
    TOO_FAR = 2  # command beyond the gate thresholds of the actual pose
    JUMP = 3  # command jumped beyond the thresholds from the previous one
    TIMEOUT = 4  # no command for command_timeout_s
    HOLD_REQUESTED = 5  # a HOLD message
    UNREACHABLE = 6  # IK cannot reach the target (joint limits / workspace)
    BAD_COMMAND = 7  # non-finite or non-unit quaternion


class LinkProtocolError(DataError):
    """A datagram that is not a valid robot-link message."""


@dataclass(frozen=True)
class Command:
    seq: int
    t_send_ns: int
    pos: FloatArray  # (3,) [m]
    quat: FloatArray  # (4,) [w, x, y, z]


@dataclass(frozen=True)
class JointsCommand:
    seq: int
    t_send_ns: int
    base_pos: FloatArray  # (3,) [m]
    base_quat: FloatArray  # (4,) [w, x, y, z]
    q: FloatArray  # (n,) [rad]


@dataclass(frozen=True)
class Hold:
    seq: int
    t_send_ns: int


@dataclass(frozen=True)
class Report:
    seq: int
    t_send_ns: int
    pos: FloatArray
    quat: FloatArray
    last_command_seq: int
    gate: Gate
    reason: Reason
    q: FloatArray  # (n,) [rad]


Message = Command | Hold | Report | JointsCommand


def _header(kind: Kind, seq: int, t_ns: int) -> bytes:
    return _HEADER.pack(MAGIC, VERSION, int(kind), 0, seq & 0xFFFFFFFF, t_ns & (2**64 - 1))


def encode_command(seq: int, t_ns: int, pos: FloatArray, quat: FloatArray) -> bytes:
    return _header(Kind.COMMAND, seq, t_ns) + _POSE.pack(*pos, *quat)


def encode_joints(
    seq: int, t_ns: int, base_pos: FloatArray, base_quat: FloatArray, q: FloatArray
) -> bytes:
    n = len(q)
    if n > MAX_JOINTS:
        raise LinkProtocolError(f"JOINTS: {n} joints, at most {MAX_JOINTS}")
    return (
        _header(Kind.JOINTS, seq, t_ns)
        + _POSE.pack(*base_pos, *base_quat)
        + _COUNT.pack(n)
        + struct.pack(f"<{n}d", *q)
    )


def encode_hold(seq: int, t_ns: int) -> bytes:
    return _header(Kind.HOLD, seq, t_ns)


def encode_report(
    seq: int,
    t_ns: int,
    pos: FloatArray,
    quat: FloatArray,
    last_command_seq: int,
    gate: Gate,
    reason: Reason,
    q: FloatArray,
) -> bytes:
    n = len(q)
    return (
        _header(Kind.REPORT, seq, t_ns)
        + _POSE.pack(*pos, *quat)
        + _REPORT_TAIL.pack(last_command_seq & 0xFFFFFFFF, int(gate), int(reason), n)
        + struct.pack(f"<{n}d", *q)
    )


def _mac(key: bytes, data: bytes) -> bytes:
    return hmac.new(key, data, hashlib.sha256).digest()[:MAC_LEN]


def sign(data: bytes, key: bytes) -> bytes:
    """The message with the signed flag set and its MAC appended."""
    flags = struct.unpack_from("<H", data, 6)[0] | FLAG_SIGNED
    body = data[:6] + struct.pack("<H", flags) + data[8:]
    return body + _mac(key, body)


def open_signed(data: bytes, key: bytes) -> bytes:
    """The message of a signed datagram (MAC checked and removed); LinkProtocolError for
    an unsigned or forged one."""
    if len(data) < _HEADER.size + MAC_LEN:
        raise LinkProtocolError(f"datagram of {len(data)} bytes is too short to be signed")
    flags = struct.unpack_from("<H", data, 6)[0]
    if not flags & FLAG_SIGNED:
        raise LinkProtocolError("unsigned datagram on a link that requires a shared key")
    body, mac = data[:-MAC_LEN], data[-MAC_LEN:]
    if not hmac.compare_digest(mac, _mac(key, body)):
        raise LinkProtocolError("bad signature (HMAC-SHA256 under the shared key)")
    return body


def decode(data: bytes) -> Message:
    """Parse one datagram; raises LinkProtocolError naming what is wrong."""
    if len(data) < _HEADER.size:
        raise LinkProtocolError(f"datagram of {len(data)} bytes is shorter than the header (20)")
    magic, version, kind, _flags, seq, t_ns = _HEADER.unpack_from(data)
    if magic != MAGIC:
        raise LinkProtocolError(f"bad magic {magic!r}, expected {MAGIC!r}")
    if version != VERSION:
        raise LinkProtocolError(f"protocol version {version}, this end speaks {VERSION}")
    body = data[_HEADER.size :]
    if kind == Kind.HOLD:
        return Hold(seq, t_ns)
    if kind not in (Kind.COMMAND, Kind.REPORT, Kind.JOINTS):
        raise LinkProtocolError(f"unknown message kind {kind}")
    if len(body) < _POSE.size:
        raise LinkProtocolError(f"{Kind(kind).name} body of {len(body)} bytes, expected >= 56")
    vals = np.array(_POSE.unpack_from(body))
    pos, quat = vals[:3], vals[3:]
    if kind == Kind.JOINTS:
        tail = body[_POSE.size :]
        if len(tail) < _COUNT.size:
            raise LinkProtocolError("JOINTS truncated before its joint count")
        (n,) = _COUNT.unpack_from(tail)
        joints = tail[_COUNT.size :]
        if n > MAX_JOINTS or len(joints) != 8 * n:
            raise LinkProtocolError(f"JOINTS announces {n} joints but carries {len(joints)} bytes")
        return JointsCommand(seq, t_ns, pos, quat, np.array(struct.unpack(f"<{n}d", joints)))
    if kind == Kind.COMMAND:
        if len(body) != _POSE.size:
            raise LinkProtocolError(f"COMMAND body of {len(body)} bytes, expected 56")
        return Command(seq, t_ns, pos, quat)
    tail = body[_POSE.size :]
    if len(tail) < _REPORT_TAIL.size:
        raise LinkProtocolError("REPORT truncated before its joint count")
    last, gate, reason, n = _REPORT_TAIL.unpack_from(tail)
    joints = tail[_REPORT_TAIL.size :]
    if n > MAX_JOINTS or len(joints) != 8 * n:
        raise LinkProtocolError(f"REPORT announces {n} joints but carries {len(joints)} bytes")
    try:
        g, r = Gate(gate), Reason(reason)
    except ValueError as exc:
        raise LinkProtocolError(f"REPORT: {exc}") from exc
    q = np.array(struct.unpack(f"<{n}d", joints))
    return Report(seq, t_ns, pos, quat, last, g, r, q)
