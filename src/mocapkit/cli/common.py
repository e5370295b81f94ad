"""Shared CLI pieces: exit codes, JSON output, progress bars, the error wrapper."""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Iterable, Iterator
from typing import Any, TypeVar

import numpy as np

# Exit codes: documented in `mocapkit --help` and docs/cli.md.
EXIT_OK = 0
EXIT_ERROR = 1  # the command ran but failed (bad input data, a failed solve...)
EXIT_USAGE = 2  # wrong arguments (argparse's own code)
EXIT_MISSING_DEPENDENCY = 3  # an optional package is not installed
EXIT_INTERRUPTED = 130  # Ctrl-C

T = TypeVar("T")

_IMPORTED_AT = time.perf_counter()


def process_seconds() -> float:
    """Seconds since this process started, as a user's stopwatch sees a command: read from
    the kernel on Linux (``/proc/self/stat`` start time, 10 ms ticks), else since this
    module was imported (interpreter start-up left out)."""
    try:
        with open("/proc/self/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        start_ticks = float(fields[19])  # field 22 of proc(5): starttime
        with open("/proc/uptime") as f:
            uptime = float(f.read().split()[0])
        return max(0.0, uptime - start_ticks / os.sysconf("SC_CLK_TCK"))
    except (OSError, ValueError, IndexError):
        return time.perf_counter() - _IMPORTED_AT


def _to_jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _to_jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_to_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


def print_json(obj: Any) -> None:
    """Print exactly one JSON object on stdout (numpy scalars converted, NaN -> null)."""
    sys.stdout.write(json.dumps(_to_jsonable(obj), indent=2, allow_nan=False) + "\n")
    sys.stdout.flush()


def progress(
    items: Iterable[T], description: str, total: int | None = None, enabled: bool = True
) -> Iterator[T]:
    """A rich progress bar on stderr (hidden when disabled or stderr is not a terminal)."""
    if not enabled:
        yield from items
        return
    from rich.console import Console
    from rich.progress import track

    console = Console(stderr=True)
    yield from track(items, description=description, total=total, console=console, transient=True)


class StepProgress:
    """Progress bars on stderr for a job made of named steps: ``bars(step, done, total)``
    adds a bar the first time a step is seen and moves it (units are the step's own).
    Use as a context manager; hidden when ``enabled`` is false or stderr is not a terminal.
    """

    def __init__(self, enabled: bool = True) -> None:
        self._tasks: dict[str, Any] = {}
        self._progress: Any = None
        if enabled and sys.stderr.isatty():
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                Progress,
                TaskProgressColumn,
                TextColumn,
                TimeElapsedColumn,
            )

            self._progress = Progress(
                TextColumn("{task.description:<24}"),
                BarColumn(),
                TaskProgressColumn(),
                TimeElapsedColumn(),
                console=Console(stderr=True),
            )

    def __call__(self, step: str, done: float, total: float) -> None:
        if self._progress is None:
            return
        task = self._tasks.get(step)
        if task is None:
            task = self._tasks[step] = self._progress.add_task(step, total=total)
        self._progress.update(task, completed=done, total=total)

    def __enter__(self) -> StepProgress:
        if self._progress is not None:
            self._progress.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._progress is not None:
            self._progress.stop()
