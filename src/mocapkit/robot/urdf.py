"""Any URDF robot's arm as an :class:`ArmModel`: load with Pinocchio, lock every joint
outside the arm, express poses in a named base (command) frame."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from mocapkit.errors import ConfigError, FileFormatError, MissingDependencyError
from mocapkit.robot.model import ArmModel

# Used when a URDF gives no (or a placeholder) velocity limit [rad/s].
DEFAULT_VELOCITY_LIMIT = 2.0


def load_urdf_arm(
    urdf: str | Path,
    joints: Sequence[str],
    base_frame: str,
    ee_frame: str,
    q_ref: Any = None,
    locked: Mapping[str, float] | None = None,
    velocity_limit: Any = None,
    name: str | None = None,
) -> ArmModel:
    """Build an arm model from a URDF file.

    Args:
        urdf: path to the URDF (meshes are not needed: kinematics only).
        joints: the arm's joint names, in chain order (1-DOF joints).
        base_frame: frame in which poses and commands are expressed (e.g. the torso).
        ee_frame: end-effector frame.
        q_ref: (n,) ready posture [rad]; defaults to mid-range.
        locked: values [rad] for joints outside the arm (others locked at neutral).
        velocity_limit: (n,) [rad/s]; defaults to the URDF's, or
            ``DEFAULT_VELOCITY_LIMIT`` when the URDF gives none or a placeholder (>= 100).
    """
    path = Path(urdf)
    if not path.is_file():
        raise FileNotFoundError(f"urdf: no such file {path}")
    try:
        full = pin.buildModelFromUrdf(str(path))
    except (RuntimeError, ValueError) as exc:
        raise FileFormatError(f"{path}: Pinocchio cannot parse this URDF ({exc})") from exc
    names = list(full.names)
    missing = [j for j in joints if j not in names]
    if missing:
        movable = ", ".join(n for n in names[1:])
        raise ConfigError(
            f"{path.name}: joint(s) {', '.join(missing)} not in the URDF; its joints: {movable}"
        )
    q_lock = pin.neutral(full)
    for jname, value in (locked or {}).items():
        if jname not in names:
            raise ConfigError(f"locked: no joint {jname!r} in {path.name}")
        jid = full.getJointId(jname)
        q_lock[full.joints[jid].idx_q] = float(value)
    lock_ids = [j for j in range(1, full.njoints) if names[j] not in joints]
    reduced = pin.buildReducedModel(full, lock_ids, q_lock)
    order = list(reduced.names[1:])
    if order != list(joints):
        raise ConfigError(
            f"joints: give the arm's joints in chain order: {', '.join(order)} (got "
            f"{', '.join(joints)})"
        )
    for frame in (base_frame, ee_frame):
        if not reduced.existFrame(frame):
            raise ConfigError(f"{path.name}: no frame {frame!r}")
    if velocity_limit is None:
        v = np.array(reduced.velocityLimit, dtype=float)
        velocity_limit = np.where((v > 0) & (v < 100), v, DEFAULT_VELOCITY_LIMIT)
    return ArmModel(
        reduced,
        ee_frame=ee_frame,
        velocity_limit=velocity_limit,
        q_ref=q_ref,
        base_frame=base_frame,
        name=name or path.stem,
    )


def example_robot_data_path(relative: str) -> Path:
    """Path of a file shipped by the ``example-robot-data`` PyPI package (extra ``robots``),
    e.g. ``robots/talos_data/robots/talos_reduced.urdf``."""
    try:
        files = metadata.files("example-robot-data") or []
    except metadata.PackageNotFoundError as exc:
        raise MissingDependencyError(
            "the example-robot-data package is not installed: pip install 'mocapkit[robots]'"
        ) from exc
    suffix = "share/example-robot-data/" + relative
    for f in files:
        if str(f).endswith(suffix):
            return Path(str(f.locate()))
    raise MissingDependencyError(
        f"example-robot-data does not ship {relative}; reinstall it (pip install "
        "'mocapkit[robots]')"
    )
