"""Retarget a recording onto a humanoid, end to end, and write the robot trajectory.

Inputs: a marker trial (C3D/TRC: reconstructed on the way), joint angles on OpenSim's
coordinate names (.mot/.sto), a BVH (common joint names), or an inertial recording
(through the body model, automatic calibration). Outputs by extension: ``.csv`` (time,
base position and quaternion [w, x, y, z], joints [rad]), ``.npz`` (the same arrays with
names), ``.mcap`` (Foxglove: ``/robot/joints`` joint positions, ``/robot/tf`` the frame
tree world -> base -> every link with real translations, ``/robot/targets`` the keypoint
targets; wall-clock timestamps from when the file is written).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.errors import ConfigError
from mocapkit.retarget.human import HumanMotion, from_coordinates, from_reconstruction
from mocapkit.retarget.robot_model import Humanoid, build_humanoid
from mocapkit.retarget.robot_spec import load_robot_spec
from mocapkit.retarget.solver import Solution, solve
from mocapkit.retarget.targets import RetargetWarning, Targets, make_targets

MARKER_SUFFIXES = (".c3d", ".trc")
ANGLE_SUFFIXES = (".mot", ".sto")
OUTPUT_SUFFIXES = (".csv", ".npz", ".mcap")


@dataclass
class Retargeted:
    robot: Humanoid
    motion: HumanMotion
    targets: Targets
    solution: Solution
    figures: dict[str, Any]
    notes: list[str]


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
    if suffix in ANGLE_SUFFIXES:
        from mocapkit.io.joint_angles_mot import read_joint_angles_mot

        a = read_joint_angles_mot(path)
        coords = {n: a.column(n) for n in a.names}
        notes = []
        if not all(c in coords for c in ("pelvis_tx", "pelvis_ty", "pelvis_tz")):
            notes.append(
                f"{path.name} has no pelvis translation (pelvis_tx/ty/tz): the robot's "
                "pelvis stays where it starts and the feet glide"
            )
        return from_coordinates(a.time, coords, segments), notes
    from mocapkit.body.pipeline import run_body
    from mocapkit.body.recordings import load_orientations
    from mocapkit.body.sensor_tree import SensorTree

    oris = load_orientations(path)
    # qmt files have no magnetometer: their sensors' headings are each their own
    align = "pose" if path.suffix.lower() == ".mat" else "shared"
    res = run_body(SensorTree.preset(preset), oris, calibration="auto", heading_alignment=align)
    a = res.body.angles
    coords = {n: a.column(n) for n in a.names}
    note = (
        "an inertial recording has no positions: the robot's pelvis stays where it starts "
        "(walking becomes walking on the spot) and only the joint angles are retargeted"
    )
    return from_coordinates(a.time, coords, segments), [note]


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
    from mocapkit.retarget.collisions import SelfCollision
    from mocapkit.retarget.metrics import evaluate

    spec = load_robot_spec(robot)
    humanoid = build_humanoid(spec)
    segments = tuple(sorted({k.segment for k in spec.keypoints} | {f.segment for f in spec.feet}
                            | {"pelvis"}))  # fmt: skip
    if hasattr(input_path, "subject"):  # a Reconstruction from mocapkit.reconstruct
        motion = from_reconstruction(input_path, segments)
        notes = list(getattr(input_path, "warnings", ()))
    else:
        motion, notes = load_human(Path(input_path), segments, height_m=height_m, preset=preset)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RetargetWarning)
        targets = make_targets(motion, humanoid)
    notes += [str(w.message) for w in caught]
    wanted = check_collisions or avoid_collisions or guard_collisions
    coll = SelfCollision(humanoid) if wanted else None
    avoid = None
    if avoid_collisions and coll is not None:
        from mocapkit.retarget.collisions import HullAvoidance

        avoid = HullAvoidance(coll)
    sol = solve(humanoid, targets, avoid, coll if guard_collisions else None)
    notes += sol.warnings
    if coll is not None and not coll.available:
        notes.append(f"self-collisions not checked: {coll.reason}")
    figures = evaluate(humanoid, targets, sol, coll)
    hits = figures["collisions"]["frames"]
    if hits:  # exit 0 must not hide a trajectory that drives the robot into itself
        pairs = "; ".join(figures["collisions"]["pairs"])
        notes.append(
            f"{hits} of {sol.time.size} frames have the robot's bodies intersecting ({pairs}):"
            " do not play it on the robot as it is"
            + ("" if guard_collisions else "; leave the collision guard on to keep them apart")
        )
    return Retargeted(humanoid, motion, targets, sol, figures, notes)


def check_output(path: Path) -> str:
    """The output format (its suffix), or a refusal naming the ones there are."""
    suffix = path.suffix.lower()
    if suffix not in OUTPUT_SUFFIXES:
        raise ConfigError(
            f"output {path}: expected one of {', '.join(OUTPUT_SUFFIXES)} (the extension "
            "picks the format)"
        )
    return suffix


def write_trajectory(path: str | Path, result: Retargeted) -> Path:
    """``.csv``, ``.npz`` or ``.mcap`` (module docstring)."""
    p = Path(path)
    suffix = check_output(p)
    robot = result.robot
    sol = result.solution
    nb = robot.n_base_q
    joints = list(robot.joint_names)
    base = sol.q[:, :nb]
    q = sol.q[:, nb:]
    if nb:  # pinocchio's free flyer: xyz + quaternion [x, y, z, w] -> [w, x, y, z]
        base = np.column_stack([base[:, :3], base[:, 6], base[:, 3:6]])
    base_names = ["base_x", "base_y", "base_z", "base_qw", "base_qx", "base_qy", "base_qz"][:nb]
    if suffix == ".mcap":
        return _write_mcap(p, result)
    if suffix == ".npz":
        np.savez(p, time=sol.time, base=base, q=q, joint_names=np.array(joints),
                 base_names=np.array(base_names), robot=robot.spec.name)  # fmt: skip
        return p
    header = ",".join(["time", *base_names, *joints])
    table = np.column_stack([sol.time, base, q])
    np.savetxt(p, table, delimiter=",", header=header, comments="", fmt="%.9g")
    return p


def _write_mcap(path: Path, result: Retargeted) -> Path:
    import time as _time

    import pinocchio as pin

    from mocapkit.geometry import quat_from_matrix
    from mocapkit.io.foxglove_mcap import FoxgloveMcapWriter

    robot = result.robot
    model, data = robot.model, robot.model.createData()
    sol = result.solution
    t0 = _time.time_ns()
    names = list(model.names)
    with FoxgloveMcapWriter(path) as w:
        for k, t in enumerate(sol.time):
            t_ns = t0 + round((t - sol.time[0]) * 1e9)
            q = sol.q[k]
            pin.forwardKinematics(model, data, q)
            w.joint_positions("/robot/joints", t_ns, robot.joint_names, q[robot.n_base_q :])
            tfs = []
            for j in range(1, model.njoints):
                parent = int(model.parents[j])
                m = data.oMi[j] if parent == 0 else data.oMi[parent].actInv(data.oMi[j])
                frame = "world" if parent == 0 else names[parent]
                rot = quat_from_matrix(np.array(m.rotation))
                tfs.append((frame, names[j], np.array(m.translation), rot))
            w.frame_transforms("/robot/tf", t_ns, tfs)
            for seg, pos in result.targets.pos.items():
                target_rot = result.targets.rot.get(seg)
                qt = (
                    quat_from_matrix(target_rot[k])
                    if target_rot is not None
                    else np.array([1.0, 0.0, 0.0, 0.0])
                )
                w.pose_in_frame(f"/robot/targets/{seg}", t_ns, "world", pos[k], qt)
    return path
