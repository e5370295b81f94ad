"""One call from sensor orientations to calibrated joint angles (used by the CLI, the
benchmarks and the real-recording tests): align time bases, crop, calibrate (from a pose
or automatically), then compute segment orientations and joint angles."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from mocapkit.body.calibration import (
    POSES_DEG,
    BodyCalibration,
    HeadingFixed,
    HeadingFromSensor,
    calibrate_pose,
    find_still_window,
)
from mocapkit.body.calibration_checks import CalibrationFinding, warn_calibration
from mocapkit.body.functional import calibrate_functional
from mocapkit.body.joint_angles import BodyAngles
from mocapkit.body.kinematics import body_angles
from mocapkit.body.plausibility import Finding, warn_implausible
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.body.timebase import align_orientations
from mocapkit.errors import ConfigError, DataError
from mocapkit.series import OrientationSeries

CALIBRATIONS = ("auto", *POSES_DEG)


@dataclass(frozen=True)
class BodyResult:
    calibration: BodyCalibration
    body: BodyAngles
    segments: dict[str, OrientationSeries]
    implausible: tuple[Finding, ...] = ()
    calibration_findings: tuple[CalibrationFinding, ...] = ()


def crop(
    series: Mapping[str, OrientationSeries], start: float | None, stop: float | None
) -> dict[str, OrientationSeries]:
    """Samples with ``start <= t <= stop`` of every series."""
    out = {}
    for k, s in series.items():
        keep = np.ones(s.n_samples, dtype=bool)
        if start is not None:
            keep &= s.time >= start
        if stop is not None:
            keep &= s.time <= stop
        if keep.sum() < 2:
            raise DataError(
                f"sensor {k!r}: fewer than 2 samples between {start} and {stop} s "
                f"(recording {s.time[0]:.3f}-{s.time[-1]:.3f} s)"
            )
        out[k] = OrientationSeries(s.time[keep], s.quat[keep], name=s.name, frame=s.frame)
    return out


def calibrate(
    tree: SensorTree,
    orientations: Mapping[str, OrientationSeries],
    *,
    calibration: str = "auto",
    window: tuple[float, float] | None = None,
    heading: HeadingFixed | HeadingFromSensor | None = None,
    heading_alignment: str = "hinges",
    root_reference: str = "body",
    still_duration_s: float = 1.0,
) -> BodyCalibration:
    """Calibrate ``tree`` on ``orientations`` (one time base).

    ``calibration="auto"`` estimates mountings and heading from a still window and the
    motion (:func:`calibrate_functional`); a pose name calibrates from that pose held in
    ``window`` (default: the first still window), with ``heading`` (default: world x).
    """
    if calibration not in CALIBRATIONS:
        raise ConfigError(
            f"calibration: expected one of {', '.join(CALIBRATIONS)}, got {calibration!r}"
        )
    if window is None:
        window = find_still_window(orientations, still_duration_s)
    if calibration == "auto":
        cal = calibrate_functional(
            tree, orientations, window, heading=heading, heading_alignment=heading_alignment
        )
    else:
        cal = calibrate_pose(
            tree, orientations, window, pose=calibration, heading=heading or HeadingFixed(0.0)
        )
    return cal.with_root_reference(root_reference)


def placement_source(
    tree: SensorTree,
    placement: Mapping[str, OrientationSeries],
    window: tuple[float, float] | None,
) -> tuple[dict[str, OrientationSeries], tuple[float, float]]:
    """A separate calibration recording (OpenSense's placement file) on one time base,
    and its window (default: its first sample)."""
    tree.check_sensors(list(placement))
    source = align_orientations({s.sensor: placement[s.sensor] for s in tree.segments})
    if window is None:
        t0 = float(source[tree.segments[0].sensor].time[0])
        window = (t0, t0)
    return source, window


def default_heading_alignment(filter_name: str | None, mode: str) -> str:
    """6D raw samples through a filter: each sensor's heading is its own, kept consistent
    by the joints (``"joints"``). 9D and a device's orientations: one world heading, the
    hinges compared across the joints and each segment aligned at the pose (``"hinges"``,
    :func:`mocapkit.body.functional.calibrate_functional`; the joint-heading pass itself
    would move the x-IMU3 recording's hips 14 deg from what two 9D filters agree on)."""
    return "joints" if (filter_name and mode == "6d") else "hinges"


def run_body(
    tree: SensorTree,
    orientations: Mapping[str, OrientationSeries],
    *,
    calibration: str | BodyCalibration = "auto",
    placement: Mapping[str, OrientationSeries] | None = None,
    window: tuple[float, float] | None = None,
    start: float | None = None,
    stop: float | None = None,
    dropout: str = "nan",
    max_hold_s: float = 0.5,
    backend: str = "fast",
    **calibrate_kwargs: Any,
) -> BodyResult:
    """Sensor orientations -> calibration, joint angles and segment orientations.

    Args:
        orientations: {sensor: q_world_sensor series}; other sensors than the tree's are
            ignored; time bases are aligned (slerp) when they differ.
        calibration: ``"auto"``, a pose name, or a ready BodyCalibration.
        placement: a separate calibration recording (OpenSense's placement file); when
            given, the calibration is computed on it instead of on ``orientations``.
        start, stop: crop [s] before anything else (e.g. a filter's convergence).
    """
    tree.check_sensors(list(orientations))
    use = {s.sensor: orientations[s.sensor] for s in tree.segments}
    use = align_orientations(crop(use, start, stop))
    checks: list[CalibrationFinding] = []
    if isinstance(calibration, BodyCalibration):
        cal = calibration
    else:
        source = use
        if placement is not None:
            source, window = placement_source(tree, placement, window)
        cal = calibrate(tree, source, calibration=calibration, window=window, **calibrate_kwargs)
        checks = warn_calibration(tree, cal)  # a calibration at odds with itself, named
    body, segments = body_angles(
        tree, cal, use, dropout=dropout, max_hold_s=max_hold_s, backend=backend
    )
    findings = warn_implausible(tree, body.angles)  # never written silently
    return BodyResult(cal, body, segments, tuple(findings), tuple(checks))


def summary(result: BodyResult) -> dict[str, Any]:
    """JSON-ready figures: per coordinate range [deg] and missing samples; calibration."""
    a = result.body.angles
    coords = {}
    for k, name in enumerate(a.names):
        v = np.rad2deg(a.values[:, k])
        good = np.isfinite(v)
        coords[name] = {
            "min_deg": float(v[good].min()) if good.any() else None,
            "max_deg": float(v[good].max()) if good.any() else None,
            "missing": int((~good).sum()),
        }
    rate = 1.0 / float(np.median(np.diff(a.time))) if a.n_samples > 1 else None
    return {
        "n_frames": a.n_samples,
        "rate_hz": rate,
        "duration_s": float(a.time[-1] - a.time[0]) if a.n_samples else 0.0,
        "calibration": calibration_summary(result.calibration),
        "gimbal_lock": {k: int(v.size) for k, v in result.body.gimbal.items()},
        "near_gimbal": dict(result.body.near_gimbal),
        "held": dict(result.body.held),
        "coordinates": coords,
        **findings_summary(result.calibration_findings, result.implausible),
    }


def calibration_summary(cal: BodyCalibration) -> dict[str, Any]:
    """The calibration's JSON figures (method, heading, window, per-segment residuals)."""
    return {
        "method": cal.method,
        "heading_deg": float(np.rad2deg(cal.heading_rad)),
        "window_s": list(cal.window),
        **{k: v for k, v in cal.diagnostics.items() if not isinstance(v, dict)},
        # per segment: how still its sensor was in the window, how clearly it showed its
        # joint's axis, how far its heading sits from the body's (the residuals)
        "segments": {
            name: {k: round(float(v), 3) for k, v in seg.diagnostics.items()}
            for name, seg in cal.segments.items()
        },
    }


def findings_summary(
    checks: Sequence[CalibrationFinding], implausible: Sequence[Finding]
) -> dict[str, Any]:
    """``calibration_checks`` and ``implausible`` as JSON lists."""
    return {
        "calibration_checks": [
            {
                "kind": f.kind,
                "segment": f.segment,
                "sensor": f.sensor,
                # None where the finding has no size (unaligned segments): valid JSON
                "value_deg": round(f.value_deg, 1) if np.isfinite(f.value_deg) else None,
                "message": f.message,
            }
            for f in checks
        ],
        "implausible": [
            {
                "coordinate": f.coordinate,
                "segment": f.segment,
                "sensor": f.sensor,
                "outside_fraction": round(f.outside_fraction, 3),
                "worst_deg": round(f.worst_deg, 1),
                "range_deg": list(f.range_deg),
            }
            for f in implausible
        ],
    }
