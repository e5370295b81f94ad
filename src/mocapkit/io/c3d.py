"""C3D marker files through ezc3d: read and write, with analogs, force plates and events.

Read: ``POINT:UNITS`` converted to metres, axes kept as in the file (C3D files from
Vicon and Qualisys are usually z-up; ``meta["up_axis"]`` is unknown until checked
against the static trial), points with a negative residual or at exactly (0, 0, 0)
become NaN, unlabelled points (labels starting with ``*``, empty, or ``uname*``) are
dropped and listed in ``meta["dropped_unlabelled"]``, and a Vicon subject prefix
common to all labels (``Male:LFHD``) is stripped (``meta["label_prefix"]``). What is not
a marker travels in ``meta["c3d"]`` (:class:`C3DExtras`): the analog channels (force
plates, EMG) with their rate, labels and units, the ``FORCE_PLATFORM`` group, and the
events, so :func:`write_c3d` can put them back.

Checked on read: a file cut short (ezc3d reads what is there and rewrites its header to
match: the frame count announced by the file's own header is compared with what was read,
and reported), and a file holding more than the 65,535 frames that ezc3d reads (refused:
the rest would be lost silently). Write: millimetres, residual -1 for gaps; more than
65,535 frames is refused (ezc3d would write them but read back only 65,535).
"""

from __future__ import annotations

import logging
import os
import re
import struct
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import DataError, FileFormatError, MissingDependencyError
from mocapkit.io.units import length_scale
from mocapkit.markers.trajectories import MarkerTrajectories

log = logging.getLogger(__name__)

_UNLABELLED = re.compile(r"^(\*\d*|uname\*?\d*|unlabeled.*|unlabelled.*|)$", re.IGNORECASE)
MAX_FRAMES = 65535  # what ezc3d reads back (the header's 16-bit frame numbers)
_KEPT_GROUPS = ("FORCE_PLATFORM", "EVENT", "EVENT_CONTEXT")


@dataclass(frozen=True)
class C3DEvent:
    """A labelled event (heel strike, toe off...) at ``time_s`` in the file's time base."""

    label: str
    context: str
    time_s: float
    description: str = ""


@dataclass(frozen=True)
class C3DExtras:
    """What a C3D holds besides the markers, kept for writing it back.

    Attributes:
        analog_rate_hz: analog sampling rate (0 without analogs).
        analog_labels, analog_units: per channel.
        analogs: (N_analog, channels) the channels' values as ezc3d gives them.
        groups: parameter groups kept whole (``FORCE_PLATFORM``, ``EVENT``,
            ``EVENT_CONTEXT``): name -> {parameter: value}.
        events: the ``EVENT`` group's events.
        first_frame: the file's first frame number (0-based), the time origin.
    """

    analog_rate_hz: float = 0.0
    analog_labels: tuple[str, ...] = ()
    analog_units: tuple[str, ...] = ()
    analogs: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    groups: dict[str, dict[str, Any]] = field(default_factory=dict)
    events: tuple[C3DEvent, ...] = ()
    first_frame: int = 0

    @property
    def n_channels(self) -> int:
        return len(self.analog_labels)

    def analog_time(self, point_rate_hz: float) -> FloatArray:
        """(N_analog,) sample times [s] in the markers' time base."""
        if self.analog_rate_hz <= 0:
            return np.zeros(0)
        return self.first_frame / point_rate_hz + np.arange(len(self.analogs)) / self.analog_rate_hz

    def between(self, t0: float, t1: float, point_rate_hz: float) -> C3DExtras:
        """The analogs sampled within [t0, t1 + one frame) (the frames of a marker crop)."""
        if self.analog_rate_hz <= 0 or len(self.analogs) == 0:
            return self
        t = self.analog_time(point_rate_hz)
        keep = (t >= t0 - 1e-9) & (t < t1 + 1.0 / point_rate_hz - 1e-9)
        return C3DExtras(
            self.analog_rate_hz, self.analog_labels, self.analog_units, self.analogs[keep],
            self.groups, self.events, self.first_frame,
        )  # fmt: skip


def _ezc3d() -> Any:
    try:
        import ezc3d
    except ImportError as exc:  # pragma: no cover - ezc3d is a core dependency
        raise MissingDependencyError("reading C3D needs ezc3d: pip install ezc3d") from exc
    return ezc3d


