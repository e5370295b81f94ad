"""Per-sensor sequencing: deduplicate, reorder, count gaps, drop stale and replayed packets.

A :class:`SensorTrack` follows one stream (one sensor, one packet kind). Sequence
numbers are 16-bit on the wire and unwrapped here relative to the next expected one.

- in order (the expected seq): delivered at once, then any buffered successors;
- ahead (a gap): buffered until the gap fills, or until the oldest buffered item has
  waited ``reorder_window_s`` (then the missing seqs count as *lost* and delivery goes
  on), or at once if the gap exceeds ``max_gap`` (a long outage: no point waiting);
- behind: a *duplicate* if that seq was delivered recently, otherwise *stale* (it came
  after we gave up on it, or it is a replay of old traffic). ``restart_after``
  consecutive behind packets in sequence, while nothing has come forward for
  ``restart_quiet_s``, mean the sensor restarted its counter: the track resynchronises.
  (A replay of old traffic while the sensor is live stays *stale*: it cannot hijack the
  sequence.)
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any

_HALF = 1 << 15
_MOD = 1 << 16


@dataclass
class TrackCounts:
    """What happened to one stream's packets (all counts are packets).

    ``reordered`` counts packets delivered from the reorder buffer, i.e. that waited for
    an earlier one (which then came late, or was declared lost)."""

    delivered: int = 0
    duplicate: int = 0
    stale: int = 0
    lost: int = 0
    reordered: int = 0
    restarts: int = 0


class SensorTrack:
    """See the module docstring. Items are opaque; :meth:`push` returns those to deliver."""

    def __init__(
        self,
        reorder_window_s: float = 0.02,
        max_gap: int = 64,
        history: int = 256,
        restart_after: int = 8,
        restart_quiet_s: float = 0.25,
    ) -> None:
        self.reorder_window_s = reorder_window_s
        self.max_gap = max_gap
        self.restart_after = restart_after
        self.restart_quiet_s = restart_quiet_s
        self._last_forward_s = -float("inf")
        self.expected: int | None = None  # next unwrapped seq to deliver
        self.pending: dict[int, tuple[float, Any]] = {}
        self.recent: deque[int] = deque(maxlen=history)
        self.recent_set: set[int] = set()
        self.counts = TrackCounts()
        self._behind_run = 0
        self._behind_last: int | None = None

    def unwrap(self, seq16: int) -> int:
        """The unwrapped seq nearest to the next expected one."""
        if self.expected is None:
            return seq16
        diff = (seq16 - self.expected + _HALF) % _MOD - _HALF
        return self.expected + diff

    def _remember(self, seq: int) -> None:
        if len(self.recent) == self.recent.maxlen:
            self.recent_set.discard(self.recent[0])
        self.recent.append(seq)
        self.recent_set.add(seq)

    def _deliver_from(self, seq: int, item: Any, out: list[tuple[int, Any]]) -> None:
        out.append((seq, item))
        self._remember(seq)
        self.counts.delivered += 1
        nxt = seq + 1
        while nxt in self.pending:
            _, it = self.pending.pop(nxt)
            out.append((nxt, it))
            self._remember(nxt)
            self.counts.delivered += 1
            self.counts.reordered += 1
            nxt += 1
        self.expected = nxt

    def push(self, seq16: int, item: Any, now_s: float) -> list[tuple[int, Any]]:
        """Offer a packet; returns the ``(unwrapped seq, item)`` pairs now deliverable."""
        out: list[tuple[int, Any]] = []
        if self.expected is None:
            self._last_forward_s = now_s
            self._deliver_from(seq16, item, out)
            return out
        seq = self.unwrap(seq16)
        if seq == self.expected:
            self._behind_run = 0
            self._last_forward_s = now_s
            self._deliver_from(seq, item, out)
            return out
        if seq > self.expected:
            self._behind_run = 0
            self._last_forward_s = now_s
            if seq in self.pending:
                self.counts.duplicate += 1
                return out
            if seq - self.expected > self.max_gap:
                self._skip_to(seq, out)
                self._deliver_from(seq, item, out)
                return out
            self.pending[seq] = (now_s, item)
            return out
        # behind the expected seq
        if seq in self.recent_set:
            self.counts.duplicate += 1
            return out
        self.counts.stale += 1
        if self._behind_last is not None and seq == self._behind_last + 1:
            self._behind_run += 1
        else:
            self._behind_run = 1
        self._behind_last = seq
        quiet = now_s - self._last_forward_s >= self.restart_quiet_s
        if self._behind_run >= self.restart_after and quiet:
            self.restart()
            self.counts.restarts += 1
        return out

    def _skip_to(self, seq: int, out: list[tuple[int, Any]]) -> None:
        """Give up on everything before ``seq``: deliver the buffered items in order,
        counting the holes as lost."""
        assert self.expected is not None
        while True:
            earlier = [k for k in self.pending if k < seq]
            if not earlier:
                break
            first = min(earlier)
            self.counts.lost += first - self.expected
            _, it = self.pending.pop(first)
            self._deliver_from(first, it, out)  # also takes any consecutive successors
        if seq > self.expected:
            self.counts.lost += seq - self.expected
            self.expected = seq

    def flush(self, now_s: float) -> list[tuple[int, Any]]:
        """Release buffered items whose wait exceeded the reorder window (gaps -> lost)."""
        out: list[tuple[int, Any]] = []
        while self.pending:
            first = min(self.pending)
            if now_s - self.pending[first][0] < self.reorder_window_s:
                break
            assert self.expected is not None
            self.counts.lost += first - self.expected
            self.expected = first
            _, it = self.pending.pop(first)
            self._deliver_from(first, it, out)
        return out

    def restart(self) -> None:
        """Forget the sequence (a restarted sensor, or one back after being missing)."""
        self.expected = None
        self.pending.clear()
        self.recent.clear()
        self.recent_set.clear()
        self._behind_run = 0
        self._behind_last = None
