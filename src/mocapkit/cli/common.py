"""Shared CLI pieces: exit codes, JSON output, progress bars, the error wrapper."""

from __future__ import annotations

import json
import sys
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
