"""Batch decoding of a byte stream of suit frames (a recording, a serial capture) with numba.

:func:`decode_stream` scans a buffer of concatenated frames, checks each CRC, skips
garbage byte by byte (the serial deframer's rule), and returns one row per *sample*:
a BUNDLE contributes one row per entry, with the bundle's seq and time. It is the fast
twin of :func:`mocapkit.suit.protocol.decode`, which the tests compare it with.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from mocapkit.suit.protocol import (
    ACC_LSB,
    BUNDLE_ENTRY,
    CRC_INIT,
    GYR_LSB,
    HEADER_SIZE,
    MAG_LSB,
    MAX_SENSOR_ID,
    OVERHEAD,
    RAW_FLAG_MAG,
    RAW_PAYLOAD,
    STATUS_PAYLOAD,
    SYNC,
    VERSION,
    Kind,
)


def _crc_table() -> np.ndarray:
    table = np.zeros(256, dtype=np.uint16)
    for b in range(256):
        c = b << 8
        for _ in range(8):
            c = ((c << 1) ^ 0x1021) if c & 0x8000 else (c << 1)
        table[b] = c & 0xFFFF
    return table


_TABLE = _crc_table()
_Q_MAX = (1 << 15) - 1
_Q_RANGE = 1.0 / np.sqrt(2.0)
_K_ORI, _K_RAW, _K_STATUS, _K_BUNDLE = (
    int(Kind.ORIENTATION),
    int(Kind.RAW),
    int(Kind.STATUS),
    int(Kind.BUNDLE),
)


@njit(cache=True)
def _crc(buf: np.ndarray, start: int, stop: int, table: np.ndarray) -> int:
    c = CRC_INIT
    for i in range(start, stop):
        c = ((c << 8) & 0xFFFF) ^ table[((c >> 8) ^ buf[i]) & 0xFF]
    return c


@njit(cache=True)
def _valid_len(buf: np.ndarray, i: int, table: np.ndarray) -> int:
    """Length of a valid version-1 frame at i, or 0."""
    n = buf.shape[0]
    if n - i < OVERHEAD or buf[i] != SYNC:
        return 0
    total = OVERHEAD + buf[i + 3]
    if n - i < total:
        return 0
    crc = buf[i + total - 2] | (np.int64(buf[i + total - 1]) << 8)
    if crc != _crc(buf, i + 1, i + total - 2, table):
        return 0
    if (buf[i + 1] >> 4) != VERSION:
        return 0
    kind = buf[i + 1] & 0x0F
    plen = buf[i + 3]
    sid = buf[i + 2]
    if kind == _K_ORI:
        ok = plen == 6 and 1 <= sid <= MAX_SENSOR_ID
    elif kind == _K_RAW:
        ok = plen == RAW_PAYLOAD and 1 <= sid <= MAX_SENSOR_ID
    elif kind == _K_STATUS:
        ok = plen == STATUS_PAYLOAD and 1 <= sid <= MAX_SENSOR_ID
    elif kind == _K_BUNDLE:
        ok = sid == 0 and plen % BUNDLE_ENTRY == 0
        if ok:
            for e in range(i + HEADER_SIZE, i + HEADER_SIZE + plen, BUNDLE_ENTRY):
                if not 1 <= buf[e] <= MAX_SENSOR_ID:
                    ok = False
    else:
        ok = False
    return total if ok else 0


@njit(cache=True)
def _scan(buf: np.ndarray, table: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, int]:
    n = buf.shape[0]
    offsets = np.empty(n // OVERHEAD + 1, dtype=np.int64)
    rows = np.empty(n // OVERHEAD + 1, dtype=np.int64)
    nf = 0
    nrows = 0
    skipped = 0
    i = 0
    while i < n:
        length = _valid_len(buf, i, table)
        if length == 0:
            skipped += 1
            i += 1
            continue
        offsets[nf] = i
        rows[nf] = nrows
        kind = buf[i + 1] & 0x0F
        nrows += buf[i + 3] // BUNDLE_ENTRY if kind == _K_BUNDLE else 1
        nf += 1
        i += length
    return offsets[:nf], rows[:nf], nrows, skipped


@njit(cache=True)
def _quat(buf: np.ndarray, p: int, out: np.ndarray) -> None:
    v = np.int64(0)
    for k in range(6):
        v |= np.int64(buf[p + k]) << (8 * k)
    big = v & 3
    shift = 2
    s = 0.0
    for j in range(4):
        if j == big:
            continue
        c = (((v >> shift) & _Q_MAX) / _Q_MAX * 2.0 - 1.0) * _Q_RANGE
        out[j] = c
        s += c * c
        shift += 15
    out[big] = np.sqrt(max(0.0, 1.0 - s))
    norm = np.sqrt(out[0] ** 2 + out[1] ** 2 + out[2] ** 2 + out[3] ** 2)
    for j in range(4):
        out[j] /= norm


@njit(cache=True)
def _i16(buf: np.ndarray, p: int) -> np.int64:
    v = np.int64(buf[p]) | (np.int64(buf[p + 1]) << 8)
    return v - 65536 if v >= 32768 else v


@njit(cache=True)
def _fill(
    buf: np.ndarray,
    offsets: np.ndarray,
    rows: np.ndarray,
    header: np.ndarray,
    quat: np.ndarray,
    vec: np.ndarray,
) -> None:
    for f in range(offsets.shape[0]):
        i = offsets[f]
        r = rows[f]
        kind = buf[i + 1] & 0x0F
        seq = np.int64(buf[i + 4]) | (np.int64(buf[i + 5]) << 8)
        t = np.int64(0)
        for k in range(4):
            t |= np.int64(buf[i + 6 + k]) << (8 * k)
        p = i + HEADER_SIZE
        if kind == _K_BUNDLE:
            for e in range(buf[i + 3] // BUNDLE_ENTRY):
                header[r + e, 0] = offsets[f]
                header[r + e, 1] = kind
                header[r + e, 2] = buf[p + e * BUNDLE_ENTRY]
                header[r + e, 3] = seq
                header[r + e, 4] = t
                _quat(buf, p + e * BUNDLE_ENTRY + 1, quat[r + e])
            continue
        header[r, 0] = i
        header[r, 1] = kind
        header[r, 2] = buf[i + 2]
        header[r, 3] = seq
        header[r, 4] = t
        if kind == _K_ORI:
            _quat(buf, p, quat[r])
        elif kind == _K_RAW:
            flags = buf[p]
            for k in range(3):
                vec[r, k] = _i16(buf, p + 1 + 2 * k) * GYR_LSB
                vec[r, 3 + k] = _i16(buf, p + 7 + 2 * k) * ACC_LSB
                if flags & RAW_FLAG_MAG:
                    vec[r, 6 + k] = _i16(buf, p + 13 + 2 * k) * MAG_LSB


@dataclass(frozen=True)
class DecodedStream:
    """Samples decoded from a stream; row i is one sample (N rows).

    Attributes:
        offset: (N,) byte offset of the frame the sample came from.
        kind: (N,) :class:`Kind` code.
        sensor_id, seq, t_us: (N,) header fields (a bundle's entries share seq and t_us).
        quat: (N, 4) [w, x, y, z] for ORIENTATION/BUNDLE rows, NaN otherwise.
        gyr, acc, mag: (N, 3) RAW rows [rad/s, m/s^2, uT], NaN otherwise (mag NaN if absent).
        n_frames: valid frames; skipped_bytes: bytes that were not part of a valid frame.
    """

    offset: np.ndarray
    kind: np.ndarray
    sensor_id: np.ndarray
    seq: np.ndarray
    t_us: np.ndarray
    quat: np.ndarray
    gyr: np.ndarray
    acc: np.ndarray
    mag: np.ndarray
    n_frames: int
    skipped_bytes: int

    def __len__(self) -> int:
        return int(self.kind.shape[0])


def decode_stream(data: bytes | bytearray | memoryview | np.ndarray) -> DecodedStream:
    """Decode every valid frame of a concatenated byte stream (see the module docstring)."""
    buf = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data
    buf = np.ascontiguousarray(buf, dtype=np.uint8)
    offsets, rows, nrows, skipped = _scan(buf, _TABLE)
    header = np.zeros((nrows, 5), dtype=np.int64)
    quat = np.full((nrows, 4), np.nan)
    vec = np.full((nrows, 9), np.nan)
    _fill(buf, offsets, rows, header, quat, vec)
    return DecodedStream(
        offset=header[:, 0],
        kind=header[:, 1],
        sensor_id=header[:, 2],
        seq=header[:, 3],
        t_us=header[:, 4],
        quat=quat,
        gyr=vec[:, 0:3],
        acc=vec[:, 3:6],
        mag=vec[:, 6:9],
        n_frames=int(offsets.shape[0]),
        skipped_bytes=int(skipped),
    )


# -- batch encoding (the nodes pre-encode whole recordings) ----------------------------------


def pack_quat_many(q: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions -> (N, 6) uint8 smallest-three bytes, equal to ``pack_quat``."""
    qa = np.asarray(q, dtype=np.float64)
    qa = qa / np.linalg.norm(qa, axis=1, keepdims=True)
    big = np.argmax(np.abs(qa), axis=1)
    rows = np.arange(len(qa))
    qa = np.where((qa[rows, big] < 0.0)[:, None], -qa, qa)
    value = big.astype(np.uint64)
    shift = np.full(len(qa), 2, dtype=np.uint64)
    for j in range(4):
        c = np.clip(qa[:, j], -_Q_RANGE, _Q_RANGE)
        n = np.round((c / _Q_RANGE + 1.0) * 0.5 * _Q_MAX).astype(np.uint64)
        use = big != j
        value = np.where(use, value | (n << shift), value)
        shift = np.where(use, shift + np.uint64(15), shift)
    out = np.empty((len(qa), 6), dtype=np.uint8)
    for k in range(6):
        out[:, k] = ((value >> np.uint64(8 * k)) & np.uint64(0xFF)).astype(np.uint8)
    return out


def _frames(
    kind: Kind, sensor_id: int, seq0: int, t_us: np.ndarray, payload: np.ndarray
) -> list[bytes]:
    import binascii

    n, plen = payload.shape
    body = np.zeros((n, HEADER_SIZE - 1 + plen), dtype=np.uint8)
    body[:, 0] = (VERSION << 4) | int(kind)
    body[:, 1] = sensor_id
    body[:, 2] = plen
    seq = (seq0 + np.arange(n)) & 0xFFFF
    body[:, 3] = seq & 0xFF
    body[:, 4] = seq >> 8
    t = np.asarray(t_us, dtype=np.int64) & 0xFFFFFFFF
    for k in range(4):
        body[:, 5 + k] = (t >> (8 * k)) & 0xFF
    body[:, HEADER_SIZE - 1 :] = payload
    sync = bytes([SYNC])
    out = []
    for row in body:
        b = row.tobytes()
        crc = binascii.crc_hqx(b, CRC_INIT)
        out.append(sync + b + bytes((crc & 0xFF, crc >> 8)))
    return out


def _counts(v: np.ndarray, lsb: float) -> tuple[np.ndarray, np.ndarray]:
    r = np.rint(np.asarray(v, dtype=np.float64) / lsb)
    sat = np.any(np.abs(r) > 32767, axis=1)
    return np.clip(r, -32767, 32767).astype("<i2"), sat


def encode_raw_many(
    sensor_id: int,
    seq0: int,
    t_us: np.ndarray,
    gyr: np.ndarray,
    acc: np.ndarray,
    mag: np.ndarray | None = None,
) -> list[bytes]:
    """RAW packets for (N, 3) arrays (seq = seq0, seq0+1, ...), equal to ``encode_raw``."""
    g, sg = _counts(gyr, GYR_LSB)
    a, sa = _counts(acc, ACC_LSB)
    n = len(g)
    flags = np.zeros(n, dtype=np.uint8)
    if mag is not None:
        m, sm = _counts(mag, MAG_LSB)
        flags |= RAW_FLAG_MAG
    else:
        m, sm = np.zeros((n, 3), dtype="<i2"), np.zeros(n, dtype=bool)
    flags[sg | sa | sm] |= 0x02
    payload = np.empty((n, RAW_PAYLOAD), dtype=np.uint8)
    payload[:, 0] = flags
    payload[:, 1:] = np.concatenate([g, a, m], axis=1).view(np.uint8)
    return _frames(Kind.RAW, sensor_id, seq0, t_us, payload)


def encode_orientation_many(
    sensor_id: int, seq0: int, t_us: np.ndarray, quat: np.ndarray
) -> list[bytes]:
    """ORIENTATION packets for (N, 4) quaternions, equal to ``encode_orientation``."""
    return _frames(Kind.ORIENTATION, sensor_id, seq0, t_us, pack_quat_many(quat))
