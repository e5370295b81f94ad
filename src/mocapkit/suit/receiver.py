"""The host receiver: validate, sequence, timestamp and hand samples to the pipeline.

One dedicated thread owns the transport. Per wake-up it drains every readable frame,
then for each: per-source token bucket (a flooding address is cut to its quota and no
one else is), decode (our protocol, or SlimeVR when the first byte says so), sensor-ID
allow-list, then the sensor's :class:`~mocapkit.suit.tracks.SensorTrack` (dedup,
reorder, gaps). Every drop increments a named counter and logs a line, at most once
per second per reason (with the number suppressed), so a flood cannot flood the log.

Delivered samples go to one bounded queue per sensor; :meth:`Receiver.get_batch` and
:meth:`Receiver.samples` take from them round-robin, so a sensor that floods only
overflows its own queue. See the consumer API in docs/design/suit.md.

Direct consumer (``on_batch``): a latency-critical pipeline (teleoperation) can run on the
receiver thread itself: ``on_batch(samples, now_ns)`` is called after every drained batch
with the samples it delivered, and at least every 5 ms with an empty list (a tick for
watchdogs). Those samples are not queued (``get_batch`` returns nothing): no queue, no
thread hand-off, so a packet's arrival-to-output time does not include waking another
thread. An exception in ``on_batch`` is counted (``consumer_error``) and logged; the
thread goes on.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from mocapkit.errors import ConfigError
from mocapkit.suit import slimevr
from mocapkit.suit.errors import ProtocolError, UnknownSensorError
from mocapkit.suit.protocol import MAX_SENSOR_ID, SYNC, Kind, Packet, decode
from mocapkit.suit.receiver_state import FrameRecorder, ReceiverConfig, SensorState
from mocapkit.suit.samples import ReceiverStats, SensorEvent, SensorStats, SuitSample
from mocapkit.suit.transport import Frame, Transport

log = logging.getLogger(__name__)
_MAX_SOURCES = 4096  # token buckets kept at once
# A SlimeVR device's packet number may skip this many (lost packets, hours of them at
# 100 Hz); a bigger jump is a malformed datagram, not the device.
_SLIME_MAX_JUMP = 1_000_000


class Receiver:
    """Receives suit (and SlimeVR) packets on a transport; see the module docstring.

    Args:
        transport: where frames come from (``UdpTransport.bind(...)``, serial, replay).
        config: :class:`ReceiverConfig`.
        recorder: optional recorder of every frame received (``McapRecorder``).
        on_batch: direct consumer called on the receiver thread (see the module docstring).
    """

    def __init__(
        self,
        transport: Transport,
        config: ReceiverConfig | None = None,
        recorder: FrameRecorder | None = None,
        on_batch: Callable[[list[SuitSample], int], None] | None = None,
    ) -> None:
        self.transport = transport
        self.cfg = config or ReceiverConfig()
        self.recorder = recorder
        self._sensors: dict[int, SensorState] = {}
        self._stats = ReceiverStats()
        self._buckets: dict[Any, list[float]] = {}
        self._events: deque[SensorEvent] = deque(maxlen=1024)
        self._listeners: list[Callable[[SuitSample], None]] = []
        self._cv = threading.Condition()  # guards the per-sensor queues and _ready
        self._ready = 0  # samples queued over all sensors
        self._rr_next = 0  # round-robin: the sensor ID to serve first next time
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._log_last: dict[str, float] = {}
        self._log_suppressed: dict[str, int] = {}
        self._slime_ids: dict[tuple[Any, int], int] = {}
        self._slime_last: dict[Any, int] = {}
        self._rate_limited = math.isfinite(self.cfg.source_rate_hz)
        self._last_check = 0.0
        self._pending_count = 0
        self._on_batch = on_batch
        self._batch: list[SuitSample] = []

    # -- lifecycle ------------------------------------------------------------------------
    def start(self) -> Receiver:
        """Start the receiver thread (returns self)."""
        if self._thread is not None:
            raise ConfigError("receiver: already started")
        self._thread = threading.Thread(target=self._run, name="suit-receiver", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread (queued samples stay readable)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        with self._cv:
            self._cv.notify_all()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def __enter__(self) -> Receiver:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                frames = self.transport.recv_batch(2048, 0.005)
            except Exception as exc:  # a transport failure must not kill the thread silently
                self._drop("transport_error", f"transport error: {exc}")
                time.sleep(0.01)
                continue
            for frame in frames:
                try:
                    self.handle(frame)
                except Exception:  # a bug must cost one datagram, not the receiver
                    self._stats.dropped["internal_error"] = (
                        self._stats.dropped.get("internal_error", 0) + 1
                    )
                    log.exception(
                        "suit receiver: internal error on a %d-byte datagram", len(frame.data)
                    )
            now_ns = time.perf_counter_ns()
            self._housekeeping(now_ns)
            if self._on_batch is not None:
                batch, self._batch = self._batch, []
                try:
                    self._on_batch(batch, now_ns)
                except Exception:  # the consumer's bug must not kill the receiver
                    self._stats.dropped["consumer_error"] = (
                        self._stats.dropped.get("consumer_error", 0) + 1
                    )
                    log.exception("suit receiver: the direct consumer (on_batch) failed")

    # -- per frame ------------------------------------------------------------------------
    def handle(self, frame: Frame) -> None:
        """Process one received frame (the thread calls this; tests may call it directly)."""
        data, source, now_ns = frame
        st = self._stats
        st.datagrams += 1
        st.bytes += len(data)
        if self._rate_limited and not self._admit(source, now_ns):
            # checked first, so a flooding source costs as little as possible (and does
            # not fill the recording) while the other sources are served
            self._drop(
                "rate_limited", f"source {source} exceeds {self.cfg.source_rate_hz:.0f} packets/s"
            )
            return
        if self.recorder is not None:
            self.recorder.write_frame(data, now_ns, source)
        if not data:
            self._drop("truncated", f"empty datagram from {source}")
            return
        is_suit = data[0] == SYNC
        mode = self.cfg.protocols
        try:
            if is_suit and mode != "slimevr":
                self._on_packet(decode(data), now_ns, source)
            elif not is_suit and mode != "suit":
                self._on_slimevr(data, source, now_ns)
            else:
                self._drop("bad_sync", f"{len(data)} bytes from {source} are not {mode} packets")
        except ProtocolError as exc:
            self._drop(exc.reason, f"dropped {len(data)} bytes from {source}: {exc}")

    def _admit(self, source: Any, now_ns: int) -> bool:
        b = self._buckets.get(source)
        now = now_ns * 1e-9
        if b is None:
            if len(self._buckets) >= _MAX_SOURCES:  # many (spoofed) sources: forget idle ones
                idle = [k for k, v in self._buckets.items() if now - v[1] > 1.0]
                for k in idle or list(self._buckets)[: _MAX_SOURCES // 2]:
                    del self._buckets[k]
            b = self._buckets[source] = [self.cfg.source_burst, now]
        tokens = min(self.cfg.source_burst, b[0] + (now - b[1]) * self.cfg.source_rate_hz)
        b[1] = now
        if tokens < 1.0:
            b[0] = tokens
            return False
        b[0] = tokens - 1.0
        return True

    def _sensor(self, sensor_id: int, now_ns: int) -> SensorState:
        allowed = self.cfg.allowed_ids
        if allowed is not None and sensor_id not in allowed:
            raise UnknownSensorError(
                f"sensor_id {sensor_id} is not in the allow-list {sorted(allowed)}"
            )
        s = self._sensors.get(sensor_id)
        if s is None:
            with self._cv:
                s = self._sensors[sensor_id] = SensorState(sensor_id, self.cfg)
            s.last_fresh_ns = now_ns
            self._events.append(SensorEvent("added", sensor_id, now_ns))
            log.info("suit: sensor %d added", sensor_id)
        elif s.stats.state == "missing":
            s.stats.state = "ok"
            for tr in s.tracks.values():
                tr.restart()
            self._events.append(SensorEvent("back", sensor_id, now_ns))
            log.info("suit: sensor %d is back", sensor_id)
        s.stats.last_arrival_ns = now_ns
        return s

    def _on_packet(self, pkt: Packet, now_ns: int, source: Any) -> None:
        if pkt.kind is Kind.BUNDLE:
            for sid, quat in pkt.entries:
                try:
                    s = self._sensor(sid, now_ns)
                except UnknownSensorError as exc:  # drop that entry, keep the others
                    self._drop(exc.reason, f"bundle {pkt.seq} from {source}: {exc}")
                    continue
                sample = SuitSample(sid, 0, s.unwrap_time(pkt.t_us), now_ns, Kind.ORIENTATION, quat)
                self._sequence(s, Kind.BUNDLE, pkt.seq, sample, now_ns)
            return
        s = self._sensor(pkt.sensor_id, now_ns)
        if pkt.kind is Kind.STATUS:
            s.stats.battery_mv = pkt.battery_mv
            return
        t = s.unwrap_time(pkt.t_us)
        sample = SuitSample(
            pkt.sensor_id, 0, t, now_ns, pkt.kind, pkt.quat, pkt.gyr, pkt.acc, pkt.mag
        )
        self._sequence(s, pkt.kind, pkt.seq, sample, now_ns)

    def _on_slimevr(self, data: bytes, source: Any, now_ns: int) -> None:
        """SlimeVR packet numbers count every packet of a *device* (all its sensors and
        packet types), so order is checked per device, as the SlimeVR server does: a
        packet not newer than the last one is dropped; a handshake starts over."""
        messages = slimevr.parse(data)
        if any(m.type == slimevr.HANDSHAKE for m in messages):
            self.transport.reply(slimevr.handshake_reply(), source)
            self._slime_last.pop(source, None)
            for m in messages:
                log.info(
                    "slimevr: handshake from %s (firmware %r, mac %s)", source, m.firmware, m.mac
                )
            return
        num = messages[0].packet_number
        last = self._slime_last.get(source)
        if last is not None and num <= last:
            reason = "duplicate" if num == last else "stale"
            self._drop(reason, f"SlimeVR packet {num} from {source} is not newer than {last}")
            return
        if last is not None and num - last > _SLIME_MAX_JUMP:
            # a malformed (or forged) packet number: taking it would make every real
            # packet look stale until the next handshake; drop this datagram alone
            self._drop(
                "bad_sequence",
                f"SlimeVR packet {num} from {source} jumps {num - last} ahead of {last}",
            )
            return
        self._slime_last[source] = num
        for m in messages:
            if m.quat is None:
                continue
            sid = self._slime_id(source, m.sensor_id)
            s = self._sensor(sid, now_ns)
            sample = SuitSample(
                sid, 0, math.nan, now_ns, Kind.ORIENTATION, m.quat, acc=m.acc, source="slimevr"
            )
            s.slime_seq += 1
            self._sequence(s, "slimevr", s.slime_seq & 0xFFFF, sample, now_ns)

    def _slime_id(self, source: Any, tracker_sensor: int) -> int:
        key = (source, tracker_sensor)
        sid = self._slime_ids.get(key)
        if sid is None:
            used = set(self._sensors) | set(self._slime_ids.values())
            allowed = self.cfg.allowed_ids or frozenset(range(1, MAX_SENSOR_ID + 1))
            free = sorted(i for i in allowed if i not in used)
            if not free:
                raise UnknownSensorError(
                    f"SlimeVR tracker {source} sensor {tracker_sensor}: no free suit ID left"
                )
            sid = self._slime_ids[key] = free[0]
            log.info("slimevr: tracker %s sensor %d -> suit ID %d", source, tracker_sensor, sid)
        return sid

    def _sequence(
        self, s: SensorState, key: object, seq16: int, sample: SuitSample, now_ns: int
    ) -> None:
        tr = s.track(key)
        before = tr.counts.restarts
        released = tr.push(seq16, sample, now_ns * 1e-9)
        if tr.counts.restarts != before:
            self._events.append(SensorEvent("restarted", s.stats.sensor_id, now_ns))
            log.warning("suit: sensor %d restarted its sequence counter", s.stats.sensor_id)
        if tr.pending:
            self._pending_count += 1
        for seq, item in released:
            item.seq = seq
            self._deliver(s, item)

    def _deliver(self, s: SensorState, sample: SuitSample) -> None:
        st = s.stats
        if self._on_batch is not None:
            self._batch.append(sample)
            full = False
        else:
            full = self._enqueue(s, sample)
        if full:
            st.queue_dropped += 1
            self._drop(
                "queue_full", f"sensor {st.sensor_id}: consumer too slow, oldest sample dropped"
            )
        self._account(s, sample)

    def _enqueue(self, s: SensorState, sample: SuitSample) -> bool:
        """Queue a sample for get_batch; True when the queue was full (oldest dropped)."""
        with self._cv:
            full = len(s.queue) >= self.cfg.queue_per_sensor
            if full:
                s.queue.popleft()
            else:
                self._ready += 1
            s.queue.append(sample)
            self._cv.notify()
        return full

    def _account(self, s: SensorState, sample: SuitSample) -> None:
        """Freshness, latency and rate figures, listeners and the recorder."""
        st = s.stats
        t_s = sample.t_sensor_s
        if not math.isfinite(t_s) or t_s > s.t_sensor_max:
            if math.isfinite(t_s):
                s.t_sensor_max = t_s
            s.last_fresh_ns = sample.t_arrival_ns
            if st.state == "stale":
                st.state = "ok"
                self._events.append(SensorEvent("fresh", st.sensor_id, sample.t_arrival_ns))
                log.info("suit: sensor %d sends new samples again", st.sensor_id)
        if math.isfinite(sample.t_sensor_s):
            offset = sample.t_arrival_ns * 1e-9 - sample.t_sensor_s
            if offset < s.offset_min:
                s.offset_min = offset
            s.latencies.append((offset - s.offset_min) * 1e3)
        sec = sample.t_arrival_ns // 1_000_000_000
        if sec != s.window_start:
            st.rate_hz = float(s.window_count) if sec == s.window_start + 1 else 0.0
            s.window_start, s.window_count = sec, 0
        s.window_count += 1
        for fn in self._listeners:
            fn(sample)
        if self.recorder is not None:
            self.recorder.write_sample(sample)

    def _housekeeping(self, now_ns: int) -> None:
        now = now_ns * 1e-9
        if self._pending_count:
            self._pending_count = 0
            for s in self._sensors.values():
                for tr in s.tracks.values():
                    if tr.pending:
                        for seq, item in tr.flush(now):
                            item.seq = seq
                            self._deliver(s, item)
                        self._pending_count += bool(tr.pending)
        if now - self._last_check < 0.05:
            return
        self._last_check = now
        for s in list(self._sensors.values()):
            st = s.stats
            if st.state == "missing":
                continue
            if now - st.last_arrival_ns * 1e-9 > self.cfg.missing_after_s:
                st.state = "missing"
                st.rate_hz = 0.0
                self._events.append(SensorEvent("missing", st.sensor_id, now_ns))
                log.warning(
                    "suit: sensor %d missing (silent for %.2f s)",
                    st.sensor_id,
                    self.cfg.missing_after_s,
                )
            elif st.state == "ok" and now - s.last_fresh_ns * 1e-9 > self.cfg.stale_after_s:
                st.state = "stale"
                self._events.append(SensorEvent("stale", st.sensor_id, now_ns))
                log.warning(
                    "suit: sensor %d stale: packets arrive but nothing new for %.2f s "
                    "(duplicates or a frozen sensor clock)",
                    st.sensor_id,
                    self.cfg.stale_after_s,
                )

    def _drop(self, reason: str, message: str) -> None:
        d = self._stats.dropped
        d[reason] = d.get(reason, 0) + 1
        now = time.monotonic()
        if now - self._log_last.get(reason, -math.inf) >= 1.0:
            extra = self._log_suppressed.pop(reason, 0)
            more = f" (+{extra} more since the last line)" if extra else ""
            log.warning("suit receiver: %s [%s]%s", message, reason, more)
            self._log_last[reason] = now
        else:
            self._log_suppressed[reason] = self._log_suppressed.get(reason, 0) + 1

    # -- consumer API ---------------------------------------------------------------------
    def add_listener(self, callback: Callable[[SuitSample], None]) -> None:
        """Call ``callback(sample)`` on the receiver thread for every delivered sample."""
        self._listeners.append(callback)

    @property
    def pending(self) -> int:
        """Samples queued and not yet taken by the consumer."""
        return self._ready

    def get_batch(self, max_items: int = 1024, timeout_s: float | None = 0.1) -> list[SuitSample]:
        """Up to ``max_items`` samples, round-robin over sensors (one from each in turn);
        waits up to ``timeout_s`` for the first (None: until one arrives or the receiver
        stops)."""
        out: list[SuitSample] = []
        with self._cv:
            if not self._ready:
                if self._stop.is_set():
                    return out
                self._cv.wait_for(lambda: self._ready > 0 or self._stop.is_set(), timeout_s)
            if not self._ready:
                return out
            ids = sorted(self._sensors)
            k = next((i for i, sid in enumerate(ids) if sid >= self._rr_next), 0)
            queues = [self._sensors[sid].queue for sid in ids[k:] + ids[:k]]
            while len(out) < max_items and self._ready:
                for q in queues:
                    if q:
                        out.append(q.popleft())
                        self._ready -= 1
                        if len(out) >= max_items:
                            break
            if out:
                self._rr_next = out[-1].sensor_id + 1
        return out

    def samples(self, timeout_s: float | None = None) -> Iterator[SuitSample]:
        """Iterate over samples as they arrive; ends when nothing arrives within
        ``timeout_s`` (None: never) or once the receiver is stopped and drained."""
        while True:
            batch = self.get_batch(256, timeout_s)
            if not batch:
                return
            yield from batch

    def events(self) -> list[SensorEvent]:
        """Sensor events since the last call (added, missing, back, restarted)."""
        out = []
        while self._events:
            out.append(self._events.popleft())
        return out

    def stats(self) -> ReceiverStats:
        """A snapshot of the counters and per-sensor figures."""
        snap = ReceiverStats(self._stats.datagrams, self._stats.bytes, dict(self._stats.dropped))
        for sid, s in sorted(self._sensors.items()):
            st = SensorStats(**{k: getattr(s.stats, k) for k in SensorStats.__dataclass_fields__})
            st.delivered = st.duplicate = st.stale = st.lost = st.reordered = 0
            for tr in s.tracks.values():
                c = tr.counts
                st.delivered += c.delivered
                st.duplicate += c.duplicate
                st.stale += c.stale
                st.lost += c.lost
                st.reordered += c.reordered
            if s.latencies:
                lat = np.fromiter(s.latencies, dtype=np.float64)
                st.latency_ms_p50 = float(np.percentile(lat, 50))
                st.latency_ms_p99 = float(np.percentile(lat, 99))
            snap.sensors[sid] = st
        return snap
