"""Marker sets: which marker sits on which segment, where, and how much it counts.

A marker set is a YAML file (presets in ``mocapkit/body/markersets/``)::

    name: gait2392
    description: ...
    reference_height_m: 1.80      # offsets below are for a subject of this stature
    up_axis: y                    # hint: the axis convention of files using this set
    markers:
      R.ASIS: {segment: pelvis, offset: [0.091, -0.128, 0.096], weight: 10}
    joint_centres:                # optional: virtual markers at joint centres
      knee_r: {segment: shank_r, markers: [R.Knee.Lat, R.Knee.Med]}   # their midpoint
    scaling:                      # optional: OpenSim-style measurements
      - {segments: [pelvis], pairs: [[R.ASIS, L.ASIS]]}
    roles: {right_shoulder: R.Acromium, ...}   # for the paper's grouping
    groups: {paper: [[R.Acromium, L.Wrist.Lat], [L.Elbow, R.Wrist.Lat]]}
    coordinate_tasks: {subtalar_angle_r: {value: 0.0, weight: 1000}}
    static:                       # optional: the static trial's IK (marker placement)
      weights: {R.ASIS: 1000, ...}
      coordinate_tasks: {abdomen_extension: {value: 0.0, weight: 1000}}

Coordinate tasks name model DOFs or OpenSim coordinates the model computes from several
DOFs (``lumbar_extension``: see :func:`mocapkit.markers.coordinates.resolve_coordinate_tasks`).

Offsets are metres in the segment frame of :mod:`mocapkit.body.human_model` (x forward,
y left, z up at the neutral pose, origin at the proximal joint centre). For a subject
they are scaled by ``height / reference_height_m`` times the segment's scale factor.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError, FileFormatError

PRESET_PACKAGE = "mocapkit.body"  # presets live in its markersets/ folder
PAPER_ROLES = ("right_shoulder", "left_wrist", "left_elbow", "right_wrist")


@dataclass(frozen=True)
class MarkerSpec:
    name: str
    segment: str
    offset: tuple[float, float, float]
    weight: float = 1.0


@dataclass(frozen=True)
class JointCentre:
    """A virtual marker at ``offset`` in ``segment`` located in trials as the mean of
    ``markers`` (e.g. the knee centre between the femoral condyle markers)."""

    name: str
    segment: str
    markers: tuple[str, ...]
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Measurement:
    """Scale ``segments`` by the mean ratio experimental / model distance of ``pairs``."""

    segments: tuple[str, ...]
    pairs: tuple[tuple[str, str], ...]


@dataclass(frozen=True)
class MarkerMatch:
    """How a trial's labels map onto a marker set."""

    index: dict[str, int]  # set marker name -> column in the trial
    missing: tuple[str, ...]  # in the set, not in the trial
    extra: tuple[str, ...]  # in the trial, not in the set


@dataclass(frozen=True)
class MarkerSet:
    name: str
    markers: tuple[MarkerSpec, ...]
    reference_height_m: float = 1.75
    description: str = ""
    up_axis: str | None = None
    joint_centres: tuple[JointCentre, ...] = ()
    scaling: tuple[Measurement, ...] = ()
    roles: Mapping[str, str] = field(default_factory=dict)
    groups: Mapping[str, tuple[tuple[str, ...], ...]] = field(default_factory=dict)
    coordinate_tasks: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    static_weights: Mapping[str, float] = field(default_factory=dict)
    static_coordinate_tasks: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(m.name for m in self.markers)

    def spec(self, name: str) -> MarkerSpec:
        for m in self.markers:
            if m.name == name:
                return m
        raise ConfigError(
            f"marker {name!r} is not in marker set {self.name!r}; markers: {', '.join(self.names)}"
        )

    def weights(self) -> dict[str, float]:
        return {m.name: m.weight for m in self.markers}

    def placements(
        self, height_m: float, segment_scales: Mapping[str, float]
    ) -> dict[str, tuple[str, FloatArray]]:
        """Generic offsets scaled to a subject: name -> (segment, offset [m])."""
        k = height_m / self.reference_height_m
        out: dict[str, tuple[str, FloatArray]] = {}
        for m in self.markers:
            s = segment_scales.get(m.segment, 1.0)
            out[m.name] = (m.segment, np.asarray(m.offset) * k * s)
        for c in self.joint_centres:
            s = segment_scales.get(c.segment, 1.0)
            out[c.name] = (c.segment, np.asarray(c.offset) * k * s)
        return out

    def match(self, labels: Sequence[str]) -> MarkerMatch:
        """Map trial labels to set markers: exact names first, then case-insensitive."""
        exact = {lab: i for i, lab in enumerate(labels)}
        folded: dict[str, int] = {}
        for i, lab in enumerate(labels):
            folded.setdefault(lab.lower(), i)
        index: dict[str, int] = {}
        for m in self.markers:
            if m.name in exact:
                index[m.name] = exact[m.name]
            elif m.name.lower() in folded:
                index[m.name] = folded[m.name.lower()]
        used = set(index.values())
        missing = tuple(m.name for m in self.markers if m.name not in index)
        extra = tuple(lab for i, lab in enumerate(labels) if i not in used)
        return MarkerMatch(index, missing, extra)

    def paper_grouping(self) -> tuple[tuple[str, ...], ...]:
        """The paper's two marker subsets: (right shoulder, left wrist), (left elbow, right
        wrist), from ``groups['paper']`` or the four ``roles``."""
        if "paper" in self.groups:
            return self.groups["paper"]
        missing = [r for r in PAPER_ROLES if r not in self.roles]
        if missing:
            raise ConfigError(
                f"marker set {self.name!r} defines no 'paper' group and lacks the roles "
                f"{', '.join(missing)}; add them under 'roles:' in its YAML"
            )
        r = self.roles
        return ((r["right_shoulder"], r["left_wrist"]), (r["left_elbow"], r["right_wrist"]))


