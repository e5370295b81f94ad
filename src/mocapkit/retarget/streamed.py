"""Retarget a joint-angle file (.mot/.sto) of any length in flat memory (issue 16).

The whole path (:func:`mocapkit.retarget.run.retarget`) holds the motion, its targets,
the solution and the figures for every frame: ~4 KB a frame, 1.2 GB for an hour at 60 Hz.
Here the file is read twice, ``PIECE_FRAMES`` rows at a time:

1. **Scan.** What the whole path finds over the whole recording, kept as small arrays
   (time and the feet, ~60 B a frame): the ground under the feet, a treadmill belt's
   velocity, the feet's contacts (each a percentile or a run over every frame, so they
   cannot come from a window without changing the result), and the pelvis height of the
   first frame.
2. **Solve.** Each piece's motion (with the whole's ground), its targets (the first
   piece's heading alignment, the whole's belt and contacts), the frame QP carrying its
   state across the seam (:meth:`FrameSolver.next_piece`), the figures summed
   (:class:`FigureTally`) and the trajectory written as it comes (:class:`TrajectoryWriter`).

The result is the whole path's: the targets are equal to the last bit, and the robot's
configurations differ only as much as two runs of the whole path do: the QP solver's sums
depend on how its arrays fall in memory (~1e-8 rad), and a frame's second iteration is a
threshold (``SETTLED_RAD``) such a difference can flip (then up to ~1e-3 rad, fading).
Marker trials, BVH and IMU recordings are still retargeted whole.
"""

from __future__ import annotations

import contextlib
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import DataError
from mocapkit.io.joint_angles_mot import iter_joint_angles_mot
from mocapkit.io.opensim_table import table_is_quaternion
from mocapkit.retarget.human import HumanMotion, from_coordinates, ground_height
from mocapkit.retarget.robot_model import Humanoid
from mocapkit.retarget.targets import (
    RetargetWarning,
    belt_velocity,
    detect_contacts,
    make_targets,
    on_belt,
    treadmill_note,
)

PIECE_FRAMES = 5000
ANGLE_SUFFIXES = (".mot", ".sto")


def streamable(path: str | Path) -> bool:
    """Whether ``path`` is retargeted piece by piece: a joint-angle file, or an OpenSense
    orientation table (:func:`retarget_orientations_streamed`)."""
    return Path(path).suffix.lower() in ANGLE_SUFFIXES


@dataclass
class StreamedRetarget:
    """What the command reports (the whole path's ``Retargeted`` has the same names)."""

    robot: Humanoid
    frames: int
    solve_seconds: float
    figures: dict[str, Any]
    notes: list[str]
    steered: int
    stopped_short: int


@dataclass
class _Scan:
    """The whole recording's quantities the pieces share (module docstring)."""

    time: FloatArray
    ground: float
    first_height: float | None
    belt: FloatArray
    contact: dict[str, np.ndarray]
    notes: list[str]


def _coordinates(piece: Any) -> dict[str, FloatArray]:
    return {n: piece.column(n) for n in piece.names}


def _first_height(coords: dict[str, FloatArray]) -> float | None:
    if all(c in coords for c in ("pelvis_tx", "pelvis_ty", "pelvis_tz")):
        return float(coords["pelvis_ty"][0])
    return None


def _scan(
    path: Path, robot: Humanoid, segments: tuple[str, ...], rows: int, inertial: bool
) -> _Scan:
    from mocapkit.retarget.run import INERTIAL_NOTE, no_translation_note

    feet = sorted({f.segment for f in robot.spec.feet})
    grounding = sorted(s for s in segments if s.startswith("foot"))
    times: list[FloatArray] = []
    pos: dict[str, list[FloatArray]] = {s: [] for s in sorted(set(feet) | set(grounding))}
    first_height: float | None = None
    notes: list[str] = []
    for k, piece in enumerate(iter_joint_angles_mot(path, rows)):
        coords = _coordinates(piece)
        if k == 0:
            first_height = _first_height(coords)
            notes = [INERTIAL_NOTE] if inertial else no_translation_note(path.name, piece.names)
        motion = from_coordinates(piece.time, coords, segments, ground=0.0,
                                  first_height=first_height)  # fmt: skip
        times.append(np.asarray(piece.time))
        for s, parts in pos.items():
            parts.append(motion.pos[s])
    time = np.concatenate(times) if times else np.empty(0)
    if time.size == 0:
        raise DataError(f"{path}: no rows of joint angles to retarget")
    whole = {s: np.concatenate(parts) for s, parts in pos.items()}
    ground = ground_height([whole[s] for s in grounding])
    empty: dict[str, FloatArray] = {}
    on_ground = HumanMotion(time, {s: p - [0.0, 0.0, ground] for s, p in whole.items()},
                            empty, empty, empty)  # fmt: skip
    belt = belt_velocity(on_ground, feet)
    if belt.any():
        notes.append(treadmill_note(belt))
        on_ground = on_belt(on_ground, belt, float(time[0]))
    contact = {f: detect_contacts(on_ground, f) for f in feet}
    return _Scan(time, ground, first_height, belt, contact, notes)


