"""Per-sensor sequencing: in order, duplicates, reordering, gaps, stale, wrap, restart."""

from __future__ import annotations

from mocapkit.suit.tracks import SensorTrack


def _seqs(out: list[tuple[int, object]]) -> list[int]:
    return [s for s, _ in out]


def test_in_order_delivery_is_immediate() -> None:
    tr = SensorTrack()
    got = []
    for s in range(5):
        got += _seqs(tr.push(s + 100, s, 0.0))
    assert got == [100, 101, 102, 103, 104]
    assert tr.counts.delivered == 5
    assert tr.counts.lost == 0


def test_reorder_within_window_and_duplicates() -> None:
    tr = SensorTrack(reorder_window_s=0.02)
    assert _seqs(tr.push(0, "a", 0.0)) == [0]
    assert _seqs(tr.push(2, "c", 0.001)) == []  # waits for 1
    assert _seqs(tr.push(2, "c", 0.001)) == []  # duplicate of a buffered one
    assert _seqs(tr.push(1, "b", 0.002)) == [1, 2]
    assert _seqs(tr.push(1, "b", 0.003)) == []  # duplicate of a delivered one
    c = tr.counts
    assert (c.delivered, c.duplicate, c.reordered, c.lost, c.stale) == (3, 2, 1, 0, 0)


def test_gap_declared_lost_after_window_then_late_packet_is_stale() -> None:
    tr = SensorTrack(reorder_window_s=0.02)
    tr.push(0, 0, 0.0)
    assert tr.push(3, 3, 0.001) == []
    assert tr.flush(0.01) == []  # still within the window
    assert _seqs(tr.flush(0.03)) == [3]
    assert tr.counts.lost == 2
    assert tr.push(1, 1, 0.04) == []  # too late: given up on
    assert tr.counts.stale == 1


def test_large_gap_skips_at_once() -> None:
    tr = SensorTrack(max_gap=64)
    tr.push(0, 0, 0.0)
    assert _seqs(tr.push(500, 500, 0.0)) == [500]
    assert tr.counts.lost == 499


def test_sixteen_bit_wrap() -> None:
    tr = SensorTrack()
    got = []
    for s in (65533, 65534, 65535, 0, 1):
        got += _seqs(tr.push(s, s, 0.0))
    assert got == [65533, 65534, 65535, 65536, 65537]
    assert tr.counts.lost == 0


def test_restart_after_consecutive_old_sequence_numbers() -> None:
    tr = SensorTrack(restart_after=4, restart_quiet_s=0.25)
    for s in range(1000, 1010):
        tr.push(s, s, 0.0)
    out = []
    for s in range(0, 6):  # the sensor rebooted: counts from 0 again, its old stream stopped
        out += _seqs(tr.push(s, s, 1.0))
    assert tr.counts.restarts == 1
    assert tr.counts.stale == 4
    assert out == [4, 5]


def test_large_gap_flushes_buffered_runs_in_order() -> None:
    tr = SensorTrack(max_gap=10)
    tr.push(0, 0, 0.0)
    for s in (3, 4, 5, 8):  # buffered, with holes at 1-2 and 6-7
        assert tr.push(s, s, 0.0) == []
    assert _seqs(tr.push(100, 100, 0.0)) == [3, 4, 5, 8, 100]
    assert tr.counts.lost == 2 + 2 + 91
    assert tr.pending == {}


def test_replay_of_old_traffic_while_live_cannot_hijack_the_sequence() -> None:
    tr = SensorTrack(restart_after=4, restart_quiet_s=0.25)
    for s in range(1000, 1300):
        tr.push(s, s, s * 1e-3)
    got = []
    for k, s in enumerate(range(1300, 1340)):
        now = 0.3 + k * 1e-3
        got += _seqs(tr.push(100 + k, 100 + k, now))  # a replayed old run, in sequence
        got += _seqs(tr.push(s, s, now))  # the live sensor
    assert got == list(range(1300, 1340))
    assert tr.counts.stale == 40
    assert tr.counts.restarts == 0
