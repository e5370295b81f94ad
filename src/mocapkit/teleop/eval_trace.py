"""The time series behind an evaluation run, against the simulated truth (for reports and
recordings: the demo's teleoperation section).

From the live session's frames (``keep_frames``) and the robot's reports:

- the body model's joint angles and segment orientations per frame (motion time), with
  the truth coordinates at the same instant;
- each sensor's orientation error: the angle between the orientation the pipeline used
  (fused on the host or on the node) and the sensor's true ``q_world_sensor`` at that
  sample's time [deg] (9D: the same world frame, no alignment);
- the end effector: every command, the truth command (the truth model with the session's
  offset at the first command) and the robot's reported positions, on one host clock;
- the pipeline time of every command and the session's transitions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.geometry import quat_angle_between
from mocapkit.series import PoseSeries
from mocapkit.teleop.live import LiveSession
from mocapkit.teleop.operator import OperatorMotion


@dataclass
class RunTrace:
    """Attributes (time first; ``A`` body frames, ``C`` commands, ``R`` robot reports):

    angle_time: (A,) motion time [s] of the frames with a body pose.
    coordinate_names: the tree's coordinates (OpenSim names).
    angles, angles_truth: (A, K) [rad] the body model's and the operator's.
    segment_names: the tree's segments.
    q_world_segment: (A, S, 4) the body model's segment orientations.
    sensor_time: (F,) motion time [s] of the frames with sensor orientations.
    sensor_names: the tree's sensors.
    sensor_error_deg: (F, S') [deg] each sensor's orientation error (NaN before its first
        sample).
    cmd_time, cmd_pos, truth_pos: (C,) host time [s] (0: the run's first frame or robot
        report), (C, 3) commanded and truth positions [m] in the chest frame.
    ach_time, ach_pos: (R,) host time [s], (R, 3) reported positions [m].
    latency_ms: (C,) pipeline time of each command [ms].
    transitions: ``"from -> to: reason"``, in order.
    """

    angle_time: FloatArray
    coordinate_names: tuple[str, ...]
    angles: FloatArray
    angles_truth: FloatArray
    segment_names: tuple[str, ...]
    q_world_segment: FloatArray
    sensor_time: FloatArray
    sensor_names: tuple[str, ...]
    sensor_error_deg: FloatArray
    cmd_time: FloatArray
    cmd_pos: FloatArray
    truth_pos: FloatArray
    ach_time: FloatArray
    ach_pos: FloatArray
    latency_ms: FloatArray
    transitions: list[str]

    def sensor_rmse_deg(self, after_s: float = 1.0) -> dict[str, float]:
        """RMS orientation error per sensor [deg] over the samples after ``after_s`` [s]
        (the filters' start-up left out)."""
        sel = self.sensor_time > after_s
        out = {}
        for j, name in enumerate(self.sensor_names):
            e = self.sensor_error_deg[sel, j]
            e = e[np.isfinite(e)]
            if e.size:
                out[name] = float(np.sqrt(np.mean(e**2)))
        return out


def _stack(rows: list[FloatArray | None], shape: tuple[int, ...]) -> FloatArray:
    """(N, *shape) from N rows that are all set (an empty list: (0, *shape))."""
    if not rows:
        return np.zeros((0, *shape))
    return np.stack([r for r in rows if r is not None])


def _last_per_time(t: FloatArray) -> np.ndarray:
    """Indices of the last frame of each distinct time (several batches of one round)."""
    rev = np.unique(t[::-1], return_index=True)[1]
    return np.sort(len(t) - 1 - rev)


def run_trace(
    motion: OperatorMotion,
    live: LiveSession,
    poses: dict[str, PoseSeries],
    T_truth: FloatArray,
    angles_truth: FloatArray,
) -> RunTrace:
    """The trace of a finished run (see the module docstring); ``poses`` are the sensors'
    true poses (:func:`mocapkit.teleop.operator_suit.suit_timeline`), ``T_truth`` and
    ``angles_truth`` the truth model's end effector and coordinates per motion sample."""
    frames = live.pipeline.frames
    tree = motion.tree
    rate = 1.0 / float(np.median(np.diff(motion.time)))
    n = len(motion.time)

    def index(t: FloatArray) -> np.ndarray:
        return np.clip(np.round(np.asarray(t) * rate).astype(int), 0, n - 1)

    body = [f for f in frames if f.angles is not None and f.q_segment is not None]
    t_body = np.array([f.t_sensor for f in body])
    body = [body[i] for i in _last_per_time(t_body)] if body else []
    angle_time = np.array([f.t_sensor for f in body])
    angles = _stack([f.angles for f in body], (len(tree.coordinate_names),))
    q_seg = _stack([f.q_segment for f in body], (len(tree.segments), 4))
    sens = [f for f in frames if f.q_sensor is not None and f.t_sample is not None]
    t_sens = np.array([f.t_sensor for f in sens])
    sens = [sens[i] for i in _last_per_time(t_sens)] if sens else []
    q_all = _stack([f.q_sensor for f in sens], (len(tree.sensor_names), 4))
    t_all = _stack([f.t_sample for f in sens], (len(tree.sensor_names),))
    err = np.full(t_all.shape, np.nan)
    for j, name in enumerate(tree.sensor_names):
        ok = np.isfinite(t_all[:, j]) & np.isfinite(q_all[:, j]).all(axis=1)
        if ok.any():
            truth = poses[name].quat[index(t_all[ok, j])]
            err[ok, j] = np.degrees(quat_angle_between(q_all[ok, j], truth))
    cmds = [f for f in frames if f.command is not None]
    starts = [f.t for f in frames[:1]] + [t for t, _ in live.reports[:1]]
    t0 = min(starts) if starts else 0.0  # the host clock's zero: the run's first event
    cmd_pos = _stack([None if f.command is None else f.command[:3, 3] for f in cmds], (3,))
    k = index(np.array([f.t_sensor for f in cmds]))
    truth_pos = T_truth[k, :3, 3] + (cmd_pos[0] - T_truth[k[0], :3, 3]) if cmds else cmd_pos
    reports = live.reports
    return RunTrace(
        angle_time=angle_time,
        coordinate_names=tree.coordinate_names,
        angles=angles,
        angles_truth=angles_truth[index(angle_time)],
        segment_names=tree.segment_names,
        q_world_segment=q_seg,
        sensor_time=np.array([f.t_sensor for f in sens]),
        sensor_names=tree.sensor_names,
        sensor_error_deg=err,
        cmd_time=np.array([f.t - t0 for f in cmds]),
        cmd_pos=cmd_pos,
        truth_pos=truth_pos,
        ach_time=np.array([t - t0 for t, _ in reports]),
        ach_pos=_stack([np.asarray(r.pos) for _, r in reports], (3,)),
        latency_ms=np.array([f.latency_ns / 1e6 for f in cmds if f.latency_ns is not None]),
        transitions=[
            f"{tr.source.value} -> {tr.target.value}: {tr.reason}"
            for tr in live.session.transitions
        ],
    )
