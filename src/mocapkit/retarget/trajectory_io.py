"""The robot trajectory written as it is solved, piece by piece: ``.csv`` (time, base
position and quaternion [w, x, y, z], joints [rad]), ``.npz`` (the same arrays with
names), ``.mcap`` (Foxglove: ``/robot/joints`` joint positions, ``/robot/tf`` the frame
tree world -> base -> every link with real translations, ``/robot/targets`` the keypoint
targets; wall-clock timestamps from when the file is written).

A whole recording is one piece; a long one (``retarget.streamed``) gives many, and the
file is the same. The ``.npz`` rows wait in a raw file beside the output until
:meth:`TrajectoryWriter.close` copies them into the archive a block at a time.
"""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._spill import RowFile
from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError
from mocapkit.retarget.robot_model import Humanoid
from mocapkit.retarget.solver import Solution
from mocapkit.retarget.targets import Targets

OUTPUT_SUFFIXES = (".csv", ".npz", ".mcap")
BASE_NAMES = ("base_x", "base_y", "base_z", "base_qw", "base_qx", "base_qy", "base_qz")
NPZ_BLOCK_ROWS = 20_000


def check_output(path: Path) -> str:
    """The output format (its suffix), or a refusal naming the ones there are."""
    suffix = path.suffix.lower()
    if suffix not in OUTPUT_SUFFIXES:
        raise ConfigError(
            f"output {path}: expected one of {', '.join(OUTPUT_SUFFIXES)} (the extension "
            "picks the format)"
        )
    return suffix


def base_and_joints(robot: Humanoid, q: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(N, 7 or 0) base position and quaternion [w, x, y, z], and (N, joints) [rad]."""
    nb = robot.n_base_q
    base = q[:, :nb]
    if nb:  # pinocchio's free flyer: xyz + quaternion [x, y, z, w] -> [w, x, y, z]
        base = np.column_stack([base[:, :3], base[:, 6], base[:, 3:6]])
    return base, q[:, nb:]


class TrajectoryWriter:
    """``write(solution, targets)`` for each piece in order, then ``close()`` (or use it as
    a context manager: a run that fails leaves no output file)."""

    def __init__(self, path: str | Path, robot: Humanoid) -> None:
        self.path = Path(path)
        self.suffix = check_output(self.path)
        self.robot = robot
        self.base_names = list(BASE_NAMES[: robot.n_base_q])
        self._file: Any = None
        self._rows: RowFile | None = None
        self._mcap: Any = None
        self._t0: tuple[int, float] | None = None  # wall clock [ns] and trajectory time
        if self.suffix == ".csv":
            self._file = open(self.path, "w", encoding="utf-8")  # noqa: SIM115 (close())
            self._file.write(",".join(["time", *self.base_names, *robot.joint_names]) + "\n")
        elif self.suffix == ".npz":
            self._rows = RowFile(self.path.with_name(self.path.name + ".rows"),
                                 (1 + robot.model.nq,))  # fmt: skip
        else:
            from mocapkit.io.foxglove_mcap import FoxgloveMcapWriter

            self._mcap = FoxgloveMcapWriter(self.path)
            self._mcap.__enter__()

    def write(self, sol: Solution, targets: Targets) -> None:
        if self._file is not None:
            base, q = base_and_joints(self.robot, sol.q)
            table = np.column_stack([sol.time, base, q])
            np.savetxt(self._file, table, delimiter=",", fmt="%.9g")
        elif self._rows is not None:
            self._rows.append(np.column_stack([sol.time, sol.q]))
        else:
            self._write_mcap(sol, targets)

    def close(self, failed: bool = False) -> None:
        """Finish the file; ``failed``: remove it (a trajectory cut short by an error must
        not look like a whole one)."""
        try:
            if self._file is not None:
                self._file.close()
            if self._mcap is not None:
                self._mcap.__exit__(None, None, None)
            if self._rows is not None and not failed:
                self._write_npz(self._rows)
        except BaseException:
            failed = True
            raise
        finally:
            if self._rows is not None:
                self._rows.close()
            if failed:
                self.path.unlink(missing_ok=True)

    def __enter__(self) -> TrajectoryWriter:
        return self

    def __exit__(self, exc_type: object, *exc: object) -> None:
        self.close(failed=exc_type is not None)

    def _write_npz(self, rows: RowFile) -> None:
        """The arrays ``np.savez`` would write (time, base, q, joint_names, base_names,
        robot), the long ones copied a block of rows at a time."""
        n, nb = rows.rows, self.robot.n_base_q
        nj = len(self.robot.joint_names)
        small = {"joint_names": np.array(list(self.robot.joint_names)),
                 "base_names": np.array(self.base_names), "robot": np.array(
                     self.robot.spec.name)}  # fmt: skip
        with zipfile.ZipFile(self.path, "w", zipfile.ZIP_STORED, allowZip64=True) as z:
            for name, width in (("time", 0), ("base", nb), ("q", nj)):
                shape = (n,) if name == "time" else (n, width)
                with z.open(f"{name}.npy", "w", force_zip64=True) as f:
                    np.lib.format.write_array_header_1_0(
                        f, {"descr": "<f8", "fortran_order": False, "shape": shape}
                    )
                    for a in range(0, n, NPZ_BLOCK_ROWS):
                        block = rows.read(a, min(a + NPZ_BLOCK_ROWS, n))
                        base, q = base_and_joints(self.robot, block[:, 1:])
                        part = {"time": block[:, 0], "base": base, "q": q}[name]
                        f.write(np.ascontiguousarray(part, dtype="<f8").tobytes())
            for name, value in small.items():
                with z.open(f"{name}.npy", "w") as f:
                    np.lib.format.write_array(f, value, allow_pickle=False)

    def _write_mcap(self, sol: Solution, targets: Targets) -> None:
        import time as _time

        import pinocchio as pin

        from mocapkit.geometry import quat_from_matrix

        robot = self.robot
        model, data = robot.model, robot.model.createData()
        if self._t0 is None and sol.time.size:
            self._t0 = (_time.time_ns(), float(sol.time[0]))
        names = list(model.names)
        w = self._mcap
        for k, t in enumerate(sol.time):
            assert self._t0 is not None
            t_ns = self._t0[0] + round((t - self._t0[1]) * 1e9)
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
            for seg, pos in targets.pos.items():
                target_rot = targets.rot.get(seg)
                qt = (
                    quat_from_matrix(target_rot[k])
                    if target_rot is not None
                    else np.array([1.0, 0.0, 0.0, 0.0])
                )
                w.pose_in_frame(f"/robot/targets/{seg}", t_ns, "world", pos[k], qt)
