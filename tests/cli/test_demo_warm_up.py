"""``mocapkit demo --warm-up``: the demo's kernels compiled in other processes."""

from __future__ import annotations

import pytest

from mocapkit.demo.warm_up import TASKS, warm_up
from mocapkit.errors import ConfigError


def test_warm_up_runs_a_section_in_another_process_and_times_it() -> None:
    done: list[str] = []
    seconds = warm_up(("imu",), jobs=1, on_done=lambda task, s: done.append(task))
    assert list(seconds) == ["imu"]
    assert done == ["imu"]
    assert seconds["imu"] > 0.0


def test_warm_up_names_what_it_can_do() -> None:
    assert set(TASKS) == {"markers-osc", "markers-ik", "teleop", "imu"}
    with pytest.raises(ConfigError, match=r"expected some of markers-osc, .*got \['gait'\]"):
        warm_up(("gait",))
    with pytest.raises(ConfigError, match="warm-up tasks: expected some of"):
        warm_up(())
    with pytest.raises(ConfigError, match="warm-up jobs: expected at least 1, got 0"):
        warm_up(("imu",), jobs=0)
