"""The warnings mocapkit logs while some work runs, collected in order (the Python API
returns them with its result, as the command line prints them)."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def logged_warnings() -> Iterator[list[str]]:
    """``with logged_warnings() as warned:``: every WARNING (or worse) the ``mocapkit``
    loggers emit inside the block, appended to ``warned`` as it is logged."""
    warned: list[str] = []

    class _Collect(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            if record.levelno >= logging.WARNING:
                warned.append(record.getMessage())

    handler = _Collect()
    logger = logging.getLogger("mocapkit")
    logger.addHandler(handler)
    try:
        yield warned
    finally:
        logger.removeHandler(handler)
