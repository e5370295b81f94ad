"""Compile the demo's numba kernels ahead of its first run: ``mocapkit demo --warm-up``.

numba compiles a kernel on its first call and caches the machine code on disk
(``cache=True``), so only a machine's first run pays for it. For the demo that is about
90 s on 2 cores (the marker reconstruction's rigid-body, prioritized-control and IK
kernels, the live chain's fusion, body and retargeting kernels, the orientation
filters): the first ``make demo`` would take well over a minute, every later one about
25 s. ``make setup`` therefore runs this once, after installing: the sections run on
their bundled data in ``jobs`` processes at once (the two marker methods compile mostly
different kernels; the teleoperation with its shortest shape), their outputs discarded.
What it leaves is numba's cache, nothing else; the demo itself then runs exactly as it
would otherwise, only without compiling.
"""

from __future__ import annotations

import logging
import multiprocessing
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Literal

from mocapkit.errors import ConfigError

#: what is compiled, in this order (the longest first, so two processes finish together)
TASKS = ("markers-osc", "markers-ik", "teleop", "imu")


def _run_task(task: str) -> float:
    """Run one task in this process; returns its seconds."""
    # the sections' warnings (estimated height, ...) belong to the demo, not here
    logging.getLogger("mocapkit").setLevel(logging.ERROR)
    t0 = time.perf_counter()
    if task == "imu":
        from mocapkit.demo.imu_section import run_imu

        run_imu()
    elif task == "teleop":  # the shortest shape: the live chain's kernels, about 8 s
        from mocapkit.demo.teleop_section import run_teleop

        run_teleop(shape_s=1.0)
    else:
        from mocapkit.demo.markers_section import run_markers

        methods: tuple[Literal["osc", "ik"], ...] = ("osc",) if task == "markers-osc" else ("ik",)
        with tempfile.TemporaryDirectory(prefix="mocapkit-warm-up-") as tmp:
            run_markers(Path(tmp), methods=methods)
    return time.perf_counter() - t0


def warm_up(
    tasks: tuple[str, ...] = TASKS,
    jobs: int = 2,
    on_done: Callable[[str, float], None] | None = None,
) -> dict[str, float]:
    """Run ``tasks`` (some of :data:`TASKS`) in ``jobs`` fresh processes; returns
    ``{task: seconds}``. A task that fails raises its error here (the demo would fail the
    same way)."""
    unknown = [t for t in tasks if t not in TASKS]
    if unknown or not tasks:
        raise ConfigError(f"warm-up tasks: expected some of {', '.join(TASKS)}, got {list(tasks)}")
    if jobs < 1:
        raise ConfigError(f"warm-up jobs: expected at least 1, got {jobs}")
    ctx = multiprocessing.get_context("spawn")  # a fresh interpreter: no inherited state
    out: dict[str, float] = {}
    with ProcessPoolExecutor(max_workers=min(jobs, len(tasks)), mp_context=ctx) as pool:
        futures = {t: pool.submit(_run_task, t) for t in tasks}
        for task, fut in futures.items():
            out[task] = fut.result()
            if on_done is not None:
                on_done(task, out[task])
    return out
