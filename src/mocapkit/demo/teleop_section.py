"""Demo section: a simulated suit teleoperates Robonaut 2's arm through the live session.

One shape of the paper's evaluation, in real time, by
:func:`mocapkit.teleop.evaluate.evaluate_shape` (the code of ``mocapkit teleop evaluate``):
the simulated operator (the body model)
stands in the N-pose, reaches and traces the shape; its suit (three sensors: upper arm,
forearm, torso; consumer-grade errors) streams RAW IMU packets from a sender process over
loopback UDP; the live session (:class:`mocapkit.teleop.live.LiveSession`) fuses them on
the host with the preferred filter (:func:`mocapkit.teleop.simulated.best_filter`),
calibrates the body model in the N-pose, retargets by eq. 16 and drives the robot-server
process. Outputs: the body model's joint angles (``.mot``) and a Foxglove-ready MCAP
(segments as ``foxglove.FrameTransforms``, commanded and achieved end effector as
``foxglove.PoseInFrame``).
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.demo.progress import Progress, no_progress
from mocapkit.errors import MocapkitError
from mocapkit.io.foxglove_mcap import FoxgloveMcapWriter
from mocapkit.io.joint_angles_mot import write_joint_angles_mot
from mocapkit.series import JointAngleSeries
from mocapkit.teleop.eval_trace import RunTrace
from mocapkit.teleop.evaluate import EvalResult, evaluate_shape
from mocapkit.teleop.operator_suit import SuitSetup
from mocapkit.teleop.pipeline import PipelineConfig
from mocapkit.teleop.simulated import best_filter
from mocapkit.viz.plots import (
    ee_paths_figure,
    filter_errors_figure,
    joint_angles_figure,
    latency_figure,
)
from mocapkit.viz.report import HtmlReport

PRESET = "right_arm_torso_3"  # upper arm, forearm and the section-6 torso sensor
#: motion before the shape (N-pose 2 s, reach 2 s, settle 1 s) and after it (hold 1 s) [s]
_BEFORE_S, _AFTER_S = 5.0, 1.0


def run_teleop(
    shape: str = "infinity", shape_s: float = 6.0, seed: int = 0, progress: Progress = no_progress
) -> EvalResult:
    """Run one shape end to end in real time (about ``shape_s + 7`` s); the result carries
    the run's trace and ``details["filter"]``."""
    total = _BEFORE_S + shape_s + _AFTER_S
    done = threading.Event()

    def follow(live: Any, t_go: float, motion: Any, server: Any) -> None:
        def report() -> None:
            import time

            while not done.wait(0.2):
                progress("teleoperation", min(total, time.perf_counter() - t_go), total)

        threading.Thread(target=report, daemon=True).start()

    name = best_filter()
    try:
        result = evaluate_shape(
            shape,
            suit=SuitSetup(fusion="host"),
            pipeline=PipelineConfig(preset=PRESET, fusion="host", filter_name=name),
            seed=seed,
            shape_s=shape_s,
            live_hook=follow,
            keep_trace=True,
        )
    except RuntimeError as exc:  # the session never engaged: say why
        raise MocapkitError(f"teleoperation: {exc}") from exc
    finally:
        done.set()
    progress("teleoperation", total, total)
    return result


def write_teleop_outputs(r: EvalResult, out_dir: Path) -> dict[str, Path]:
    """The body model's joint angles (.mot) and the Foxglove MCAP; returns their paths."""
    h = _trace(r)
    out_dir.mkdir(parents=True, exist_ok=True)
    ok = np.isfinite(h.angles).all(axis=1)
    mot = write_joint_angles_mot(
        out_dir / "teleop_body_angles.mot",
        JointAngleSeries(h.angle_time[ok], h.coordinate_names, h.angles[ok], name="teleop_body"),
    )
    mcap = out_dir / "teleop_foxglove.mcap"
    with FoxgloveMcapWriter(mcap) as w:
        for k, t in enumerate(h.angle_time):
            t_ns = round(float(t) * 1e9)
            w.frame_transforms(
                "/body/segments",
                t_ns,
                [("world", seg, np.zeros(3), h.q_world_segment[k, i])
                 for i, seg in enumerate(h.segment_names)],
            )  # fmt: skip
        for t, p in zip(h.cmd_time, h.cmd_pos, strict=True):
            w.pose_in_frame("/robot/ee_command", round(float(t) * 1e9), "chest", p, [1, 0, 0, 0])
        for t, p in zip(h.ach_time, h.ach_pos, strict=True):
            w.pose_in_frame("/robot/ee_actual", round(float(t) * 1e9), "chest", p, [1, 0, 0, 0])
    return {"body_angles_mot": mot, "foxglove_mcap": mcap}


