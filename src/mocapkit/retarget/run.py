"""Retarget a recording onto a humanoid, end to end, and write the robot trajectory.

Inputs: a marker trial (C3D/TRC: reconstructed on the way), joint angles on OpenSim's
coordinate names (.mot/.sto), a BVH (common joint names), or an inertial recording
(sensor orientations: an OpenSense quaternion .sto, a qmt .mat, an x-IMU3 export; through
the body model, automatic calibration). Outputs by extension (.csv, .npz,
.mcap): :mod:`mocapkit.retarget.trajectory_io`. The whole recording is held here; the
command line retargets joint-angle files piece by piece (:mod:`mocapkit.retarget.streamed`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mocapkit.io.opensim_table import table_is_quaternion
from mocapkit.retarget.collisions import HullAvoidance, SelfCollision
from mocapkit.retarget.human import HumanMotion, from_coordinates, from_reconstruction
from mocapkit.retarget.robot_model import Humanoid, build_humanoid
from mocapkit.retarget.robot_spec import load_robot_spec
from mocapkit.retarget.solver import Solution, solve
from mocapkit.retarget.targets import RetargetWarning, Targets, make_targets
from mocapkit.retarget.trajectory_io import TrajectoryWriter, check_output

__all__ = ["Retargeted", "check_output", "load_human", "retarget", "write_trajectory"]

MARKER_SUFFIXES = (".c3d", ".trc")
INERTIAL_NOTE = (
    "an inertial recording has no positions: the robot's pelvis stays where it starts "
    "(walking becomes walking on the spot) and only the joint angles are retargeted"
)
ANGLE_SUFFIXES = (".mot", ".sto")


@dataclass
class Retargeted:
    robot: Humanoid
    motion: HumanMotion
    targets: Targets
    solution: Solution
    figures: dict[str, Any]
    notes: list[str]

    @property
    def frames(self) -> int:
        return int(self.solution.time.size)

    @property
    def solve_seconds(self) -> float:
        return self.solution.solve_seconds

    @property
    def steered(self) -> int:
        """Frames the collision guard steered round a collision."""
        return len(self.solution.kept_apart)

    @property
    def stopped_short(self) -> int:
        """Frames the collision guard stopped short of the human's pose."""
        return len(self.solution.stopped)


def robot_and_segments(robot: str | Path) -> tuple[Humanoid, tuple[str, ...]]:
    """The robot, and the human segments its map uses (keypoints, feet, pelvis)."""
    spec = load_robot_spec(robot)
    segments = {k.segment for k in spec.keypoints} | {f.segment for f in spec.feet}
    return build_humanoid(spec), tuple(sorted(segments | {"pelvis"}))


def no_translation_note(name: str, labels: Any) -> list[str]:
    """The doubt a joint-angle file without the pelvis's translation raises."""
    if all(c in labels for c in ("pelvis_tx", "pelvis_ty", "pelvis_tz")):
        return []
    return [
        f"{name} has no pelvis translation (pelvis_tx/ty/tz): the robot's pelvis stays "
        "where it starts and the feet glide"
    ]


def load_human(
    path: Path, segments: tuple[str, ...], *, height_m: float | None = None,
    preset: str = "full_body_15",
) -> tuple[HumanMotion, list[str]]:  # fmt: skip
    """The human motion of ``path`` (module docstring) and the doubts raised on the way."""
    suffix = path.suffix.lower()
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file or directory")
    if suffix in MARKER_SUFFIXES:
        from mocapkit.api import reconstruct

        rec = reconstruct(path, height_m=height_m)
        return from_reconstruction(rec, segments), list(rec.warnings)
    if suffix == ".bvh":
        from mocapkit.retarget.human import from_bvh

        return from_bvh(path, segments)
    if suffix in ANGLE_SUFFIXES and not table_is_quaternion(path):
        from mocapkit.io.joint_angles_mot import read_joint_angles_mot

        a = read_joint_angles_mot(path)
        coords = {n: a.column(n) for n in a.names}
        return from_coordinates(a.time, coords, segments), no_translation_note(path.name, a.names)
    from mocapkit.body.pipeline import run_body
    from mocapkit.body.recordings import load_orientations
    from mocapkit.body.sensor_tree import SensorTree

    oris = load_orientations(path)
    # qmt files have no magnetometer: their sensors' headings are each their own
    align = "pose" if path.suffix.lower() == ".mat" else "hinges"
    res = run_body(SensorTree.preset(preset), oris, calibration="auto", heading_alignment=align)
    a = res.body.angles
    coords = {n: a.column(n) for n in a.names}
    return from_coordinates(a.time, coords, segments), [INERTIAL_NOTE]


