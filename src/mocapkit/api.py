"""The common path in a few calls, importable from the top level (``mocapkit.reconstruct``,
``mocapkit.read_c3d``, ...). Every option is keyword-only; units are SI and radians.

>>> import mocapkit
>>> rec = mocapkit.reconstruct("walk.trc", height_m=1.80)        # doctest: +SKIP
>>> rec.angles.to_dataframe(degrees=True).head()                  # doctest: +SKIP
>>> imu = mocapkit.read_imu("thigh.csv")["thigh"]                 # doctest: +SKIP
>>> q = mocapkit.make_filter("polaris", imu.rate_hz).run_recording(imu)  # doctest: +SKIP
>>> body = mocapkit.body_angles("suit.mat", filter="polaris-body", mode="6d")  # doctest: +SKIP
>>> robot = mocapkit.retarget(rec, robot="g1")                    # doctest: +SKIP
>>> robot.write("walk_g1.mcap")                                   # doctest: +SKIP

``import mocapkit`` stays light: each name imports its module when first used.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit import _API
from mocapkit.errors import ConfigError
from mocapkit.series import JointAngleSeries


@dataclass(frozen=True)
class Reconstruction:
    """What :func:`reconstruct` returns.

    Attributes:
        angles: the joint angles (OpenSim coordinate names; [rad], [m] for ``*_t?``);
            ``angles.to_dataframe()`` for a table.
        rms_marker_error_m: RMS distance of the tracked model markers to the captured ones.
        result: everything the reconstruction computed (bounds, model markers, levels).
        subject: the scaled model and its marker set.
        cleaning: what was done to the markers before (gaps, filtering, axes).
        warnings: the doubts the run raised, as sentences.
    """

    angles: JointAngleSeries
    rms_marker_error_m: float
    result: Any
    subject: Any
    cleaning: Any
    warnings: tuple[str, ...]

    def to_dataframe(self, degrees: bool = False) -> Any:
        """``angles.to_dataframe`` (pandas)."""
        return self.angles.to_dataframe(degrees=degrees)


def reconstruct(
    trial: str | Path,
    *,
    static: str | Path | None = None,
    markerset: str | Path | None = None,
    height_m: float | None = None,
    mass_kg: float | None = None,
    method: str = "osc",
    start_s: float | None = None,
    end_s: float | None = None,
) -> Reconstruction:
    """Joint angles from a marker trial (C3D or TRC), as ``mocapkit markers reconstruct``:
    by direct marker control (``method="osc"``, the paper) or least-squares IK (``"ik"``).

    ``height_m`` None: estimated from the markers (warned); ``markerset`` None: chosen
    from the trial's labels (or refused with the markers named)."""
    from mocapkit._logged import logged_warnings
    from mocapkit.markers.reconstruct import ReconstructionOptions, run

    with logged_warnings() as warned:
        opts = ReconstructionOptions(method=method, start_s=start_s, end_s=end_s)  # type: ignore[arg-type]
        result, subject, cleaning = run(trial, static, markerset, height_m, mass_kg, opts)
    keep = [k for k in range(len(result.coordinate_names))
            if np.isfinite(result.coordinates[:, k]).any()]  # fmt: skip
    angles = JointAngleSeries(
        result.time,
        tuple(result.coordinate_names[k] for k in keep),
        result.coordinates[:, keep],
        name=Path(trial).stem,
    )
    rms = result.frame_rms(result.tracked)
    seen = rms[rms == rms]
    rms_m = float(seen.mean()) if seen.size else float("nan")
    return Reconstruction(angles, rms_m, result, subject, cleaning, tuple(warned))


def read_c3d(path: str | Path, *, units: str | None = None) -> Any:
    """Marker trajectories [m] of a C3D file (analogs, force plates and events kept in
    ``meta["c3d"]``)."""
    from mocapkit.io.c3d import read_c3d as _read

    return _read(path, units=units)


def read_trc(path: str | Path, *, units: str | None = None) -> Any:
    """Marker trajectories [m] of a TRC file (OpenSim's variants included)."""
    from mocapkit.io.trc import read_trc as _read

    return _read(path, units=units)


def read_imu(path: str | Path) -> dict[str, Any]:
    """Every sensor's IMU recording in a file or directory (mocapkit CSV, BROAD, x-IMU3,
    Xsens): ``{name: ImuRecording}`` [rad/s, m/s^2, uT]."""
    from mocapkit.io.imu_files import read_imu_recordings

    return read_imu_recordings(path)