def _labels(point: dict[str, Any], used: int, key: str = "LABELS") -> list[str]:
    labels: list[str] = list(point[key]["value"])
    k = 2
    while len(labels) < used and f"{key}{k}" in point:
        labels += list(point[f"{key}{k}"]["value"])
        k += 1
    return [str(s).strip() for s in labels[:used]]


def _strip_prefix(labels: list[str]) -> tuple[list[str], str]:
    prefixes = {s.rsplit(":", 1)[0] for s in labels if ":" in s}
    if len(prefixes) == 1 and all(":" in s for s in labels):
        prefix = prefixes.pop()
        return [s.rsplit(":", 1)[1] for s in labels], prefix + ":"
    return labels, ""


def check_structure(path: Path) -> None:
    """Walk the C3D header and parameter section in Python before ezc3d reads the file:
    ezc3d (native code) crashes the whole process on a damaged parameter section
    (found by fuzzing), where a clear error is owed. Raises FileFormatError naming the
    byte; a sane file passes untouched (the data section is left to ezc3d)."""
    with path.open("rb") as f:  # the header, then only the parameter section
        data = f.read(512)
        if len(data) == 512 and data[0] >= 2:
            f.seek(512 * (data[0] - 1))
            head = f.read(4)
            n_blocks = head[2] if len(head) == 4 else 1
            data = data + bytes(512 * (data[0] - 2)) + head + f.read(512 * max(1, n_blocks) - 4)

    def bad(where: int, what: str) -> FileFormatError:
        return FileFormatError(
            f"{path}: damaged C3D ({what} at byte {where}); re-export the trial or restore "
            "the file from its source"
        )

    if len(data) < 512 or data[1] != 0x50:
        raise bad(1, "no C3D signature (byte 2 must be 0x50)")
    block = data[0]
    start = 512 * (block - 1)
    if block < 2 or start + 4 > len(data):
        raise bad(0, f"parameter section at block {block} outside the file")
    n_blocks, processor = data[start + 2], data[start + 3]
    if processor not in (84, 85, 86):
        raise bad(start + 3, f"unknown processor type {processor}")
    end = min(len(data), start + 512 * max(1, n_blocks))
    fmt = ">" if processor == 86 else "<"
    p = start + 4
    groups: set[int] = set()
    params: set[int] = set()
    while p + 2 <= end:
        name_len = abs(struct.unpack_from("b", data, p)[0])
        gid = struct.unpack_from("b", data, p + 1)[0]
        if name_len == 0:
            break  # the end of the parameters
        q = p + 2 + name_len
        if q + 2 > end:
            raise bad(p, "a parameter name runs past the section")
        offset = struct.unpack_from(fmt + "h", data, q)[0]
        if offset == 0:
            break
        nxt = q + offset
        if offset < 0 or nxt > end:
            raise bad(q, f"a record points to byte {nxt}, outside the parameter section")
        if gid < 0:
            if q + 3 > nxt or q + 3 + data[q + 2] > nxt:
                raise bad(q + 2, "a group's description runs past its record")
            groups.add(-gid)
        elif gid > 0:
            params.add(gid)
            r = q + 2
            if r + 2 > nxt:
                raise bad(r, "a parameter's type runs past its record")
            kind = struct.unpack_from("b", data, r)[0]
            ndim = data[r + 1]
            if kind not in (-1, 1, 2, 4) or ndim > 7 or r + 2 + ndim > nxt:
                raise bad(r, f"a parameter has type {kind} and {ndim} dimensions")
            size = abs(kind)
            for d in data[r + 2 : r + 2 + ndim]:
                size *= d
            desc = r + 2 + ndim + size
            if desc + 1 > nxt or desc + 1 + data[desc] > nxt:
                raise bad(r, "a parameter's values or description run past its record")
        p = nxt
    if not groups:
        raise bad(start + 4, "no parameter group")
    orphans = sorted(params - groups)
    if orphans:
        raise bad(start + 4, f"parameters of undefined group(s) {orphans}")


def probe_in_child(path: Path, ezc3d: Any) -> None:
    """Let ezc3d read the file once in a forked child first (POSIX): damage that the
    structural check does not see can still crash it (a segfault kills the process with
    no message); here it kills only the child, and the user gets an error."""
    if not hasattr(os, "fork"):
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # fork() with threads: the
        pid = os.fork()  # child only runs ezc3d and exits at once
    if pid == 0:  # pragma: no cover (the child)
        try:
            ezc3d.c3d(str(path))
        except BaseException:
            os._exit(1)  # an exception: the parent reads again and reports it
        os._exit(0)
    _, status = os.waitpid(pid, 0)
    if os.WIFSIGNALED(status):
        raise FileFormatError(
            f"{path}: damaged C3D: the C3D library (ezc3d) crashed reading it (signal "
            f"{os.WTERMSIG(status)}); re-export the trial or restore the file from its source"
        )


