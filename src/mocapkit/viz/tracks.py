"""What ``mocapkit view`` draws: every file as a track of poses over time (no viser here).

- a human (:class:`HumanTrack`): a marker trial (C3D/TRC, reconstructed by mocapkit, with
  its markers), joint angles (a mocapkit ``.mot``/``.sto``), a BVH, or an IMU recording
  (through the body model): the 15 body segments' world poses
  (:mod:`mocapkit.retarget.human`), drawn as a body of capsules;
- a robot (:class:`RobotTrack`): a trajectory written by ``mocapkit retarget`` (``.npz``
  names its robot; ``.csv`` needs ``--robot``), drawn from its URDF's visual meshes placed
  by Pinocchio's forward kinematics.

:func:`load_track` picks by the file; a file it cannot read raises a ``MocapkitError``
naming the file and the fix (the viewer shows the others and says so).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError, DataError
from mocapkit.retarget.human import TREE_TO_HUMAN, HumanMotion

HUMAN_SEGMENTS = tuple(TREE_TO_HUMAN.values())
# (from, to): a capsule between the two segments' origins (their proximal joints)
BONES = (
    ("pelvis", "thigh_r"), ("thigh_r", "shank_r"), ("shank_r", "foot_r"),
    ("pelvis", "thigh_l"), ("thigh_l", "shank_l"), ("shank_l", "foot_l"),
    ("pelvis", "thorax"), ("thorax", "head"),
    ("thorax", "upper_arm_r"), ("upper_arm_r", "forearm_r"), ("forearm_r", "hand_r"),
    ("thorax", "upper_arm_l"), ("upper_arm_l", "forearm_l"), ("forearm_l", "hand_l"),
)  # fmt: skip
ENDS = ("head", "hand_r", "hand_l", "foot_r", "foot_l")  # a sphere at these
ROBOT_SUFFIXES = (".npz", ".csv")


@dataclass
class HumanTrack:
    name: str
    motion: HumanMotion
    markers: FloatArray | None = None  # (N, M, 3) [m], world z up, or None
    notes: list[str] = field(default_factory=list)

    @property
    def time(self) -> FloatArray:
        return self.motion.time

    def bones(self) -> list[tuple[str, str]]:
        have = set(self.motion.pos)
        return [(a, b) for a, b in BONES if a in have and b in have]

    def origin(self) -> FloatArray:
        """Where the track starts on the floor (the pelvis's first xy), to centre it."""
        p = self.motion.pos["pelvis"][0] if "pelvis" in self.motion.pos else np.zeros(3)
        return np.array([p[0], p[1], 0.0])


@dataclass
class RobotTrack:
    name: str
    robot: Any  # mocapkit.retarget.robot_model.Humanoid
    time: FloatArray
    q: FloatArray  # (N, nq) Pinocchio configurations
    notes: list[str] = field(default_factory=list)

    def origin(self) -> FloatArray:
        p = self.q[0, :3] if self.robot.spec.floating_base else np.zeros(3)
        return np.array([p[0], p[1], 0.0])


Track = HumanTrack | RobotTrack


def frame_at(time: FloatArray, t: float) -> int:
    """The frame shown at time ``t`` (the latest at or before it, clamped)."""
    return int(np.clip(np.searchsorted(time, t, side="right") - 1, 0, time.size - 1))


def load_track(path: str | Path, *, robot: str | None = None, height_m: float | None = None
               ) -> Track:  # fmt: skip
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file or directory")
    suffix = p.suffix.lower()
    if suffix in ROBOT_SUFFIXES and _is_robot_file(p):
        return _robot_track(p, robot)
    if suffix in (".c3d", ".trc"):
        return _marker_track(p, height_m)
    from mocapkit.retarget.run import load_human

    motion, notes = load_human(p, HUMAN_SEGMENTS)
    return HumanTrack(p.name, motion, None, notes)


def _is_robot_file(p: Path) -> bool:
    if p.suffix.lower() == ".npz":
        with np.load(p) as z:
            return "joint_names" in z.files and "q" in z.files
    with p.open() as f:
        return f.readline().startswith("time,")


def _robot_track(p: Path, robot: str | None) -> RobotTrack:
    from mocapkit.retarget.robot_model import build_humanoid
    from mocapkit.retarget.robot_spec import load_robot_spec

    if p.suffix.lower() == ".npz":
        with np.load(p) as z:
            time, base, q = z["time"], z["base"], z["q"]
            names = [str(n) for n in z["joint_names"]]
            robot = robot or str(z["robot"])
    else:
        if robot is None:
            raise ConfigError(f"{p}: a CSV trajectory does not name its robot; give --robot")
        header = p.open().readline().strip().split(",")
        table = np.loadtxt(p, delimiter=",", skiprows=1, ndmin=2)
        nb = sum(h.startswith("base_") for h in header)
        time, base, q, names = (
            table[:, 0],
            table[:, 1 : 1 + nb],
            table[:, 1 + nb :],
            header[1 + nb :],
        )
    humanoid = build_humanoid(load_robot_spec(robot))
    if tuple(names) != tuple(humanoid.joint_names):
        raise DataError(
            f"{p}: its joints ({len(names)}) are not robot {robot}'s ({len(humanoid.joint_names)});"
            " give --robot with the robot it was retargeted onto"
        )
    if humanoid.spec.floating_base:  # [w, x, y, z] on file, Pinocchio wants [x, y, z, w]
        base = np.column_stack([base[:, :3], base[:, 4:7], base[:, 3]])
    qs = np.column_stack([base, q]) if humanoid.spec.floating_base else np.asarray(q)
    if not np.isfinite(qs).all():
        raise DataError(
            f"{p}: non-finite joint values (frame {int(np.argwhere(~np.isfinite(qs))[0, 0])})"
        )
    return RobotTrack(p.name, humanoid, np.asarray(time, dtype=float), qs)


def _marker_track(p: Path, height_m: float | None) -> HumanTrack:
    import mocapkit
    from mocapkit.retarget.human import from_reconstruction

    rec = mocapkit.reconstruct(p, height_m=height_m)
    human = rec.subject.human
    model = human.bare_model if human.bare_model is not None else human.model
    segs = tuple(s for s in HUMAN_SEGMENTS if model.existFrame(s))
    motion = from_reconstruction(rec, segs)
    markers = _markers_on(rec, motion)
    return HumanTrack(p.name, motion, markers, list(rec.warnings))


def _markers_on(rec: Any, motion: HumanMotion) -> FloatArray | None:
    """The model's tracked markers (N, M, 3) in the motion's world (its ground at z = 0),
    or None."""
    import pinocchio as pin

    xyz = getattr(rec.result, "tracked_positions", None)
    if xyz is None or np.ndim(xyz) != 3 or np.shape(xyz)[0] != motion.n_frames:
        return None
    human = rec.subject.human
    model = human.bare_model if human.bare_model is not None else human.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.asarray(rec.result.q[0])[: model.nq])
    raw = np.asarray(data.oMf[model.getFrameId("pelvis")].translation)
    return np.asarray(xyz, dtype=float) + (motion.pos["pelvis"][0] - raw)
