"""Recording of a teleoperated motion (MCAP) and autonomous looping playback.

Channels (JSON messages, JSON schemas, so Foxglove can plot them):
``/teleop/command`` ``{t, pos, quat}`` (the full end-effector pose sent, chest frame),
``/teleop/report`` ``{t, pos, quat, gate, reason, q}`` (the robot's actual pose and joints),
``/teleop/joints`` ``{t, names, values}`` (the human joint angles and the intermediate
model's robot joints [rad], per command), ``/teleop/transition`` ``{t, from, to, reason}``.
Times [s] on the session's clock; ``log_time`` is the same in ns. With ``threaded=True``
the JSON encoding and the writing happen on a writer thread: the caller (the receiver
thread, in a live session) only queues.

Playback (Miller et al., section 5: recorded motions that begin and end near the same
configuration were looped autonomously): :func:`loop_trajectory` measures the seam
(the distance and angle between the last and first poses); when it is within
``loop_pos_m`` / ``loop_rot_rad`` the last ``blend_s`` are blended towards the start
(linear position, slerp orientation, smoothstep weight) so the loop is continuous;
otherwise the motion plays once.
"""

from __future__ import annotations

import json
import queue
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import DataError, FileFormatError
from mocapkit.geometry import quat_slerp

_POSE_SCHEMA = {
    "type": "object",
    "properties": {
        "t": {"type": "number"},
        "pos": {"type": "array", "items": {"type": "number"}},
        "quat": {"type": "array", "items": {"type": "number"}},
    },
}
_JOINTS_SCHEMA = {
    "type": "object",
    "properties": {
        "t": {"type": "number"},
        "names": {"type": "array", "items": {"type": "string"}},
        "values": {"type": "array", "items": {"type": "number"}},
    },
}
_TRANSITION_SCHEMA = {
    "type": "object",
    "properties": {k: {"type": "string"} for k in ("from", "to", "reason")}
    | {"t": {"type": "number"}},
}


class TeleopRecorder:
    """Write a session to an MCAP file; use as a context manager.

    Args:
        path: the output file.
        threaded: encode and write on a writer thread (the callers only queue).
    """

    def __init__(self, path: str | Path, threaded: bool = False) -> None:
        from mcap.writer import Writer

        self._file = open(path, "wb")  # noqa: SIM115 (closed in close())
        self._w = Writer(self._file)
        self._w.start(profile="", library="mocapkit")
        pose = self._w.register_schema(
            "mocapkit.teleop.Pose", "jsonschema", json.dumps(_POSE_SCHEMA).encode()
        )
        tr = self._w.register_schema(
            "mocapkit.teleop.Transition", "jsonschema", json.dumps(_TRANSITION_SCHEMA).encode()
        )
        joints = self._w.register_schema(
            "mocapkit.teleop.Joints", "jsonschema", json.dumps(_JOINTS_SCHEMA).encode()
        )
        self._ch = {
            "command": self._w.register_channel("/teleop/command", "json", pose),
            "report": self._w.register_channel("/teleop/report", "json", pose),
            "joints": self._w.register_channel("/teleop/joints", "json", joints),
            "transition": self._w.register_channel("/teleop/transition", "json", tr),
        }
        self._last_flush = time.monotonic()
        self._queue: queue.SimpleQueue[tuple[str, float, dict[str, Any]] | None] | None = None
        self._thread: threading.Thread | None = None
        if threaded:
            self._queue = queue.SimpleQueue()
            self._thread = threading.Thread(target=self._drain, name="teleop-recorder", daemon=True)
            self._thread.start()

    def _drain(self) -> None:
        from mocapkit.io.mcap_recovery import FLUSH_S

        assert self._queue is not None
        while True:
            try:
                item = self._queue.get(timeout=FLUSH_S)
            except queue.Empty:
                self._maybe_flush()
                continue
            if item is None:
                return
            self._encode(*item)

    def _maybe_flush(self) -> None:
        """Close a chunk at least every ``FLUSH_S`` (crash safety, see ``mcap_recovery``)."""
        from mocapkit.io.mcap_recovery import FLUSH_S

        now = time.monotonic()
        if now - self._last_flush >= FLUSH_S:
            self._w.flush()
            self._last_flush = now

    def _encode(self, channel: str, t: float, msg: dict[str, Any]) -> None:
        ns = max(0, int(t * 1e9))
        self._w.add_message(self._ch[channel], ns, json.dumps(msg).encode(), ns)
        self._maybe_flush()

    def _write(self, channel: str, t: float, msg: dict[str, Any]) -> None:
        if self._queue is not None:
            self._queue.put((channel, t, msg))
        else:
            self._encode(channel, t, msg)

    def command(self, t: float, pos: Any, quat: Any) -> None:
        self._write(
            "command", t, {"t": t, "pos": list(map(float, pos)), "quat": list(map(float, quat))}
        )

    def report(
        self, t: float, pos: Any, quat: Any, gate: str = "", reason: str = "", q: Any = ()
    ) -> None:
        self._write(
            "report",
            t,
            {"t": t, "pos": list(map(float, pos)), "quat": list(map(float, quat)), "gate": gate,
             "reason": reason, "q": list(map(float, q))},
        )  # fmt: skip

    def joints(self, t: float, names: Any, values: Any) -> None:
        self._write("joints", t, {"t": t, "names": list(names), "values": list(map(float, values))})

    def transition(self, t: float, source: str, target: str, reason: str) -> None:
        self._write("transition", t, {"t": t, "from": source, "to": target, "reason": reason})

    def close(self) -> None:
        if self._queue is not None and self._thread is not None:
            self._queue.put(None)
            self._thread.join()
            self._queue = None
        self._w.finish()
        self._file.close()

    def __enter__(self) -> TeleopRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass(frozen=True)
