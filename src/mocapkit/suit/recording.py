"""Recording to MCAP and bit-for-bit replay.

An MCAP file written by :class:`McapRecorder` has two topics:

- ``/suit/packets``: every frame exactly as received (malformed ones too), message
  encoding ``mocapkit.suit.frame`` (no schema: opaque bytes), one channel per source
  (its ``source`` in the channel metadata); ``log_time`` = arrival [ns, Unix epoch],
  ``sequence`` = arrival order.
- ``/suit/samples``: the decoded samples as JSON with a ``jsonschema`` schema, which
  Foxglove Studio opens and plots.

:func:`read_frames` returns the frames in arrival order; :func:`replay` sends them again
with the recorded spacing scaled by ``1 / speed``; :class:`ReplayTransport` feeds them to
a receiver. Replayed bytes are identical to the recorded ones (tested).
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mocapkit.errors import FileFormatError
from mocapkit.suit.batch import DecodedStream, decode_stream
from mocapkit.suit.protocol import Kind
from mocapkit.suit.samples import SuitSample
from mocapkit.suit.transport import Frame, Transport

PACKETS_TOPIC = "/suit/packets"
SAMPLES_TOPIC = "/suit/samples"
FRAME_ENCODING = "mocapkit.suit.frame"

_VEC = {"type": ["array", "null"], "items": {"type": "number"}, "minItems": 3, "maxItems": 3}
SAMPLE_SCHEMA = {
    "title": "mocapkit.suit.Sample",
    "type": "object",
    "properties": {
        "sensor_id": {"type": "integer"},
        "seq": {"type": "integer"},
        "t_sensor_s": {"type": ["number", "null"]},
        "t_arrival_ns": {"type": "integer"},
        "kind": {"type": "string"},
        "source": {"type": "string"},
        "quat": {
            "type": ["object", "null"],
            "properties": {k: {"type": "number"} for k in ("w", "x", "y", "z")},
        },
        "gyr": _VEC,
        "acc": _VEC,
        "mag": _VEC,
    },
}


def _vec(v: Any) -> list[float] | None:
    return None if v is None else [float(x) for x in v]


class McapRecorder:
    """Writes frames and samples to an MCAP file; call :meth:`close` to finish it.

    Arrival times (``perf_counter_ns``) are mapped to the Unix epoch once, at creation.
    Thread-safe (the receiver thread writes, another thread may close).
    """

    def __init__(self, path: str | Path) -> None:
        from mcap.writer import Writer

        self.path = Path(path)
        self._file = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._file)
        self._writer.start(profile="", library="mocapkit")
        self._lock = threading.Lock()
        self._epoch_offset_ns = time.time_ns() - time.perf_counter_ns()
        schema = self._writer.register_schema(
            "mocapkit.suit.Sample", "jsonschema", json.dumps(SAMPLE_SCHEMA).encode()
        )
        self._samples_ch = self._writer.register_channel(SAMPLES_TOPIC, "json", schema)
        self._frame_ch: dict[str, int] = {}
        self._seq = 0
        self.frames = 0
        self.samples = 0
        self._closed = False

    def _channel(self, source: Any) -> int:
        key = str(source)
        ch = self._frame_ch.get(key)
        if ch is None:
            ch = self._frame_ch[key] = self._writer.register_channel(
                PACKETS_TOPIC, FRAME_ENCODING, 0, {"source": key}
            )
        return ch

    def write_frame(self, data: bytes, t_arrival_ns: int, source: Any = "") -> None:
        t = t_arrival_ns + self._epoch_offset_ns
        with self._lock:
            if self._closed:
                return
            self._writer.add_message(self._channel(source), t, bytes(data), t, self._seq)
            self._seq += 1
            self.frames += 1

    def write_sample(self, sample: SuitSample) -> None:
        q = sample.quat
        msg = {
            "sensor_id": sample.sensor_id,
            "seq": sample.seq,
            "t_sensor_s": sample.t_sensor_s if sample.t_sensor_s == sample.t_sensor_s else None,
            "t_arrival_ns": sample.t_arrival_ns,
            "kind": Kind(sample.kind).name,
            "source": sample.source,
            "quat": None if q is None else dict(zip("wxyz", (float(c) for c in q), strict=True)),
            "gyr": _vec(sample.gyr),
            "acc": _vec(sample.acc),
            "mag": _vec(sample.mag),
        }
        t = sample.t_arrival_ns + self._epoch_offset_ns
        with self._lock:
            if self._closed:
                return
            self._writer.add_message(self._samples_ch, t, json.dumps(msg).encode(), t, self.samples)
            self.samples += 1

    def close(self) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._writer.finish()
            self._file.close()

    def __enter__(self) -> McapRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass(frozen=True, slots=True)
class RecordedFrame:
    """A frame read back: its exact bytes, arrival time [ns, Unix epoch], and source."""

    data: bytes
    log_time_ns: int
    source: str


def read_frames(path: str | Path) -> list[RecordedFrame]:
    """All ``/suit/packets`` frames of a recording, in arrival order."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"recording: no such file {p}")
    rows: list[tuple[int, int, RecordedFrame]] = []
    try:
        with open(p, "rb") as f:
            reader = make_reader(f)
            for _, channel, msg in reader.iter_messages(topics=[PACKETS_TOPIC]):
                if channel.message_encoding != FRAME_ENCODING:
                    continue
                frame = RecordedFrame(msg.data, msg.log_time, channel.metadata.get("source", ""))
                rows.append((msg.log_time, msg.sequence, frame))
    except (McapError, ValueError, EOFError) as exc:
        raise FileFormatError(f"{p}: not a readable MCAP recording ({exc})") from exc
    rows.sort(key=lambda r: (r[0], r[1]))
    return [r[2] for r in rows]


