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


def check_angles(tree: SensorTree, angles: JointAngleSeries) -> list[Finding]:
    """The coordinates of ``angles`` outside their physiological ranges."""
    segment_of: dict[str, tuple[str, str]] = {}
    for seg in tree.segments:
        for coord in seg.joint.coordinates:
            if coord is not None:
                segment_of[coord] = (seg.name, seg.sensor)
    findings = []
    for k, name in enumerate(angles.names):
        rng = RANGES_DEG.get(_base(name))
        if rng is None:
            continue
        deg = np.degrees(angles.values[:, k])
        deg = deg[np.isfinite(deg)]
        if deg.size == 0:
            continue
        lo, hi = rng[0] - MARGIN_DEG, rng[1] + MARGIN_DEG
        outside = (deg < lo) | (deg > hi)
        fraction = float(outside.mean())
        if fraction <= OUTSIDE_FRACTION:
            continue
        worst = float(deg[outside][np.argmax(np.abs(deg[outside]))])
        segment, sensor = segment_of.get(name, ("?", "?"))
        findings.append(Finding(name, segment, sensor, fraction, worst, rng))
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
    "check_angles",
    "warn_implausible",
]