def retarget_streamed(
    input_path: str | Path,
    robot: str | Path,
    output: str | Path | None = None,
    *,
    check_collisions: bool = True,
    avoid_collisions: bool = False,
    guard_collisions: bool = True,
    piece_frames: int = PIECE_FRAMES,
    inertial: bool = False,
    preset: str = "full_body_15",
) -> StreamedRetarget:
    """``retarget(input_path, robot, ...)`` then ``write_trajectory(output, ...)`` for a
    joint-angle file, in flat memory (module docstring); an orientation table goes to
    :func:`retarget_orientations_streamed` (``preset``: its sensor tree). ``inertial``: the
    angles come from an inertial recording (the notes say so, not that the file lacks
    translation)."""
    from mocapkit.retarget.metrics import FigureTally
    from mocapkit.retarget.run import collision_guards, collision_notes, robot_and_segments
    from mocapkit.retarget.solver import FrameSolver, Solution, finish, solve_piece
    from mocapkit.retarget.trajectory_io import TrajectoryWriter

    path = Path(input_path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file or directory")
    humanoid, segments = robot_and_segments(robot)
    if table_is_quaternion(path):
        return retarget_orientations_streamed(
            path, robot, output, check_collisions=check_collisions,
            avoid_collisions=avoid_collisions, guard_collisions=guard_collisions,
            preset=preset, piece_frames=piece_frames,
        )  # fmt: skip
    scan = _scan(path, humanoid, segments, piece_frames, inertial)
    coll, avoid = collision_guards(humanoid, check_collisions, avoid_collisions,
                                   guard_collisions)  # fmt: skip
    tally = FigureTally(humanoid, coll)
    solver: FrameSolver | None = None
    start = None
    seconds = 0.0
    a = 0
    belt = (scan.belt, float(scan.time[0]))
    writer = TrajectoryWriter(output, humanoid) if output is not None else None
    with writer if writer is not None else contextlib.nullcontext():
        for piece in iter_joint_angles_mot(path, piece_frames):
            b = a + piece.time.size
            if b > scan.time.size or not np.array_equal(piece.time, scan.time[a:b]):
                raise DataError(f"{path} changed while it was being retargeted (at row {a})")
            coords = _coordinates(piece)
            motion = from_coordinates(piece.time, coords, segments, ground=scan.ground,
                                      first_height=scan.first_height)  # fmt: skip
            contact = {f: c[a:b] for f, c in scan.contact.items()}
            with warnings.catch_warnings():
                warnings.simplefilter("error", RetargetWarning)  # none expected here
                targets = make_targets(motion, humanoid, start=start, contact=contact, belt=belt)
            start = targets.start
            if solver is None:
                solver = FrameSolver(humanoid, targets, avoid,
                                     coll if guard_collisions else None)  # fmt: skip
            else:
                solver.next_piece(targets, a)
            sol = solve_piece(solver)
            seconds += sol.solve_seconds
            tally.add(targets, sol)
            if writer is not None:
                writer.write(sol, targets)
            a = b
    if solver is None or a != scan.time.size:
        raise DataError(f"{path} changed while it was being retargeted ({a} rows read back)")
    summary = Solution(np.empty(0), np.empty((0, humanoid.model.nq)), {}, {})
    finish(solver, summary)
    figures = tally.figures(len(summary.held_frames))
    notes = scan.notes + summary.warnings
    notes += collision_notes(coll, figures, a, guard_collisions)
    return StreamedRetarget(humanoid, a, seconds, figures, notes, len(summary.kept_apart),
                            len(summary.stopped))  # fmt: skip


def retarget_orientations_streamed(
    path: str | Path,
    robot: str | Path,
    output: str | Path | None = None,
    *,
    preset: str = "full_body_15",
    piece_frames: int = PIECE_FRAMES,
    check_collisions: bool = True,
    avoid_collisions: bool = False,
    guard_collisions: bool = True,
) -> StreamedRetarget:
    """An OpenSense orientation table (an inertial recording) onto ``robot`` in flat
    memory: the body model streams its joint angles into a ``.mot`` on disk
    (:func:`mocapkit.body.streamed.stream_body`, automatic calibration from the start of
    the recording, as ``body angles`` does), which is then retargeted in pieces."""
    import tempfile

    from mocapkit.body.sensor_tree import SensorTree
    from mocapkit.body.streamed import stream_body

    out_dir = Path(output).parent if output is not None else None
    with tempfile.TemporaryDirectory(dir=out_dir, prefix=".mocapkit-retarget-") as d:
        angles = Path(d) / f"{Path(path).stem}.mot"
        stream_body(SensorTree.preset(preset), path, output=angles, calibration="auto",
                    heading_alignment="shared", rows=piece_frames)  # fmt: skip
        return retarget_streamed(
            angles, robot, output, check_collisions=check_collisions,
            avoid_collisions=avoid_collisions, guard_collisions=guard_collisions,
            piece_frames=piece_frames, inertial=True,
        )  # fmt: skip
