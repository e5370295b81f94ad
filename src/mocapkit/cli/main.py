"""Entry point of the ``mocapkit`` command (``main(argv)`` for in-process tests)."""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence
from typing import Any

from mocapkit import __version__
from mocapkit.cli.boundary import (
    REPORT_URL,
    check_outputs_are_not_inputs,
    describe_decode_error,
    describe_os_error,
)
from mocapkit.cli.common import (
    EXIT_ERROR,
    EXIT_INTERRUPTED,
    EXIT_MISSING_DEPENDENCY,
    EXIT_OK,
)
from mocapkit.errors import MissingDependencyError, MocapkitError

# Each module adds one command group with ``register(subparsers)``. The help line is
# repeated here so that ``mocapkit --help`` and the parser of one command never import the
# other command modules (and their numpy/scipy/numba/matplotlib): a command starts with
# only what it uses. tests/cli/test_help.py checks that each line equals the module's own.
_COMMANDS: dict[str, tuple[str, str]] = {
    "batch": (
        "mocapkit.cli.batch_cmd",
        "a single-file command over many recordings (local processes or Ray)",
    ),
    "body": ("mocapkit.cli.body_cmd", "sensor orientations -> body joint angles"),
    "demo": (
        "mocapkit.cli.demo_cmd",
        "run the whole pipeline on bundled data and write an HTML report",
    ),
    "export": (
        "mocapkit.cli.export_cmd",
        "recordings and results into other tools' formats (ROS 2 bags)",
    ),
    "imu": ("mocapkit.cli.imu_cmd", "inertial orientation: evaluate, run, calibrate"),
    "markers": (
        "mocapkit.cli.markers_cmd",
        "optical markers: reconstruct joint angles, report, inspect",
    ),
    "retarget": (
        "mocapkit.cli.retarget_cmd",
        "a recording (markers, joint angles, IMUs) onto a humanoid robot",
    ),
    "robot": ("mocapkit.cli.robot_cmd", "humanoid robots for retargeting: list them"),
    "suit": (
        "mocapkit.cli.suit_cmd",
        "the motion suit: simulate, receive, record, replay, benchmark",
    ),
    "teleop": (
        "mocapkit.cli.teleop_cmd",
        ("robot teleoperation: six-shape evaluation, live session, robot server, playback"),
    ),
    "view": (
        "mocapkit.cli.view_cmd",
        "recordings and results in the browser (viser), side by side on a timeline",
    ),
    "viewer": (
        "mocapkit.cli.viewer_cmd",
        ("live web viewer (viser) of a teleoperation session, with its controls"),
    ),
}
_COMMAND_MODULES: tuple[str, ...] = tuple(mod for mod, _ in _COMMANDS.values())

_EPILOG = """\
exit codes: 0 success, 1 failed on the input (the message says why and how to fix it),
2 wrong arguments, 3 an optional dependency is missing, 130 interrupted.

examples:
  mocapkit imu evaluate ../shared/data/broad --filter polaris --json
  mocapkit demo
"""


def _command_of(argv: Sequence[str]) -> str | None:
    """The command group named on the command line (the first non-option word), if any."""
    for word in argv:
        if word in _COMMANDS:
            return word
        if not word.startswith("-"):
            return None
    return None


def build_parser(only: str | None = None, *, every: bool = False) -> argparse.ArgumentParser:
    """The ``mocapkit`` parser. ``only``: register that command group in full and the others
    as one-line placeholders (what :func:`main` does, so a command imports only its own
    module); ``every``: register every group in full (tests walk it)."""
    parser = argparse.ArgumentParser(
        prog="mocapkit",
        description="Human motion capture to humanoid joint angles and robot commands.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"mocapkit {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (mod_name, help_line) in _COMMANDS.items():
        if every or name == only:
            importlib.import_module(mod_name).register(sub)
        else:
            sub.add_parser(name, help=help_line, add_help=False)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code (never calls sys.exit)."""
    args_list = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(_command_of(args_list))
    try:
        args = parser.parse_args(args_list)
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
        check_outputs_are_not_inputs(args)
        return int(args.func(args) or EXIT_OK)
    except MissingDependencyError as exc:
        print(f"mocapkit: {exc}", file=sys.stderr)
        return EXIT_MISSING_DEPENDENCY
    except MocapkitError as exc:
        print(f"mocapkit: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print("mocapkit: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except OSError as exc:  # disk full, permissions, a directory, a port in use...
        print(f"mocapkit: error: {describe_os_error(exc)}", file=sys.stderr)
        return EXIT_ERROR
    except Exception as exc:  # the boundary: decode errors, else a bug
        decoded = describe_decode_error(exc)
        if decoded is not None:
            print(f"mocapkit: error: {decoded}", file=sys.stderr)
            return EXIT_ERROR
        if args.verbose:
            import traceback

            traceback.print_exc()
        print(
            f"mocapkit: internal error ({type(exc).__name__}: {exc}). This is a bug in "
            f"mocapkit {__version__}; please report it with the command line at "
            f"{REPORT_URL} (add -v for the traceback)",
            file=sys.stderr,
        )
        return EXIT_ERROR


def _one_line_warnings() -> None:
    """Warnings (a time gap, a saturated gyroscope...) as one line a user reads, not the
    source line that raised them."""
    import warnings

    def show(message: Any, category: Any, filename: Any, lineno: Any, file: Any = None,
             line: Any = None) -> None:  # fmt: skip
        print(f"mocapkit: warning: {message}", file=sys.stderr)

    warnings.showwarning = show


def _stop_signals_interrupt() -> None:
    """SIGTERM (a service stop, ``timeout``, ``kill``) and SIGHUP (a closed terminal) stop
    a command like Ctrl-C: its ``finally`` blocks close the recordings and sockets, so an
    MCAP file is finished, not left without its summary."""
    import signal

    def interrupt(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt(signal.Signals(signum).name)

    for name in ("SIGTERM", "SIGHUP"):
        sig = getattr(signal, name, None)
        if sig is not None:
            signal.signal(sig, interrupt)


def run() -> None:
    """Console-script entry point.

    Ends with ``os._exit`` once the exit handlers have run and the streams are flushed:
    tearing down the interpreter's modules (numba's LLVM objects, Pinocchio) took ~0.5 s
    after the files were written, a third of a short command's wall time. Every output file
    is closed by the command itself before ``main`` returns."""
    import atexit
    import contextlib
    import os

    _one_line_warnings()
    _stop_signals_interrupt()
    code = main()
    logging.shutdown()
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):  # a closed pipe: nothing more to say
            stream.flush()
    os._exit(code)