class Trajectory:
    """End-effector poses over time: t (N,) [s], pos (N, 3) [m], quat (N, 4) [w,x,y,z]."""

    t: FloatArray
    pos: FloatArray
    quat: FloatArray


def read_messages(path: str | Path, topic: str) -> list[dict[str, Any]]:
    """Every JSON message on ``topic`` (e.g. ``/teleop/report``), in log order (a recording
    that was never closed: up to its last complete record, with a warning)."""
    from mocapkit.io.mcap_recovery import iter_messages

    out: list[dict[str, Any]] = []
    try:
        with open(path, "rb") as f:
            for _channel, message in iter_messages(f, path, [topic]):
                out.append(json.loads(message.data))
    except (ValueError, KeyError, json.JSONDecodeError) as exc:
        raise FileFormatError(f"{path}: not a mocapkit teleop MCAP recording ({exc})") from exc
    except Exception as exc:  # mcap raises its own error types for corrupt files
        if type(exc).__module__.startswith("mcap"):
            raise FileFormatError(f"{path}: not a valid MCAP file ({exc})") from exc
        raise
    return out


def read_commands(path: str | Path) -> Trajectory:
    """The ``/teleop/command`` channel of a recording (time from its first command)."""
    msgs = read_messages(path, "/teleop/command")
    try:
        t = [m["t"] for m in msgs]
        pos = [m["pos"] for m in msgs]
        quat = [m["quat"] for m in msgs]
    except KeyError as exc:
        raise FileFormatError(f"{path}: /teleop/command message without {exc}") from exc
    if len(t) < 2:
        raise DataError(f"{path}: needs at least 2 commands on /teleop/command, found {len(t)}")
    return Trajectory(np.array(t) - t[0], np.array(pos, dtype=float), np.array(quat, dtype=float))


@dataclass(frozen=True)
class LoopCheck:
    seam_pos_m: float
    seam_rot_rad: float
    loops: bool


def loop_trajectory(
    traj: Trajectory, loop_pos_m: float = 0.03, loop_rot_rad: float = 0.35, blend_s: float = 0.5
) -> tuple[Trajectory, LoopCheck]:
    """Check the seam and blend the end into the start when the motion loops."""
    dp = float(np.linalg.norm(traj.pos[-1] - traj.pos[0]))
    dot = abs(float(traj.quat[-1] @ traj.quat[0]))
    dr = 2.0 * float(np.arccos(min(1.0, dot)))
    check = LoopCheck(dp, dr, dp <= loop_pos_m and dr <= loop_rot_rad)
    if not check.loops:
        return traj, check
    pos = traj.pos.copy()
    quat = traj.quat.copy()
    t_end = traj.t[-1]
    sel = traj.t >= t_end - blend_s
    u = np.clip((traj.t[sel] - (t_end - blend_s)) / blend_s, 0, 1)
    w = u * u * (3 - 2 * u)  # smoothstep: 0 -> 1
    pos[sel] = (1 - w)[:, None] * pos[sel] + w[:, None] * traj.pos[0]
    q0 = traj.quat[0] * np.sign(traj.quat[sel] @ traj.quat[0])[:, None]
    quat[sel] = quat_slerp(traj.quat[sel], q0, w)
    return Trajectory(traj.t, pos, quat), check


def playback_pose(traj: Trajectory, t: float, loop: bool) -> tuple[FloatArray, FloatArray]:
    """Pose (pos, quat) at time t [s] (wrapped when looping, held at the end otherwise)."""
    period = traj.t[-1] + float(np.median(np.diff(traj.t)))
    tt = t % period if loop else min(t, traj.t[-1])
    i = int(np.clip(np.searchsorted(traj.t, tt) - 1, 0, len(traj.t) - 2))
    u = float(np.clip((tt - traj.t[i]) / (traj.t[i + 1] - traj.t[i]), 0, 1))
    pos = (1 - u) * traj.pos[i] + u * traj.pos[i + 1]
    qb = traj.quat[i + 1] * np.sign(traj.quat[i] @ traj.quat[i + 1])
    return pos, quat_slerp(traj.quat[i], qb, u)
