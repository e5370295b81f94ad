"""The paper's evaluation, end to end (Miller et al., section 5, Figs. 8-9).

For one shape, in real time, through the real chain:

1. the simulated operator (:mod:`mocapkit.teleop.operator`) stands in the calibration
   pose, raises the hand to the working point and traces the shape;
2. the simulated suit (:mod:`mocapkit.teleop.operator_suit`) turns the sensors' poses into
   IMU signals with sensor errors, runs the nodes' filters (or forwards RAW samples) and
   the hub, and a separate process sends the frames over UDP on the real clock;
3. a :class:`~mocapkit.teleop.live.LiveSession` receives them (suit receiver), fuses (on
   the host, if asked), calibrates the body model from the held pose (as a real session
   does: the operator is told to hold still, then ``calibrate()``), retargets, runs the
   session (``engage()`` at the working point: reindexing) and sends commands to
4. a robot-server process (own IK, joint limits, actuation latency, safety gate), whose
   pose reports come back.

The truth is the same body model, retargeting and intermediate model fed with the true
segment orientations (:func:`truth_model`), reindexed at the same instant.

Figures, over the shape (``shape_start`` to ``shape_end``):

- ``lag_ms``: the shift (0-500 ms) of the achieved path that best matches the commanded
  one: the robot's own tracking lag (actuation latency + IK), reported separately;
- ``ee_rmse_mm``: the achieved path, shifted back by that lag, against the truth command;
- ``joint_rmse_deg``: the intermediate model's joint angles against the truth's (the joints
  the suit drives: 5 of R2's 7 with two sensors);
- ``pipeline_ms_p50/p99``: host-side time per command, from the receiver's arrival stamp of
  the oldest contributing packet to the command's send, over the whole run.

The ideal chain (``--chain ideal``) is an ablation: the true orientations go over the
same wire and through the same host side, without IMU errors and filters.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.calibration import HeadingFixed, calibrate_pose
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError
from mocapkit.series import OrientationSeries
from mocapkit.teleop.eval_trace import RunTrace, run_trace
from mocapkit.teleop.live import LiveConfig, LiveSession
from mocapkit.teleop.operator import OperatorMotion, operator_motion
from mocapkit.teleop.operator_suit import Dropout, SuitSetup, suit_timeline
from mocapkit.teleop.pipeline import PipelineConfig, TeleopPipeline
from mocapkit.teleop.sender import TimelineSender
from mocapkit.teleop.server import ServerConfig, spawn_robot_server
from mocapkit.teleop.session import SessionConfig, TeleopSession

log = logging.getLogger("mocapkit.teleop.evaluate")
_NICE = 10


@dataclass
class EvalResult:
    """One shape's figures (see the module docstring) and the paths behind them."""

    shape: str
    ee_rmse_mm: float
    lag_ms: float
    pipeline_ms_p50: float
    pipeline_ms_p99: float
    joint_rmse_deg: float
    details: dict[str, Any] = field(default_factory=dict)
    commanded: FloatArray = field(repr=False, default_factory=lambda: np.zeros((0, 4)))
    achieved: FloatArray = field(repr=False, default_factory=lambda: np.zeros((0, 4)))
    truth: FloatArray = field(repr=False, default_factory=lambda: np.zeros((0, 4)))
    transitions: list[str] = field(default_factory=list)
    trace: RunTrace | None = field(default=None, repr=False)
    """The run's time series (``evaluate_shape(..., keep_trace=True)``)."""

    def summary(self) -> dict[str, Any]:
        """Exactly the six figures of ``mocapkit teleop evaluate --json``."""
        return {
            "shape": self.shape,
            "ee_rmse_mm": round(self.ee_rmse_mm, 3),
            "lag_ms": round(self.lag_ms, 1),
            "pipeline_ms_p50": round(self.pipeline_ms_p50, 4),
            "pipeline_ms_p99": round(self.pipeline_ms_p99, 4),
            "joint_rmse_deg": round(self.joint_rmse_deg, 3),
        }


