"""Sensor-to-segment calibration from a known pose (seed: section 5, the initialisation
posture and its offsets; section 6, "connectors pointed up" and a root sensor for the
global heading).

Frames. ``q_world_sensor`` comes from the orientation filter (world z up). The OpenSim
ground frame, heading-aligned with the body at calibration, is
``q_world_ground = Rz(psi) * Rx(+90 deg)`` (OpenSim's y up is world z; its x is the body's
forward direction, at heading ``psi`` from world x). A calibrated segment orientation is

    q_world_segment = q_heading * q_world_sensor * q_sensor_segment

with ``q_sensor_segment`` the mounting of the sensor on its segment and ``q_heading`` a yaw
about world z that puts a sensor with its own heading reference (a 6D filter) into the
common world (identity when the sensors share one, e.g. 9D). A pose calibration solves the
mounting so that at calibration every segment has the orientation the pose prescribes:
``q_sensor_segment = q_world_sensor(cal)^-1 * q_world_ground * q_ground_segment(pose)``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.joint_angles import compose_pose
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError, DataError
from mocapkit.geometry import (
    quat_angle_between,
    quat_conj,
    quat_from_axis_angle,
    quat_identity,
    quat_mul,
    quat_normalize,
    quat_rotate,
)
from mocapkit.series import OrientationSeries


class CalibrationError(DataError):
    """The calibration data cannot give a calibration (motion during the pose, a missing
    sensor, a heading axis that is vertical...). The message names the sensor and the fix."""


# Known poses as {coordinate: value [deg]}; coordinates absent from a tree are ignored.
POSES_DEG: dict[str, dict[str, float]] = {
    "anatomical": {},
    # arms hanging at the sides, palms facing the thighs (forearms in neutral rotation)
    "npose": {"pro_sup_r": 90.0, "pro_sup_l": 90.0},
    # arms abducted to horizontal, palms down
    "tpose": {"arm_add_r": -90.0, "arm_add_l": -90.0, "pro_sup_r": 90.0, "pro_sup_l": 90.0},
    # the paper's initialisation: neutral standing with each sensor's connector pointing up
    "connectors_up": {"pro_sup_r": 90.0, "pro_sup_l": 90.0},
}

# Largest rotation [deg] of any sensor away from its mean orientation inside a calibration
# window that still counts as "held still": quiet standing sways a few degrees (postural
# sway of the trunk and soft-tissue motion of sensors on the limbs), a deliberate movement
# is tens of degrees.
STILL_TOLERANCE_DEG = 6.0

_AXES = {"x": 0, "y": 1, "z": 2}
_Q_WORLD_OPENSIM = quat_from_axis_angle([1.0, 0.0, 0.0], np.pi / 2)  # OpenSim y-up -> world z-up


def q_world_ground(heading_rad: float) -> FloatArray:
    """(4,) OpenSim ground frame in the world for a body facing ``heading_rad`` (from world x)."""
    return quat_mul(quat_from_axis_angle([0.0, 0.0, 1.0], heading_rad), _Q_WORLD_OPENSIM)


def yaw_quat(angle_rad: float) -> FloatArray:
    """(4,) rotation by ``angle_rad`` about world z."""
    return quat_from_axis_angle([0.0, 0.0, 1.0], angle_rad)


def parse_axis(axis: str) -> FloatArray:
    """``"x"``, ``"-y"``... -> (3,) unit vector."""
    a = axis.strip().lower()
    sign = -1.0 if a.startswith("-") else 1.0
    letter = a.lstrip("+-")
    if letter not in _AXES:
        raise ConfigError(f"axis: expected x, y, z, -x, -y or -z, got {axis!r}")
    v = np.zeros(3)
    v[_AXES[letter]] = sign
    return v


@dataclass(frozen=True)
class SegmentCalibration:
    """Calibration of one segment: mounting, heading correction and diagnostics."""

    sensor: str
    q_sensor_segment: FloatArray
    q_heading: FloatArray = field(default_factory=lambda: quat_identity())
    diagnostics: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for key in ("q_sensor_segment", "q_heading"):
            q = quat_normalize(np.asarray(getattr(self, key), dtype=np.float64))
            q.setflags(write=False)
            object.__setattr__(self, key, q)


@dataclass(frozen=True)
class BodyCalibration:
    """A calibrated sensor tree: per segment mountings and the body heading at calibration.

    Attributes:
        tree_name: the tree it was made for (checked when applied).
        segments: {segment name: SegmentCalibration}.
        heading_rad: body heading ``psi`` at calibration [rad from world x].
        method: ``"pose"`` or ``"functional"``.
        pose: the pose's coordinates [rad].
        window: (t0, t1) [s] of the calibration samples.
        ground_heading_rad: heading of the root joints' reference frame ``ground``:
            ``heading_rad`` (default, ``root_reference="body"``: ``pelvis_rotation`` is 0
            at calibration) or 0 (``"world"``: relative to world x, OpenSense IK's
            convention).
    """

    tree_name: str
    segments: dict[str, SegmentCalibration]
    heading_rad: float
    method: str
    pose: dict[str, float] = field(default_factory=dict)
    window: tuple[float, float] = (0.0, 0.0)
    diagnostics: dict[str, Any] = field(default_factory=dict)
    ground_heading_rad: float | None = None

    @property
    def q_world_ground(self) -> FloatArray:
        """(4,) the root joints' reference frame in the world."""
        psi = self.heading_rad if self.ground_heading_rad is None else self.ground_heading_rad
        return q_world_ground(psi)

    def with_root_reference(self, root_reference: str) -> BodyCalibration:
        """``"body"``: root angles relative to the body at calibration; ``"world"``:
        relative to the world's x axis (OpenSense IK)."""
        if root_reference not in ("body", "world"):
            raise ConfigError(f"root_reference: expected 'body' or 'world', got {root_reference!r}")
        return replace(self, ground_heading_rad=None if root_reference == "body" else 0.0)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (angles in rad, quaternions [w, x, y, z])."""
        return {
            "tree": self.tree_name,
            "method": self.method,
            "heading_rad": self.heading_rad,
            "pose_rad": dict(self.pose),
            "window_s": list(self.window),
            "ground_heading_rad": self.ground_heading_rad,
            "segments": {
                name: {
                    "sensor": c.sensor,
                    "q_sensor_segment": c.q_sensor_segment.tolist(),
                    "q_heading": c.q_heading.tolist(),
                    "diagnostics": dict(c.diagnostics),
                }
                for name, c in self.segments.items()
            },
            "diagnostics": self.diagnostics,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> BodyCalibration:
        try:
            segs = {
                str(name): SegmentCalibration(
                    sensor=str(c["sensor"]),
                    q_sensor_segment=np.asarray(c["q_sensor_segment"], dtype=np.float64),
                    q_heading=np.asarray(c.get("q_heading", [1, 0, 0, 0]), dtype=np.float64),
                    diagnostics=dict(c.get("diagnostics", {})),
                )
                for name, c in data["segments"].items()
            }
            window = tuple(float(v) for v in data.get("window_s", (0.0, 0.0)))
            return cls(
                tree_name=str(data["tree"]),
                segments=segs,
                heading_rad=float(data["heading_rad"]),
                method=str(data.get("method", "pose")),
                pose={str(k): float(v) for k, v in data.get("pose_rad", {}).items()},
                window=(window[0], window[1]),
                diagnostics=dict(data.get("diagnostics", {})),
                ground_heading_rad=(
                    None
                    if data.get("ground_heading_rad") is None
                    else float(data["ground_heading_rad"])
                ),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigError(f"calibration: malformed dictionary ({exc!r})") from exc

    def check_tree(self, tree: SensorTree) -> None:
        """Refuse a calibration made for another tree or missing segments."""
        missing = [s.name for s in tree.segments if s.name not in self.segments]
        if missing:
            raise ConfigError(
                f"calibration for tree {self.tree_name!r} has no segment(s) "
                f"{', '.join(missing)} of tree {tree.name!r}; calibrate this tree"
            )
        wrong = [
            f"{s.name} (calibrated with {self.segments[s.name].sensor!r}, tree has {s.sensor!r})"
            for s in tree.segments
            if self.segments[s.name].sensor != s.sensor
        ]
        if wrong:
            raise ConfigError(f"calibration sensor names differ from the tree: {'; '.join(wrong)}")


# -- poses and still windows ----------------------------------------------------------------------
def pose_coordinates(tree: SensorTree, pose: str | Mapping[str, float]) -> dict[str, float]:
    """A pose name (:data:`POSES_DEG`) or ``{coordinate: rad}`` -> ``{coordinate: rad}``.

    Named poses ignore coordinates the tree lacks; explicit dictionaries must only name
    coordinates of the tree.
    """
    names = set(tree.coordinate_names)
    if isinstance(pose, str):
        if pose not in POSES_DEG:
            raise ConfigError(f"unknown pose {pose!r}; known: {', '.join(POSES_DEG)}")
        return {k: float(np.deg2rad(v)) for k, v in POSES_DEG[pose].items() if k in names}
    unknown = sorted(set(pose) - names)
    if unknown:
        raise ConfigError(
            f"pose names coordinate(s) {', '.join(unknown)} that tree {tree.name!r} does not "
            f"have; its coordinates: {', '.join(tree.coordinate_names)}"
        )
    return {str(k): float(v) for k, v in pose.items()}


def window_indices(time: FloatArray, window: tuple[float, float]) -> np.ndarray:
    t0, t1 = window
    idx = np.flatnonzero((time >= t0 - 1e-9) & (time <= t1 + 1e-9))
    if idx.size == 0:
        raise CalibrationError(
            f"calibration window {t0:.3f}-{t1:.3f} s holds no sample (recording "
            f"{time[0]:.3f}-{time[-1]:.3f} s)"
        )
    return idx


def mean_orientation(q: FloatArray) -> FloatArray:
    """Chordal mean (4,) of unit quaternions (N, 4), signs aligned to the first."""
    good = q[np.isfinite(q).all(axis=1)]
    signs = np.where(good @ good[0] < 0.0, -1.0, 1.0)
    return quat_normalize((good * signs[:, None]).mean(axis=0))


def still_orientation(
    series: OrientationSeries,
    idx: np.ndarray,
    sensor: str,
    tolerance_deg: float = STILL_TOLERANCE_DEG,
) -> tuple[FloatArray, float]:
    """Mean orientation of ``series`` over samples ``idx`` and its largest deviation [deg].

    Raises CalibrationError naming the sensor when it moved more than ``tolerance_deg``
    or has no valid sample in the window.
    """
    q = series.quat[idx]
    valid = np.isfinite(q).all(axis=1)
    t0, t1 = float(series.time[idx[0]]), float(series.time[idx[-1]])
    if valid.sum() < max(1, idx.size // 2):
        raise CalibrationError(
            f"sensor {sensor!r}: only {int(valid.sum())} of {idx.size} samples are valid in the "
            f"calibration window {t0:.2f}-{t1:.2f} s; the sensor dropped out during "
            "calibration. Repeat the calibration or choose another window."
        )
    mean = mean_orientation(q[valid])
    dev = float(np.rad2deg(quat_angle_between(q[valid], mean).max()))
    if dev > tolerance_deg:
        worst = int(idx[valid][np.argmax(quat_angle_between(q[valid], mean))])
        raise CalibrationError(
            f"sensor {sensor!r} moved during the calibration pose: it turned {dev:.1f} deg "
            f"(sample {worst}, t = {series.time[worst]:.2f} s) within {t0:.2f}-{t1:.2f} s, "
            f"more than the {tolerance_deg:.1f} deg allowed. Hold the pose still for the "
            "whole window, or pick a still window (find_still_window, CLI --calib-window)."
        )
    return mean, dev


def angular_rate(series: OrientationSeries) -> FloatArray:
    """(N, 3) angular rate in the sensor frame [rad/s] from orientation differences
    (backward difference; the first sample repeats the second; NaN across gaps)."""
    q = series.quat
    dt = np.diff(series.time)[:, None]
    rel = quat_mul(quat_conj(q[:-1]), q[1:])
    rel = np.where(rel[:, :1] < 0.0, -rel, rel)
    w = rel[:, 1:]
    s = np.linalg.norm(w, axis=1, keepdims=True)
    angle = 2.0 * np.arctan2(s, rel[:, :1])
    with np.errstate(invalid="ignore", divide="ignore"):
        rate = np.where(s > 1e-12, w / np.where(s > 1e-12, s, 1.0) * angle, 2.0 * w) / dt
    return np.vstack([rate[:1], rate]) if len(rate) else np.zeros((len(q), 3))


def find_still_window(
    series: Mapping[str, OrientationSeries],
    duration_s: float = 1.0,
    rate_threshold: float = 0.35,
    start_s: float | None = None,
) -> tuple[float, float]:
    """The first window of ``duration_s`` in which every sensor turns slower than
    ``rate_threshold`` [rad/s] (median-filtered over 0.1 s). Raises CalibrationError
    naming the sensor that moved most when there is none."""
    names = list(series)
    time = series[names[0]].time
    rates = np.stack([np.linalg.norm(angular_rate(series[n]), axis=1) for n in names])
    rates = np.nan_to_num(rates, nan=np.inf)
    rate_hz = 1.0 / float(np.median(np.diff(time)))
    k = max(1, round(0.1 * rate_hz))
    if k > 1:
        from scipy.ndimage import median_filter

        rates = median_filter(rates, size=(1, k), mode="nearest")
    still = (rates < rate_threshold).all(axis=0)
    if start_s is not None:
        still &= time >= start_s
    n = max(2, round(duration_s * rate_hz))
    run = np.convolve(still.astype(np.int64), np.ones(n, dtype=np.int64), mode="valid")
    hits = np.flatnonzero(run == n)
    if hits.size == 0:
        worst = names[int(np.argmax(np.median(rates, axis=1)))]
        raise CalibrationError(
            f"no still window of {duration_s:.1f} s where every sensor turns slower than "
            f"{rate_threshold:.2f} rad/s; sensor {worst!r} moves the most. Record a still "
            "calibration pose or give the window explicitly."
        )
    i = int(hits[0])
    return float(time[i]), float(time[i + n - 1])


# -- heading sources ----------------------------------------------------------------------------
@dataclass(frozen=True)
class HeadingFixed:
    """The body faced ``heading_rad`` (from world x, counter-clockwise) at calibration."""

    heading_rad: float = 0.0


@dataclass(frozen=True)
class HeadingFromSensor:
    """The body's forward direction is ``axis`` of ``sensor``, projected on the horizontal
    (OpenSense's base IMU and base heading axis; the paper's root sensor)."""

    sensor: str
    axis: str = "x"


def heading_from_sensor(q_world_sensor: FloatArray, spec: HeadingFromSensor) -> float:
    v = quat_rotate(q_world_sensor, parse_axis(spec.axis))
    horiz = float(np.hypot(v[0], v[1]))
    if horiz < np.sin(np.deg2rad(20.0)):
        raise CalibrationError(
            f"heading sensor {spec.sensor!r}: its axis {spec.axis} is "
            f"{np.rad2deg(np.arccos(min(1.0, horiz))):.0f} deg from horizontal at calibration, "
            "so it gives no forward direction; choose a horizontal axis of that sensor"
        )
    return float(np.arctan2(v[1], v[0]))


def calibrate_pose(
    tree: SensorTree,
    orientations: Mapping[str, OrientationSeries],
    window: tuple[float, float],
    *,
    pose: str | Mapping[str, float] = "npose",
    heading: HeadingFixed | HeadingFromSensor = HeadingFixed(0.0),
    still_tolerance_deg: float = STILL_TOLERANCE_DEG,
    connector_axis: str = "x",
    connector_tolerance_deg: float = 30.0,
) -> BodyCalibration:
    """Calibrate every mounting from a known, held-still pose.

    Assumes the sensors share one world heading (9D, or 6D aligned beforehand); for
    sensors with unrelated headings use :func:`mocapkit.body.functional.calibrate_functional`.

    Args:
        orientations: {sensor name: OrientationSeries ``q_world_sensor``} on one time base.
        window: (t0, t1) [s] during which the pose is held.
        pose: a name from :data:`POSES_DEG` or ``{coordinate: rad}``.
        heading: where the body faced (fixed, or a sensor axis as OpenSense's base IMU).
        connector_axis: for ``pose="connectors_up"``, the sensor axis of the connector,
            which must point up within ``connector_tolerance_deg`` on every sensor.
    """
    tree.check_sensors(list(orientations))
    coords = pose_coordinates(tree, pose)
    q_ground_seg = compose_pose(tree, coords)
    q_cal: dict[str, FloatArray] = {}
    devs: dict[str, float] = {}
    for seg in tree.segments:
        s = orientations[seg.sensor]
        idx = window_indices(s.time, window)
        q_cal[seg.sensor], devs[seg.sensor] = still_orientation(
            s, idx, seg.sensor, still_tolerance_deg
        )
    if pose == "connectors_up":
        up = parse_axis(connector_axis)
        for seg in tree.segments:
            tilt = float(
                np.rad2deg(np.arccos(np.clip(quat_rotate(q_cal[seg.sensor], up)[2], -1.0, 1.0)))
            )
            if tilt > connector_tolerance_deg:
                raise CalibrationError(
                    f"sensor {seg.sensor!r} on {seg.name}: its connector axis "
                    f"{connector_axis} is {tilt:.0f} deg from vertical; the connectors-up "
                    f"initialisation needs every connector within {connector_tolerance_deg:.0f} "
                    "deg of up. Re-mount the sensor or use pose='npose'."
                )
    if isinstance(heading, HeadingFromSensor):
        if heading.sensor not in q_cal:
            raise ConfigError(
                f"heading sensor {heading.sensor!r} is not in tree {tree.name!r}; sensors: "
                f"{', '.join(tree.sensor_names)}"
            )
        psi = heading_from_sensor(q_cal[heading.sensor], heading)
    else:
        psi = float(heading.heading_rad)
    q_wg = q_world_ground(psi)
    segs = {}
    for i, seg in enumerate(tree.segments):
        target = quat_mul(q_wg, q_ground_seg[i])
        segs[seg.name] = SegmentCalibration(
            sensor=seg.sensor,
            q_sensor_segment=quat_mul(quat_conj(q_cal[seg.sensor]), target),
            diagnostics={"still_deviation_deg": devs[seg.sensor]},
        )
    return BodyCalibration(
        tree_name=tree.name,
        segments=segs,
        heading_rad=psi,
        method="pose",
        pose=coords,
        window=(float(window[0]), float(window[1])),
        diagnostics={"pose": pose if isinstance(pose, str) else "custom"},
    )


def reset_headings(
    tree: SensorTree,
    calib: BodyCalibration,
    orientations: Mapping[str, OrientationSeries],
    window: tuple[float, float],
    *,
    pose: str | Mapping[str, float] = "npose",
    still_tolerance_deg: float = STILL_TOLERANCE_DEG,
) -> BodyCalibration:
    """Keep the mountings, re-estimate every sensor's heading correction ``q_heading`` so
    that in ``pose`` (held still in ``window``) each segment faces the calibration's body
    heading: the heading reset for sensors whose worlds have unrelated headings (6D
    filters), any size of offset. Redo it at any time the headings have drifted."""
    calib.check_tree(tree)
    coords = pose_coordinates(tree, pose)
    q_ground_seg = compose_pose(tree, coords)
    q_wg = q_world_ground(calib.heading_rad)
    segs = {}
    for i, seg in enumerate(tree.segments):
        s = orientations[seg.sensor]
        q_cal, _ = still_orientation(
            s, window_indices(s.time, window), seg.sensor, still_tolerance_deg
        )
        old = calib.segments[seg.name]
        have = quat_rotate(quat_mul(q_cal, old.q_sensor_segment), np.array([1.0, 0.0, 0.0]))
        want = quat_rotate(quat_mul(q_wg, q_ground_seg[i]), np.array([1.0, 0.0, 0.0]))
        if np.hypot(have[0], have[1]) < 0.2 or np.hypot(want[0], want[1]) < 0.2:
            raise CalibrationError(
                f"sensor {seg.sensor!r} on {seg.name}: the segment's forward axis is near "
                "vertical in this pose, so its heading cannot be reset from it; use a pose "
                "with the segment upright (npose)"
            )
        delta = float(np.arctan2(want[1], want[0]) - np.arctan2(have[1], have[0]))
        d = dict(old.diagnostics)
        d["heading_reset_deg"] = float(np.rad2deg(np.angle(np.exp(1j * delta))))
        segs[seg.name] = SegmentCalibration(old.sensor, old.q_sensor_segment, yaw_quat(delta), d)
    return replace(calib, segments=segs)