def make_filter(name: str, rate_hz: float, **params: Any) -> Any:
    """An orientation filter (``polaris``, ``polaris-body``, ``bachmann``, ``miller``)."""
    from mocapkit.imu.filters import make_filter as _make

    return _make(name, rate_hz, **params)


@dataclass(frozen=True)
class BodyMotion:
    """What :func:`body_angles` returns.

    Attributes:
        angles: joint angles on OpenSim's coordinate names [rad]; ``to_dataframe()``.
        segments: ``{segment: OrientationSeries}`` ``q_world_segment`` [w, x, y, z].
        calibration: the sensor-to-segment calibration (``.to_dict()`` for JSON).
        warnings: the doubts the run raised (joints no human reaches, a calibration at
            odds with itself, dropouts), as sentences; also issued as Python warnings.
    """

    angles: JointAngleSeries
    segments: dict[str, Any]
    calibration: Any
    warnings: tuple[str, ...]

    def to_dataframe(self, degrees: bool = False) -> Any:
        """``angles.to_dataframe`` (pandas): ``time_s`` index, ``<coordinate>_rad``."""
        return self.angles.to_dataframe(degrees=degrees)


def body_angles(
    recording: str | Path | Mapping[str, Any],
    *,
    preset: str = "full_body_15",
    tree: str | Path | None = None,
    filter: str | None = None,
    mode: str = "9d",
    calibration: str = "auto",
    heading_alignment: str | None = None,
    start_s: float | None = None,
    end_s: float | None = None,
    dropout: str = "nan",
) -> BodyMotion:
    """Joint angles from body-worn sensors, as ``mocapkit body angles``.

    Args:
        recording: a file or directory (qmt ``.mat``, OpenSense quaternion ``.sto``,
            x-IMU3 or Xsens exports), or ``{sensor: OrientationSeries}`` ``q_world_sensor``.
        preset, tree: the sensor tree (a built-in name, or a YAML file).
        filter: run this orientation filter (``polaris-body``, ``polaris``, ...) on the
            raw samples in ``mode`` ``"9d"``/``"6d"``; None uses the recording's own
            orientations.
        calibration: ``"auto"`` (from a still pose and the motion) or a held pose name.
        heading_alignment: None: ``"joints"`` with a 6D filter (each sensor's heading
            kept consistent through the joints), else ``"hinges"`` (one world heading,
            each segment aligned at the pose: ``body.functional.calibrate_functional``).
        start_s, end_s: crop [s]. dropout: ``"nan"`` or ``"hold"`` a missing sensor.

    Example:
        >>> body = mocapkit.body_angles("walking_orientations.sto", preset="opensense")
        >>> body.to_dataframe(degrees=True)["knee_angle_r_deg"].max()  # doctest: +SKIP
    """
    import warnings

    from mocapkit.body.pipeline import default_heading_alignment, run_body
    from mocapkit.body.recordings import load_orientations, read_raw, recording_format
    from mocapkit.body.sensor_tree import SensorTree

    body_tree = SensorTree.from_yaml(tree) if tree else SensorTree.preset(preset)
    heading_alignment = heading_alignment or default_heading_alignment(filter, mode)
    raw = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if isinstance(recording, Mapping):
            if filter is not None:
                raise ConfigError("filter: give a recording's path for raw samples to filter")
            orientations = dict(recording)
        elif filter is not None:
            from mocapkit.body.recordings import run_filter

            raw = read_raw(Path(recording), recording_format(Path(recording)))
            orientations = run_filter(raw, filter, mode)
        else:
            orientations = load_orientations(Path(recording))
        if heading_alignment == "joints":
            if raw is None:
                raise ConfigError(
                    "heading_alignment='joints' needs raw samples: give filter=NAME, mode='6d'"
                )
            from mocapkit.body.joint_headings import align_headings_by_joints

            orientations, info = align_headings_by_joints(body_tree, orientations, raw)
            for note in info.notes:
                warnings.warn(f"joint headings: {note}", stacklevel=2)
        result = run_body(
            body_tree, orientations, calibration=calibration, start=start_s, stop=end_s,
            dropout=dropout, heading_alignment=heading_alignment,
        )  # fmt: skip
    for w in caught:  # kept in the result, and still shown
        warnings.warn(w.message, stacklevel=2)
    return BodyMotion(result.body.angles, dict(result.segments), result.calibration,
                      tuple(str(w.message) for w in caught))  # fmt: skip


