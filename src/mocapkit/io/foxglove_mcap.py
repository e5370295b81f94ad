"""MCAP channels in Foxglove's well-known schemas (JSON encoding), and a reader.

Foxglove Studio draws a message in 3-D when its schema is one of its own: here
``foxglove.FrameTransforms`` (a batch of parent -> child transforms: the body segments,
the sensors, the robot links) and ``foxglove.PoseInFrame`` (one pose in a named frame:
the commanded and reported end effector). Messages are JSON with ``jsonschema``
schemas, which Foxglove decodes without any plug-in; quaternions are written in its
``{x, y, z, w}`` order, converted from ours ``[w, x, y, z]`` only here; timestamps are
``{sec, nsec}``; positions in metres.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.errors import FileFormatError

_TIME = {
    "type": "object",
    "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
}
_VEC = {
    "type": "object",
    "properties": {k: {"type": "number"} for k in ("x", "y", "z")},
}
_QUAT = {
    "type": "object",
    "properties": {k: {"type": "number"} for k in ("x", "y", "z", "w")},
}
_FRAME_TRANSFORM = {
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "parent_frame_id": {"type": "string"},
        "child_frame_id": {"type": "string"},
        "translation": _VEC,
        "rotation": _QUAT,
    },
}
SCHEMAS: dict[str, dict[str, Any]] = {
    "foxglove.FrameTransforms": {
        "title": "foxglove.FrameTransforms",
        "type": "object",
        "properties": {"transforms": {"type": "array", "items": _FRAME_TRANSFORM}},
    },
    "foxglove.PoseInFrame": {
        "title": "foxglove.PoseInFrame",
        "type": "object",
        "properties": {
            "timestamp": _TIME,
            "frame_id": {"type": "string"},
            "pose": {
                "type": "object",
                "properties": {"position": _VEC, "orientation": _QUAT},
            },
        },
    },
    # not a Foxglove schema: joint positions by name (a ROS JointState's name/position)
    "mocapkit.JointPositions": {
        "title": "mocapkit.JointPositions",
        "type": "object",
        "properties": {
            "timestamp": _TIME,
            "name": {"type": "array", "items": {"type": "string"}},
            "position": {"type": "array", "items": {"type": "number"}},
        },
    },
}


def _stamp(t_ns: int) -> dict[str, int]:
    return {"sec": int(t_ns // 1_000_000_000), "nsec": int(t_ns % 1_000_000_000)}


def _vec(v: Any) -> dict[str, float]:
    a = np.asarray(v, dtype=float)
    return {"x": float(a[0]), "y": float(a[1]), "z": float(a[2])}


def _quat(q_wxyz: Any) -> dict[str, float]:
    q = np.asarray(q_wxyz, dtype=float)
    return {"x": float(q[1]), "y": float(q[2]), "z": float(q[3]), "w": float(q[0])}


class FoxgloveMcapWriter:
    """Write Foxglove-schema channels to an MCAP file (use as a context manager).

    Args:
        path: the ``.mcap`` file (overwritten).
        profile: the MCAP profile string (empty: none).
    """

    def __init__(self, path: str | Path, profile: str = "") -> None:
        from mcap.writer import CompressionType, Writer

        self.path = Path(path)
        self._file = self.path.open("wb")
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile=profile, library="mocapkit")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._seq: dict[str, int] = {}
        self.messages = 0

    def _channel(self, topic: str, schema: str) -> int:
        if topic not in self._channels:
            if schema not in self._schemas:
                self._schemas[schema] = self._writer.register_schema(
                    name=schema, encoding="jsonschema", data=json.dumps(SCHEMAS[schema]).encode()
                )
            self._channels[topic] = self._writer.register_channel(
                topic=topic, message_encoding="json", schema_id=self._schemas[schema]
            )
            self._seq[topic] = 0
        return self._channels[topic]

    def _write(self, topic: str, schema: str, t_ns: int, msg: dict[str, Any]) -> None:
        ch = self._channel(topic, schema)
        self._writer.add_message(
            channel_id=ch,
            log_time=int(t_ns),
            publish_time=int(t_ns),
            sequence=self._seq[topic],
            data=json.dumps(msg, separators=(",", ":")).encode(),
        )
        self._seq[topic] += 1
        self.messages += 1

    def frame_transforms(
        self,
        topic: str,
        t_ns: int,
        transforms: Iterable[tuple[str, str, Any, Any]],
    ) -> None:
        """``(parent, child, translation (3,) [m], q_parent_child (4,) [w,x,y,z])`` each.
        Transforms with a non-finite value (a lost segment) are left out."""
        items = []
        for parent, child, p, q in transforms:
            if not (np.isfinite(p).all() and np.isfinite(q).all()):
                continue
            items.append(
                {
                    "timestamp": _stamp(t_ns),
                    "parent_frame_id": parent,
                    "child_frame_id": child,
                    "translation": _vec(p),
                    "rotation": _quat(q),
                }
            )
        self._write(topic, "foxglove.FrameTransforms", t_ns, {"transforms": items})

    def pose_in_frame(self, topic: str, t_ns: int, frame_id: str, position: Any, q: Any) -> None:
        """One pose (position [m], orientation [w, x, y, z]) in ``frame_id``."""
        msg = {
            "timestamp": _stamp(t_ns),
            "frame_id": frame_id,
            "pose": {"position": _vec(position), "orientation": _quat(q)},
        }
        self._write(topic, "foxglove.PoseInFrame", t_ns, msg)

    def joint_positions(self, topic: str, t_ns: int, names: Sequence[str], positions: Any) -> None:
        """Joint positions [rad, m] by name (``mocapkit.JointPositions``)."""
        msg = {
            "timestamp": _stamp(t_ns),
            "name": list(names),
            "position": [float(x) for x in positions],
        }
        self._write(topic, "mocapkit.JointPositions", t_ns, msg)

    def close(self) -> None:
        self._writer.finish()
        self._file.close()

    def __enter__(self) -> FoxgloveMcapWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_foxglove_mcap(
    path: str | Path, topics: Sequence[str] | None = None
) -> dict[str, list[tuple[int, str, dict[str, Any]]]]:
    """``{topic: [(log_time_ns, schema name, decoded JSON message), ...]}`` in file order.

    Raises:
        FileFormatError: not an MCAP file, or a channel that is not JSON.
    """
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    out: dict[str, list[tuple[int, str, dict[str, Any]]]] = {}
    p = Path(path)
    try:
        with p.open("rb") as f:
            for schema, channel, message in make_reader(f).iter_messages(topics=topics):
                if channel.message_encoding != "json":
                    raise FileFormatError(
                        f"{p}: channel {channel.topic!r} is {channel.message_encoding!r}, not json"
                    )
                name = schema.name if schema is not None else ""
                out.setdefault(channel.topic, []).append(
                    (message.log_time, name, json.loads(message.data))
                )
    except McapError as exc:
        raise FileFormatError(f"{p}: not a readable MCAP file ({exc})") from exc
    return out
