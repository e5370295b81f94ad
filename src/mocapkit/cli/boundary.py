"""The command line's one error boundary: what reaches the user when a command fails.

- mocapkit's own errors already name the field, sample or file and the fix;
- operating-system errors (disk full, permission denied, a directory where a file is
  expected, the parent of ``-o`` being a file, a port in use or not on this machine)
  become one line naming the file or address and the fix (:func:`describe_os_error`);
- decode errors from the libraries we read with (YAML, JSON, zstd, MCAP, C3D, text that
  is not UTF-8) become one line naming the file when it is known;
- anything else is a bug: one line saying so and where to report it, with the
  traceback only under ``-v``.

Before a command runs, :func:`check_outputs_are_not_inputs` refuses an output path that
is also one of its inputs (``-o`` pointing at the recording would destroy it).
"""

from __future__ import annotations

import argparse
import errno
from pathlib import Path

from mocapkit.errors import ConfigError

REPORT_URL = "https://github.com/mocapkit/mocapkit/issues"

#: argparse destinations that name files a command reads ...
INPUT_ATTRS = (
    "recording",
    "path",
    "trial",
    "file",
    "directory",
    "static",
    "placement",
    "tree",
    "calibration_in",
    "markerset",
)
#: ... and files or folders it writes.
OUTPUT_ATTRS = (
    "output",
    "out",
    "record",
    "segments",
    "bvh",
    "calibration_out",
    "osim",
    "tracked_trc",
    "tracked_c3d",
    "save_markerset",
    "plot",
)

_FIXES = {
    errno.ENOSPC: "the disk is full; free some space or write elsewhere",
    errno.EDQUOT: "the disk quota is exhausted; free some space or write elsewhere",
    errno.EACCES: "permission denied; choose a path you may use or change its permissions",
    errno.EPERM: "operation not permitted; choose a path you may use",
    errno.EROFS: "the file system is read-only; write elsewhere",
    errno.EISDIR: "this is a directory, a file is expected here",
    errno.ENOTDIR: "a part of this path is a file, not a directory; fix the path",
    errno.ENOENT: "no such file or directory",
    errno.EADDRINUSE: "the port is in use by another program; choose another --port or stop it",
    errno.EADDRNOTAVAIL: "this address is not on this machine; use --host 127.0.0.1 or 0.0.0.0",
    errno.ECONNREFUSED: "nothing listens there; start the server first or check --host/--port",
    errno.EMFILE: "too many open files; raise the limit (ulimit -n) or open fewer files",
}


def describe_os_error(exc: OSError) -> str:
    """One line: the file or address, what went wrong, and the fix."""
    fix = _FIXES.get(exc.errno or -1, exc.strerror or str(exc))
    where = exc.filename if exc.filename is not None else None
    if where is None:
        return f"{fix} ({exc.strerror or exc})" if exc.strerror and exc.strerror not in fix else fix
    second = f" -> {exc.filename2}" if exc.filename2 else ""
    return f"{where}{second}: {fix}"


def describe_decode_error(exc: BaseException) -> str | None:
    """One line for an error raised while decoding a file's content, or None when ``exc``
    is not a decode error."""
    kind = type(exc)
    module = kind.__module__.split(".")[0]
    if isinstance(exc, UnicodeDecodeError):
        return f"not UTF-8 text ({exc.reason} at byte {exc.start}); is it the right file?"
    if module == "yaml":
        return f"not valid YAML: {exc}; fix the file (a YAML linter shows the line)"
    if module == "json" or kind.__name__ == "JSONDecodeError":
        return f"not valid JSON: {exc}; fix the file"
    if module in ("zstandard", "lz4"):
        return f"a compressed block is corrupt ({kind.__name__}: {exc}); the file is damaged"
    if module == "mcap":
        return f"not a valid MCAP file ({kind.__name__}: {exc})"
    if module == "ezc3d" or "c3d" in str(exc).lower():
        return f"not a readable C3D file ({exc})"
    return None


def _paths(args: argparse.Namespace, names: tuple[str, ...]) -> list[tuple[str, Path]]:
    out = []
    for name in names:
        value = getattr(args, name, None)
        if isinstance(value, (str, Path)) and str(value):
            out.append((name, Path(value)))
    return out


def check_outputs_are_not_inputs(args: argparse.Namespace) -> None:
    """Refuse an output that is one of the inputs, or two outputs that are one file."""
    inputs = [(n, p) for n, p in _paths(args, INPUT_ATTRS) if p.exists()]
    outputs = _paths(args, OUTPUT_ATTRS)
    for out_name, out in outputs:
        for in_name, src in inputs:
            if out.exists() and src.exists() and out.resolve() == src.resolve():
                raise ConfigError(
                    f"--{out_name.replace('_', '-')}: {out} is also the input "
                    f"({in_name.replace('_', ' ')}); writing it would destroy the input. "
                    "Choose another output path"
                )
    seen: dict[Path, str] = {}
    for out_name, out in outputs:
        key = out.resolve()
        if key in seen:
            raise ConfigError(
                f"--{out_name.replace('_', '-')}: {out} is also --{seen[key].replace('_', '-')}; "
                "give each output its own path"
            )
        seen[key] = out_name


def is_loopback(host: str) -> bool:
    """Whether ``host`` is this machine's loopback (127.0.0.0/8, ::1, ``localhost``)."""
    import ipaddress

    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def port(text: str) -> int:
    """argparse type of a UDP/TCP port: an integer 0..65535 (0: any free port)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port number 0..65535, got {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port number 0..65535, got {value}")
    return value
