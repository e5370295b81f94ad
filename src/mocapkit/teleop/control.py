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
``{"ok": false, "error": ...}``; ``status`` returns the snapshot) to its sender; it binds to
loopback by default: it steers a robot.
"""

from __future__ import annotations

import json
import logging
import socket
import threading
from collections.abc import Callable
from typing import IO, Any

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

    def __init__(self, controls: Controls, host: str = "127.0.0.1", port: int = 0) -> None:
        self.controls = controls
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
            reply = self.controls.apply(data.decode("utf-8", "replace"))
            try:
                self.sock.sendto(json.dumps(reply).encode(), addr)
            except OSError as exc:
                log.debug("control reply to %s failed: %s", addr, exc)

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


def read_keys(controls: Controls, stream: IO[str], stop: threading.Event) -> None:
    """Apply one command per line of ``stream`` until it ends or ``stop`` is set (run it on
    a daemon thread)."""
    for line in stream:
        if stop.is_set():
            return
        reply = controls.apply(line)
        log.info("%s", json.dumps(reply))
