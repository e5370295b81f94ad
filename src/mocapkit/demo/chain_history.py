"""What a simulated teleoperation session did, against the simulation's truth.

Recorded on the pipeline thread (appends only), turned into arrays and figures once at
the end by :meth:`HistoryRecorder.finish`:

- filter errors: angle between each sensor's fused orientation and its true
  ``q_world_sensor`` at the same sensor time [deg] (9D: same world frame, no alignment);
- joint angles: the body model's human coordinates against the simulated operator's;
- end effector: commanded (session output), achieved (robot server's reports) and the
  truth command (the intermediate model driven by the true segment orientations,
  reindexed at the same instant), with the robot's lag and the two errors.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.calibration import BodyCalibration
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.demo.operator_cycle import COMPARED_COORDS, SENSORS, TREE, OperatorCycle
from mocapkit.geometry import quat_angle_between, quat_to_matrix
from mocapkit.robot.model import ArmModel
from mocapkit.robot.segment_retarget import (
    SegmentRetargeter,
    robonaut2_groups,
    robonaut2_init_posture,
)
from mocapkit.teleop.arm_pipeline import FrameLog
from mocapkit.teleop.session import TeleopSession

_MAX_LAG_S = 0.5


@dataclass
class ChainHistory:
    """Arrays (time first) and figures of one run; see the module docstring."""

    filter_name: str
    filter_time: dict[str, FloatArray]  # sensor name -> (M,) sensor time [s]
    filter_error_deg: dict[str, FloatArray]  # sensor name -> (M,) [deg]
    angle_time: FloatArray  # (A,) [s]
    angle_names: tuple[str, ...]
    angles_est: FloatArray  # (A, k) [rad] body model
    angles_true: FloatArray  # (A, k) [rad] simulated operator
    body_names: tuple[str, ...]  # every coordinate of the body model
    body_angles: FloatArray  # (A, K) [rad]
    segment_names: tuple[str, ...]
    q_world_segment: FloatArray  # (A, S, 4) the body model's segment orientations
    cmd_time: FloatArray  # (C,) host time since start [s]
    cmd_motion_time: FloatArray  # (C,) motion (sensor) time of the command's data [s]
    cmd_pos: FloatArray  # (C, 3) commanded end-effector position, chest frame [m]
    truth_pos: FloatArray  # (C, 3) truth command [m]
    ach_time: FloatArray  # (R,) host time of the robot's reports [s]
    ach_pos: FloatArray  # (R, 3) achieved end-effector position [m]
    latency_ms: FloatArray  # (C,) packet arrival -> command sent [ms]
    transitions: list[str] = field(default_factory=list)
    figures: dict[str, Any] = field(default_factory=dict)


def _lag(t: FloatArray, cmd: FloatArray, t_ach: FloatArray, ach: FloatArray) -> float:
    """The delay [s] (0..0.5 s) of the achieved path that best matches the commanded one."""
    lags = np.arange(0.0, _MAX_LAG_S, 0.002)
    costs = [
        np.mean(np.sum((np.stack([np.interp(t + lag, t_ach, ach[:, k]) for k in range(3)], 1)
                        - cmd) ** 2, axis=1))
        for lag in lags
    ]  # fmt: skip
    return float(lags[int(np.argmin(costs))])


class HistoryRecorder:
    """Collects the run (pipeline thread) and computes :class:`ChainHistory`."""

    def __init__(self, motion: OperatorCycle, arm: ArmModel) -> None:
        self.motion = motion
        self.arm = arm
        self._q: dict[int, list[tuple[float, FloatArray]]] = {sid: [] for sid in SENSORS}
        self._angles: list[tuple[float, FloatArray, FloatArray]] = []
        self._angle_names: tuple[str, ...] = ()
        self._cmd: list[tuple[float, float, FloatArray, FloatArray, float]] = []
        self._rep: list[tuple[float, FloatArray]] = []
        self._t_cal: float | None = None

    def orientation(self, sensor_id: int, t: float, q: FloatArray) -> None:
        self._q[sensor_id].append((t, np.array(q)))

    def calibrated(self, t: float, calib: BodyCalibration) -> None:
        self._t_cal = t

    def angles(self, t: float, values: FloatArray, q_world_segment: FloatArray) -> None:
        """One body frame at sensor time t; a frame at the same time replaces the last one
        (a packet of another sensor of the same hub round)."""
        row = (t, values.copy(), q_world_segment.copy())
        if self._angles and t <= self._angles[-1][0]:
            self._angles[-1] = row
        else:
            self._angles.append(row)

    def command(self, t_host: float, t_motion: float, frame: FrameLog) -> None:
        assert frame.out.command is not None
        assert frame.T_model is not None
        lat = np.nan if frame.latency_ns is None else frame.latency_ns / 1e6
        self._cmd.append(
            (t_host, t_motion, frame.out.command[:3, 3].copy(), frame.T_model[:3, 3].copy(), lat)
        )

    def report(self, t_host: float, report: Any) -> None:
        self._rep.append((t_host, np.array(report.pos)))

    # -- figures ------------------------------------------------------------------------------
    def _index(self, t: FloatArray) -> np.ndarray:
        k = np.round(np.asarray(t) * self.motion.rate_hz).astype(int)
        return np.clip(k, 0, len(self.motion.time) - 1)

    def _truth_model_pos(self, t_motion: FloatArray) -> FloatArray:
        """Intermediate-model end-effector positions from the true segment orientations,
        calibrated at the same instant as the session's body calibration."""
        rt = SegmentRetargeter(
            self.arm, robonaut2_groups("right")[:2], robonaut2_init_posture("right")
        )
        segs = ("humerus_r", "radius_r")
        k0 = int(self._index(np.array([self._t_cal or 0.0]))[0])
        rt.calibrate({s: quat_to_matrix(self.motion.q_segments[s][k0]) for s in segs})
        out = np.empty((len(t_motion), 3))
        for i, k in enumerate(self._index(t_motion)):
            R = {s: quat_to_matrix(self.motion.q_segments[s][k]) for s in segs}
            out[i] = self.arm.fk(rt.joint_angles(R).q)[:3, 3]
        return out

    def finish(self, session: TeleopSession, motion: OperatorCycle) -> ChainHistory:
        names = {sid: v[0] for sid, v in SENSORS.items()}
        f_time: dict[str, FloatArray] = {}
        f_err: dict[str, FloatArray] = {}
        for sid, rows in self._q.items():
            if not rows:
                continue
            t = np.array([r[0] for r in rows])
            q = np.stack([r[1] for r in rows])
            truth = motion.sensor_poses[sid].quat[self._index(t)]
            f_time[names[sid]] = t
            f_err[names[sid]] = np.degrees(quat_angle_between(q, truth))
        a_t = np.array([r[0] for r in self._angles])
        tree = SensorTree.preset(TREE)
        coords = tree.coordinate_names
        cols = [coords.index(c) for c in COMPARED_COORDS]
        n_seg = len(tree.segment_names)
        all_angles = (
            np.stack([r[1] for r in self._angles]) if self._angles else np.zeros((0, len(coords)))
        )
        q_seg = np.stack([r[2] for r in self._angles]) if self._angles else np.zeros((0, n_seg, 4))
        est = all_angles[:, cols]
        truth_cols = [motion.coords.index(c) for c in COMPARED_COORDS]
        true = motion.q_human[self._index(a_t)][:, truth_cols] if len(a_t) else est.copy()
        c_host = np.array([r[0] for r in self._cmd])
        c_mot = np.array([r[1] for r in self._cmd])
        cmd = np.stack([r[2] for r in self._cmd]) if self._cmd else np.zeros((0, 3))
        model = np.stack([r[3] for r in self._cmd]) if self._cmd else np.zeros((0, 3))
        lat = np.array([r[4] for r in self._cmd])
        truth_pos = np.zeros((0, 3))
        if len(cmd):
            # both retargeters start from the robot's reference posture at the calibration
            # instant, so the truth command is the truth model with the session's offset
            truth_pos = self._truth_model_pos(c_mot) + (cmd - model)
        r_t = np.array([r[0] for r in self._rep])
        r_p = np.stack([r[1] for r in self._rep]) if self._rep else np.zeros((0, 3))
        h = ChainHistory(
            filter_name="",
            filter_time=f_time,
            filter_error_deg=f_err,
            angle_time=a_t,
            angle_names=COMPARED_COORDS,
            angles_est=est,
            angles_true=true,
            body_names=coords,
            body_angles=all_angles,
            segment_names=tree.segment_names,
            q_world_segment=q_seg,
            cmd_time=c_host,
            cmd_motion_time=c_mot,
            cmd_pos=cmd,
            truth_pos=truth_pos,
            ach_time=r_t,
            ach_pos=r_p,
            latency_ms=lat,
            transitions=[
                f"{t.source.value} -> {t.target.value}: {t.reason}" for t in session.transitions
            ],
        )
        h.figures = figures(h, self._t_cal, [(s.t_start, s.t_end) for s in motion.spans])
        return h


