"""Entry point of the ``mocapkit`` command (``main(argv)`` for in-process tests)."""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

from mocapkit import __version__
from mocapkit.cli.common import (
    EXIT_ERROR,
    EXIT_INTERRUPTED,
    EXIT_MISSING_DEPENDENCY,
    EXIT_OK,
)
from mocapkit.errors import MissingDependencyError, MocapkitError

# Each module adds one command group with ``register(subparsers)``.
_COMMAND_MODULES: tuple[str, ...] = (
    "mocapkit.cli.body_cmd",
    "mocapkit.cli.demo_cmd",
    "mocapkit.cli.imu_cmd",
    "mocapkit.cli.markers_cmd",
    "mocapkit.cli.suit_cmd",
    "mocapkit.cli.teleop_cmd",
    "mocapkit.cli.viewer_cmd",
)

_EPILOG = """\
exit codes: 0 success, 1 failed on the input (the message says why and how to fix it),
2 wrong arguments, 3 an optional dependency is missing, 130 interrupted.

examples:
  mocapkit imu evaluate ../shared/data/broad --filter polaris --json
  mocapkit demo
"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mocapkit",
        description="Human motion capture to humanoid joint angles and robot commands.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"mocapkit {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod_name in _COMMAND_MODULES:
        importlib.import_module(mod_name).register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code (never calls sys.exit)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or a usage error (2)
        return int(exc.code or 0)
    logging.basicConfig(
        level=logging.WARNING - 10 * min(args.verbose, 2),
        format="%(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return EXIT_OK if args.command is None else EXIT_ERROR
    try:
        return int(args.func(args) or EXIT_OK)
    except MissingDependencyError as exc:
        print(f"mocapkit: {exc}", file=sys.stderr)
        return EXIT_MISSING_DEPENDENCY
    except MocapkitError as exc:
        print(f"mocapkit: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except FileNotFoundError as exc:
        print(f"mocapkit: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print("mocapkit: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def run() -> None:
    """Console-script entry point."""
    sys.exit(main())
