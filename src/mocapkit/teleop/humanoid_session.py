"""The session state machine for a humanoid: joint targets instead of an end-effector pose.

:class:`HumanoidSession` keeps :class:`~mocapkit.teleop.session.TeleopSession`'s operator
events and states (``engage``, ``disable``, ``clutch``, ``reindex``; disabled, aligning,
engaged, clutched, held) and replaces its tick: :meth:`tick_joints` takes the retargeted
target (base pose and joints, ``mocapkit.retarget.live.LiveRetargeter``) and the robot's
reported joints, and returns a JOINTS command, a HOLD, or nothing.

- **Aligning** (after engage, a clutch release, a reindex or a cleared fault): the robot
  server accepts only commands near its actual joints, so the command walks from the
  robot's joints towards the target at ``align_speed_rad_s`` per joint; the target
  reached, the session is engaged.
- **Engaged**: the target is sent as it is (the retargeting QP already keeps the joint
  and velocity limits). A target that moves a joint faster than ``JUMP_FACTOR`` times its
  velocity limit is a glitch, not a person: held, named, and re-aligned only once the
  operator engages again.
- **Held** on a fault (a stale sensor, the body model unknown, calibrating) or a robot link
  without reports for ``link_timeout_s``: a HOLD goes out; when the fault clears the
  session aligns again by itself (the robot has not moved since: aligning is safe).
- The robot server dropping its gate (a jump it refused, a timeout) sends an engaged
  session back to aligning.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.teleop import protocol as proto
from mocapkit.teleop.session import SessionConfig, State, TeleopSession, TickOutput

JUMP_FACTOR = 3.0  # a target step beyond this many times the velocity limit is a glitch
ALIGN_SPEED_RAD_S = 0.8  # how fast aligning walks the joints towards the target
ALIGNED_RAD = 1e-3  # aligning ends when every joint is this near the target
MAX_DT_S = 0.05  # a longer pause between ticks counts as this long


@dataclass
class JointsTarget:
    base_pos: FloatArray  # (3,) [m]
    base_quat: FloatArray  # (4,) [w, x, y, z]
    q: FloatArray  # (n,) [rad]


class HumanoidSession(TeleopSession):
    """See the module docstring; ``v_max`` (n,) the joints' velocity limits [rad/s]."""

    def __init__(self, config: SessionConfig | None = None) -> None:
        super().__init__(config)
        self.v_max: FloatArray | None = None
        self.align_speed_rad_s = ALIGN_SPEED_RAD_S
        self._last_cmd: FloatArray | None = None
        self._last_tick: float | None = None
        self._glitch = False

    def engage(self, t: float) -> None:
        """Start from disabled, or re-arm a session held by a glitch: align first."""
        self._glitch = False
        if self.state == State.HELD:
            self._last_cmd = None
            self._go(t, State.ALIGNING, "operator engaged")
            return
        super().engage(t)

    def _hold(self, t: float, reason: str, out: TickOutput) -> TickOutput:
        if self.state in (State.ALIGNING, State.ENGAGED):
            out.hold = True
            self._go(t, State.HELD, reason)
        self._last_cmd = None
        out.state = self.state
        return out

    def tick_joints(
        self,
        t: float,
        target: JointsTarget | None,
        robot_q: FloatArray | None,
        report_age_s: float,
        fault: str | None,
        gate: proto.Gate | None = None,
        reason: proto.Reason | None = None,
    ) -> TickOutput:
        """One tick (module docstring): ``out.joints`` is the command to send, or None."""
        dt = 0.01 if self._last_tick is None else min(max(t - self._last_tick, 0.0), MAX_DT_S)
        self._last_tick = t
        out = TickOutput(self.state)
        if self._hold_pending:
            out.hold = True
            self._hold_pending = False
        self.fault = fault
        if self.state in (State.DISABLED, State.CLUTCHED):
            return out
        if fault is not None or target is None:
            return self._hold(t, fault or "no target", out)
        if report_age_s > self.config.link_timeout_s:
            return self._hold(t, f"robot link: no report for {report_age_s:.2f} s", out)
        if self.state == State.HELD:
            if self._glitch:
                return out  # a glitch waits for the operator (engage again)
            self._go(t, State.ALIGNING, "fault cleared: aligning")
        if robot_q is None or robot_q.shape != target.q.shape:
            out.state = self.state
            return out  # no report with the robot's joints yet
        if self.state == State.ENGAGED:
            if gate is not None and gate != proto.Gate.SYNCED:
                why = reason.name if reason is not None else gate.name
                self._go(t, State.ALIGNING, f"robot gate dropped ({why}): aligning")
            elif self._last_cmd is not None and self.v_max is not None:
                step = np.abs(target.q - self._last_cmd)
                limit = JUMP_FACTOR * self.v_max * max(dt, 0.01) + 1e-3
                if bool(np.any(step > limit)):
                    k = int(np.argmax(step - limit))
                    self._glitch = True
                    self.jumps += 1
                    return self._hold(
                        t, f"target jumped {np.degrees(step[k]):.1f} deg on joint {k} in "
                        f"{dt * 1e3:.0f} ms (a glitch, not a person): engage again", out,
                    )  # fmt: skip
        if self.state == State.ALIGNING:
            start = robot_q if self._last_cmd is None else self._last_cmd
            walk = self.align_speed_rad_s * max(dt, 0.01)
            q = start + np.clip(target.q - start, -walk, walk)
            if float(np.max(np.abs(target.q - q))) < ALIGNED_RAD:
                self._go(t, State.ENGAGED, "aligned with the robot")
        else:
            q = target.q
        self._last_cmd = q.copy()
        out.joints = (target.base_pos, target.base_quat, q)
        out.state = self.state
        return out

    def disable(self, t: float, reason: str = "operator disabled") -> None:
        self._last_cmd = None
        super().disable(t, reason)

    def clutch(self, pressed: bool, t: float) -> None:
        self._last_cmd = None
        super().clutch(pressed, t)

    def reindex(self, t: float) -> None:
        """A humanoid follows the body as it is: reindexing re-aligns."""
        super().reindex(t)
        if self.state == State.ENGAGED:
            self._last_cmd = None
            self._go(t, State.ALIGNING, "reindex: aligning")
