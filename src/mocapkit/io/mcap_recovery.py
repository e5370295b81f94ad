"""Reading MCAP recordings that were never finished (a recorder killed by SIGKILL, a power
cut, a full disk): everything up to the last complete record, with a warning.

mocapkit's recorders flush a chunk at least every :data:`FLUSH_S` seconds, so such a
file holds all but the last moments of the session. The ``mcap`` library's indexed
reader needs the summary section written at close; without it this module reads the
file record by record from the start, keeps the channels as they come and stops at the
first record cut short. A corrupt chunk (bad compression) is a
:class:`~mocapkit.errors.FileFormatError` naming the file and the offset.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO, Any

from mocapkit.errors import FileFormatError

#: [s] the recorders close a chunk at least this often (crash safety).
FLUSH_S = 0.5


class RecoveredRecordingWarning(UserWarning):
    """The recording had no summary (it was not closed): read up to its last record."""


def decode_errors() -> tuple[type[BaseException], ...]:
    """The exceptions reading a damaged MCAP file can raise (mcap, zstd, struct...)."""
    import struct

    import zstandard
    from mcap.exceptions import McapError

    # a damaged length or offset field makes the mcap library seek or allocate absurdly:
    # OSError (EINVAL), OverflowError, MemoryError are corruption here, not the machine
    return (
        McapError,
        EOFError,
        ValueError,
        KeyError,
        IndexError,
        struct.error,
        zstandard.ZstdError,
        OSError,
        OverflowError,
        MemoryError,
    )


def summary_or_none(f: IO[bytes]) -> Any:
    """The file's summary, or None when it has none (or it cannot be read)."""
    from mcap.reader import make_reader

    try:
        return make_reader(f).get_summary()
    except decode_errors():
        return None


def iter_messages(
    f: IO[bytes], path: str | Path, topics: Iterable[str] | None = None
) -> Iterator[tuple[Any, Any]]:
    """``(channel, message)`` of every message on ``topics`` (all when None), in file order.

    A finished file is read through its index; an unfinished one record by record up to
    its last complete record, with a :class:`RecoveredRecordingWarning` saying how much
    was recovered and where it stopped."""
    from mcap.reader import make_reader
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader

    wanted = None if topics is None else set(topics)
    errors = decode_errors()
    f.seek(0)
    if summary_or_none(f) is not None:
        f.seek(0)
        try:
            for _schema, channel, message in make_reader(f).iter_messages(topics=wanted):
                yield channel, message
        except errors as exc:
            raise FileFormatError(
                f"{path}: a chunk of this MCAP file is corrupt ({type(exc).__name__}: {exc}); "
                "the file was damaged after it was written"
            ) from exc
        return
    channels: dict[int, Any] = {}
    count = 0
    size = f.seek(0, 2)
    f.seek(0)
    try:
        for record in StreamReader(f, record_size_limit=max(size, 1)).records:
            if isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                known = channels.get(record.channel_id)
                if known is not None and (wanted is None or known.topic in wanted):
                    count += 1
                    yield known, record
    except errors as exc:
        if count == 0:
            raise FileFormatError(
                f"{path}: no complete message in this MCAP file (it has no summary and is cut "
                f"short at byte {f.tell()}: {type(exc).__name__}); nothing can be recovered"
            ) from exc
        warnings.warn(
            f"{path}: the recording was not closed (no summary; the recorder was killed or "
            f"the disk filled): recovered {count} messages up to byte {f.tell()}, where a "
            f"record is cut short ({type(exc).__name__})",
            RecoveredRecordingWarning,
            stacklevel=3,
        )
        return
    warnings.warn(
        f"{path}: the recording was not closed (no summary): read {count} messages record "
        "by record",
        RecoveredRecordingWarning,
        stacklevel=3,
    )