# -- YAML -----------------------------------------------------------------------------------
def _vec3(value: Any, where: str) -> tuple[float, float, float]:
    try:
        arr = np.asarray(value, dtype=float).reshape(3)
    except (TypeError, ValueError) as exc:
        raise FileFormatError(f"{where}: expected [x, y, z] in metres, got {value!r}") from exc
    if not np.isfinite(arr).all() or np.abs(arr).max() > 1.0:
        raise FileFormatError(
            f"{where}: offset {arr.tolist()} is not a plausible marker offset in metres "
            "(each component within 1 m of the segment origin)"
        )
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def markerset_from_dict(doc: Mapping[str, Any], where: str = "marker set") -> MarkerSet:
    """Build a :class:`MarkerSet` from parsed YAML (``where`` names the source in errors)."""
    if not isinstance(doc, Mapping) or "markers" not in doc:
        raise FileFormatError(f"{where}: expected a mapping with a 'markers' section")
    name = str(doc.get("name", Path(where).stem))
    markers = []
    raw = doc["markers"]
    if not isinstance(raw, Mapping) or not raw:
        raise FileFormatError(f"{where}: 'markers' must map marker names to {{segment, offset}}")
    for mname, spec in raw.items():
        if not isinstance(spec, Mapping) or "segment" not in spec:
            raise FileFormatError(f"{where}: marker {mname!r} needs a 'segment'")
        weight = float(spec.get("weight", 1.0))
        if not (np.isfinite(weight) and weight >= 0):
            raise FileFormatError(f"{where}: marker {mname!r}: weight must be >= 0, got {weight}")
        markers.append(
            MarkerSpec(
                str(mname),
                str(spec["segment"]),
                _vec3(spec.get("offset", [0, 0, 0]), f"{where}: marker {mname!r}"),
                weight,
            )
        )
    names = {m.name for m in markers}
    centres = []
    for cname, spec in (doc.get("joint_centres") or {}).items():
        members = tuple(str(m) for m in spec.get("markers", ()))
        if not members or any(m not in names for m in members):
            raise FileFormatError(
                f"{where}: joint centre {cname!r}: 'markers' must list markers of the set"
            )
        centres.append(
            JointCentre(
                str(cname),
                str(spec["segment"]),
                members,
                _vec3(spec.get("offset", [0, 0, 0]), f"{where}: joint centre {cname!r}"),
            )
        )
    known = names | {c.name for c in centres}
    scaling = []
    for i, spec in enumerate(doc.get("scaling") or ()):
        segs = tuple(str(s) for s in spec.get("segments", ()))
        pairs = tuple((str(a), str(b)) for a, b in spec.get("pairs", ()))
        bad = [m for pair in pairs for m in pair if m not in known]
        if not segs or not pairs or bad:
            raise FileFormatError(
                f"{where}: scaling[{i}] needs 'segments' and 'pairs' of known markers"
                + (f" (unknown: {', '.join(bad)})" if bad else "")
            )
        scaling.append(Measurement(segs, pairs))
    groups = {
        str(g): tuple(tuple(str(m) for m in level) for level in levels)
        for g, levels in (doc.get("groups") or {}).items()
    }
    for g, levels in groups.items():
        bad = [m for level in levels for m in level if m not in names]
        if bad:
            raise FileFormatError(f"{where}: group {g!r} names unknown markers {', '.join(bad)}")
    tasks = _tasks(doc.get("coordinate_tasks"))
    static = doc.get("static") or {}
    static_weights = {str(k): float(v) for k, v in (static.get("weights") or {}).items()}
    bad = [k for k in static_weights if k not in names]
    if bad:
        raise FileFormatError(f"{where}: static weights name unknown markers {', '.join(bad)}")
    return MarkerSet(
        name=name,
        markers=tuple(markers),
        reference_height_m=float(doc.get("reference_height_m", 1.75)),
        description=str(doc.get("description", "")),
        up_axis=doc.get("up_axis"),
        joint_centres=tuple(centres),
        scaling=tuple(scaling),
        roles={str(k): str(v) for k, v in (doc.get("roles") or {}).items()},
        groups=groups,
        coordinate_tasks=tasks,
        static_weights=static_weights,
        static_coordinate_tasks=_tasks(static.get("coordinate_tasks")),
    )


