"""Errors of the suit wire protocols: every parse failure is a :class:`ProtocolError`.

Each subclass carries a short ``reason`` used as the receiver's drop counter name,
so a log line, a counter and a test all speak of the same thing.
"""

from __future__ import annotations

from mocapkit.errors import MocapkitError


class ProtocolError(MocapkitError, ValueError):
    """A datagram or frame is not a valid packet. ``reason`` names the counter."""

    reason = "malformed"


class TruncatedPacketError(ProtocolError):
    """Fewer bytes than the header or the declared payload length needs."""

    reason = "truncated"


class OversizedPacketError(ProtocolError):
    """More bytes than the largest packet, or than the declared length."""

    reason = "oversized"


class BadSyncError(ProtocolError):
    """The first byte is not the sync byte (not one of our frames)."""

    reason = "bad_sync"


class CrcMismatchError(ProtocolError):
    """The CRC-16 does not match: the bytes were corrupted on the way."""

    reason = "bad_crc"


class UnsupportedVersionError(ProtocolError):
    """A protocol version this receiver does not speak."""

    reason = "bad_version"


class UnknownKindError(ProtocolError):
    """A payload kind this version does not define, or a length that does not fit it."""

    reason = "bad_kind"


class UnknownSensorError(ProtocolError):
    """A sensor ID outside 1..15 (or outside the configured allow-list)."""

    reason = "unknown_sensor"