def read_samples(path: str | Path) -> list[dict[str, Any]]:
    """The decoded ``/suit/samples`` messages of a recording (JSON objects)."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [json.loads(m.data) for _, _, m in make_reader(f).iter_messages([SAMPLES_TOPIC])]


def decode_recording(path: str | Path) -> DecodedStream:
    """Batch-decode every frame of a recording: the fast chunk reader
    (:mod:`mocapkit.suit.mcap_fast`) then the numba stream decoder."""
    from mocapkit.suit.mcap_fast import read_frame_buffer

    return decode_stream(read_frame_buffer(path).data)


def paced(
    items: list[tuple[float, bytes]],
    send: Callable[[bytes], None],
    speed: float = 1.0,
    stop: threading.Event | None = None,
    on_sent: Callable[[int, int], None] | None = None,
) -> int:
    """Send ``(t [s], bytes)`` items at ``t / speed`` after the start on the real clock
    (``speed <= 0``: as fast as possible). Returns how many were sent.

    ``on_sent(index, perf_counter_ns)`` is called right before each send.
    """
    if not items:
        return 0
    t0 = items[0][0]
    start = time.perf_counter()
    clock = time.perf_counter_ns
    for i, (t, data) in enumerate(items):
        if stop is not None and stop.is_set():
            return i
        if speed > 0:
            due = start + (t - t0) / speed
            wait = due - time.perf_counter()
            if wait > 0:
                # sleep, never spin: a spinning sender holds the GIL and would delay a
                # receiver thread in the same process by up to the switch interval (5 ms)
                time.sleep(wait)
        if on_sent is not None:
            on_sent(i, clock())
        send(data)
    return len(items)


def replay(
    path: str | Path,
    send: Callable[[bytes], None],
    speed: float = 1.0,
    stop: threading.Event | None = None,
) -> int:
    """Send a recording's frames again, byte for byte, with the recorded spacing / speed."""
    frames = read_frames(path)
    return paced([(f.log_time_ns * 1e-9, f.data) for f in frames], send, speed, stop)


class ReplayTransport(Transport):
    """A transport that yields a recording's frames at their (scaled) times.

    Args:
        path: the MCAP recording.
        speed: 1 real time, 10 ten times faster, 0 as fast as possible.
    """

    def __init__(self, path: str | Path, speed: float = 1.0) -> None:
        self.frames = read_frames(path)
        self.speed = speed
        self.name = f"replay://{path}"
        self._i = 0
        self._start: float | None = None

    @property
    def finished(self) -> bool:
        return self._i >= len(self.frames)

    def send(self, data: bytes) -> None:
        """A replay has no peer: sent bytes (e.g. handshake replies) are discarded."""

    def recv_batch(self, max_frames: int = 1024, timeout_s: float = 0.05) -> list[Frame]:
        if self.finished:
            time.sleep(timeout_s)
            return []
        now = time.perf_counter()
        if self._start is None:
            self._start = now
        t0 = self.frames[0].log_time_ns
        out: list[Frame] = []
        deadline = now + timeout_s
        while not out:
            while self._i < len(self.frames) and len(out) < max_frames:
                f = self.frames[self._i]
                due = (f.log_time_ns - t0) * 1e-9 / self.speed if self.speed > 0 else 0.0
                if self._start + due > time.perf_counter():
                    break
                out.append(Frame(f.data, f.source, time.perf_counter_ns()))
                self._i += 1
            if out or self.finished or time.perf_counter() >= deadline:
                break
            time.sleep(0.0005)
        return out

    def close(self) -> None:
        self._i = len(self.frames)