def retarget(
    input_path: str | Path | Any,
    robot: str | Path,
    *,
    height_m: float | None = None,
    preset: str = "full_body_15",
    check_collisions: bool = True,
    avoid_collisions: bool = False,
    guard_collisions: bool = True,
) -> Retargeted:
    """``input_path`` (or a ``mocapkit.Reconstruction``) onto ``robot`` (a packaged name
    or a YAML): targets, one QP per
    frame, and the figures of :mod:`mocapkit.retarget.metrics`. ``guard_collisions``
    (default): every frame checked on the robot's meshes, a colliding step steered round or
    stopped short (``solver`` docstring), so no frame has bodies intersecting.
    ``avoid_collisions``: in addition, rows in every frame's QP keep spheres around the
    bodies apart (smoother near contact, ~3x slower)."""
    from mocapkit.retarget.metrics import evaluate

    humanoid, segments = robot_and_segments(robot)
    if hasattr(input_path, "subject"):  # a Reconstruction from mocapkit.reconstruct
        motion = from_reconstruction(input_path, segments)
        notes = list(getattr(input_path, "warnings", ()))
    else:
        motion, notes = load_human(Path(input_path), segments, height_m=height_m, preset=preset)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RetargetWarning)
        targets = make_targets(motion, humanoid)
    notes += [str(w.message) for w in caught]
    coll, avoid = collision_guards(humanoid, check_collisions, avoid_collisions,
                                   guard_collisions)  # fmt: skip
    sol = solve(humanoid, targets, avoid, coll if guard_collisions else None)
    figures = evaluate(humanoid, targets, sol, coll)
    notes += sol.warnings + collision_notes(coll, figures, sol.time.size, guard_collisions)
    return Retargeted(humanoid, motion, targets, sol, figures, notes)


def collision_guards(
    humanoid: Humanoid, check_collisions: bool, avoid_collisions: bool, guard_collisions: bool
) -> tuple[SelfCollision | None, HullAvoidance | None]:
    """The meshes' checker (counting, guarding) and the QP's avoidance rows, as asked."""
    wanted = check_collisions or avoid_collisions or guard_collisions
    coll = SelfCollision(humanoid) if wanted else None
    avoid = HullAvoidance(coll) if avoid_collisions and coll is not None else None
    return coll, avoid


def collision_notes(
    coll: SelfCollision | None, figures: dict[str, Any], frames: int, guard_collisions: bool
) -> list[str]:
    """What the user must hear about self-collisions after the solve."""
    notes = []
    if coll is not None and not coll.available:
        notes.append(f"self-collisions not checked: {coll.reason}")
    hits = figures["collisions"]["frames"]
    if hits:  # exit 0 must not hide a trajectory that drives the robot into itself
        pairs = "; ".join(figures["collisions"]["pairs"])
        notes.append(
            f"{hits} of {frames} frames have the robot's bodies intersecting ({pairs}):"
            " do not play it on the robot as it is"
            + ("" if guard_collisions else "; leave the collision guard on to keep them apart")
        )
    return notes


def write_trajectory(path: str | Path, result: Retargeted) -> Path:
    """``.csv``, ``.npz`` or ``.mcap`` (:mod:`mocapkit.retarget.trajectory_io`)."""
    with TrajectoryWriter(path, result.robot) as w:
        w.write(result.solution, result.targets)
    return Path(path)
