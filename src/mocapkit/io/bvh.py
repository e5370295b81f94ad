"""BVH (Biovision hierarchy) files: write and read a skeleton and its motion. No maths
here: the channels are written as given (rotations in degrees, positions in the file's
length unit); :mod:`mocapkit.body.skeleton` turns segment orientations into channels.

Layout: ``HIERARCHY`` with nested ``ROOT`` / ``JOINT`` blocks (``OFFSET x y z``,
``CHANNELS n ...``, optional ``End Site``), then ``MOTION`` with ``Frames:``,
``Frame Time:`` and one line of channel values per frame, in hierarchy order.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray, check_shape
from mocapkit.errors import FileFormatError, ShapeError
from mocapkit.io._text_table import read_text

_VALID_CHANNELS = {"Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation"}


@dataclass(frozen=True)
class BvhJoint:
    """One joint: name, parent index (-1 for the root), offset from the parent, channels."""

    name: str
    parent: int
    offset: FloatArray
    channels: tuple[str, ...]
    end_site: FloatArray | None = None


@dataclass(frozen=True)
class BvhMotion:
    """A BVH file's content.

    Attributes:
        joints: in file (depth-first) order.
        frame_time: [s].
        values: (N, total channels) in joint order, each joint's channels in its order.
    """

    joints: tuple[BvhJoint, ...]
    frame_time: float
    values: FloatArray
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return int(self.values.shape[0])

    def channel_slices(self) -> dict[str, slice]:
        """{joint name: slice of its channels in ``values``}."""
        out, k = {}, 0
        for j in self.joints:
            out[j.name] = slice(k, k + len(j.channels))
            k += len(j.channels)
        return out

    def joint_channels(self, name: str) -> FloatArray:
        """(N, n) values of one joint's channels."""
        sl = self.channel_slices()
        if name not in sl:
            raise FileFormatError(
                f"no joint {name!r} in the BVH; joints: {', '.join(j.name for j in self.joints)}"
            )
        return self.values[:, sl[name]]


def _check(motion: BvhMotion) -> None:
    n_ch = sum(len(j.channels) for j in motion.joints)
    check_shape(motion.values, "values", None, n_ch)
    names = [j.name for j in motion.joints]
    for i, j in enumerate(motion.joints):
        if not j.name or any(c.isspace() for c in j.name):
            raise ShapeError(
                f"joints[{i}]: BVH joint names cannot be empty or contain spaces: {j.name!r}"
            )
        bad = [c for c in j.channels if c not in _VALID_CHANNELS]
        if bad:
            raise ShapeError(
                f"joint {j.name!r}: unknown channel(s) {bad}; use {sorted(_VALID_CHANNELS)}"
            )
        if (i == 0) != (j.parent < 0) or j.parent >= i:
            raise ShapeError(
                f"joint {j.name!r}: the first joint must be the only root and parents "
                "must come first"
            )
    if len(set(names)) != len(names):
        raise ShapeError(f"joint names must be unique, got {names}")


def write_bvh(path: str | Path, motion: BvhMotion, precision: int = 6) -> Path:
    """Write ``motion`` to ``path``; returns the path."""
    _check(motion)
    if not (np.isfinite(motion.frame_time) and motion.frame_time > 0):
        raise ShapeError(
            f"frame_time: expected a positive time in seconds, got {motion.frame_time}"
        )
    if not np.isfinite(motion.values).all():
        bad = int(np.argwhere(~np.isfinite(motion.values))[0][0])
        raise ShapeError(
            f"values: non-finite channel value at frame {bad}; BVH cannot store gaps "
            "(fill or cut the frames first)"
        )
    children: dict[int, list[int]] = {}
    for i, j in enumerate(motion.joints):
        children.setdefault(j.parent, []).append(i)
    lines = ["HIERARCHY"]
    fmt = f"{{:.{precision}f}}"

    def emit(i: int, depth: int) -> None:
        j = motion.joints[i]
        pad = "\t" * depth
        lines.append(f"{pad}{'ROOT' if j.parent < 0 else 'JOINT'} {j.name}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}\tOFFSET " + " ".join(fmt.format(v) for v in j.offset))
        lines.append(f"{pad}\tCHANNELS {len(j.channels)} " + " ".join(j.channels))
        for c in children.get(i, []):
            emit(c, depth + 1)
        if j.end_site is not None:
            lines.append(f"{pad}\tEnd Site")
            lines.append(f"{pad}\t{{")
            lines.append(f"{pad}\t\tOFFSET " + " ".join(fmt.format(v) for v in j.end_site))
            lines.append(f"{pad}\t}}")
        lines.append(f"{pad}}}")

    emit(0, 0)
    lines += ["MOTION", f"Frames: {motion.n_frames}", f"Frame Time: {motion.frame_time:.8f}"]
    lines += [" ".join(fmt.format(v) for v in row) for row in motion.values]
    p = Path(path)
    p.write_text("\n".join(lines) + "\n")
    return p