def figures(
    h: ChainHistory, t_cal: float | None, spans: list[tuple[float, float]]
) -> dict[str, Any]:
    """Summary figures of a history (NaN where there is nothing to measure); the end
    effector's over the shapes only (``spans``: motion-time intervals)."""
    out: dict[str, Any] = {}
    out["filter_rmse_deg"] = {
        name: float(np.sqrt(np.mean(e[h.filter_time[name] > 1.0] ** 2)))
        for name, e in h.filter_error_deg.items()
        if (h.filter_time[name] > 1.0).any()
    }
    if len(h.angle_time):
        err = np.degrees(h.angles_est - h.angles_true)
        ok = np.isfinite(err).all(axis=1)
        out["joint_rmse_deg"] = {
            n: float(np.sqrt(np.mean(err[ok, k] ** 2))) for k, n in enumerate(h.angle_names)
        }
    nan = float("nan")
    out["pipeline_ms_p50"] = float(np.nanpercentile(h.latency_ms, 50)) if len(h.latency_ms) else nan
    out["pipeline_ms_p99"] = float(np.nanpercentile(h.latency_ms, 99)) if len(h.latency_ms) else nan
    out["commands"] = len(h.cmd_time)
    sel = np.zeros(len(h.cmd_time), dtype=bool)
    for t0, t1 in spans:
        sel |= (h.cmd_motion_time >= t0) & (h.cmd_motion_time <= t1)
    out["shape_commands"] = int(sel.sum())
    if sel.sum() > 10 and len(h.ach_time) > 10:
        t, cmd, truth = h.cmd_time[sel], h.cmd_pos[sel], h.truth_pos[sel]
        lag = _lag(t, cmd, h.ach_time, h.ach_pos)
        shifted = np.stack([np.interp(t + lag, h.ach_time, h.ach_pos[:, k]) for k in range(3)], 1)

        def rms_mm(d: FloatArray) -> float:
            return 1e3 * float(np.sqrt(np.mean(np.sum(d**2, axis=1))))

        out["robot_lag_ms"] = lag * 1e3
        out["tracking_rmse_mm"] = rms_mm(shifted - cmd)
        out["ee_rmse_mm"] = rms_mm(shifted - truth)
        out["command_rmse_mm"] = rms_mm(cmd - truth)
    out["calibrated_at_s"] = t_cal
    return out
