"""Network and robot faults injected into a live session: what it did, how long to recover.

    python -m benchmarks.teleop_faults [--write-docs]

The simulated operator's suit (right arm and torso, RAW datagrams fused on the host,
consumer-grade errors) streams through a UDP relay into the live session, which drives a
robot-server process. Once the session is engaged the relay injects, one after the
other, with 8 s of clean stream between them:

- a burst of packet loss (every datagram dropped for 0.5 s);
- reordering (each pair of datagrams swapped, for 2 s);
- duplicates (every datagram sent twice, for 2 s);
- forged datagrams (random bytes and valid-looking suit packets with a wrong CRC,
  five per real one, for 2 s);
- a sensor unplugged (the forearm's datagrams dropped for 2 s, then back);
- the robot server killed (SIGKILL) and restarted on its port 2 s later.

For each: the session's transitions from the fault's start until it is engaged again
(with their reasons), the time from the fault's end until it is engaged again, and what
the receiver dropped, by reason. A fault that needs no hold (duplicates, forged
datagrams, reordering within the receiver's window) should leave the session engaged.
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import socket
import threading
import time
from typing import Any

from benchmarks._docs import write_section
from mocapkit.suit.errors import ProtocolError
from mocapkit.suit.protocol import decode, encode_orientation
from mocapkit.teleop.server import spawn_robot_server
from mocapkit.teleop.simulated import SimulatedConfig, SimulatedSession

GAP_S = 8.0
FAULTS: tuple[tuple[str, float], ...] = (
    ("loss burst", 0.5),
    ("reordering", 2.0),
    ("duplicates", 2.0),
    ("forged datagrams", 2.0),
    ("sensor unplugged", 2.0),
    ("robot server killed", 2.0),
)


class Relay:
    """A UDP relay in front of the session's suit port that applies ``self.mode``."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.port = int(self.sock.getsockname()[1])
        self.target: tuple[str, int] | None = None
        self.mode = "clean"
        self.unplugged_id = 0
        self._held: bytes | None = None
        self._rng = random.Random(0)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fault-relay", daemon=True)

    def start(self) -> Relay:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.sock.close()

    def _send(self, data: bytes) -> None:
        if self.target is not None:
            self.sock.sendto(data, self.target)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data, _ = self.sock.recvfrom(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            mode = self.mode
            if mode == "loss burst":
                continue
            if mode == "reordering":
                if self._held is None:
                    self._held = data
                else:
                    self._send(data)
                    self._send(self._held)
                    self._held = None
                continue
            if self._held is not None:
                self._send(self._held)
                self._held = None
            if mode == "duplicates":
                self._send(data)
                self._send(data)
            elif mode == "forged datagrams":
                for _ in range(5):
                    if self._rng.random() < 0.5:
                        self._send(bytes(self._rng.getrandbits(8) for _ in range(40)))
                    else:
                        fake = bytearray(encode_orientation(2, 1, 0, [0.0, 1.0, 0.0, 0.0]))
                        fake[-1] ^= 0xFF  # a wrong CRC
                        self._send(bytes(fake))
                self._send(data)
            elif mode == "sensor unplugged":
                try:
                    sid = decode(data).sensor_id
                except ProtocolError:  # not ours to judge: pass it on
                    sid = -1
                if sid != self.unplugged_id:
                    self._send(data)
            else:
                self._send(data)


def _wait_engaged(sim: SimulatedSession, timeout_s: float) -> float | None:
    """Seconds until the session is engaged (None: not within ``timeout_s``)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        if sim.snapshot().get("state") == "engaged":
            return time.monotonic() - t0
        time.sleep(0.02)
    return None


def run() -> list[dict[str, Any]]:
    relay = Relay().start()
    cfg = SimulatedConfig(auto_engage=True, send_port=relay.port, shape_s=8.0)
    rows: list[dict[str, Any]] = []
    try:
        with SimulatedSession(cfg) as sim:
            assert sim.live is not None
            relay.target = ("127.0.0.1", sim.live.suit_port)
            relay.unplugged_id = sim.live.pipeline.sensor_ids["forearm_r"]
            if _wait_engaged(sim, 30.0) is None:
                raise RuntimeError("the session never engaged")
            for name, length in FAULTS:
                time.sleep(GAP_S)
                if sim.snapshot().get("state") != "engaged":
                    # the operator's shape left the robot's reach meanwhile (the session
                    # stopped following, as it should): engage again before the next fault
                    sim.live.disengage()
                    sim.live.engage()
                    _wait_engaged(sim, 10.0)
                before = sim.snapshot()
                n_tr = len(sim.live.session.transitions)
                dropped0 = dict(before.get("dropped", {}))
                if name == "robot server killed":
                    assert sim.server is not None
                    port = sim.server.port
                    os.kill(sim.server.proc.pid, signal.SIGKILL)
                    sim.server.proc.wait()
                    time.sleep(length)
                    sim.server = spawn_robot_server(cfg.server, max_seconds=600.0, port=port)
                else:
                    relay.mode = name
                    time.sleep(length)
                    relay.mode = "clean"
                back = _wait_engaged(sim, 20.0)
                after = sim.snapshot()
                trs = [
                    f"{t.source.value} -> {t.target.value}: {t.reason}"
                    for t in sim.live.session.transitions[n_tr:]
                ]
                dropped = {
                    k: v - dropped0.get(k, 0)
                    for k, v in after.get("dropped", {}).items()
                    if v - dropped0.get(k, 0)
                }
                rows.append({"fault": name, "length_s": length, "transitions": trs,
                             "engaged_after_s": back, "dropped": dropped,
                             "state_before": before.get("state")})  # fmt: skip
                print(rows[-1], flush=True)
    finally:
        relay.stop()
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    rows = run()
    lines = [
        "| fault | length | what the session did | engaged again after the fault ended | "
        "receiver dropped |",
        "|---|---:|---|---:|---|",
    ]
    for r in rows:
        did = "<br>".join(r["transitions"]) or "stayed engaged"
        back = "never (20 s)" if r["engaged_after_s"] is None else f"{r['engaged_after_s']:.2f} s"
        dropped = ", ".join(f"{k} {v}" for k, v in sorted(r["dropped"].items())) or "-"
        lines.append(f"| {r['fault']} | {r['length_s']:g} s | {did} | {back} | {dropped} |")
    text = (
        "`python -m benchmarks.teleop_faults` (method in the module docstring; the right "
        "arm and torso, 100 Hz, host fusion).\n\n" + "\n".join(lines)
    )
    print(text)
    if args.write_docs:
        write_section("Teleoperation under network and robot faults", text)


if __name__ == "__main__":
    main()
