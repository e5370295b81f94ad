"""Retarget a recording of any length in flat memory (issue 16): joint angles (.mot/.sto),
an OpenSense orientation table (through the streamed body model) or a marker trial
(C3D/TRC, reconstructed piece by piece).

The whole path (:func:`mocapkit.retarget.run.retarget`) holds the motion, its targets,
the solution and the figures for every frame: ~4 KB a frame, 1.2 GB for an hour at 60 Hz.
Here the motion is gone through twice, ``PIECE_FRAMES`` frames at a time (a joint-angle
file read again; a marker trial's configurations spilled to disk as they are tracked):

1. **Scan.** What the whole path finds over the whole recording, kept as small arrays
   (time and the feet, ~60 B a frame): the ground under the feet, a treadmill belt's
   velocity, the feet's contacts (each a percentile or a run over every frame, so they
   cannot come from a window without changing the result), and the pelvis height of the
   first frame.
2. **Solve.** Each piece's motion (with the whole's ground), its targets (the first
   piece's heading alignment, the whole's belt and contacts), the frame QP carrying its
   state across the seam (:meth:`FrameSolver.next_piece`), the figures summed
   (:class:`FigureTally`) and the trajectory written as it comes (:class:`TrajectoryWriter`).

The result is the whole path's: without the collision guard, the same trajectory to the
last bit (tests/retarget/test_streamed.py); with it (the default), the configurations
differ only as much as two runs of the whole path already do, because the guard's
near-contact decisions (hull tests, bisections) follow rounding that depends on where
arrays fall in memory: median ~1e-5 rad, up to ~1e-3-1e-2 rad near a contact, fading.
A marker trial longer than ``markers.streamed.HEAD_S`` is scaled from its start (as
``markers reconstruct`` does); an orientation table is calibrated from its start (as
``body angles`` does); an x-IMU3 export's device orientations go the same way. BVH and
qmt .mat files are still retargeted whole.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._spill import RowFile
from mocapkit._validate import FloatArray
from mocapkit.errors import DataError
from mocapkit.io.joint_angles_mot import iter_joint_angles_mot
from mocapkit.io.opensim_table import table_is_quaternion
from mocapkit.retarget.human import HumanMotion, from_coordinates, ground_height
from mocapkit.retarget.robot_model import Humanoid
from mocapkit.retarget.run import ANGLE_SUFFIXES, MARKER_SUFFIXES
from mocapkit.retarget.targets import (
    RetargetWarning,
    belt_velocity,
    detect_contacts,
    make_targets,
    on_belt,
    treadmill_note,
)

PIECE_FRAMES = 5000


def streamable(path: str | Path) -> bool:
    """Whether ``path`` is retargeted piece by piece: a joint-angle file, an OpenSense
    orientation table, a marker trial or an x-IMU3 export (:func:`retarget_streamed`)."""
    return Path(path).suffix.lower() in ANGLE_SUFFIXES + MARKER_SUFFIXES or _is_export(Path(path))


def _is_export(path: Path) -> bool:
    """An export of sensors on their own clocks: x-IMU3 or Xsens."""
    from mocapkit.imu.sensor_streams import is_sensor_export

    return is_sensor_export(path)


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
    belt: FloatArray
    contact: dict[str, np.ndarray]
    notes: list[str]


class _Angles:
    """A joint-angle file's motion, read again for each pass, ``rows`` rows at a time."""

    def __init__(
        self, path: Path, segments: tuple[str, ...], rows: int, inertial: bool
    ) -> None:  # fmt: skip
        self.path, self.segments, self.rows, self.inertial = path, segments, rows, inertial
        self.name = str(path)  # what messages call the recording
        self.first_height: float | None = None
        self.notes: list[str] = []

    def pieces(self, ground: float) -> Iterator[HumanMotion]:
        from mocapkit.retarget.run import INERTIAL_NOTE, no_translation_note

        for k, piece in enumerate(iter_joint_angles_mot(self.path, self.rows)):
            coords = {n: piece.column(n) for n in piece.names}
            if k == 0:  # what the whole path takes from the first frame
                self.notes = (
                    [INERTIAL_NOTE]
                    if self.inertial
                    else no_translation_note(self.path.name, piece.names)
                )
                have = all(c in coords for c in ("pelvis_tx", "pelvis_ty", "pelvis_tz"))
                self.first_height = float(coords["pelvis_ty"][0]) if have else None
            yield from_coordinates(piece.time, coords, self.segments, ground=ground,
                                   first_height=self.first_height)  # fmt: skip