def _trace(r: EvalResult) -> RunTrace:
    if r.trace is None:
        raise MocapkitError("the teleoperation result has no trace (keep_trace=True)")
    return r.trace


def teleop_summary(r: EvalResult, shape: str) -> dict[str, Any]:
    """The figures of the run (JSON-ready)."""
    h = _trace(r)
    d = r.details
    return {
        "shape": shape,
        "filter": d.get("filter"),
        "fusion": d.get("fusion"),
        "preset": d.get("preset"),
        "ee_rmse_mm": r.ee_rmse_mm,
        "command_rmse_mm": d.get("cmd_rmse_mm"),
        "tracking_rmse_mm": d.get("tracking_rmse_mm"),
        "robot_lag_ms": r.lag_ms,
        "pipeline_ms_p50": r.pipeline_ms_p50,
        "pipeline_ms_p99": r.pipeline_ms_p99,
        "robot_joint_rmse_deg": r.joint_rmse_deg,
        "joint_rmse_deg": d.get("human_rmse_deg", {}),
        "filter_rmse_deg": h.sensor_rmse_deg(),
        "commands": d.get("commands"),
        "transitions": h.transitions,
    }


def report_teleop(report: HtmlReport, r: EvalResult, summary: dict[str, Any]) -> None:
    h = _trace(r)
    filt = summary["filter"]
    sec = report.section(
        "Teleoperation from a simulated suit",
        f"The simulated operator traces the '{summary['shape']}' shape with the right arm. "
        "Three suit sensors (upper arm, forearm, torso; consumer-grade noise, bias and drift, "
        "mountings 5 deg off, magnetometers calibrated beforehand) stream raw IMU packets "
        "from a sender process over loopback UDP at 100 Hz to the live session "
        f"(mocapkit.teleop.live): host-side '{filt}' filters with a still start, the body "
        "model calibrated in the N-pose (heading refined at the first elbow flexion), the "
        "paper's eq. 16 retargeting onto Robonaut 2 and the session drive the robot-server "
        "process (its own IK, 30 ms actuation latency, safety gate). The same code as "
        "`mocapkit teleop evaluate`.",
    )
    rows = [
        ["end-effector RMSE, achieved (after the lag) vs truth [mm]", summary["ee_rmse_mm"]],
        ["command RMSE, commanded vs truth [mm]", summary["command_rmse_mm"]],
        ["robot tracking RMSE after its lag [mm]", summary["tracking_rmse_mm"]],
        ["robot lag [ms]", summary["robot_lag_ms"]],
        ["robot joint RMSE vs the truth model [deg]", summary["robot_joint_rmse_deg"]],
        ["pipeline latency p50 [ms]", summary["pipeline_ms_p50"]],
        ["pipeline latency p99 [ms]", summary["pipeline_ms_p99"]],
        ["commands sent", summary["commands"]],
    ]
    sec.table(["figure (over the shape)", "value"], rows)
    sec.figure(
        ee_paths_figure(h.cmd_time, h.cmd_pos, h.ach_time, h.ach_pos, h.truth_pos),
        "Commanded (green) and achieved (blue) end-effector paths against the truth command "
        "(grey): the paper's Fig. 9",
    )
    jr = summary["joint_rmse_deg"]
    sec.table(["human joint angle", "RMSE vs the simulated operator [deg]"], list(jr.items()))
    sec.figure(
        joint_angles_figure(
            h.angle_time, h.coordinate_names, h.angles, h.angles_truth,
            "Body model joint angles (blue) against the simulated operator (grey)",
        ),
        "Joint angles from the suit",
    )  # fmt: skip
    fr = summary["filter_rmse_deg"]
    sec.table(["sensor", f"{filt} orientation RMSE [deg]"], list(fr.items()))
    names = h.sensor_names
    sec.figure(
        filter_errors_figure(
            {n: h.sensor_time for n in names},
            {n: h.sensor_error_deg[:, j] for j, n in enumerate(names)},
            "Host-side filter error against the true sensor orientation",
        ),
        "Filter errors per sensor",
    )
    sec.figure(latency_figure(h.latency_ms, "Pipeline latency"), "Host-side latency")
    sec.note("Session transitions: " + "; ".join(h.transitions))
