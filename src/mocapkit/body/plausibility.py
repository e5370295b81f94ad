"""Is a body result humanly possible? Joint angles checked against physiological ranges.

A calibration that turned a segment round, a sensor mounted the other way, or headings
that drifted apart (6D filters) give joint angles no human reaches: a knee bent 70 deg
backwards, a forearm pronated 250 deg. Those used to be written with exit 0. Here every
coordinate with a known range is checked over the recording: when more than
``OUTSIDE_FRACTION`` of its samples lie outside the range (widened by ``MARGIN_DEG`` for
calibration error), a :class:`ImplausibleAnglesWarning` names the coordinate, its
segment and sensor, how far out it goes, and what to check. The ranges follow the body
model's conventions (flexion positive, as OpenSim's gait models; knee flexion positive).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from mocapkit.body.sensor_tree import SensorTree
from mocapkit.series import JointAngleSeries

#: physiological ranges [deg] of the coordinates the presets use (generous: standing,
#: walking, sitting, reaching; sports and falls can exceed them).
RANGES_DEG: dict[str, tuple[float, float]] = {
    "pelvis_tilt": (-90.0, 90.0),
    "pelvis_list": (-60.0, 60.0),
    "lumbar_extension": (-90.0, 90.0),
    "lumbar_bending": (-60.0, 60.0),
    "lumbar_rotation": (-60.0, 60.0),
    "neck_extension": (-90.0, 90.0),
    "neck_bending": (-60.0, 60.0),
    "neck_rotation": (-90.0, 90.0),
    # 90 is neutral (the N-pose: palms to the thighs), 0 supinated (palms forward), 180
    # pronated; a forearm sensor also sees the ulna's share of the twist
    "pro_sup": (-60.0, 210.0),
    "wrist_flex": (-90.0, 90.0),
    "wrist_dev": (-50.0, 50.0),
    "hip_flexion": (-40.0, 140.0),
    "hip_adduction": (-50.0, 50.0),
    "hip_rotation": (-70.0, 70.0),
    "knee_angle": (-20.0, 160.0),
    "ankle_angle": (-60.0, 60.0),
    "subtalar_angle": (-40.0, 40.0),
}
MARGIN_DEG = 15.0
OUTSIDE_FRACTION = 0.05


class ImplausibleAnglesWarning(UserWarning):
    """Joint angles outside what a human body reaches: the result is probably wrong."""


@dataclass(frozen=True)
class Finding:
    """One coordinate outside its range."""

    coordinate: str
    segment: str
    sensor: str
    outside_fraction: float
    worst_deg: float
    range_deg: tuple[float, float]

    def message(self) -> str:
        lo, hi = self.range_deg
        return (
            f"{self.coordinate} (segment {self.segment}, sensor {self.sensor}) is outside "
            f"{lo:.0f}..{hi:.0f} deg in {100 * self.outside_fraction:.0f} % of the samples "
            f"(up to {self.worst_deg:.0f} deg): no human joint does that. The sensor's mounting "
            "was probably calibrated turned round, or its heading drifted from its "
            "neighbours' (a 6D filter): check that sensor's placement, calibrate from a held "
            "pose (--calibration npose), or use 9D orientations"
        )


def _base(name: str) -> str:
    for suffix in ("_r", "_l"):
        if name.endswith(suffix):
            return name[: -len(suffix)]
    return name


class RangeTally:
    """Counts, over pieces of a recording, each coordinate's samples outside its range:
    :meth:`findings` then equals :func:`check_angles` on the whole (the streamed body
    pipeline checks an hour without holding it)."""

    def __init__(self, tree: SensorTree, names: tuple[str, ...]) -> None:
        segment_of: dict[str, tuple[str, str]] = {}
        for seg in tree.segments:
            for coord in seg.joint.coordinates:
                if coord is not None:
                    segment_of[coord] = (seg.name, seg.sensor)
        # (column, name, range, segment, sensor) of each coordinate with a known range
        self._checked = [
            (k, name, RANGES_DEG[_base(name)], *segment_of.get(name, ("?", "?")))
            for k, name in enumerate(names)
            if _base(name) in RANGES_DEG
        ]
        n = len(self._checked)
        self._finite = np.zeros(n, dtype=np.int64)
        self._outside = np.zeros(n, dtype=np.int64)
        self._worst = np.zeros(n)

    def add(self, values: np.ndarray) -> None:
        """Joint angles (n, K) [rad], columns in ``names`` order."""
        for j, (k, _, rng, _, _) in enumerate(self._checked):
            deg = np.degrees(values[:, k])
            deg = deg[np.isfinite(deg)]
            out = deg[(deg < rng[0] - MARGIN_DEG) | (deg > rng[1] + MARGIN_DEG)]
            self._finite[j] += deg.size
            self._outside[j] += out.size
            if out.size:
                w = float(out[np.argmax(np.abs(out))])
                if abs(w) > abs(self._worst[j]):
                    self._worst[j] = w

    def findings(self) -> list[Finding]:
        found = []
        for j, (_, name, rng, segment, sensor) in enumerate(self._checked):
            if self._finite[j] == 0:
                continue
            fraction = float(self._outside[j] / self._finite[j])
            if fraction > OUTSIDE_FRACTION:
                found.append(Finding(name, segment, sensor, fraction, float(self._worst[j]), rng))
        return found


def check_angles(tree: SensorTree, angles: JointAngleSeries) -> list[Finding]:
    """The coordinates of ``angles`` outside their physiological ranges."""
    tally = RangeTally(tree, tuple(angles.names))
    tally.add(angles.values)
    return tally.findings()


def warn_findings(findings: list[Finding]) -> list[Finding]:
    """Each finding warned (``ImplausibleAnglesWarning``)."""
    for f in findings:
        warnings.warn(f.message(), ImplausibleAnglesWarning, stacklevel=3)
    return findings


def warn_implausible(tree: SensorTree, angles: JointAngleSeries) -> list[Finding]:
    """:func:`check_angles`, each finding warned (``ImplausibleAnglesWarning``)."""
    findings = check_angles(tree, angles)
    for f in findings:
        warnings.warn(f.message(), ImplausibleAnglesWarning, stacklevel=3)
    return findings


__all__ = [
    "MARGIN_DEG",
    "OUTSIDE_FRACTION",
    "RANGES_DEG",
    "Finding",
    "ImplausibleAnglesWarning",
    "RangeTally",
    "check_angles",
    "warn_findings",
    "warn_implausible",
]