def _tasks(doc: Any) -> dict[str, tuple[float, float]]:
    return {
        str(c): (float(t.get("value", 0.0)), float(t.get("weight", 1.0)))
        for c, t in (doc or {}).items()
    }


def markerset_to_dict(ms: MarkerSet) -> dict[str, Any]:
    """The YAML document of a marker set (round-trips through :func:`markerset_from_dict`)."""
    doc: dict[str, Any] = {
        "name": ms.name,
        "description": ms.description,
        "reference_height_m": ms.reference_height_m,
        "up_axis": ms.up_axis,
        "markers": {
            m.name: {
                "segment": m.segment,
                "offset": [round(v, 5) for v in m.offset],
                "weight": m.weight,
            }
            for m in ms.markers
        },
    }
    if ms.joint_centres:
        doc["joint_centres"] = {
            c.name: {"segment": c.segment, "markers": list(c.markers), "offset": list(c.offset)}
            for c in ms.joint_centres
        }
    if ms.scaling:
        doc["scaling"] = [
            {"segments": list(s.segments), "pairs": [list(p) for p in s.pairs]} for s in ms.scaling
        ]
    if ms.roles:
        doc["roles"] = dict(ms.roles)
    if ms.groups:
        doc["groups"] = {g: [list(level) for level in lv] for g, lv in ms.groups.items()}
    if ms.coordinate_tasks:
        doc["coordinate_tasks"] = {
            c: {"value": v, "weight": w} for c, (v, w) in ms.coordinate_tasks.items()
        }
    if ms.static_weights or ms.static_coordinate_tasks:
        doc["static"] = {
            "weights": dict(ms.static_weights),
            "coordinate_tasks": {
                c: {"value": v, "weight": w} for c, (v, w) in ms.static_coordinate_tasks.items()
            },
        }
    return doc


def save_markerset(ms: MarkerSet, path: str | Path) -> Path:
    p = Path(path)
    p.write_text(yaml.safe_dump(markerset_to_dict(ms), sort_keys=False))
    return p


def available_markersets() -> tuple[str, ...]:
    """Names of the bundled presets."""
    files = resources.files(PRESET_PACKAGE).joinpath("markersets").iterdir()
    return tuple(sorted(f.name[:-5] for f in files if f.name.endswith(".yaml")))


def load_markerset(name_or_path: str | Path) -> MarkerSet:
    """A preset by name (``gait2392``, ``cmu41``, ``walking2``) or a YAML file."""
    text: str
    where = str(name_or_path)
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") or p.is_file():
        if not p.is_file():
            raise FileNotFoundError(f"{p}: no such marker set file")
        text = p.read_text()
    else:
        presets = available_markersets()
        if str(name_or_path) not in presets:
            raise ConfigError(
                f"marker set {name_or_path!r}: not a preset ({', '.join(presets)}) nor a YAML file"
            )
        folder = resources.files(PRESET_PACKAGE).joinpath("markersets")
        text = folder.joinpath(f"{name_or_path}.yaml").read_text()
    try:
        doc = yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    except yaml.YAMLError as exc:
        raise FileFormatError(f"{where}: invalid YAML ({exc})") from exc
    return markerset_from_dict(doc, where)


def guess_markerset(labels: Sequence[str]) -> tuple[MarkerSet, MarkerMatch]:
    """The preset matching most of ``labels`` (ties: the first in name order)."""
    best: tuple[MarkerSet, MarkerMatch] | None = None
    for name in available_markersets():
        ms = load_markerset(name)
        match = ms.match(labels)
        if best is None or len(match.index) > len(best[1].index):
            best = (ms, match)
    if best is None or not best[1].index:
        raise ConfigError(
            "none of the trial's markers is in a bundled marker set "
            f"({', '.join(available_markersets())}); labels: {', '.join(labels[:12])}... "
            "Write a YAML marker set (see mocapkit.body.markersets) and pass --markerset FILE"
        )
    return best