def truth_model(
    motion: OperatorMotion, config: PipelineConfig
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The intermediate model driven by the true segment orientations: robot joints (N, n),
    end-effector poses (N, 4, 4) and human joint angles (N, K), through the same body model
    (calibrated on the truth in the same pose window), retargeting and forward kinematics."""
    cfg = replace(config, heading_axis=None, heading_rad=motion.heading_rad, fusion="node")
    pipe = TeleopPipeline(cfg, TeleopSession(SessionConfig()), None)
    tree = motion.tree
    series = {
        s.sensor: OrientationSeries(motion.time, motion.q_world_segment[:, i], name=s.sensor)
        for i, s in enumerate(tree.segments)
    }
    calib = calibrate_pose(
        tree, series, motion.calib_window, pose=cfg.pose, heading=HeadingFixed(motion.heading_rad)
    )
    pipe.set_calibration(calib)
    n = len(motion.time)
    if pipe.arm is None:
        raise ConfigError(f"evaluate: robot {cfg.robot!r} is a humanoid; evaluation drives arms")
    q = np.empty((n, pipe.arm.n))
    T = np.empty((n, 4, 4))
    angles = np.empty((n, len(tree.coordinate_names)))
    for k in range(n):
        t = float(motion.time[k])
        pipe.q_sensor[:] = motion.q_world_segment[k]
        pipe.t_valid[:] = t
        Tk, fault = pipe.model_pose(t)
        if Tk is None or pipe.q_robot is None or pipe.angles is None:
            raise RuntimeError(f"truth model: no pose at {t:.2f} s ({fault})")
        q[k], T[k], angles[k] = pipe.q_robot, Tk, pipe.angles
    return q, T, angles


def interp_rows(t: FloatArray, tp: FloatArray, xp: FloatArray) -> FloatArray:
    """Each column of ``xp`` (M, k) at times ``tp`` linearly interpolated at ``t``."""
    return np.stack([np.interp(t, tp, xp[:, k]) for k in range(xp.shape[1])], axis=1)


def best_lag(t: FloatArray, cmd: FloatArray, t_ach: FloatArray, ach: FloatArray) -> float:
    """The shift [s] (0-0.5 s, 1 ms steps) of the achieved path that matches the commanded."""
    lags = np.arange(0.0, 0.5, 0.001)
    costs = [np.mean(np.sum((interp_rows(t + lag, t_ach, ach) - cmd) ** 2, axis=1)) for lag in lags]
    return float(lags[int(np.argmin(costs))])


def evaluate_shape(
    shape: str,
    *,
    suit: SuitSetup | None = None,
    pipeline: PipelineConfig | None = None,
    session: SessionConfig | None = None,
    server: ServerConfig | None = None,
    seed: int = 0,
    shape_s: float = 6.0,
    dropouts: tuple[Dropout, ...] = (),
    record: Path | None = None,
    live_hook: Any = None,
    size_m: float = 0.10,
    keep_trace: bool = False,
) -> EvalResult:
    """Run one shape through the chain in real time (about ``shape_s`` + 7 s).

    ``size_m`` is the shape's size at the operator's hand [m]. ``live_hook(live, t_go,
    motion, server)``, if given, is called on the main thread right after the calibration
    starts (fault scenarios: pause the server, inject samples...), and must return. With
    ``keep_trace`` the result carries the run's time series (:class:`RunTrace`).
    """
    suit = suit or SuitSetup()
    pipe_cfg = pipeline or PipelineConfig()
    if suit.chain == "real":
        pipe_cfg = replace(pipe_cfg, fusion=suit.fusion)
    else:
        pipe_cfg = replace(pipe_cfg, fusion="node")
    rng = np.random.default_rng(seed)
    tree = SensorTree.preset(pipe_cfg.preset)
    heading = float(rng.uniform(-np.pi, np.pi))  # the operator faces anywhere (9D world)
    motion = operator_motion(
        shape, tree, rate_hz=suit.rate_hz, shape_s=shape_s, size_m=size_m, heading_rad=heading
    )
    ids = {n: i + 1 for i, n in enumerate(tree.sensor_names)}
    if pipe_cfg.sensor_ids is not None:
        ids = dict(pipe_cfg.sensor_ids)
    items, poses = suit_timeline(motion, suit, ids, rng, dropouts)
    q_truth, T_truth, angles_truth = truth_model(motion, pipe_cfg)
    srv_cfg = server or ServerConfig(robot=pipe_cfg.robot)
    live_cfg = LiveConfig(pipeline=pipe_cfg, session=session or SessionConfig())
    end = float(motion.time[-1])
    # the suit and the robot run on their own hardware; here they share the machine, at a
    # lower priority so they do not preempt the host pipeline being measured
    with spawn_robot_server(srv_cfg, max_seconds=end + 120, nice=_NICE) as srv:
        live = LiveSession(live_cfg, srv.address, record=record, keep_frames=True)
        with live, TimelineSender(items, "127.0.0.1", live.suit_port, nice=_NICE) as sender:
            if not _wait(lambda: live.link.latest is not None, 10.0):
                raise RuntimeError("the robot server does not report")
            t_go = sender.go()
            w0, w1 = motion.calib_window
            _sleep_until(t_go + w0)
            live.calibrate(w1 - w0, wait=False)
            if live_hook is not None:
                live_hook(live, t_go, motion, srv)
            _sleep_until(t_go + motion.engage_t)
            live.engage()
            sent = sender.wait(end + 30.0)
            # the last packets through the chain and the robot's last reports; shorter than
            # the receiver's missing_after_s (0.5 s): the sensors ended, they did not fail
            _sleep_until(time.perf_counter() + 0.3)
        transitions = [
            f"{tr.source.value}->{tr.target.value}: {tr.reason}" for tr in live.session.transitions
        ]
        result = _figures(shape, motion, live, q_truth, T_truth, angles_truth, transitions)
        if keep_trace:
            result.trace = run_trace(motion, live, poses, T_truth, angles_truth)
    result.details.update(
        {
            "chain": suit.chain,
            "fusion": pipe_cfg.fusion,
            "filter": suit.filter_name if pipe_cfg.fusion == "node" else pipe_cfg.filter_name,
            "retarget": pipe_cfg.retarget,
            "preset": pipe_cfg.preset,
            "heading_deg": float(np.degrees(heading)),
            "sender_late_ms_p99": sent["late_ms_p99"],
            "calibration": live.snapshot().get("calibration"),
        }
    )
    return result


def _wait(pred: Any, timeout_s: float) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.01)
    return False


def _sleep_until(t_perf: float) -> None:
    wait = t_perf - time.perf_counter()
    if wait > 0:
        time.sleep(wait)


def _figures(
    shape: str,
    motion: OperatorMotion,
    live: LiveSession,
    q_truth: FloatArray,
    T_truth: FloatArray,
    angles_truth: FloatArray,
    transitions: list[str],
) -> EvalResult:
    rate = 1.0 / float(np.median(np.diff(motion.time)))
    frames = [f for f in live.pipeline.frames if f.command is not None and f.q_robot is not None]
    if len(frames) < 10:
        raise RuntimeError(f"{shape}: the session never engaged; transitions: {transitions}")
    k = np.array([round(f.t_sensor * rate) for f in frames])
    k = np.clip(k, 0, len(motion.time) - 1)
    t_cmd = np.array([f.t for f in frames])
    cmd = np.stack([f.command[:3, 3] for f in frames if f.command is not None])
    # the truth command: the truth model reindexed at the first command (= the robot's pose)
    ref = T_truth[k, :3, 3] + (cmd[0] - T_truth[k[0], :3, 3])
    sel = (motion.time[k] >= motion.shape_start) & (motion.time[k] <= motion.shape_end)
    if sel.sum() < 10:
        raise RuntimeError(f"{shape}: no command during the shape; transitions: {transitions}")
    t_rep = np.array([t for t, _ in live.reports])
    p_rep = np.stack([r.pos for _, r in live.reports])
    lag = best_lag(t_cmd[sel], cmd[sel], t_rep, p_rep)
    achieved = interp_rows(t_cmd + lag, t_rep, p_rep)
    ee = np.sqrt(np.mean(np.sum((achieved[sel] - ref[sel]) ** 2, axis=1)))
    cmd_err = np.sqrt(np.mean(np.sum((cmd[sel] - ref[sel]) ** 2, axis=1)))
    track = np.sqrt(np.mean(np.sum((achieved[sel] - cmd[sel]) ** 2, axis=1)))
    q_est = np.stack([f.q_robot for f in frames if f.q_robot is not None])
    driven = np.ptp(q_truth, axis=0) > 1e-6  # the joints the suit moves
    jerr = q_est[sel][:, driven] - q_truth[k[sel]][:, driven]
    ang = np.stack([f.angles for f in frames if f.angles is not None])
    herr = np.degrees(np.sqrt(np.mean((ang[sel] - angles_truth[k[sel]]) ** 2, axis=0)))
    lat = live.pipeline.latency_ms()
    t0 = t_cmd[0]
    return EvalResult(
        shape,
        float(ee * 1e3),
        lag * 1e3,
        float(np.percentile(lat, 50)),
        float(np.percentile(lat, 99)),
        float(np.degrees(np.sqrt(np.mean(jerr**2)))),
        details={
            "cmd_rmse_mm": float(cmd_err * 1e3),
            "tracking_rmse_mm": float(track * 1e3),
            "human_rmse_deg": {
                c: round(float(v), 3)
                for c, v in zip(motion.tree.coordinate_names, herr, strict=True)
            },
            "commands": len(frames),
            "pipeline_ms_max": float(lat.max()),
        },
        commanded=np.column_stack([t_cmd[sel] - t0, cmd[sel]]),
        achieved=np.column_stack([t_cmd[sel] - t0, achieved[sel]]),
        truth=np.column_stack([t_cmd[sel] - t0, ref[sel]]),
        transitions=transitions,
    )


def plot_shapes(results: list[EvalResult], path: Path) -> None:
    """Fig. 9: commanded (green) and achieved (blue) end-effector paths in the chest's
    frontal plane (y left, z up), the truth dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = min(3, len(results))
    rows = (len(results) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 4 * rows), squeeze=False)
    for ax, r in zip(axes.flat, results, strict=False):
        ax.plot(r.truth[:, 2] * 1e3, r.truth[:, 3] * 1e3, "k--", lw=0.8, label="truth")
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
