"""Autonomous looping playback of a recorded teleoperated motion (Miller et al., section 5:
"each recorded motion ... was executed autonomously ... looping through the motion").

:func:`play_recording` reads the commanded end-effector poses of a recording
(``/teleop/command``), checks the seam (:func:`~mocapkit.teleop.recording.loop_trajectory`:
a motion that begins and ends near the same pose loops, its last ``blend_s`` blended into
its start), and sends it to a robot server through a
:class:`~mocapkit.teleop.session.TeleopSession` in relative mode: on engaging, the
session reindexes (the motion is replayed relative to where the robot is), the robot's
gate accepts the first command because it equals the robot's pose, and the speed limits
apply as in teleoperation. It reports how closely the robot followed.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.errors import MocapkitError
from mocapkit.robot.model import pose_matrix
from mocapkit.teleop.link import RobotLink
from mocapkit.teleop.recording import loop_trajectory, playback_pose, read_commands
from mocapkit.teleop.session import SessionConfig, TeleopSession


def play_recording(
    path: str | Path,
    server: tuple[str, int],
    seconds: float = 10.0,
    rate_hz: float = 100.0,
    session: SessionConfig | None = None,
) -> dict[str, Any]:
    """Play (and loop) a recording for ``seconds``; returns ``loops``, ``seam_mm``,
    ``period_s``, ``loops_played``, ``commands_sent``, ``tracking_rmse_mm`` (the robot's
    reported positions, shifted by their best lag, against the commands) and the
    session's ``transitions``."""
    traj, check = loop_trajectory(read_commands(path))
    s = TeleopSession(session or SessionConfig(mode="relative"))
    sent_t: list[float] = []
    sent_p: list[np.ndarray] = []
    reports: list[tuple[float, np.ndarray]] = []
    with RobotLink(server, on_report=lambda t, r: reports.append((t, r.pos.copy()))) as link:
        link.send_hold()
        if not link.wait_for_report(5.0):
            raise MocapkitError(f"no robot server answers at {server[0]}:{server[1]}")
        start = time.monotonic()
        s.engage(start)
        period = 1.0 / rate_hz
        k = 0
        while (now := time.monotonic()) - start < seconds:
            pos, quat = playback_pose(traj, now - start, check.loops)
            link.poll()
            robot = link.robot_pose()
            out = s.tick(now, pose_matrix(pos, quat), robot, link.report_age(now))
            if out.command is not None:
                link.send_command(out.command)
                sent_t.append(now)
                sent_p.append(out.command[:3, 3].copy())
            elif out.hold:
                link.send_hold()
            k += 1
            time.sleep(max(0.0, start + k * period - time.monotonic()))
        link.send_hold()
    track = float("nan")
    if len(sent_t) > 20 and len(reports) > 20:
        from mocapkit.teleop.evaluate import best_lag, interp_rows

        t_c, p_c = np.array(sent_t), np.stack(sent_p)
        t_r, p_r = np.array([t for t, _ in reports]), np.stack([p for _, p in reports])
        lag = best_lag(t_c, p_c, t_r, p_r)
        ach = interp_rows(t_c + lag, t_r, p_r)
        use = t_c + lag <= t_r[-1]
        track = float(np.sqrt(np.mean(np.sum((ach[use] - p_c[use]) ** 2, axis=1))) * 1e3)
    duration = float(traj.t[-1] + np.median(np.diff(traj.t)))
    return {
        "loops": check.loops,
        "seam_mm": check.seam_pos_m * 1e3,
        "seam_deg": float(np.degrees(check.seam_rot_rad)),
        "period_s": duration,
        "loops_played": (seconds / duration) if check.loops else min(1.0, seconds / duration),
        "commands_sent": len(sent_t),
        "tracking_rmse_mm": track,
        "transitions": [f"{t.source.value}->{t.target.value}: {t.reason}" for t in s.transitions],
    }
