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
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from mocapkit.errors import ConfigError, FileFormatError
from mocapkit.suit.batch import DecodedStream, decode_stream
from mocapkit.suit.errors import ProtocolError
from mocapkit.suit.protocol import SYNC, Kind, decode
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


_KIND_NAMES = {int(k): k.name for k in Kind}


def _vec_json(v: Any) -> str:
    if v is None:
        return "null"
    x, y, z = v.tolist()
    return f"[{x!r},{y!r},{z!r}]"


def sample_json(sample: SuitSample) -> bytes:
    """A sample as the ``/suit/samples`` JSON message (formatted directly: ~4x faster
    than ``json.dumps`` of a dict, which matters at 15 k samples/s)."""
    t = sample.t_sensor_s
    q = sample.quat
    quat = "null"
    if q is not None:
        w, x, y, z = q.tolist()
        quat = f'{{"w":{w!r},"x":{x!r},"y":{y!r},"z":{z!r}}}'
    t_json = "null" if t != t else repr(float(t))
    return (
        f'{{"sensor_id":{sample.sensor_id:d},"seq":{sample.seq:d},"t_sensor_s":{t_json},'
        f'"t_arrival_ns":{sample.t_arrival_ns:d},"kind":"{_KIND_NAMES[int(sample.kind)]}",'
        f'"source":"{sample.source}","quat":{quat},"gyr":{_vec_json(sample.gyr)},'
        f'"acc":{_vec_json(sample.acc)},"mag":{_vec_json(sample.mag)}}}'
    ).encode()


SampleMode = Literal["live", "at_close", "none"]


def samples_from_frames(frames: list[tuple[bytes, int]]) -> list[SuitSample]:
    """Samples of every valid suit frame in ``(bytes, t_arrival_ns)`` pairs, in order
    (seq as on the wire; sensor time unwrapped per sensor; other frames skipped)."""
    out: list[SuitSample] = []
    wraps: dict[int, list[int]] = {}

    def t_s(sid: int, t_us: int) -> float:
        w = wraps.setdefault(sid, [0, t_us])
        if t_us < w[1] - (1 << 31):
            w[0] += 1
        w[1] = t_us
        return (w[0] * (1 << 32) + t_us) * 1e-6

    for data, t_ns in frames:
        if not data or data[0] != SYNC:
            continue
        try:
            pkt = decode(data)
        except ProtocolError:
            continue
        if pkt.kind is Kind.BUNDLE:
            for sid, q in pkt.entries:
                out.append(SuitSample(sid, pkt.seq, t_s(0, pkt.t_us), t_ns, Kind.ORIENTATION, q))
        elif pkt.kind is not Kind.STATUS:
            t = t_s(pkt.sensor_id, pkt.t_us)
            out.append(
                SuitSample(
                    pkt.sensor_id, pkt.seq, t, t_ns, pkt.kind, pkt.quat, pkt.gyr, pkt.acc, pkt.mag
                )
            )
    return out


