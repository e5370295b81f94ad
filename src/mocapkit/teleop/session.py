"""The teleoperation session: a state machine between the operator's model and the robot.

States (docs/design/teleop.md): ``disabled``, ``aligning``,
``engaged``, ``clutched``, ``held``. The session is pure logic: each :meth:`tick` gets
the intermediate model's end-effector pose (or a fault), the robot's latest reported
pose and its age, and returns what to send (a command, a HOLD, or nothing). Every
transition is logged (logger ``mocapkit.teleop.session``, ``extra={"event": ...}``) and
kept in :attr:`TeleopSession.transitions`.

Relative control (reindexing, Miller et al. Fig. 10): at a reindex instant
``dp = p_robot - p_model`` and ``dR = R_model^T R_robot``; afterwards
``p_cmd = p_model + dp`` and ``R_cmd = R_model dR``: displacements of the operator's hand
are reproduced in the chest frame whatever the two postures are.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, Literal

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.errors import ConfigError
from mocapkit.teleop import _kernels
from mocapkit.teleop import protocol as proto

log = logging.getLogger("mocapkit.teleop.session")


class State(StrEnum):
    DISABLED = "disabled"
    ALIGNING = "aligning"
    ENGAGED = "engaged"
    CLUTCHED = "clutched"
    HELD = "held"


@dataclass(frozen=True)
class SessionConfig:
    """Session thresholds and limits (SI units; frames: the robot's chest frame).

    Attributes:
        mode: ``relative`` (reindex on engage and after a clutch or a fault) or
            ``absolute`` (the operator must find the robot's pose, as in the paper).
        engage_pos_m, engage_rot_rad: command-to-robot distance to engage.
        disengage_pos_m, disengage_rot_rad: wider thresholds to disengage (hysteresis)...
        disengage_after_s: ...when exceeded for this long.
        link_timeout_s: no robot report for this long -> held.
        workspace_min, workspace_max: box for the commanded position [m].
        max_speed_m_s, max_rot_speed_rad_s: end-effector command speed limits.
        unreachable_follow_m: while the server reports the target out of reach, stay
            engaged (the robot holds its closest pose and follows again when the target
            comes back) as long as it is at most this far [m]; beyond, disengage.
        max_model_rate_rad_s, max_model_speed_m_s: the operator's model pose moving faster
            than this between two ticks is a glitch (a bad packet, a sensor jump), not a
            human: the session holds with the reason and re-engages only after
            re-synchronising (reindex and alignment) instead of following at the speed
            limit. A human hand turns at most about 1,000-1,500 deg/s.
    """

    mode: Literal["relative", "absolute"] = "relative"
    engage_pos_m: float = 0.02
    engage_rot_rad: float = float(np.radians(8.0))
    disengage_pos_m: float = 0.08
    disengage_rot_rad: float = float(np.radians(25.0))
    disengage_after_s: float = 0.3
    link_timeout_s: float = 0.3
    workspace_min: tuple[float, float, float] = (-0.2, -1.0, -0.8)
    workspace_max: tuple[float, float, float] = (1.0, 1.0, 0.7)
    max_speed_m_s: float = 1.5
    max_rot_speed_rad_s: float = 4.0
    unreachable_follow_m: float = 0.3
    max_model_rate_rad_s: float = float(np.radians(2000.0))
    max_model_speed_m_s: float = 10.0

    def __post_init__(self) -> None:
        if self.mode not in ("relative", "absolute"):
            raise ConfigError(f"mode: expected 'relative' or 'absolute', got {self.mode!r}")
        if self.disengage_pos_m < self.engage_pos_m:
            raise ConfigError(
                "disengage_pos_m must be >= engage_pos_m (hysteresis), got "
                f"{self.disengage_pos_m} < {self.engage_pos_m}"
            )
        if self.disengage_rot_rad < self.engage_rot_rad:
            raise ConfigError(
                "disengage_rot_rad must be >= engage_rot_rad (hysteresis), got "
                f"{self.disengage_rot_rad} < {self.engage_rot_rad}"
            )
        if any(lo >= hi for lo, hi in zip(self.workspace_min, self.workspace_max, strict=True)):
            raise ConfigError(
                f"workspace: each min must be below its max, got {self.workspace_min} and "
                f"{self.workspace_max}"
            )
        for name in (
            "max_speed_m_s",
            "max_rot_speed_rad_s",
            "link_timeout_s",
            "max_model_rate_rad_s",
            "max_model_speed_m_s",
        ):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a positive number")


@dataclass(frozen=True)
class Transition:
    t: float
    source: State
    target: State
    reason: str


@dataclass
class TickOutput:
    """What the caller sends this tick: ``command`` (4, 4) or ``hold`` or nothing."""

    state: State
    command: FloatArray | None = None
    hold: bool = False
    notes: list[str] = field(default_factory=list)
    joints: tuple[FloatArray, FloatArray, FloatArray] | None = None  # humanoid: base, q


class TeleopSession:
    """See the module docstring. Times are the caller's clock [s] (e.g. monotonic)."""

    def __init__(self, config: SessionConfig | None = None) -> None:
        self.config = config or SessionConfig()
        self.state = State.DISABLED
        self.transitions: list[Transition] = []
        self.fault: str | None = None
        self._dp = np.zeros(3)
        self._dR = np.eye(3)
        self._reindex_pending = False
        self._clutch = False
        self._last_sent: FloatArray | None = None
        self._last_t: float | None = None
        self._far_since: float | None = None
        self._last_notes: set[str] = set()
        self._hold_pending = False
        self._lost = False  # disengaged because the robot could not follow
        self._short = False  # following a target out of the robot's reach
        self._lo = np.asarray(self.config.workspace_min, dtype=np.float64)
        self._hi = np.asarray(self.config.workspace_max, dtype=np.float64)
        self._prev = np.eye(4)
        self._prev_model: FloatArray | None = None
        self._prev_model_t = 0.0
        self.jumps = 0  # model-pose jumps held

    # -- operator events -------------------------------------------------------------------
    def _go(self, t: float, target: State, reason: str) -> None:
        if target == self.state:
            return
        tr = Transition(t, self.state, target, reason)
        self.transitions.append(tr)
        log.info(
            "transition %s -> %s: %s",
            tr.source.value,
            tr.target.value,
            reason,
            extra={"event": "transition", "from": tr.source.value, "to": tr.target.value,
                   "reason": reason, "t": t},
        )  # fmt: skip
        self.state = target
        self._far_since = None

    def engage(self, t: float) -> None:
        """Start (from disabled): align, reindexing first in relative mode."""
        if self.state == State.DISABLED:
            self._reindex_pending = self.config.mode == "relative"
            self._lost = False
            self._go(t, State.ALIGNING, "operator engaged")

    def disable(self, t: float, reason: str = "operator disabled") -> None:
        """Stop (any state): the next tick sends a HOLD, then nothing until engage()."""
        if self.state != State.DISABLED:
            self._hold_pending = True
        self._go(t, State.DISABLED, reason)

    def clutch(self, pressed: bool, t: float) -> None:
        """Operator's clutch: pressed -> the robot holds; released -> reindex, re-engage."""
        self._clutch = pressed
        if pressed and self.state in (State.ENGAGED, State.ALIGNING):
            self._hold_pending = True
            self._go(t, State.CLUTCHED, "clutch pressed")
        elif not pressed and self.state == State.CLUTCHED:
            self._reindex_pending = True
            self._go(t, State.ALIGNING, "clutch released: reindexing")

    def reindex(self, t: float) -> None:
        """Take a new offset at the next tick (any state); the model may jump then (a new
        calibration), so the jump check starts over."""
        self._reindex_pending = True
        self._prev_model = None
        log.info("reindex requested", extra={"event": "reindex", "t": t})

    @property
    def hold_pending(self) -> bool:
        """A HOLD is due at the next tick (after disable or clutch)."""
        return self._hold_pending

    # -- the tick --------------------------------------------------------------------------
    def offset(self) -> tuple[FloatArray, FloatArray]:
        """Current reindexing offset (dp (3,) [m], dR (3, 3))."""
        return self._dp.copy(), self._dR.copy()

    def apply_offset(self, T_model: FloatArray) -> FloatArray:
        T = np.empty((4, 4))
        _kernels.apply_offset(T_model, self._dR, self._dp, T)
        return T

    def tick(
        self,
        t: float,
        T_model: Any,
        robot_pose: Any,
        robot_age_s: float,
        model_fault: str | None = None,
        robot_gate: proto.Gate | None = None,
        robot_reason: proto.Reason | None = None,
    ) -> TickOutput:
        """One control step.

        Args:
            t: now [s].
            T_model: intermediate model's end-effector pose (4, 4), or None.
            robot_pose: the robot's latest reported pose (4, 4), or None.
            robot_age_s: age of that report [s].
            model_fault: why the model pose cannot be trusted (stale or NaN sensor...).
            robot_gate, robot_reason: the server's gate state from its latest report.
        """
        c = self.config
        dt = 0.0 if self._last_t is None else max(0.0, t - self._last_t)
        self._last_t = t
        if T_model is not None:
            T_model = np.asarray(T_model, dtype=np.float64)
            if not np.isfinite(T_model).all():
                model_fault = model_fault or "model pose is not finite"
                T_model = None
        elif model_fault is None:
            model_fault = "no model pose"
        if T_model is not None:
            jump = self._jump(t, T_model)
            if jump is not None:
                model_fault = model_fault or jump
        link_fault = None
        if robot_pose is None or robot_age_s > c.link_timeout_s:
            link_fault = (
                "no report from the robot server yet"
                if robot_pose is None
                else f"robot server silent for {robot_age_s:.2f} s"
            )
        fault = model_fault or link_fault
        hold = self._hold_pending
        self._hold_pending = False
        if self.state == State.DISABLED:
            return TickOutput(self.state, hold=hold)
        if fault is not None:
            if self.state != State.HELD:
                self.fault = fault
                self._go(t, State.HELD, fault)
                self._last_sent = None
                return TickOutput(self.state, hold=True, notes=[fault])
            return TickOutput(self.state, hold=hold, notes=[fault])
        assert T_model is not None
        assert robot_pose is not None
        robot = np.asarray(robot_pose, dtype=np.float64)
        if self.state == State.HELD:
            self.fault = None
            self._reindex_pending = self._reindex_pending or c.mode == "relative"
            self._go(t, State.CLUTCHED if self._clutch else State.ALIGNING, "fault cleared")
        if self.state == State.CLUTCHED:
            return TickOutput(self.state, hold=hold)
        if self._reindex_pending:
            self._dp = robot[:3, 3] - T_model[:3, 3]
            self._dR = np.ascontiguousarray(T_model[:3, :3].T @ robot[:3, :3])
            self._reindex_pending = False
            self._last_sent = None
            log.info("reindexed", extra={"event": "reindex", "t": t, "dp": self._dp.tolist()})
        cmd = self.apply_offset(T_model)
        notes = self._limit(cmd, dt)
        dp, dr = _kernels.pose_error(cmd, robot)
        if self.state == State.ALIGNING:
            if dp <= c.engage_pos_m and dr <= c.engage_rot_rad:
                self._go(t, State.ENGAGED, f"aligned within {dp * 1e3:.0f} mm, "
                         f"{np.degrees(dr):.1f} deg")  # fmt: skip
            elif (
                self._lost
                and c.mode == "relative"
                and dp <= c.disengage_pos_m
                and dr <= c.disengage_rot_rad
            ):
                # the target came back near where the robot stopped: take up the rest
                # by reindexing (no jump) and follow again
                self._lost = False
                self._dp = robot[:3, 3] - T_model[:3, 3]
                self._dR = np.ascontiguousarray(T_model[:3, :3].T @ robot[:3, :3])
                self._last_sent = None
                cmd = self.apply_offset(T_model)
                self._go(t, State.ENGAGED, f"target back within {dp * 1e3:.0f} mm: reindexed")
                dp, dr = 0.0, 0.0
            else:
                return TickOutput(self.state, hold=hold, notes=notes)
        # engaged
        far = dp > c.disengage_pos_m or dr > c.disengage_rot_rad
        short = robot_reason == proto.Reason.UNREACHABLE and dp <= c.unreachable_follow_m
        if far and short:
            # the server's IK holds the arm at its closest to a target out of its reach:
            # safe to keep commanding; it follows again when the target comes back
            note = "target out of reach: the robot follows as close as it can (server: UNREACHABLE)"
            if not self._short:
                log.info(note, extra={"event": "limit"})
            self._short = True
            notes = [*notes, note]
            self._far_since = None
        elif far:
            self._far_since = t if self._far_since is None else self._far_since
            if t - self._far_since >= c.disengage_after_s:
                why = f"robot cannot follow: {dp * 1e3:.0f} mm, {np.degrees(dr):.0f} deg away"
                if robot_reason is not None and robot_reason != proto.Reason.OK:
                    why += f" (server: {robot_reason.name})"
                self._lost = True
                self._go(t, State.ALIGNING, why)
                return TickOutput(self.state, hold=True, notes=[*notes, why])
        else:
            self._far_since = None
        if not far:
            self._short = False
        if (
            robot_gate is not None
            and robot_gate != proto.Gate.SYNCED
            and self._last_sent is not None
        ) and robot_reason in (proto.Reason.JUMP, proto.Reason.TIMEOUT, proto.Reason.TOO_FAR):
            self._reindex_pending = c.mode == "relative"
            why = f"robot server dropped synchronisation ({robot_reason.name})"
            self._go(t, State.ALIGNING, why)
            return TickOutput(self.state, notes=[*notes, why])
        self._last_sent = cmd
        return TickOutput(self.state, command=cmd, notes=notes)

    def _jump(self, t: float, T_model: FloatArray) -> str | None:
        """Why the model pose moved faster than a human can since the last one, or None."""
        c = self.config
        prev, t_prev = self._prev_model, self._prev_model_t
        self._prev_model, self._prev_model_t = T_model.copy(), t
        if prev is None:
            return None
        dt = max(t - t_prev, 1e-3)  # ticks closer than 1 ms: judged over 1 ms
        dpos, drot = _kernels.pose_error(T_model, prev)
        if drot <= c.max_model_rate_rad_s * dt and dpos <= c.max_model_speed_m_s * dt:
            return None
        self.jumps += 1
        return (
            f"model pose jumped {np.degrees(drot):.0f} deg / {dpos * 1e3:.0f} mm in "
            f"{dt * 1e3:.0f} ms (limits {np.degrees(c.max_model_rate_rad_s):.0f} deg/s, "
            f"{c.max_model_speed_m_s:g} m/s): a sensor glitch? held; re-engages after "
            "re-synchronising"
        )

    def _limit(self, cmd: FloatArray, dt: float) -> list[str]:
        """Workspace box and end-effector speed limits, in place; returns notes."""
        c = self.config
        prev = self._last_sent
        have_prev = prev is not None and dt > 0
        flags = _kernels.limit_command(
            cmd,
            prev if prev is not None else self._prev,
            self._lo,
            self._hi,
            c.max_speed_m_s * dt,
            c.max_rot_speed_rad_s * dt,
            have_prev,
        )
        if not flags and not self._last_notes:
            return []
        notes = [note for bit, note in _LIMIT_NOTES if flags & bit]
        new = set(notes) - self._last_notes
        for note in new:
            log.info(note, extra={"event": "limit"})
        self._last_notes = set(notes)
        return notes


_LIMIT_NOTES = (
    (1, "workspace limit: command clamped to the box"),
    (2, "speed limit: command slowed"),
    (4, "rotation speed limit: command slowed"),
)