class _Model:
    """A marker reconstruction's motion: the scaled model's configurations, spilled to
    disk as they were tracked, through its forward kinematics ``rows`` frames at a time."""

    def __init__(
        self, human: Any, time: RowFile, q: RowFile, segments: tuple[str, ...], rows: int,
        notes: list[str], name: str,
    ) -> None:  # fmt: skip
        self.human, self.time, self.q, self.segments = human, time, q, segments
        self.rows, self.notes, self.name = rows, notes, name

    def pieces(self, ground: float) -> Iterator[HumanMotion]:
        from mocapkit.retarget.human import model_motion

        n = self.time.rows
        for a in range(0, n, self.rows):
            b = min(n, a + self.rows)
            yield model_motion(self.human, self.time.read(a, b), self.q.read(a, b),
                               self.segments, ground=ground)  # fmt: skip


def _scan(source: _Angles | _Model, robot: Humanoid, segments: tuple[str, ...]) -> _Scan:
    feet = sorted({f.segment for f in robot.spec.feet})
    grounding = sorted(s for s in segments if s.startswith("foot"))
    times: list[FloatArray] = []
    pos: dict[str, list[FloatArray]] = {s: [] for s in sorted(set(feet) | set(grounding))}
    for motion in source.pieces(0.0):
        times.append(np.asarray(motion.time))
        for s, parts in pos.items():
            parts.append(motion.pos[s])
    time = np.concatenate(times) if times else np.empty(0)
    if time.size == 0:
        raise DataError(f"{source.name}: no frames to retarget")
    whole = {s: np.concatenate(parts) for s, parts in pos.items()}
    ground = ground_height([whole[s] for s in grounding])
    empty: dict[str, FloatArray] = {}
    on_ground = HumanMotion(time, {s: p - [0.0, 0.0, ground] for s, p in whole.items()},
                            empty, empty, empty)  # fmt: skip
    belt = belt_velocity(on_ground, feet)
    notes = list(source.notes)
    if belt.any():
        notes.append(treadmill_note(belt))
        on_ground = on_belt(on_ground, belt, float(time[0]))
    contact = {f: detect_contacts(on_ground, f) for f in feet}
    return _Scan(time, ground, belt, contact, notes)


