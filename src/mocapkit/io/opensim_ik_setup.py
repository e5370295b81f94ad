"""Read an OpenSim Inverse Kinematics setup file (``<InverseKinematicsTool>``, e.g. the
tutorial's ``subject01_Setup_IK.xml``): marker weights, coordinate tasks, time range and
file names, for ``mocapkit markers ... --ik-setup FILE``.

What is read (the rest, e.g. ``accuracy`` and ``constraint_weight``, has no counterpart
here and is listed in :attr:`IKSetup.ignored`):

- ``IKMarkerTask``: weight per marker; ``apply`` false means weight 0 (not fitted).
- ``IKCoordinateTask`` with ``apply`` true: the coordinate held at ``value``
  (``manual_value``) or at 0 (``default_value``: the model's default, 0 for the
  coordinates OpenSim's gait models hold); ``from_file`` is refused (no coordinate file).
- ``time_range`` [s], ``marker_file``, ``output_motion_file``, ``model_file`` (paths as
  written, relative to the setup file's folder when not absolute).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

from mocapkit.errors import FileFormatError

_KNOWN = {
    "IKTaskSet", "time_range", "marker_file", "output_motion_file", "model_file",
    "results_directory", "input_directory", "report_errors", "coordinate_file",
}  # fmt: skip


@dataclass(frozen=True)
class IKSetup:
    """An OpenSim IK setup: see the module docstring.

    Attributes:
        marker_weights: marker -> weight (0 where ``apply`` is false).
        coordinate_tasks: coordinate -> (value [rad or m], weight), applied tasks only.
        time_range: (start, end) [s] or None.
        marker_file, output_motion_file, model_file: resolved paths or None.
        ignored: settings read but without effect here.
    """

    marker_weights: dict[str, float]
    coordinate_tasks: dict[str, tuple[float, float]]
    time_range: tuple[float, float] | None = None
    marker_file: Path | None = None
    output_motion_file: Path | None = None
    model_file: Path | None = None
    ignored: tuple[str, ...] = field(default=())


def _bool(text: str | None, where: str) -> bool:
    t = (text or "true").strip().lower()
    if t not in ("true", "false"):
        raise FileFormatError(f"{where}: <apply> must be true or false, got {text!r}")
    return t == "true"


def _float(text: str | None, where: str) -> float:
    try:
        value = float((text or "").strip())
    except ValueError:
        raise FileFormatError(f"{where}: expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise FileFormatError(f"{where}: expected a finite number, got {text!r}")
    return value


def read_ik_setup(path: str | Path) -> IKSetup:
    """Parse ``path``; errors name the file, the task and the field."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such IK setup file")
    try:
        root = ET.parse(p).getroot()
    except ET.ParseError as exc:
        raise FileFormatError(f"{p}: not an XML file ({exc})") from None
    tool = root if root.tag == "InverseKinematicsTool" else root.find("InverseKinematicsTool")
    if tool is None:
        raise FileFormatError(
            f"{p}: no <InverseKinematicsTool> element; pass an OpenSim IK setup file "
            "(e.g. subject01_Setup_IK.xml), not a Scale or model file"
        )
    weights: dict[str, float] = {}
    tasks: dict[str, tuple[float, float]] = {}
    for task in tool.iter("IKMarkerTask"):
        name = task.get("name", "")
        where = f"{p}: IKMarkerTask {name!r}"
        if not name:
            raise FileFormatError(f"{p}: an IKMarkerTask has no name attribute")
        w = _float(task.findtext("weight", "1"), f"{where} <weight>")
        if w < 0:
            raise FileFormatError(f"{where} <weight>: must be >= 0, got {w}")
        weights[name] = w if _bool(task.findtext("apply"), where) else 0.0
    for task in tool.iter("IKCoordinateTask"):
        name = task.get("name", "")
        where = f"{p}: IKCoordinateTask {name!r}"
        if not name:
            raise FileFormatError(f"{p}: an IKCoordinateTask has no name attribute")
        if not _bool(task.findtext("apply"), where):
            continue
        kind = (task.findtext("value_type") or "default_value").strip()
        if kind == "from_file":
            raise FileFormatError(
                f"{where} <value_type>: from_file is not supported (no coordinate file is "
                "read); use manual_value or set <apply> false"
            )
        if kind not in ("default_value", "manual_value"):
            raise FileFormatError(
                f"{where} <value_type>: expected default_value or manual_value, got {kind!r}"
            )
        value = _float(task.findtext("value", "0"), f"{where} <value>")
        w = _float(task.findtext("weight", "1"), f"{where} <weight>")
        tasks[name] = (value if kind == "manual_value" else 0.0, w)
    time_range = None
    text = tool.findtext("time_range")
    if text and text.strip():
        parts = text.split()
        if len(parts) != 2:
            raise FileFormatError(f"{p}: <time_range> expects two times, got {text!r}")
        t0, t1 = (_float(x, f"{p}: <time_range>") for x in parts)
        if not t1 > t0:
            raise FileFormatError(f"{p}: <time_range> must end after it starts, got {text!r}")
        time_range = (t0, t1)

    def path_of(tag: str) -> Path | None:
        t = (tool.findtext(tag) or "").strip()
        if not t or t.lower() == "unassigned":
            return None
        q = Path(t)
        return q if q.is_absolute() else p.parent / q

    ignored = tuple(sorted({c.tag for c in tool} - _KNOWN))
    return IKSetup(
        weights, tasks, time_range, path_of("marker_file"), path_of("output_motion_file"),
        path_of("model_file"), ignored,
    )  # fmt: skip
