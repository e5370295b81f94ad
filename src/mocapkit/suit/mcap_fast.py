"""Fast reading of a recording's frames: chunk by chunk, message records scanned by numba.

The generic MCAP reader builds one Python object per message (~250 k messages/s here);
a recording of 15 sensors at 1 kHz holds 15 k messages per second of session. This
reader decompresses each chunk once (zstd/lz4, in C), then a numba kernel walks the
chunk's records (MCAP spec: ``opcode u8, length u64``; a Message is ``channel u16,
sequence u32, log_time u64, publish_time u64, data``) and gathers the ``/suit/packets``
payloads into one buffer with offsets. :func:`read_frames` in ``recording.py`` is the
reference it is tested against.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit

from mocapkit.errors import FileFormatError

_OP_MESSAGE = 0x05
_MSG_HEADER = 2 + 4 + 8 + 8


@njit(cache=True)
def _u64(buf: np.ndarray, p: int) -> np.int64:
    v = np.int64(0)
    for k in range(8):
        v |= np.int64(buf[p + k]) << (8 * k)
    return v


@njit(cache=True)
def _scan_messages(
    buf: np.ndarray, wanted: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]:
    """(data start, data length, log_time, sequence) of wanted messages; ok flag."""
    n = buf.shape[0]
    cap = n // (9 + _MSG_HEADER) + 1
    start = np.empty(cap, dtype=np.int64)
    length = np.empty(cap, dtype=np.int64)
    log_time = np.empty(cap, dtype=np.int64)
    seq = np.empty(cap, dtype=np.int64)
    m = 0
    p = 0
    ok = True
    while p < n:
        if n - p < 9:
            ok = False
            break
        op = buf[p]
        rec_len = _u64(buf, p + 1)
        body = p + 9
        if rec_len < 0 or body + rec_len > n:
            ok = False
            break
        if op == _OP_MESSAGE and rec_len >= _MSG_HEADER:
            ch = np.int64(buf[body]) | (np.int64(buf[body + 1]) << 8)
            if wanted[ch]:
                s = np.int64(0)
                for k in range(4):
                    s |= np.int64(buf[body + 2 + k]) << (8 * k)
                start[m] = body + _MSG_HEADER
                length[m] = rec_len - _MSG_HEADER
                log_time[m] = _u64(buf, body + 6)
                seq[m] = s
                m += 1
        p = body + int(rec_len)
    return start[:m], length[:m], log_time[:m], seq[:m], ok


@njit(cache=True)
def _gather(
    chunks: np.ndarray, start: np.ndarray, length: np.ndarray, out: np.ndarray
) -> np.ndarray:
    offsets = np.empty(start.shape[0] + 1, dtype=np.int64)
    q = 0
    for i in range(start.shape[0]):
        offsets[i] = q
        s = start[i]
        for k in range(length[i]):
            out[q + k] = chunks[s + k]
        q += length[i]
    offsets[start.shape[0]] = q
    return offsets


@dataclass(frozen=True)
class FrameBuffer:
    """All frames of a recording in arrival order: ``data[offsets[i]:offsets[i+1]]`` is
    frame i; ``log_time_ns`` its arrival time (Unix epoch)."""

    data: np.ndarray
    offsets: np.ndarray
    log_time_ns: np.ndarray

    def __len__(self) -> int:
        return int(self.offsets.shape[0] - 1)

    def frame(self, i: int) -> bytes:
        return self.data[self.offsets[i] : self.offsets[i + 1]].tobytes()


def _decompress(compression: str, data: bytes, size: int) -> bytes:
    if compression == "":
        return data
    if compression == "zstd":
        import zstandard

        return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    if compression == "lz4":
        import lz4.frame

        return bytes(lz4.frame.decompress(data))
    raise FileFormatError(f"chunk compression {compression!r} is not supported")


def _chunk_records(record: bytes) -> bytes:
    """The compressed ``records`` field of a Chunk record (MCAP spec, opcode 0x06):
    opcode u8, length u64, start u64, end u64, uncompressed size u64, crc u32,
    compression (u32 n + n bytes), records (u64 n + n bytes)."""
    if len(record) < 9 + 28 + 4 or record[0] != 0x06:
        raise FileFormatError("chunk index points at something that is not a chunk")
    p = 9 + 8 + 8 + 8 + 4
    n = int.from_bytes(record[p : p + 4], "little")
    p += 4 + n
    size = int.from_bytes(record[p : p + 8], "little")
    p += 8
    if p + size > len(record):
        raise FileFormatError("a chunk is cut short")
    return record[p : p + size]


def _scan_chunk(raw: bytes, wanted: np.ndarray, parts: list[Any], path: Path) -> None:
    buf = np.frombuffer(raw, dtype=np.uint8)
    start, length, t, seq, ok = _scan_messages(buf, wanted)
    if not ok:
        raise FileFormatError(f"{path}: a chunk's records are cut short")
    parts.append((buf, start, length, t, seq))


def read_frame_buffer(path: str | Path, topic: str = "/suit/packets") -> FrameBuffer:
    """Every frame on ``topic`` of an MCAP recording, fast (see the module docstring)."""
    from mcap.records import Chunk, Message
    from mcap.stream_reader import StreamReader

    from mocapkit.io.mcap_recovery import decode_errors, iter_messages, summary_or_none

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"recording: no such file {p}")
    wanted = np.zeros(1 << 16, dtype=np.bool_)
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    loose: list[tuple[bytes, int, int]] = []
    try:
        with open(p, "rb") as f:
            summary = summary_or_none(f)
            if summary is None:  # never closed: read record by record (with a warning)
                f.seek(0)
                for _channel, rec in iter_messages(f, p, [topic]):
                    loose.append((rec.data, rec.log_time, rec.sequence))
                return _assemble(parts, loose)
            for cid, ch in summary.channels.items():
                if ch.topic == topic:
                    wanted[cid] = True
            if summary.chunk_indexes:
                # seek straight to each chunk (skips the per-message index records)
                for ci in summary.chunk_indexes:
                    f.seek(ci.chunk_start_offset)
                    raw = _decompress(
                        ci.compression,
                        _chunk_records(f.read(ci.chunk_length)),
                        ci.uncompressed_size,
                    )
                    _scan_chunk(raw, wanted, parts, p)
            else:
                f.seek(0)
                for rec in StreamReader(f, emit_chunks=True).records:
                    if isinstance(rec, Chunk):
                        raw = _decompress(rec.compression, rec.data, rec.uncompressed_size)
                        _scan_chunk(raw, wanted, parts, p)
                    elif isinstance(rec, Message) and wanted[rec.channel_id]:
                        loose.append((rec.data, rec.log_time, rec.sequence))
    except decode_errors() as exc:
        raise FileFormatError(f"{p}: not a readable MCAP recording ({exc})") from exc
    return _assemble(parts, loose)


def _assemble(parts: list[Any], loose: list[tuple[bytes, int, int]]) -> FrameBuffer:
    """One buffer of frames in (log time, sequence) order from scanned chunks and loose
    messages."""
    total = sum(int(length.sum()) for _, _, length, _, _ in parts) + sum(
        len(d) for d, _, _ in loose
    )
    out = np.empty(total, dtype=np.uint8)
    offsets_list, times, seqs = [], [], []
    base = 0
    for buf, start, length, t, seq in parts:
        offs = _gather(buf, start, length, out[base:])
        offsets_list.append(offs[:-1] + base)
        base += int(offs[-1])
        times.append(t)
        seqs.append(seq)
    for data, t_ns, s in loose:
        out[base : base + len(data)] = np.frombuffer(data, dtype=np.uint8)
        offsets_list.append(np.array([base]))
        base += len(data)
        times.append(np.array([t_ns]))
        seqs.append(np.array([s]))
    starts = np.concatenate(offsets_list) if offsets_list else np.zeros(0, dtype=np.int64)
    log_time = np.concatenate(times) if times else np.zeros(0, dtype=np.int64)
    sequence = np.concatenate(seqs) if seqs else np.zeros(0, dtype=np.int64)
    order = np.lexsort((sequence, log_time))
    if np.all(order == np.arange(order.shape[0])):
        return FrameBuffer(out, np.append(starts, base), log_time)
    ends = np.append(starts[1:], base)
    lengths = ends - starts
    starts, lengths = starts[order], lengths[order]
    joined = np.concatenate([out[s : s + n] for s, n in zip(starts, lengths, strict=True)])
    return FrameBuffer(joined, np.concatenate([[0], np.cumsum(lengths)]), log_time[order])