def read_bvh(path: str | Path) -> BvhMotion:
    """Read a BVH file (any channel layout, several end sites, tabs or spaces)."""
    p = Path(path)
    tokens_by_line = [line.split() for line in read_text(p)]
    lines = [t for t in tokens_by_line if t]
    if not lines or lines[0][0] != "HIERARCHY":
        raise FileFormatError(f"{p}: does not start with HIERARCHY; is it a BVH file?")
    joints: list[dict[str, Any]] = []
    stack: list[int] = []
    in_end = False
    i = 1
    while i < len(lines) and lines[i][0] != "MOTION":
        tok = lines[i]
        key = tok[0]
        try:
            if key in ("ROOT", "JOINT"):
                joints.append({"name": tok[1], "parent": stack[-1] if stack else -1,
                               "offset": None, "channels": (), "end": None})  # fmt: skip
                stack.append(len(joints) - 1)
            elif key == "End":
                in_end = True
            elif key == "OFFSET":
                vec = np.array([float(v) for v in tok[1:4]])
                if in_end:
                    joints[stack[-1]]["end"] = vec
                else:
                    joints[stack[-1]]["offset"] = vec
            elif key == "CHANNELS":
                n = int(tok[1])
                joints[stack[-1]]["channels"] = tuple(tok[2 : 2 + n])
            elif key == "}":
                if in_end:
                    in_end = False
                else:
                    stack.pop()
        except (IndexError, ValueError) as exc:
            raise FileFormatError(
                f"{p}: malformed hierarchy line {' '.join(tok)!r} ({exc})"
            ) from exc
        i += 1
    if i >= len(lines):
        raise FileFormatError(f"{p}: no MOTION section")
    try:
        n_frames = int(lines[i + 1][1])
        frame_time = float(lines[i + 2][2])
    except (IndexError, ValueError) as exc:
        raise FileFormatError(
            f"{p}: expected 'Frames: n' and 'Frame Time: dt' after MOTION"
        ) from exc
    rows = lines[i + 3 : i + 3 + n_frames]
    n_ch = sum(len(j["channels"]) for j in joints)
    if len(rows) != n_frames:
        raise FileFormatError(f"{p}: header says {n_frames} frames, file has {len(rows)}")
    try:
        values = np.array([[float(v) for v in r] for r in rows], dtype=np.float64).reshape(
            n_frames, -1
        )
    except ValueError as exc:
        raise FileFormatError(f"{p}: non-numeric motion data ({exc})") from exc
    if values.shape[1] != n_ch and n_frames:
        raise FileFormatError(
            f"{p}: {values.shape[1]} values per frame, hierarchy has {n_ch} channels"
        )
    out = tuple(
        BvhJoint(
            j["name"],
            j["parent"],
            j["offset"] if j["offset"] is not None else np.zeros(3),
            j["channels"],
            j["end"],
        )
        for j in joints
    )
    return BvhMotion(out, frame_time, values.reshape(n_frames, n_ch), meta={"source": str(p)})
