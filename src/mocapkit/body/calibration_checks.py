"""Does an automatic calibration agree with itself? Checked before any angle is written.

The automatic calibration (:mod:`mocapkit.body.functional`) asks every segment with a
flexion axis which way the body faced in the held pose, and the knees and elbows which
way is forward. When the sensors share one world (9D, a device's orientations, 6D after
the joints aligned them), those answers must agree:

- **a segment turned away**: its flexion axis says the body faced more than
  ``TURNED_DEG`` away from the consensus. A sensor that slipped or sits turned round on
  its strap, or a joint that hardly moved, does this; its joint angles then carry the
  error as an offset of that size.
- **forward or backward unclear**: the knees and elbows flex about as much one way as
  the other (``MIN_FORWARD_MARGIN_DEG``): the body may be calibrated facing backwards,
  every flexion then has the wrong sign.
- **headings spread**: the segments' answers scatter by more than ``MAX_SPREAD_DEG``.

Each is a :class:`CalibrationWarning` naming the segment and sensor and the fix, and a
:class:`CalibrationFinding` in the result (``body angles --json``: ``calibration_checks``).
With unrelated 6D worlds aligned only at the pose (``heading_alignment="pose"``), a
segment's offset is its sensor's own heading, not a fault: those are not checked. There,
instead:

- **unaligned**: the segments calibrated from the pose alone (no functional axis: the
  pelvis, trunk and head, in that mode the forearms and hands) keep their sensors' own
  world headings, which nothing relates to the others': their joint angles mix by the
  difference (pelvis tilt with list, lumbar angles; on the closed loop's full body the
  elbows 29-35 deg off). One warning names them all, with the fix.

The thresholds sit well above what the simulated suits (1-5 deg) and the real
recordings here (up to 21 deg on the 15-IMU recording's walks) give, and below the
45-50 deg of a calibration that went wrong (the same recording cut to its sit-down).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

from mocapkit.body.calibration import BodyCalibration
from mocapkit.body.sensor_tree import SensorTree

TURNED_DEG = 30.0
MIN_FORWARD_MARGIN_DEG = 10.0
MAX_SPREAD_DEG = 25.0


class CalibrationWarning(UserWarning):
    """An automatic calibration that disagrees with itself: its angles may be wrong."""


@dataclass(frozen=True)
class CalibrationFinding:
    """One disagreement: ``kind`` is ``turned``, ``forward`` or ``spread``."""

    kind: str
    segment: str
    sensor: str
    value_deg: float
    message: str


def check_calibration(tree: SensorTree, cal: BodyCalibration) -> list[CalibrationFinding]:
    """The disagreements of an automatic calibration (module docstring); none for a pose
    calibration; for 6D worlds aligned at the pose only, the segments left unaligned."""
    if cal.method != "functional":
        return []
    if cal.diagnostics.get("heading_alignment") == "pose":
        return _unaligned(tree, cal)
    out = []
    fix = (
        "check that sensor's strap and placement, record more motion of its joint (walking "
        "with arm swing), or calibrate from a held pose (--calibration npose with "
        "--heading-sensor)"
    )
    for seg in tree.segments:
        off = cal.segments[seg.name].diagnostics.get("heading_offset_deg")
        if off is not None and abs(off) > TURNED_DEG:
            out.append(CalibrationFinding(
                "turned", seg.name, seg.sensor, float(off),
                f"calibration: segment {seg.name} (sensor {seg.sensor}) says the body faced "
                f"{off:+.0f} deg from the other segments' consensus (more than "
                f"{TURNED_DEG:.0f}): its joint angles carry that as an offset; {fix}",
            ))  # fmt: skip
    fwd = cal.diagnostics.get("forward_score_deg")
    back = cal.diagnostics.get("backward_score_deg")
    if fwd is not None and back is not None and fwd - back < MIN_FORWARD_MARGIN_DEG:
        out.append(CalibrationFinding(
            "forward", "", "", float(fwd - back),
            f"calibration: forward and backward are hard to tell apart (knees and elbows "
            f"flex {fwd:+.0f} deg on average facing one way, {back:+.0f} the other): the "
            "body may be calibrated facing backwards, every flexion with the wrong sign; "
            "record some walking, or give the heading (--heading-sensor / --heading-deg)",
        ))  # fmt: skip
    spread = cal.diagnostics.get("heading_spread_deg")
    if spread is not None and spread > MAX_SPREAD_DEG:
        out.append(CalibrationFinding(
            "spread", "", "", float(spread),
            f"calibration: the segments' flexion axes disagree on the body's heading by "
            f"{spread:.0f} deg (more than {MAX_SPREAD_DEG:.0f}); the joint angles carry "
            f"offsets of that size; {fix}",
        ))  # fmt: skip
    return out


def _unaligned(tree: SensorTree, cal: BodyCalibration) -> list[CalibrationFinding]:
    loose = [s for s in tree.segments
             if not cal.segments[s.name].diagnostics.get("functional", 0.0)]  # fmt: skip
    if not loose:
        return []
    names = ", ".join(f"{s.name} (sensor {s.sensor})" for s in loose)
    return [CalibrationFinding(
        "unaligned", loose[0].name, loose[0].sensor, float("nan"),
        f"calibration: with heading_alignment=pose each sensor's world heading is its own, "
        f"and {names} {'has' if len(loose) == 1 else 'have'} no functional axis to align "
        f"{'its' if len(loose) == 1 else 'theirs'} by: their joint angles mix "
        "by the heading between their sensors' worlds and the others' (pelvis tilt with "
        "list, lumbar and elbow angles). Fix: with raw samples use --heading-alignment "
        "joints (the 6D default); if the orientations share one world heading (a "
        "device's, or a 9D filter's) use --heading-alignment hinges",
    )]  # fmt: skip


def warn_calibration(tree: SensorTree, cal: BodyCalibration) -> list[CalibrationFinding]:
    """:func:`check_calibration`, each finding warned (``CalibrationWarning``)."""
    findings = check_calibration(tree, cal)
    for f in findings:
        warnings.warn(f.message, CalibrationWarning, stacklevel=3)
    return findings


__all__ = [
    "MAX_SPREAD_DEG",
    "MIN_FORWARD_MARGIN_DEG",
    "TURNED_DEG",
    "CalibrationFinding",
    "CalibrationWarning",
    "check_calibration",
    "warn_calibration",
]
