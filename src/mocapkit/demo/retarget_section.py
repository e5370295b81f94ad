"""The demo's retargeting section: the bundled marker trial onto Unitree G1 (whole body),
with the figures ``mocapkit retarget --json`` gives, and the robot's leg joints."""

from __future__ import annotations

import importlib.util
import logging
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.demo.markers_section import bundled_marker_files
from mocapkit.demo.progress import Progress, no_progress
from mocapkit.viz.report import HtmlReport

ROBOT = "g1"
HEIGHT_M = 1.80  # the tutorial subject's
LEG_JOINTS = ("right_hip_pitch_joint", "right_knee_joint", "right_ankle_pitch_joint")


def retarget_available() -> str | None:
    """None, or why the section cannot run (the robots extra: proxsuite and the G1 URDF
    from example-robot-data)."""
    if importlib.util.find_spec("proxsuite") is None:
        return "proxsuite is missing: pip install 'mocapkit[robots]'"
    from mocapkit.errors import MocapkitError
    from mocapkit.retarget.robot_spec import load_robot_spec

    try:
        spec = load_robot_spec(ROBOT)
    except (MocapkitError, OSError) as exc:
        return f"robot {ROBOT}: {exc} (pip install 'mocapkit[robots]')"
    if not spec.urdf.is_file():
        return f"robot {ROBOT}: no URDF at {spec.urdf}: pip install 'mocapkit[robots]'"
    return None


def run_retarget(out_dir: Path, progress: Progress = no_progress) -> dict[str, Any]:
    why = retarget_available()
    if why is not None:
        return {"status": "unavailable", "reason": why}
    from mocapkit.retarget.run import retarget, write_trajectory

    progress("retargeting onto G1", 0, 1)
    with ExitStack() as stack:
        walk, _static = bundled_marker_files(stack)
        # the reconstruction's doubts come back in res.notes and go into the report
        quiet = logging.getLogger("mocapkit.markers")
        level = quiet.level
        quiet.setLevel(logging.ERROR)
        stack.callback(quiet.setLevel, level)
        res = retarget(walk, ROBOT, height_m=HEIGHT_M)
    out = write_trajectory(out_dir / "walk1_g1.npz", res)
    progress("retargeting onto G1", 1, 1)
    sol = res.solution
    names = list(res.robot.joint_names)
    nb = res.robot.n_base_q
    legs = {n: sol.q[:, nb + names.index(n)] for n in LEG_JOINTS if n in names}
    return {"status": "ok", "figures": res.figures, "notes": res.notes, "time": sol.time,
            "legs": legs, "kept_apart": len(sol.kept_apart), "stopped": len(sol.stopped),
            "solve_fps": sol.time.size / sol.solve_seconds if sol.solve_seconds else None,
            "outputs": {"retarget_g1_npz": out}}  # fmt: skip


def retarget_summary(r: dict[str, Any]) -> dict[str, Any]:
    if r["status"] != "ok":
        return {"status": r["status"], "reason": r["reason"]}
    f = r["figures"]
    return {"status": "ok", "robot": ROBOT, "keypoint_rmse_mm": f["keypoint_rmse_mm"]["mean"],
            "foot_skate_mm": f["foot_skate_mm"], "limit_violations": f["limit_violations"],
            "collision_frames": f["collisions"]["frames"],
            "solve_fps": None if r["solve_fps"] is None else round(r["solve_fps"], 1)}  # fmt: skip


def report_retarget(report: HtmlReport, r: dict[str, Any]) -> None:
    sec = report.section(
        "The walking trial on a humanoid (Unitree G1)",
        "The same marker trial reconstructed and retargeted onto G1's 29 joints and floating "
        "base (mocapkit retarget): the human pose drawn with the robot's bones, one QP per "
        "frame with joint and velocity limits, feet held still in contact and above the "
        "ground, and every frame checked for self-collisions on the robot's meshes. "
        "See it: mocapkit view walk1_g1.npz.",
    )
    if r["status"] != "ok":
        sec.note(f"Not run: {r['reason']}.")
        return
    f = r["figures"]
    kp = f["keypoint_rmse_mm"]
    worst = max((k for k in kp if k != "mean"), key=lambda k: kp[k])
    lim = f["limit_violations"]
    sec.table(
        ["figure", "value"],
        [
            ["frames", int(r["time"].size)],
            ["keypoint RMS after scaling [mm]", f"{kp['mean']} (worst {worst} {kp[worst]})"],
            ["foot skating in contact [mm/frame]", f["foot_skate_mm"]],
            ["frames below the ground", f["ground_penetration"]["frames"]],
            ["limit violations (position / velocity)", f"{lim['position']} / {lim['velocity']}"],
            ["self-collision frames", f["collisions"]["frames"]],
            ["collision guard: steered / stopped short", f"{r['kept_apart']} / {r['stopped']}"],
            ["QP frames per second", None if r["solve_fps"] is None else round(r["solve_fps"])],
        ],
    )  # fmt: skip
    if r["legs"]:
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7.0, 3.0))
        for name, q in r["legs"].items():
            ax.plot(r["time"], np.degrees(q), label=name.replace("_joint", ""))
        ax.set_xlabel("time [s]")
        ax.set_ylabel("joint [deg]")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        sec.figure(fig, "G1's right leg over the walk")
        plt.close(fig)
    for note in r["notes"]:
        sec.note(note)