@dataclass(frozen=True)
class RobotMotion:
    """What :func:`retarget` returns.

    Attributes:
        robot: the robot's name.
        time: (N,) [s].
        base: (N, 7) floating base ``[x, y, z]`` [m] and ``[w, x, y, z]`` (empty (N, 0)
            for a fixed base).
        q: (N, J) joint positions [rad; m for prismatic joints], ``joint_names`` order.
        joint_names: the actuated joints.
        figures: keypoint error [mm], foot skating [mm/frame], limit violations and
            collisions (counts), as ``mocapkit retarget --json`` reports them.
        notes: the doubts the run raised, as sentences.
        result: everything the retargeting computed (targets, robot model, solution).
    """

    robot: str
    time: Any
    base: Any
    q: Any
    joint_names: tuple[str, ...]
    figures: dict[str, Any]
    notes: tuple[str, ...]
    result: Any

    def to_dataframe(self) -> Any:
        """A pandas DataFrame indexed by ``time_s``: ``base_x_m`` ... ``base_qz``, then
        ``<joint>_rad`` (``_m`` for prismatic joints)."""
        import pandas as pd

        model = self.result.robot.model
        cols: dict[str, Any] = {}
        names = ["base_x_m", "base_y_m", "base_z_m", "base_qw", "base_qx", "base_qy", "base_qz"]
        for k in range(self.base.shape[1]):
            cols[names[k]] = self.base[:, k]
        for k, name in enumerate(self.joint_names):
            kind = model.joints[model.getJointId(name)].shortname().removeprefix("JointModel")
            prismatic = kind.startswith("P")  # PX, PY, PZ, PrismaticUnaligned
            cols[f"{name}_{'m' if prismatic else 'rad'}"] = self.q[:, k]
        return pd.DataFrame(cols, index=pd.Index(self.time, name="time_s"))

    def write(self, path: str | Path) -> Path:
        """The trajectory as ``.csv``, ``.npz`` or ``.mcap`` (by the extension)."""
        from mocapkit.retarget.run import write_trajectory

        return write_trajectory(path, self.result)


def retarget(
    source: str | Path | Reconstruction,
    *,
    robot: str | Path = "g1",
    height_m: float | None = None,
    preset: str = "full_body_15",
    guard_collisions: bool = True,
) -> RobotMotion:
    """A human motion onto a humanoid, as ``mocapkit retarget``: one QP a frame with joint
    position and velocity limits, feet held in contact, no ground penetration, and (by
    default) a collision guard on the robot's meshes.

    Args:
        source: a C3D or TRC (reconstructed on the way), a ``.mot`` on OpenSim's
            coordinate names, a BVH, an inertial recording (through the body model), or
            a :class:`Reconstruction` from :func:`reconstruct`.
        robot: a packaged name (``mocapkit robot list``: g1, talos, romeo, icub, ...) or a
            robot YAML file.
        height_m: the subject's height for a marker trial (None: estimated, warned).
        preset: the sensor tree of an inertial recording.

    Example:
        >>> motion = mocapkit.retarget("walk.trc", robot="g1", height_m=1.80)
        >>> motion.figures["foot_skate_mm"], motion.write("walk_g1.mcap")  # doctest: +SKIP
    """
    from mocapkit.retarget.run import retarget as _retarget

    res = _retarget(source, robot, height_m=height_m, preset=preset,
                    guard_collisions=guard_collisions)  # fmt: skip
    nb = res.robot.n_base_q
    base = res.solution.q[:, :nb]
    if nb:  # pinocchio's free flyer: xyz + quaternion [x, y, z, w] -> [w, x, y, z]
        base = np.column_stack([base[:, :3], base[:, 6], base[:, 3:6]])
    q = res.solution.q[:, nb:]
    names = tuple(res.robot.joint_names)
    return RobotMotion(res.robot.spec.name, res.solution.time, base, q, names, res.figures,
                       tuple(res.notes), res)  # fmt: skip


__all__ = list(_API)  # the names mocapkit exports lazily (mocapkit/__init__.py)
