"""How the demo reports progress: ``progress(step, done, total)`` (the CLI draws bars)."""

from __future__ import annotations

from collections.abc import Callable

#: ``(step name, amount done, total)``; the units are the step's own (s, frames, plots)
Progress = Callable[[str, float, float], None]


def no_progress(step: str, done: float, total: float) -> None:
    """A :data:`Progress` that shows nothing."""