def retarget_streamed(
    input_path: str | Path,
    robot: str | Path,
    output: str | Path | None = None,
    *,
    check_collisions: bool = True,
    avoid_collisions: bool = False,
    guard_collisions: bool = True,
    piece_frames: int = PIECE_FRAMES,
    preset: str = "full_body_15",
    height_m: float | None = None,
) -> StreamedRetarget:
    """``retarget(input_path, robot, ...)`` then ``write_trajectory(output, ...)`` in flat
    memory (module docstring): a joint-angle file, an orientation table (through the body
    model, ``preset`` its sensor tree) or a marker trial (reconstructed piece by piece,
    ``height_m`` as ``retarget``'s)."""
    path = Path(input_path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file or directory")
    collisions = {"check_collisions": check_collisions, "avoid_collisions": avoid_collisions,
                  "guard_collisions": guard_collisions}  # fmt: skip
    if path.suffix.lower() in MARKER_SUFFIXES:
        return _markers(path, robot, output, height_m, piece_frames, collisions)
    if _is_export(path):
        return _orientations(path, robot, output, preset, piece_frames, collisions)
    if table_is_quaternion(path):
        return _orientations(path, robot, output, preset, piece_frames, collisions)
    return _angles(path, robot, output, piece_frames, collisions)


def _angles(
    path: Path, robot: str | Path, output: str | Path | None, rows: int,
    collisions: dict[str, bool], inertial: bool = False,
) -> StreamedRetarget:  # fmt: skip
    from mocapkit.retarget.run import robot_and_segments

    humanoid, segments = robot_and_segments(robot)
    return _retarget(_Angles(path, segments, rows, inertial), humanoid, segments, output,
                     **collisions)  # fmt: skip


def _orientations(
    path: Path, robot: str | Path, output: str | Path | None, preset: str, rows: int,
    collisions: dict[str, bool],
) -> StreamedRetarget:  # fmt: skip
    """An inertial recording, an OpenSense orientation table or an x-IMU3 export (its
    devices' own orientations, as the whole path reads them: each sensor into a file on
    disk, then aligned onto one time base a piece at a time): the body model streams its
    joint angles into a ``.mot`` on disk (:func:`mocapkit.body.streamed.stream_body`,
    automatic calibration from the start of the recording, as ``body angles`` does),
    which is then retargeted in pieces."""
    import tempfile

    from mocapkit.body.sensor_tree import SensorTree
    from mocapkit.body.streamed import stream_body

    tree = SensorTree.preset(preset)
    with tempfile.TemporaryDirectory(dir=_beside(output), prefix=".mocapkit-retarget-") as d:
        angles = Path(d) / f"{path.name}.mot"
        if _is_export(path):
            from mocapkit.imu.sensor_spill import body_pieces
            from mocapkit.imu.sensor_streams import sensor_names, spill_device

            # the whole path's message for a sensor the export lacks
            tree.check_sensors(sensor_names(path))
            spills = spill_device(path, d, [s.sensor for s in tree.segments], rows)
            try:
                stream_body(tree, path, output=angles, calibration="auto",
                            heading_alignment="hinges", pieces=body_pieces(spills))  # fmt: skip
            finally:
                for s in spills:
                    s.close()
        else:
            stream_body(tree, path, output=angles, calibration="auto",
                        heading_alignment="hinges", rows=rows)  # fmt: skip
        return _angles(angles, robot, output, rows, collisions, inertial=True)


def _markers(
    path: Path, robot: str | Path, output: str | Path | None, height_m: float | None,
    rows: int, collisions: dict[str, bool],
) -> StreamedRetarget:  # fmt: skip
    """A marker trial: reconstructed piece by piece as ``markers reconstruct`` does
    (:func:`mocapkit.markers.streamed.reconstruct_streamed`, the options ``retarget``
    uses), the configurations spilled to disk, then retargeted in pieces through the
    scaled model."""
    import tempfile

    from mocapkit._logged import logged_warnings
    from mocapkit.markers.reconstruct import ReconstructionOptions
    from mocapkit.markers.streamed import reconstruct_streamed
    from mocapkit.retarget.run import robot_and_segments

    humanoid, segments = robot_and_segments(robot)
    with tempfile.TemporaryDirectory(dir=_beside(output), prefix=".mocapkit-retarget-") as d:
        time = RowFile(Path(d) / "time.raw")
        spill: list[RowFile] = []

        def keep(result: Any) -> None:
            if not spill:
                spill.append(RowFile(Path(d) / "q.raw", (result.q.shape[1],)))
            time.append(result.time)
            spill[0].append(result.q)

        try:
            with logged_warnings() as warned:  # as the whole path's reconstruct() has them
                done = reconstruct_streamed(path, None, None, height_m, None,
                                            ReconstructionOptions(), None, on_piece=keep,
                                            chunk_frames=rows)  # fmt: skip
            source = _Model(done.subject.human, time, spill[0], segments, rows, warned,
                            str(path))  # fmt: skip
            return _retarget(source, humanoid, segments, output, **collisions)
        finally:
            time.close()
            for f in spill:
                f.close()


def _beside(output: str | Path | None) -> Path | None:
    """Where temporary files go: beside the output (its disk), else the system's."""
    return Path(output).resolve().parent if output is not None else None


def _retarget(
    source: _Angles | _Model,
    humanoid: Humanoid,
    segments: tuple[str, ...],
    output: str | Path | None,
    *,
    check_collisions: bool,
    avoid_collisions: bool,
    guard_collisions: bool,
) -> StreamedRetarget:
    """The two passes over ``source`` (module docstring)."""
    from mocapkit.retarget.metrics import FigureTally
    from mocapkit.retarget.run import collision_guards, collision_notes
    from mocapkit.retarget.solver import FrameSolver, Solution, finish, solve_piece
    from mocapkit.retarget.trajectory_io import TrajectoryWriter

    scan = _scan(source, humanoid, segments)
    coll, avoid = collision_guards(humanoid, check_collisions, avoid_collisions,
                                   guard_collisions)  # fmt: skip
    tally = FigureTally(humanoid, coll)
    solver: FrameSolver | None = None
    start = None
    seconds = 0.0
    a = 0
    belt = (scan.belt, float(scan.time[0]))
    what = source.name
    writer = TrajectoryWriter(output, humanoid) if output is not None else None
    with writer if writer is not None else contextlib.nullcontext():
        for motion in source.pieces(scan.ground):
            b = a + motion.n_frames
            if b > scan.time.size or not np.array_equal(motion.time, scan.time[a:b]):
                raise DataError(f"{what} changed while it was being retargeted (at row {a})")
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
        raise DataError(f"{what} changed while it was being retargeted ({a} rows read back)")
    summary = Solution(np.empty(0), np.empty((0, humanoid.model.nq)), {}, {})
    finish(solver, summary)
    figures = tally.figures(len(summary.held_frames))
    notes = scan.notes + summary.warnings
    notes += collision_notes(coll, figures, a, guard_collisions)
    return StreamedRetarget(humanoid, a, seconds, figures, notes, len(summary.kept_apart),
                            len(summary.stopped))  # fmt: skip