def _declared_frames(path: Path, c3d: Any) -> int | None:
    """The frame count the file's own header announces (ezc3d rewrites its copy of the
    header to what it could read), or None when it cannot say (past 65,535 frames)."""
    try:
        with path.open("rb") as f:
            head = f.read(512)
            f.seek(512 * (head[0] - 1))
            param = f.read(4)
    except (OSError, IndexError):
        return None
    if len(head) < 12 or len(param) < 4:
        return None
    fmt = ">" if param[3] == 86 else "<"  # processor type 86: MIPS (big-endian)
    first, last = struct.unpack(fmt + "HH", head[6:10])
    if last < first or last == MAX_FRAMES:
        return None
    return int(last) - int(first) + 1


def _frames_in_data(path: Path, c3d: Any) -> int | None:
    """How many whole frames the data section of the file holds (from its size, which
    512-byte block padding can exceed by less than a block)."""
    params = c3d["parameters"]
    point = params["POINT"]
    try:
        start = int(point["DATA_START"]["value"][0])
        n_points = int(point["USED"]["value"][0])
        scale = float(point["SCALE"]["value"][0])
        analog = params.get("ANALOG", {})
        channels = int(analog["USED"]["value"][0]) if "USED" in analog else 0
        a_rate = float(analog["RATE"]["value"][0]) if channels else 0.0
        p_rate = float(point["RATE"]["value"][0])
    except (KeyError, IndexError, TypeError, ValueError):
        return None
    word = 4 if scale < 0 else 2
    per_frame = n_points * 4 * word
    if channels and p_rate > 0:
        per_frame += round(a_rate / p_rate) * channels * word
    if per_frame <= 0:
        return None
    data_bytes = path.stat().st_size - 512 * (start - 1)
    return max(0, (data_bytes - 511) // per_frame)  # padding left out


def _extras(c3d: Any, first: int) -> C3DExtras:
    params = c3d["parameters"]
    analog = params.get("ANALOG", {})
    channels = int(analog["USED"]["value"][0]) if "USED" in analog else 0
    labels = tuple(_labels(analog, channels)) if channels and "LABELS" in analog else ()
    units: tuple[str, ...] = ()
    if channels and "UNITS" in analog:
        units = tuple(str(u).strip() for u in list(analog["UNITS"]["value"])[:channels])
    data = np.asarray(c3d["data"]["analogs"], dtype=float)
    analogs = data[0].T.copy() if data.ndim == 3 and channels else np.zeros((0, 0))
    rate = float(analog["RATE"]["value"][0]) if channels and "RATE" in analog else 0.0
    groups: dict[str, dict[str, Any]] = {}
    for g in _KEPT_GROUPS:
        if g in params:
            groups[g] = {
                k: v["value"] for k, v in params[g].items() if k != "__METADATA__" and "value" in v
            }
    events: list[C3DEvent] = []
    ev = groups.get("EVENT", {})
    n_ev = int(np.asarray(ev.get("USED", [0])).reshape(-1)[0]) if ev else 0
    if n_ev:
        times = np.asarray(ev.get("TIMES", np.zeros((2, 0))), dtype=float).reshape(2, -1)
        lab = list(ev.get("LABELS", [])) + [""] * n_ev
        ctx = list(ev.get("CONTEXTS", [])) + [""] * n_ev
        desc = list(ev.get("DESCRIPTIONS", [])) + [""] * n_ev
        for i in range(min(n_ev, times.shape[1])):
            t = float(times[0, i]) * 60.0 + float(times[1, i])  # minutes, seconds
            events.append(C3DEvent(str(lab[i]).strip(), str(ctx[i]).strip(), t, str(desc[i])))
    return C3DExtras(rate, labels, units, analogs, groups, tuple(events), first)


def read_c3d(path: str | Path, units: str | None = None) -> MarkerTrajectories:
    """Read the labelled points of a C3D file (and keep the rest in ``meta["c3d"]``).

    Args:
        path: the ``.c3d`` file.
        units: override ``POINT:UNITS`` (``"mm"``, ``"cm"``, ``"m"``).
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such C3D file")
    ezc3d = _ezc3d()
    check_structure(p)
    probe_in_child(p, ezc3d)
    try:
        c3d = ezc3d.c3d(str(p))
    except (RuntimeError, ValueError, IndexError, OSError) as exc:
        raise FileFormatError(f"{p}: not a readable C3D file ({exc})") from exc
    point = c3d["parameters"]["POINT"]
    used = int(point["USED"]["value"][0])
    if used == 0:
        raise FileFormatError(f"{p}: the file holds no 3-D points (POINT:USED = 0)")
    labels = _labels(point, used)
    if len(labels) < used:
        raise FileFormatError(f"{p}: POINT:LABELS names {len(labels)} of {used} points")
    rate = float(point["RATE"]["value"][0])
    if not rate > 0:
        raise FileFormatError(f"{p}: POINT:RATE is {rate}; pass the frame rate explicitly")
    declared = units or (point["UNITS"]["value"][0] if point["UNITS"]["value"] else "")
    if not declared:
        raise FileFormatError(
            f"{p}: POINT:UNITS is empty; pass the file's unit (--units mm|cm|m, or units=...)"
        )
    scale = length_scale(declared, f"{p}: POINT:UNITS")
    pts = np.asarray(c3d["data"]["points"], dtype=float)[:3]  # (3, M, N)
    n = pts.shape[2]
    in_data = _frames_in_data(p, c3d)
    if n >= MAX_FRAMES and in_data is not None and in_data > n:
        raise DataError(
            f"{p}: the file holds more frames than the {MAX_FRAMES} that C3D readers built on "
            f"ezc3d (this one included) read (at least {in_data} by its size); the rest would "
            "be lost. Fix: export the trial as TRC, or in parts of at most 65,535 frames"
        )
    meta_trunc: dict[str, int] | None = None
    announced = _declared_frames(p, c3d)
    if announced is not None and announced > n:
        meta_trunc = {"frames": n, "declared": announced}
        log.warning(
            "%s: the file's header announces %d frames but only %d are in the file: it was "
            "cut short (an interrupted copy or export?); only those %d frames are used",
            p,
            announced,
            n,
            n,
        )
    residuals = np.asarray(c3d["data"]["meta_points"]["residuals"], dtype=float)[0]
    pos = np.transpose(pts, (2, 1, 0)).copy()  # (N, M, 3)
    bad = (residuals.T < 0) | np.all(pos == 0.0, axis=2) | ~np.isfinite(pos).all(axis=2)
    pos[bad] = np.nan
    keep = [i for i, s in enumerate(labels) if not _UNLABELLED.match(s)]
    dropped = [labels[i] or f"<point {i}>" for i in range(used) if i not in keep]
    if dropped:
        log.warning(
            "%s: dropped %d unlabelled points (%s); label them in your capture software to "
            "use them",
            p,
            len(dropped),
            ", ".join(dropped[:10]) + (" ..." if len(dropped) > 10 else ""),
        )
    names, prefix = _strip_prefix([labels[i] for i in keep])
    first = int(c3d["header"]["points"]["first_frame"])
    meta: dict[str, Any] = {
        "source": str(p),
        "format": "c3d",
        "units": declared,
        "rate_hz": rate,
        "up_axis": None,
        "up_axis_source": "unknown (C3D does not declare it)",
        "label_prefix": prefix,
        "dropped_unlabelled": dropped,
        "first_frame": first,
        "c3d": _extras(c3d, first),
    }
    if meta_trunc is not None:
        meta["truncated"] = meta_trunc
    time = (first + np.arange(n)) / rate
    return MarkerTrajectories(time, pos[:, keep] * scale, tuple(names), meta=meta)


def _set(c3d: Any, group: str, name: str, value: Any) -> None:
    """Set (or add) a parameter in the forms ezc3d's binding accepts: strings as lists,
    reals as float arrays, integers as (nested) lists when added, arrays when replaced."""
    arr = np.asarray(value)
    exists = group in c3d["parameters"] and name in c3d["parameters"][group]
    if arr.dtype.kind in "US":
        val: Any = [str(v) for v in arr.reshape(-1)]
    elif arr.dtype.kind == "f":
        val = arr.astype(float)
    else:  # an existing parameter keeps ezc3d's own array form
        val = arr.astype(int) if exists else arr.astype(int).tolist()
    if exists:
        c3d["parameters"][group][name]["value"] = val
    else:
        c3d.add_parameter(group, name, val)


def write_c3d(
    path: str | Path, trajectories: MarkerTrajectories, extras: C3DExtras | None = None
) -> Path:
    """Write trajectories (metres) as a C3D file in millimetres; gaps get residual -1.

    ``extras`` (default: ``trajectories.meta["c3d"]`` when present): analogs, force
    platforms and events to write with them. The file starts at time 0 with the first
    frame: analogs are cropped to the markers' time span and events shifted with it.
    """
    p = Path(path)
    traj = trajectories
    if traj.n_frames > MAX_FRAMES:
        raise DataError(
            f"{p}: {traj.n_frames} frames; a C3D written through ezc3d holds at most "
            f"{MAX_FRAMES} frames that it can read back. Fix: write TRC (-o ... .trc), or "
            "split the trial"
        )
    ezc3d = _ezc3d()
    rate = traj.rate_hz
    ex = extras if extras is not None else traj.meta.get("c3d")
    c3d = ezc3d.c3d()
    point = c3d["parameters"]["POINT"]
    point["RATE"]["value"] = [rate]
    point["LABELS"]["value"] = tuple(traj.names)
    point["UNITS"]["value"] = ["mm"]
    pts = np.ones((4, traj.n_markers, traj.n_frames))
    mm = np.transpose(traj.positions, (2, 1, 0)) * 1000.0
    visible = np.asarray(np.isfinite(mm).all(axis=0))
    pts[:3] = np.where(visible[None], mm, 0.0)
    c3d["data"]["points"] = pts
    residuals = np.where(visible, 0.0, -1.0)[None]
    c3d["data"]["meta_points"] = {
        "residuals": residuals,
        "camera_masks": np.zeros((7, traj.n_markers, traj.n_frames), dtype=bool),
    }
    if isinstance(ex, C3DExtras):
        _write_extras(c3d, ex, traj, rate)
    c3d.write(str(p))
    return p


def _write_extras(c3d: Any, ex: C3DExtras, traj: MarkerTrajectories, rate: float) -> None:
    if ex.n_channels and ex.analog_rate_hz > 0:
        ratio = round(ex.analog_rate_hz / rate)
        if ratio < 1 or abs(ratio * rate - ex.analog_rate_hz) > 1e-6 * ex.analog_rate_hz:
            log.warning(
                "analogs at %g Hz are not a whole multiple of the %g Hz frames: not written",
                ex.analog_rate_hz,
                rate,
            )
        else:
            cropped = ex.between(float(traj.time[0]), float(traj.time[-1]), rate)
            want = traj.n_frames * ratio
            data = np.full((want, ex.n_channels), 0.0)
            k = min(want, len(cropped.analogs))
            data[:k] = cropped.analogs[:k]
            analog = c3d["parameters"]["ANALOG"]
            analog["RATE"]["value"] = [ex.analog_rate_hz]
            analog["LABELS"]["value"] = tuple(ex.analog_labels)
            analog["UNITS"]["value"] = tuple(ex.analog_units or [""] * ex.n_channels)
            c3d["data"]["analogs"] = data.T[None]
    groups = {g: dict(v) for g, v in ex.groups.items()}
    ev = groups.get("EVENT")
    if ev and "TIMES" in ev and int(np.asarray(ev.get("USED", [0])).reshape(-1)[0]) > 0:
        # written frames start at time 0: events move with them, those outside are dropped
        times = np.asarray(ev["TIMES"], dtype=float).reshape(2, -1)
        t = times[0] * 60.0 + times[1] - float(traj.time[0])
        inside = (t >= -1e-9) & (t <= float(traj.time[-1] - traj.time[0]) + 1e-9)
        for key in ("LABELS", "CONTEXTS", "DESCRIPTIONS", "SUBJECTS", "ICON_IDS", "GENERIC_FLAGS"):
            if key in ev and len(np.asarray(ev[key]).reshape(-1)) == times.shape[1]:
                ev[key] = np.asarray(ev[key]).reshape(-1)[inside]
        ev["TIMES"] = np.array([np.zeros(int(inside.sum())), t[inside]])
        ev["USED"] = np.array([int(inside.sum())])
    for group, values in groups.items():
        for name, value in values.items():
            try:
                _set(c3d, group, name, value)
            except (TypeError, ValueError, RuntimeError) as exc:
                log.warning("C3D parameter %s:%s not written (%s)", group, name, exc)
