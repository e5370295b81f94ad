"""Sensor-to-segment trees: which sensor sits on which segment, the parent of each segment,
and the joint between them (seed: inertial motion suit, section 5, "the parent-child order
placement of the sensors").

Segment frames follow OpenSim's body axes: x anterior, y superior (long axis), z to the
right; with every coordinate at zero (anatomical position) all segment frames are aligned.
The root segment's parent is ``ground``: the heading-aligned OpenSim ground frame (see
:mod:`mocapkit.body.calibration`).

A :class:`JointSpec` gives up to three coordinates with their rotation axes in the parent
frame, as OpenSim writes them (``hip_l``: ``z, -x, -y``). The axes span an orthonormal
joint frame ``B = [b1, b2, b1 x b2]`` (Gram-Schmidt), in which the relative rotation is
decomposed with the intrinsic sequence ``XYZ`` (:mod:`mocapkit.body.joint_angles`).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_from_matrix

GROUND = "ground"


def _yaml_load(text: str) -> Any:
    import yaml

    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml when available
    return yaml.load(text, Loader=loader)


def sequence_axes(sequence: str, where: str = "sequence") -> list[list[float]]:
    """Axes of an intrinsic Euler sequence (``"ZXY"``: z, then x, then y), for joints
    written as a sequence instead of axes (negate a coordinate with ``signs``)."""
    seq = sequence.strip()
    if len(seq) != 3 or not seq.isupper() or any(c not in "XYZ" for c in seq):
        raise ConfigError(
            f"{where}: expected three upper-case axis letters (intrinsic), e.g. 'ZXY'; "
            f"got {sequence!r}"
        )
    if seq[0] == seq[1] or seq[1] == seq[2] or seq[0] == seq[2]:
        raise ConfigError(
            f"{where}: {sequence!r} repeats an axis; a joint's three axes must differ (Tait-Bryan)"
        )
    return [[1.0 if "XYZ".index(c) == k else 0.0 for k in range(3)] for c in seq]


@functools.lru_cache(maxsize=32)
def _load_preset(name: str) -> SensorTree:
    """Parse a preset once (trees are immutable, so sharing one is safe)."""
    text = resources.files("mocapkit.body.presets").joinpath(f"{name}.yaml").read_text()
    return SensorTree.from_dict(_yaml_load(text))


# Two joint axes closer than this to parallel [rad] cannot span a joint frame.
_MIN_AXIS_SEPARATION = np.deg2rad(10.0)


@dataclass(frozen=True)
class JointSpec:
    """The joint between a segment and its parent.

    Attributes:
        name: joint name (``hip_r``); used in messages.
        coordinates: three coordinate names (OpenSim's, e.g. ``hip_flexion_r``) for the
            rotations about ``b1, b2, b3``; ``None`` for an angle that is not reported.
        axes: (2, 3) or (3, 3) rotation axes in the parent segment frame. The third, if
            given, only sets the sign of the third coordinate.
        signs: (3,) extra factors (+1 or -1) applied to the angles (the paper's negations).
        offsets: (3,) [rad] added after the signs: ``coordinate = sign * angle + offset``.
        order: the rotation order as a permutation of (0, 1, 2) over ``b1, b2, b3``
            (OpenSim's rotation1, 2, 3 is ``(0, 1, 2)``). Default: ``(0, 1, 2)``, except
            for two reported coordinates, where the unreported angle goes in the middle
            (``(0, 2, 1)``): the middle angle is the one that must stay away from +-90 deg
            (gimbal lock), and an unreported residual stays near zero where a forearm
            rotation of 90 deg would not.
    """

    name: str
    coordinates: tuple[str | None, str | None, str | None]
    axes: FloatArray
    signs: FloatArray = field(default_factory=lambda: np.ones(3))
    offsets: FloatArray = field(default_factory=lambda: np.zeros(3))
    order: tuple[int, int, int] | None = None

    def __post_init__(self) -> None:
        where = f"joint {self.name!r}"
        coords = tuple(self.coordinates)
        if len(coords) != 3:
            raise ConfigError(
                f"{where}: coordinates must list three names (null for an angle that is not "
                f"reported), got {list(coords)}"
            )
        axes = np.array(self.axes, dtype=np.float64)
        if axes.ndim != 2 or axes.shape[1] != 3 or axes.shape[0] not in (2, 3):
            raise ConfigError(
                f"{where}: axes must be 2 or 3 vectors [x, y, z], got {axes.tolist()}"
            )
        norms = np.linalg.norm(axes, axis=1)
        if np.any(~np.isfinite(norms)) or np.any(norms < 1e-9):
            raise ConfigError(f"{where}: axes must be finite non-zero vectors, got {axes.tolist()}")
        axes = axes / norms[:, None]
        if abs(axes[0] @ axes[1]) > np.cos(_MIN_AXIS_SEPARATION):
            raise ConfigError(
                f"{where}: the first two axes {axes[0].round(3).tolist()} and "
                f"{axes[1].round(3).tolist()} are nearly parallel; give two axes at least "
                "10 deg apart"
            )
        signs = np.array(self.signs, dtype=np.float64).reshape(-1)
        offsets = np.array(self.offsets, dtype=np.float64).reshape(-1)
        if signs.shape != (3,) or not np.all(np.isin(signs, (-1.0, 1.0))):
            raise ConfigError(f"{where}: signs must be three values of +1 or -1, got {signs}")
        if offsets.shape != (3,) or not np.all(np.isfinite(offsets)):
            raise ConfigError(f"{where}: offsets must be three finite angles [rad], got {offsets}")
        order = self.order
        if order is None:
            two = coords[1] is not None and coords[2] is None
            order = (0, 2, 1) if two else (0, 1, 2)
        perm = tuple(int(o) for o in order)
        if sorted(perm) != [0, 1, 2]:
            raise ConfigError(f"{where}: order must be a permutation of 0, 1, 2, got {list(perm)}")
        object.__setattr__(self, "order", (perm[0], perm[1], perm[2]))
        for arr in (axes, signs, offsets):
            arr.setflags(write=False)
        object.__setattr__(self, "coordinates", coords)
        object.__setattr__(self, "axes", axes)
        object.__setattr__(self, "signs", signs)
        object.__setattr__(self, "offsets", offsets)

    @property
    def frame(self) -> FloatArray:
        """(3, 3) joint frame ``B`` in the parent frame: columns ``b1, b2, b3`` (orthonormal)."""
        b1 = self.axes[0]
        b2 = self.axes[1] - (self.axes[1] @ b1) * b1
        b2 = b2 / np.linalg.norm(b2)
        return np.column_stack([b1, b2, np.cross(b1, b2)])

    @property
    def total_signs(self) -> FloatArray:
        """(3,) signs per coordinate, including the third axis' direction against b1 x b2."""
        out = self.signs.copy()
        if self.axes.shape[0] == 3 and float(self.axes[2] @ self.frame[:, 2]) < 0.0:
            out[2] = -out[2]
        return out

    @property
    def decomposition_frame(self) -> FloatArray:
        """(3, 3) frame ``F = [b_o0, b_o1, b_o0 x b_o1]`` in which the relative rotation is
        decomposed with intrinsic ``XYZ`` (``o`` = :attr:`order`)."""
        b = self.frame
        o = self.order
        assert o is not None
        f0, f1 = b[:, o[0]], b[:, o[1]]
        return np.column_stack([f0, f1, np.cross(f0, f1)])

    @functools.cached_property
    def q_parent_joint(self) -> FloatArray:
        """(4,) orientation of the decomposition frame ``F`` in the parent segment frame."""
        q = quat_from_matrix(self.decomposition_frame)
        q.setflags(write=False)
        return q

    def second_axis_in_child(self) -> FloatArray | None:
        """(3,) the axis of a two-coordinate joint's second rotation in the child segment's
        frame, where it is fixed (the forearm's pronation after the elbow's flexion, the
        subtalar joint after the ankle): the decomposition's last axis, when the middle
        angle is the unreported one; None otherwise. Its sign is arbitrary."""
        o = self.order
        assert o is not None
        if self.coordinates[o[1]] is not None or self.coordinates[o[2]] is None:
            return None
        return np.asarray(self.decomposition_frame[:, 2])

    def slots(self) -> tuple[tuple[int, int, int], FloatArray, FloatArray]:
        """Per XYZ angle of ``F``: the coordinate index (into :attr:`coordinates`), its sign
        and its offset: ``coordinate[slot_coord[j]] = sign[j] * angle[j] + offset[j]``."""
        return self._slots

    @functools.cached_property
    def _slots(self) -> tuple[tuple[int, int, int], FloatArray, FloatArray]:
        o = self.order
        assert o is not None
        parity = float(np.linalg.det(self.frame[:, list(o)]))  # +1 even, -1 odd permutation
        total = self.total_signs
        sign = np.array([total[o[0]], total[o[1]], total[o[2]] * np.sign(parity)])
        offset = np.array([self.offsets[o[0]], self.offsets[o[1]], self.offsets[o[2]]])
        return (o[0], o[1], o[2]), sign, offset


#: how automatic calibration may find a segment's axes (SegmentSpec.functional)
FUNCTIONAL_KINDS = ("flexion", "twist", "none")


@dataclass(frozen=True)
class SegmentSpec:
    """One body segment carrying one sensor.

    Attributes:
        name: segment name (OpenSim body names where one exists: ``pelvis``, ``femur_r``).
        parent: parent segment name, or ``"ground"`` for a root.
        sensor: name of the sensor on this segment (the key of its orientation stream).
        joint: the joint between the parent and this segment.
        offset: (3,) [m] position of this segment's joint in the parent frame at zero pose
            (skeleton drawing and BVH only).
        end: (3,) [m] the segment's far end in its own frame (BVH end site of a leaf).
        functional: how automatic calibration may find this segment's z (flexion) axis:
            ``"flexion"`` (dominant rotation axis in motion), ``"twist"`` (calibrated from
            the pose, its tilt then corrected by the second axis of its own joint, fixed in
            it and found from the motion: the forearm's pronation axis) or ``"none"``.
    """

    name: str
    parent: str
    sensor: str
    joint: JointSpec
    offset: FloatArray = field(default_factory=lambda: np.zeros(3))
    end: FloatArray = field(default_factory=lambda: np.array([0.0, -0.1, 0.0]))
    functional: str = "none"

    def __post_init__(self) -> None:
        offset = np.array(self.offset, dtype=np.float64).reshape(-1)
        if offset.shape != (3,) or not np.all(np.isfinite(offset)):
            raise ConfigError(f"segment {self.name!r}: offset must be [x, y, z] in metres")
        end = np.array(self.end, dtype=np.float64).reshape(-1)
        if end.shape != (3,) or not np.all(np.isfinite(end)):
            raise ConfigError(f"segment {self.name!r}: end must be [x, y, z] in metres")
        offset.setflags(write=False)
        end.setflags(write=False)
        object.__setattr__(self, "offset", offset)
        object.__setattr__(self, "end", end)
        if self.functional not in FUNCTIONAL_KINDS:
            raise ConfigError(
                f"segment {self.name!r}: functional must be one of "
                f"{', '.join(FUNCTIONAL_KINDS)}, got {self.functional!r}"
            )
        if self.functional == "twist" and self.joint.second_axis_in_child() is None:
            raise ConfigError(
                f"segment {self.name!r}: functional 'twist' needs a joint with two "
                f"coordinates, the second fixed in the segment (an elbow's flexion and "
                f"pronation); joint {self.joint.name!r} reports {self.joint.coordinates}"
            )


@dataclass(frozen=True)
class SensorTree:
    """Segments in parent-first order; see the module docstring."""

    name: str
    segments: tuple[SegmentSpec, ...]
    description: str = ""

    def __post_init__(self) -> None:
        segs = tuple(self.segments)
        if not segs:
            raise ConfigError(f"tree {self.name!r}: no segments")
        seen: dict[str, SegmentSpec] = {}
        sensors: dict[str, str] = {}
        coords: dict[str, str] = {}
        for s in segs:
            if s.name in seen or s.name == GROUND:
                raise ConfigError(f"tree {self.name!r}: segment name {s.name!r} used twice")
            if s.parent != GROUND and s.parent not in seen:
                raise ConfigError(
                    f"tree {self.name!r}: segment {s.name!r} has parent {s.parent!r}, which is "
                    f"not an earlier segment; parents must come first (known: "
                    f"{', '.join([GROUND, *seen])})"
                )
            if s.sensor in sensors:
                raise ConfigError(
                    f"tree {self.name!r}: sensor {s.sensor!r} is on both "
                    f"{sensors[s.sensor]!r} and {s.name!r}; one sensor per segment"
                )
            for c in s.joint.coordinates:
                if c is None:
                    continue
                if c in coords:
                    raise ConfigError(
                        f"tree {self.name!r}: coordinate {c!r} in joints {coords[c]!r} and "
                        f"{s.joint.name!r}"
                    )
                coords[c] = s.joint.name
            seen[s.name] = s
            sensors[s.sensor] = s.name
        object.__setattr__(self, "segments", segs)

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SensorTree:
        """Build from the YAML/JSON layout of ``presets/*.yaml``."""
        name = str(data.get("name", "tree"))
        raw = data.get("segments")
        if not isinstance(raw, list) or not raw:
            raise ConfigError(f"tree {name!r}: 'segments' must be a non-empty list")
        segments = []
        for i, entry in enumerate(raw):
            if not isinstance(entry, Mapping) or "name" not in entry or "joint" not in entry:
                raise ConfigError(f"tree {name!r}: segments[{i}] needs 'name' and 'joint'")
            j = entry["joint"]
            offsets_deg = j.get("offsets_deg", [0.0, 0.0, 0.0])
            axes = j.get("axes")
            if axes is None and "sequence" in j:
                axes = sequence_axes(str(j["sequence"]), f"segments[{i}].joint.sequence")
            joint = JointSpec(
                name=str(j.get("name", entry["name"])),
                coordinates=tuple(j.get("coordinates", (None, None, None))),
                axes=np.asarray(axes if axes is not None else [], dtype=np.float64),
                signs=np.asarray(j.get("signs", [1.0, 1.0, 1.0]), dtype=np.float64),
                offsets=np.deg2rad(np.asarray(offsets_deg, dtype=np.float64)),
                order=tuple(j["order"]) if "order" in j else None,
            )
            segments.append(
                SegmentSpec(
                    name=str(entry["name"]),
                    parent=str(entry.get("parent", GROUND)),
                    sensor=str(entry.get("sensor", entry["name"])),
                    joint=joint,
                    offset=np.asarray(entry.get("offset", [0.0, 0.0, 0.0]), dtype=np.float64),
                    end=np.asarray(entry.get("end", [0.0, -0.1, 0.0]), dtype=np.float64),
                    functional=str(entry.get("functional", "none")),
                )
            )
        return cls(name, tuple(segments), str(data.get("description", "")))

    @classmethod
    def from_yaml(cls, path: str | Path) -> SensorTree:
        import yaml

        p = Path(path)
        try:
            data = _yaml_load(p.read_text())
        except yaml.YAMLError as exc:
            raise ConfigError(f"{p}: not valid YAML ({exc})") from exc
        if not isinstance(data, Mapping):
            raise ConfigError(f"{p}: expected a mapping with 'name' and 'segments'")
        return cls.from_dict(data)

    @classmethod
    def preset(cls, name: str) -> SensorTree:
        """A built-in tree (``SensorTree.preset_names()`` lists them)."""
        names = cls.preset_names()
        if name not in names:
            raise ConfigError(f"unknown body preset {name!r}; available: {', '.join(names)}")
        return _load_preset(name)

    @staticmethod
    def preset_names() -> tuple[str, ...]:
        files = resources.files("mocapkit.body.presets").iterdir()
        return tuple(sorted(f.name[:-5] for f in files if f.name.endswith(".yaml")))

    def to_dict(self) -> dict[str, Any]:
        """The YAML/JSON layout (round-trips through :meth:`from_dict`)."""
        out = []
        for s in self.segments:
            j = s.joint
            out.append(
                {
                    "name": s.name,
                    "parent": s.parent,
                    "sensor": s.sensor,
                    "offset": s.offset.tolist(),
                    "end": s.end.tolist(),
                    "functional": s.functional,
                    "joint": {
                        "name": j.name,
                        "coordinates": list(j.coordinates),
                        "axes": j.axes.tolist(),
                        "signs": j.signs.tolist(),
                        "offsets_deg": np.rad2deg(j.offsets).tolist(),
                        "order": list(j.order or (0, 1, 2)),
                    },
                }
            )
        return {"name": self.name, "description": self.description, "segments": out}

    def with_sensor_names(self, mapping: Mapping[str, str]) -> SensorTree:
        """Rename sensors: ``{segment name: sensor name}``; unknown segments are refused."""
        unknown = sorted(set(mapping) - set(self.segment_names))
        if unknown:
            raise ConfigError(
                f"tree {self.name!r}: sensor mapping names unknown segment(s) "
                f"{', '.join(map(repr, unknown))}; segments are: {', '.join(self.segment_names)}"
            )
        segs = tuple(replace(s, sensor=str(mapping.get(s.name, s.sensor))) for s in self.segments)
        return SensorTree(self.name, segs, self.description)

    def subtree(self, segment_names: Sequence[str]) -> SensorTree:
        """Only the named segments (each one's parent must be kept too, or be ground)."""
        keep = set(segment_names)
        unknown = sorted(keep - set(self.segment_names))
        if unknown:
            raise ConfigError(
                f"tree {self.name!r}: unknown segment(s) {', '.join(map(repr, unknown))}; "
                f"segments are: {', '.join(self.segment_names)}"
            )
        segs = tuple(s for s in self.segments if s.name in keep)
        return SensorTree(self.name, segs, self.description)

    # -- queries --------------------------------------------------------------------------------
    @property
    def segment_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.segments)

    @property
    def sensor_names(self) -> tuple[str, ...]:
        return tuple(s.sensor for s in self.segments)

    @property
    def coordinate_names(self) -> tuple[str, ...]:
        """Reported coordinates in segment order (each joint's b1, b2, b3)."""
        return tuple(c for s in self.segments for c in s.joint.coordinates if c is not None)

    @property
    def parent_index(self) -> np.ndarray:
        """(S,) int: index of each segment's parent, -1 for ground."""
        idx = {s.name: i for i, s in enumerate(self.segments)}
        return np.array([idx.get(s.parent, -1) for s in self.segments], dtype=np.int64)

    def segment(self, name: str) -> SegmentSpec:
        for s in self.segments:
            if s.name == name:
                return s
        raise ConfigError(
            f"tree {self.name!r}: no segment {name!r}; segments are: "
            f"{', '.join(self.segment_names)}"
        )

    def segment_of_sensor(self, sensor: str) -> SegmentSpec:
        for s in self.segments:
            if s.sensor == sensor:
                return s
        raise ConfigError(
            f"tree {self.name!r}: no segment carries sensor {sensor!r}; sensors are: "
            f"{', '.join(self.sensor_names)}"
        )

    def check_sensors(self, available: Sequence[str]) -> None:
        """Refuse when a sensor of the tree is absent from ``available`` (names both lists)."""
        have = set(available)
        missing = [s for s in self.segments if s.sensor not in have]
        if missing:
            lines = ", ".join(f"{s.name} <- {s.sensor!r}" for s in missing)
            raise ConfigError(
                f"tree {self.name!r}: no data for sensor(s) {lines}; the recording has: "
                f"{', '.join(map(repr, sorted(have)))}. Map segments to sensors with "
                "tree.with_sensor_names({segment: sensor}) (CLI: --map segment=sensor)."
            )
