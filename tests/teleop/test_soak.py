"""A short soak (issue 12; the 30-minute one is ``python -m benchmarks.soak``): 15 sensors
at 100 Hz through the live session with recording. Nothing is lost, memory does not grow
between the two halves, and the recording reads back whole."""

from __future__ import annotations

from pathlib import Path

import pytest
from benchmarks.soak import soak

from mocapkit.teleop.recording import read_messages

pytestmark = pytest.mark.realtime


def test_a_short_soak_loses_nothing_and_keeps_its_memory(tmp_path: Path) -> None:
    record = tmp_path / "soak.mcap"
    rows = soak(20.0, 10.0, record)
    assert [r["lost"] for r in rows] == [0, 0]
    assert rows[1]["delivered"] > rows[0]["delivered"] > 10_000  # 15 x 100 Hz
    # memory after the warm-up window: flat (a leak of one object per packet would add
    # tens of MB in 15,000 packets); generous, as the allocator keeps freed pages
    assert rows[1]["rss_mb"] - rows[0]["rss_mb"] < 25.0
    commands = read_messages(record, "/teleop/command")
    assert len(commands) > 500  # engaged for most of the 20 s at 100 Hz
