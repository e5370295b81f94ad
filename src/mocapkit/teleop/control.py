"""Operator controls for a live session: keyboard lines on stdin and a UDP control socket.

Both call the thread-safe :class:`~mocapkit.teleop.live.LiveSession` API. Commands (one
per line or datagram, case-insensitive):

=============================  ==============================================
``calibrate`` / ``c``          hold the calibration pose (N-pose) now
``engage`` / ``e``             follow the operator (reindexing first)
``disengage`` / ``d``          stop following; the robot holds
``reindex`` / ``r``            new operator-to-robot offset (Fig. 10)
``clutch on|off`` / ``space``  hold the robot while the operator moves (toggle)
``status`` / ``s``             the session's snapshot (JSON)
``quit`` / ``q``               end the session
=============================  ==============================================

The control socket answers every datagram with one JSON object (``{"ok": true, ...}`` or
``{"ok": false, "error": ...}``; ``status`` returns the snapshot) to its sender. It steers
a robot, so:

- it binds to loopback by default; on any other address it needs a shared ``key``, and
  then every datagram is ``SEQ COMMAND`` followed by a newline and the hex HMAC-SHA256 of
  ``SEQ COMMAND`` under the key, with ``SEQ`` increasing (a replayed or forged datagram is
  refused and logged);
- the first sender whose datagram is accepted is the paired controller; datagrams from
  any other address are refused;
- an empty datagram is refused (on the keyboard a bare Enter toggles the clutch; on a
  network, one stray empty packet must not).
"""

from __future__ import annotations

import hashlib
import hmac
import json
import logging
import socket
import threading
from collections.abc import Callable
from typing import IO, Any

from mocapkit.cli.boundary import is_loopback
from mocapkit.errors import ConfigError, MocapkitError
from mocapkit.teleop.live import LiveSession

log = logging.getLogger("mocapkit.teleop.control")

_ALIASES = {
    "c": "calibrate",
    "e": "engage",
    "d": "disengage",
    "r": "reindex",
    "s": "status",
    "q": "quit",
    "": "clutch",  # a bare Enter (space + Enter reads as empty too): clutch toggle
    "space": "clutch",
}


class Controls:
    """Parses operator commands and applies them to a session.

    Args:
        live: the session.
        on_quit: called on ``quit``.
    """

    def __init__(self, live: LiveSession, on_quit: Callable[[], None]) -> None:
        self.live = live
        self.on_quit = on_quit
        self._clutched = False

    def apply(self, text: str) -> dict[str, Any]:
        """Run one command; returns the reply (``ok`` and details)."""
        words = text.strip().lower().split()
        name = _ALIASES.get(words[0] if words else "", words[0] if words else "clutch")
        try:
            if name == "calibrate":
                calib = self.live.calibrate(wait=True)
                heading = None if calib is None else calib.heading_rad
                return {"ok": True, "command": name, "heading_rad": heading}
            if name == "engage":
                self.live.engage()
            elif name == "disengage":
                self.live.disengage()
            elif name == "reindex":
                self.live.reindex()
            elif name == "clutch":
                if len(words) > 1 and words[1] in ("on", "off"):
                    self._clutched = words[1] == "on"
                else:
                    self._clutched = not self._clutched
                self.live.clutch(self._clutched)
                return {"ok": True, "command": name, "pressed": self._clutched}
            elif name == "status":
                return {"ok": True, "command": name, "status": self.live.snapshot()}
            elif name == "quit":
                self.on_quit()
            else:
                raise ConfigError(
                    f"unknown command {text.strip()!r}; use calibrate, engage, disengage, "
                    "reindex, clutch [on|off], status or quit"
                )
        except MocapkitError as exc:
            log.warning("%s: %s", name, exc)
            return {"ok": False, "command": name, "error": str(exc)}
        return {"ok": True, "command": name}


class ControlSocket:
    """A UDP control socket on ``host:port`` served by a thread; use as a context manager."""

    def __init__(
        self, controls: Controls, host: str = "127.0.0.1", port: int = 0, key: bytes | None = None
    ) -> None:
        if key is None and not is_loopback(host):
            raise ConfigError(
                f"control host {host}: the control socket steers a robot; off loopback it "
                "needs a shared key (signed datagrams), or bind it to 127.0.0.1"
            )
        self.controls = controls
        self.key = key
        self.peer: tuple[str, int] | None = None
        self._last_seq = -1
        self.refused = 0
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind((host, port))
        except OSError as exc:
            self.sock.close()
            raise ConfigError(f"control port: cannot bind UDP {host}:{port} ({exc})") from exc
        self.sock.settimeout(0.1)
        self.port = int(self.sock.getsockname()[1])
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="teleop-control", daemon=True)

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                data, addr = self.sock.recvfrom(1024)
            except TimeoutError:
                continue
            except OSError:
                return
            text, why = self._accept(data, addr)
            if why is not None:
                self.refused += 1
                log.warning("control datagram from %s refused: %s", addr, why)
                reply: dict[str, Any] = {"ok": False, "error": why}
            else:
                reply = self.controls.apply(text)
            try:
                self.sock.sendto(json.dumps(reply).encode(), addr)
            except OSError as exc:
                log.debug("control reply to %s failed: %s", addr, exc)

    def _accept(self, data: bytes, addr: tuple[str, int]) -> tuple[str, str | None]:
        """The command of a datagram, or why it is refused."""
        if self.peer is not None and addr != self.peer:
            return "", f"not the paired controller ({self.peer[0]}:{self.peer[1]})"
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            return "", "not UTF-8 text"
        if self.key is not None:
            body, _, mac = text.rpartition("\n")
            expected = hmac.new(self.key, body.encode(), hashlib.sha256).hexdigest()
            if not hmac.compare_digest(mac.strip(), expected):
                return "", "bad signature (HMAC-SHA256 of 'SEQ COMMAND' under the shared key)"
            seq_text, _, text = body.partition(" ")
            if not seq_text.isdigit() or int(seq_text) <= self._last_seq:
                return "", f"sequence {seq_text!r} not above {self._last_seq} (a replay?)"
            self._last_seq = int(seq_text)
        if not text.strip():
            return "", "empty command (send 'clutch' to toggle the clutch)"
        self.peer = addr
        return text, None

    def start(self) -> ControlSocket:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)
        self.sock.close()

    def __enter__(self) -> ControlSocket:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def sign(key: bytes, seq: int, command: str) -> bytes:
    """A signed control datagram (see the module docstring)."""
    body = f"{seq} {command}"
    return f"{body}\n{hmac.new(key, body.encode(), hashlib.sha256).hexdigest()}".encode()


def read_keys(controls: Controls, stream: IO[str], stop: threading.Event) -> None:
    """Apply one command per line of ``stream`` until it ends or ``stop`` is set (run it on
    a daemon thread)."""
    for line in stream:
        if stop.is_set():
            return
        reply = controls.apply(line)
        log.info("%s", json.dumps(reply))