class McapRecorder:
    """Writes frames and samples to an MCAP file; call :meth:`close` to finish it.

    ``write_frame`` / ``write_sample`` only queue the item: a writer thread encodes and
    writes, so the receiver thread never waits on the file (``close`` drains the queue).
    Arrival times (``perf_counter_ns``) are mapped to the Unix epoch once, at creation.

    Args:
        path: the MCAP file to write.
        samples: what goes on ``/suit/samples``: ``"live"`` the receiver's delivered
            samples as they come (in order, deduplicated; for SlimeVR and for rates up
            to a few kHz: JSON costs CPU the receiver needs at 15 kHz on a loaded
            machine), ``"at_close"`` every valid suit frame decoded when the recording
            is closed (raw header seq, sensor time unwrapped per sensor), or ``"none"``.
    """

    def __init__(self, path: str | Path, samples: SampleMode = "at_close") -> None:
        if samples not in ("live", "at_close", "none"):
            raise ConfigError(f"samples: expected live, at_close or none, got {samples!r}")
        self.sample_mode: SampleMode = samples
        self._kept: list[tuple[bytes, int]] = []
        from mcap.writer import Writer

        self.path = Path(path)
        self._file = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._file)
        self._writer.start(profile="", library="mocapkit")
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
        self._queue: queue.SimpleQueue[tuple[int, Any, int, Any] | None] = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._loop, name="mcap-recorder", daemon=True)
        self._thread.start()

    def _channel(self, source: Any) -> int:
        key = str(source)
        ch = self._frame_ch.get(key)
        if ch is None:
            ch = self._frame_ch[key] = self._writer.register_channel(
                PACKETS_TOPIC, FRAME_ENCODING, 0, {"source": key}
            )
        return ch

    def write_frame(self, data: bytes, t_arrival_ns: int, source: Any = "") -> None:
        """Queue one frame exactly as received."""
        if not self._closed:
            self._queue.put((0, bytes(data), t_arrival_ns, source))

    def write_sample(self, sample: SuitSample) -> None:
        """Queue one delivered sample (JSON on ``/suit/samples``) in ``"live"`` mode."""
        if not self._closed and self.sample_mode == "live":
            self._queue.put((1, sample, sample.t_arrival_ns, None))

    def _loop(self) -> None:
        """Write the queue; close a chunk at least every ``FLUSH_S`` (crash safety: after
        a SIGKILL everything but the last moments is readable, see ``mcap_recovery``)."""
        from mocapkit.io.mcap_recovery import FLUSH_S

        add = self._writer.add_message
        last_flush = time.monotonic()
        while True:
            now = time.monotonic()
            if now - last_flush >= FLUSH_S:
                self._writer.flush()
                last_flush = now
            try:
                item = self._queue.get(timeout=FLUSH_S)
            except queue.Empty:
                continue
            if item is None:
                return
            what, payload, t_ns, source = item
            t = t_ns + self._epoch_offset_ns
            if what == 0:
                add(self._channel(source), t, payload, t, self._seq)
                self._seq += 1
                self.frames += 1
                if self.sample_mode == "at_close":
                    self._kept.append((payload, t_ns))
            else:
                add(self._samples_ch, t, sample_json(payload), t, self.samples)
                self.samples += 1

    def close(self) -> None:
        """Write everything queued, then finish the file (summary, indexes)."""
        if self._closed:
            return
        self._closed = True
        self._queue.put(None)
        self._thread.join()
        if self.sample_mode == "at_close":
            for sample in samples_from_frames(self._kept):
                t = sample.t_arrival_ns + self._epoch_offset_ns
                self._writer.add_message(self._samples_ch, t, sample_json(sample), t, self.samples)
                self.samples += 1
            self._kept = []
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
    """All ``/suit/packets`` frames of a recording, in arrival order (a recording that was
    never closed: up to its last complete record, with a warning)."""

    from mocapkit.io.mcap_recovery import decode_errors, iter_messages

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"recording: no such file {p}")
    rows: list[tuple[int, int, RecordedFrame]] = []
    try:
        with open(p, "rb") as f:
            for channel, msg in iter_messages(f, p, [PACKETS_TOPIC]):
                if channel.message_encoding != FRAME_ENCODING:
                    continue
                frame = RecordedFrame(msg.data, msg.log_time, channel.metadata.get("source", ""))
                rows.append((msg.log_time, msg.sequence, frame))
    except decode_errors() as exc:
        raise FileFormatError(f"{p}: not a readable MCAP recording ({exc})") from exc
    rows.sort(key=lambda r: (r[0], r[1]))
    return [r[2] for r in rows]


def read_samples(path: str | Path) -> list[dict[str, Any]]:
    """The decoded ``/suit/samples`` messages of a recording (JSON objects)."""
    from mocapkit.io.mcap_recovery import iter_messages

    with open(path, "rb") as f:
        return [json.loads(m.data) for _, m in iter_messages(f, path, [SAMPLES_TOPIC])]


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
