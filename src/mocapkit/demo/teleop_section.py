"""Demo section: a simulated suit teleoperates Robonaut 2's arm through the live chain.

One shape of the paper's evaluation, in real time: the suit streams raw IMU packets over
loopback UDP to the receiver; host-side filters, the calibrated body model, the eq. 16
retargeting and the session drive the robot-server process. Outputs: the body model's
joint angles (``.mot``) and a Foxglove-ready MCAP (segments and sensor frames as
``foxglove.FrameTransforms``, commanded and achieved end effector as
``foxglove.PoseInFrame``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.demo.chain_history import ChainHistory
from mocapkit.demo.progress import Progress, no_progress
from mocapkit.demo.suit_chain import ChainConfig, SuitTeleopChain
from mocapkit.errors import MocapkitError
from mocapkit.io.foxglove_mcap import FoxgloveMcapWriter
from mocapkit.io.joint_angles_mot import write_joint_angles_mot
from mocapkit.series import JointAngleSeries
from mocapkit.viz.plots import (
    ee_paths_figure,
    filter_errors_figure,
    joint_angles_figure,
    latency_figure,
)
from mocapkit.viz.report import HtmlReport

_REST_REACH_S = 3.0  # the operator rests 1 s, then reaches for 2 s
_HOLD_S = 1.0


def run_teleop(
    shape: str = "infinity", shape_s: float = 6.0, seed: int = 0, progress: Progress = no_progress
) -> ChainHistory:
    """Run one shape end to end in real time (about ``shape_s + 6`` s)."""
    t_end = _REST_REACH_S + shape_s + _HOLD_S
    cfg = ChainConfig(
        shapes=(shape,),
        shape_s=shape_s,
        duration_s=t_end + 0.5,
        seed=seed,
        auto_engage=True,
        record=True,
    )
    chain = SuitTeleopChain(cfg)
    with chain:
        done = chain.wait_motion_time(
            t_end, timeout_s=t_end + 30.0, on_progress=lambda t: progress("teleoperation", t, t_end)
        )
        if not done:
            raise MocapkitError(
                f"teleoperation: the pipeline reached only t = {chain.motion_time:.1f} s of "
                f"{t_end:.1f} s within the time limit (the machine is overloaded?)"
            )
        progress("teleoperation", t_end, t_end)
    return chain.result()


def write_teleop_outputs(h: ChainHistory, out_dir: Path) -> dict[str, Path]:
    """The body model's joint angles (.mot) and the Foxglove MCAP; returns their paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    ok = np.isfinite(h.body_angles).all(axis=1)
    mot = write_joint_angles_mot(
        out_dir / "teleop_body_angles.mot",
        JointAngleSeries(h.angle_time[ok], h.body_names, h.body_angles[ok], name="teleop_body"),
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


def teleop_summary(h: ChainHistory, shape: str) -> dict[str, Any]:
    f = h.figures
    return {
        "shape": shape,
        "filter": h.filter_name,
        "ee_rmse_mm": f.get("ee_rmse_mm"),
        "command_rmse_mm": f.get("command_rmse_mm"),
        "tracking_rmse_mm": f.get("tracking_rmse_mm"),
        "robot_lag_ms": f.get("robot_lag_ms"),
        "pipeline_ms_p50": f.get("pipeline_ms_p50"),
        "pipeline_ms_p99": f.get("pipeline_ms_p99"),
        "joint_rmse_deg": f.get("joint_rmse_deg", {}),
        "filter_rmse_deg": f.get("filter_rmse_deg", {}),
        "commands": f.get("commands"),
        "transitions": h.transitions,
    }


def report_teleop(report: HtmlReport, h: ChainHistory, summary: dict[str, Any]) -> None:
    sec = report.section(
        "Teleoperation from a simulated suit",
        f"The simulated operator traces the '{summary['shape']}' shape with the right arm. "
        "Three suit sensors (upper arm, forearm, chest; consumer-grade noise, bias, unknown "
        "mountings) stream raw IMU packets over loopback UDP at 100 Hz to the receiver; "
        f"host-side '{h.filter_name}' filters, the body model (calibrated in the N-pose), "
        "the paper's eq. 16 retargeting onto Robonaut 2 and the teleoperation session drive "
        "the robot-server process (its own IK, 30 ms actuation latency, safety gate).",
    )
    rows = [
        ["end-effector RMSE, achieved vs truth [mm]", summary["ee_rmse_mm"]],
        ["command RMSE, commanded vs truth [mm]", summary["command_rmse_mm"]],
        ["robot tracking RMSE after its lag [mm]", summary["tracking_rmse_mm"]],
        ["robot lag [ms]", summary["robot_lag_ms"]],
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
    sec.note(
        "pro_sup_r: the body model uses Rajagopal's oblique elbow and forearm axes (a carrying "
        "angle), the simulated arm orthogonal ones, so elbow flexion leaks into pro_sup_r by a "
        "few degrees: a difference of models, not of measurement."
    )
    sec.figure(
        joint_angles_figure(
            h.angle_time, h.angle_names, h.angles_est, h.angles_true,
            "Body model joint angles (blue) against the simulated operator (grey)",
        ),
        "Joint angles from the suit",
    )  # fmt: skip
    fr = summary["filter_rmse_deg"]
    sec.table(["sensor", f"{h.filter_name} orientation RMSE [deg]"], list(fr.items()))
    sec.figure(
        filter_errors_figure(
            h.filter_time, h.filter_error_deg, "Host-side filter error against the true sensor"
        ),
        "Filter errors per sensor",
    )
    sec.figure(latency_figure(h.latency_ms, "Pipeline latency"), "Host-side latency")
    sec.note("Session transitions: " + "; ".join(h.transitions))
