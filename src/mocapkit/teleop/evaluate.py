"""The paper's evaluation, end to end (Miller et al., section 5, Figs. 8-9).

For one shape: the simulated operator (``operator.py``) traces it; the sensors on the
upper arm (1) and forearm (2) (random mountings) produce orientations; the per-packet
pipeline (``ArmTeleop``: watchdog, eq. 16 retargeting onto Robonaut 2, intermediate
model, session) sends commands over UDP to a robot-server *process*, in real time.

PROVISIONAL (until the suit and body parts land on main): the sensors' orientations are
the truth with an orientation-error model (white noise + random walk per axis) instead
of suit packets -> receiver -> filters -> body model.

Figures (over the shape only):
- ``lag_ms``: the shift of the achieved path that best matches the commanded one;
- ``ee_rmse_mm``: achieved vs the truth command (the intermediate model driven by the
  true segment orientations, reindexed at the same instant), after removing the lag;
- ``joint_rmse_deg``: intermediate-model joint angles vs those from the truth (the 5
  teleoperated joints);
- ``pipeline_ms_p50/p99``: per packet, arrival to command sent.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.geometry import quat_exp, quat_from_matrix, quat_mul
from mocapkit.robot.robonaut2 import robonaut2_arm
from mocapkit.robot.segment_retarget import (
    SegmentRetargeter,
    robonaut2_groups,
    robonaut2_init_posture,
)
from mocapkit.teleop import protocol as proto
from mocapkit.teleop.link import RobotLink
from mocapkit.teleop.operator import OperatorMotion, operator_motion
from mocapkit.teleop.pipeline import ArmTeleop, OrientationSample
from mocapkit.teleop.server import ServerConfig, spawn_robot_server
from mocapkit.teleop.session import SessionConfig, TeleopSession

SENSORS = {1: "humerus_r", 2: "radius_r"}
_TELEOP_JOINTS = slice(0, 5)  # the paper teleoperates 5 of R2's 7 joints


@dataclass(frozen=True)
class NoiseModel:
    """Provisional orientation error per sensor: white noise [rad] + random walk
    [rad/sqrt(s)] per axis, applied on the sensor side."""

    white_rad: float = float(np.radians(0.3))
    walk_rad_per_sqrt_s: float = float(np.radians(0.05))


@dataclass
class EvalResult:
    shape: str
    ee_rmse_mm: float
    lag_ms: float
    pipeline_ms_p50: float
    pipeline_ms_p99: float
    joint_rmse_deg: float
    commanded: FloatArray = field(repr=False, default_factory=lambda: np.zeros((0, 4)))
    achieved: FloatArray = field(repr=False, default_factory=lambda: np.zeros((0, 4)))
    truth: FloatArray = field(repr=False, default_factory=lambda: np.zeros((0, 4)))
    transitions: list[str] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        return {
            "shape": self.shape,
            "ee_rmse_mm": round(self.ee_rmse_mm, 3),
            "lag_ms": round(self.lag_ms, 1),
            "pipeline_ms_p50": round(self.pipeline_ms_p50, 4),
            "pipeline_ms_p99": round(self.pipeline_ms_p99, 4),
            "joint_rmse_deg": round(self.joint_rmse_deg, 3),
        }


def _sensor_quats(
    motion: OperatorMotion, rng: np.random.Generator, noise: NoiseModel
) -> tuple[dict[int, FloatArray], dict[int, FloatArray]]:
    """(true, measured) q_world_sensor (N, 4) per sensor, with random mountings."""
    n = len(motion.time)
    dt = float(np.median(np.diff(motion.time)))
    true: dict[int, FloatArray] = {}
    meas: dict[int, FloatArray] = {}
    for sid, seg in SENSORS.items():
        mount = rng.normal(size=4)
        mount /= np.linalg.norm(mount)
        q_seg = quat_from_matrix(motion.R_segments[seg])
        q = quat_mul(q_seg, mount)
        walk = np.cumsum(rng.normal(0, noise.walk_rad_per_sqrt_s * np.sqrt(dt), (n, 3)), axis=0)
        err = walk + rng.normal(0, noise.white_rad, (n, 3))
        true[sid] = q
        meas[sid] = quat_mul(q, quat_exp(0.5 * err))
    return true, meas


def _lag_and_rmse(
    t: FloatArray, cmd: FloatArray, t_ach: FloatArray, ach: FloatArray, ref: FloatArray
) -> tuple[float, float]:
    """Best lag [s] (0..0.5 s) aligning achieved to commanded, and the RMSE [m] of the
    achieved path against ``ref`` shifted by that lag."""
    lags = np.arange(0.0, 0.5, 0.002)
    costs = []
    for lag in lags:
        shifted = np.stack([np.interp(t + lag, t_ach, ach[:, k]) for k in range(3)], axis=1)
        costs.append(np.mean(np.sum((shifted - cmd) ** 2, axis=1)))
    lag = float(lags[int(np.argmin(costs))])
    shifted = np.stack([np.interp(t + lag, t_ach, ach[:, k]) for k in range(3)], axis=1)
    rmse = float(np.sqrt(np.mean(np.sum((shifted - ref) ** 2, axis=1))))
    return lag, rmse


def evaluate_shape(
    shape: str,
    seed: int = 0,
    shape_s: float = 6.0,
    server: ServerConfig | None = None,
    noise: NoiseModel | None = None,
    plot: Path | None = None,
) -> EvalResult:
    """Run one shape through the whole chain in real time (about shape_s + 4.5 s)."""
    rng = np.random.default_rng(seed)
    motion = operator_motion(shape, shape_s=shape_s)
    _true_q, meas_q = _sensor_quats(motion, rng, noise or NoiseModel())
    arm = robonaut2_arm("right")
    q_init = robonaut2_init_posture("right")
    groups = robonaut2_groups("right")[:2]  # the paper's two sensors: 5 joints
    truth_rt = SegmentRetargeter(arm, groups, q_init)
    R0 = {seg: motion.R_segments[seg][0] for seg in SENSORS.values()}
    truth_rt.calibrate(R0)
    q_truth = np.stack(
        [
            truth_rt.joint_angles({s: motion.R_segments[s][k] for s in SENSORS.values()}).q
            for k in range(len(motion.time))
        ]
    )
    T_truth = arm.fk_batch(q_truth)
    reports: list[tuple[float, FloatArray]] = []

    def on_report(t: float, r: proto.Report) -> None:
        reports.append((t, r.pos.copy()))

    cfg = server or ServerConfig()
    with (
        spawn_robot_server(cfg, max_seconds=shape_s + 60) as srv,
        RobotLink(srv.address, on_report=on_report) as link,
    ):
        link.send_hold()
        link.wait_for_report(10.0)
        session = TeleopSession(SessionConfig())
        pipe = ArmTeleop(
            robonaut2_arm("right"),
            SegmentRetargeter(robonaut2_arm("right"), groups, q_init),
            SENSORS,
            session,
            link,
        )
        pipe.calibrate({sid: meas_q[sid][0] for sid in SENSORS})
        rate = 1.0 / float(np.median(np.diff(motion.time)))
        engage_k = int((motion.shape_start - 0.5) * rate)
        start = time.monotonic()
        t_frames = []
        for k in range(len(motion.time)):
            due = start + motion.time[k]
            while (now := time.monotonic()) < due:
                time.sleep(min(0.002, due - now))
            if k == engage_k:
                session.engage(time.monotonic())
            arrival = time.perf_counter_ns()
            samples = [OrientationSample(sid, arrival, meas_q[sid][k]) for sid in SENSORS]
            pipe.process(samples)
            t_frames.append(time.monotonic() - start)
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            link.poll()
            time.sleep(0.005)
    frames = pipe.frames
    t_rel = np.array(t_frames)
    sel = (motion.time >= motion.shape_start) & (motion.time <= motion.shape_end)
    cmd_ok = np.array([f.out.command is not None for f in frames])
    use = sel & cmd_ok
    if use.sum() < 10:
        raise RuntimeError(
            f"{shape}: the session never engaged; transitions: {session.transitions}"
        )
    cmds = [f.out.command for f, u in zip(frames, use, strict=True) if u]
    cmd = np.stack([c[:3, 3] for c in cmds if c is not None])
    dp, _ = session.offset()
    # the truth command: the same offset taken at the same instant from the truth model
    first = int(np.flatnonzero(cmd_ok)[0])
    T_first = frames[first].T_model
    assert T_first is not None
    dp_truth = dp + T_first[:3, 3] - T_truth[first][:3, 3]
    ref = T_truth[use][:, :3, 3] + dp_truth
    t_rep = np.array([r[0] for r in reports]) - start
    p_rep = np.stack([r[1] for r in reports])
    lag, rmse = _lag_and_rmse(t_rel[use], cmd, t_rep, p_rep, ref)
    q_est = np.stack([f.q for f, u in zip(frames, use, strict=True) if u])  # type: ignore[misc]
    jerr = q_est[:, _TELEOP_JOINTS] - q_truth[use][:, _TELEOP_JOINTS]
    lat = np.array([f.latency_ns for f in frames if f.latency_ns is not None]) / 1e6
    achieved = np.stack([np.interp(t_rel[use] + lag, t_rep, p_rep[:, k]) for k in range(3)], 1)
    result = EvalResult(
        shape,
        rmse * 1e3,
        lag * 1e3,
        float(np.percentile(lat, 50)),
        float(np.percentile(lat, 99)),
        float(np.degrees(np.sqrt(np.mean(jerr**2)))),
        commanded=np.column_stack([t_rel[use], cmd]),
        achieved=np.column_stack([t_rel[use], achieved]),
        truth=np.column_stack([t_rel[use], ref]),
        transitions=[
            f"{tr.source.value}->{tr.target.value}: {tr.reason}" for tr in session.transitions
        ],
    )
    if plot is not None:
        plot_shapes([result], plot)
    return result


def plot_shapes(results: list[EvalResult], path: Path) -> None:
    """Fig. 9: commanded (green) vs achieved (blue) end-effector paths, chest y-z plane."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = min(3, len(results))
    rows = (len(results) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 4 * rows), squeeze=False)
    for ax, r in zip(axes.flat, results, strict=False):
        ax.plot(r.commanded[:, 2] * 1e3, r.commanded[:, 3] * 1e3, "g-", label="commanded")
        ax.plot(r.achieved[:, 2] * 1e3, r.achieved[:, 3] * 1e3, "b-", label="achieved")
        ax.set_title(f"{r.shape}: {r.ee_rmse_mm:.1f} mm RMSE, lag {r.lag_ms:.0f} ms")
        ax.set_xlabel("chest y [mm]")
        ax.set_ylabel("chest z [mm]")
        ax.set_aspect("equal", adjustable="datalim")
    axes.flat[0].legend(loc="best")
    for ax in list(axes.flat)[len(results) :]:
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
