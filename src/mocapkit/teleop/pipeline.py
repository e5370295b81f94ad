"""The per-packet teleoperation pipeline: suit samples -> robot command on the wire.

``TeleopPipeline.process(samples, now_ns)`` takes the samples the suit receiver delivered
in one drained batch (a hub bundle, or the RAW datagrams of a round) and runs, on the
caller's thread (the receiver's, see :class:`mocapkit.teleop.live.LiveSession`):

1. per sample: host-side fusion for RAW samples (``--fusion host``: a
   :class:`~mocapkit.imu.filter_bank.FilterBank`, i.e. a still start around a registry
   filter per sensor, the batch's samples advanced in one numba call), or the node's own
   orientation (``--fusion node``, the paper's design); the quaternion is checked (finite,
   unit);
2. the sensor watchdog: every sensor of the tree must have brought a valid sample within
   ``stale_after_s``, else the session holds and says which sensor and why;
3. the body model (:class:`mocapkit.body.kinematics.BodyStream`, calibrated from a held
   pose by :meth:`TeleopPipeline.start_calibration`): segment orientations and the
   human joint angles (OpenSim coordinates);
4. retargeting onto the robot: ``segments`` (the paper's eq. 16 along the robot's own
   axes, :class:`~mocapkit.robot.segment_retarget.SegmentRetargeter`) or ``map`` (a
   YAML joint map on the joint angles); joints clipped to a limit are reported;
5. the intermediate model's forward kinematics, ``T_chest_ee``;
6. the session (:class:`~mocapkit.teleop.session.TeleopSession`): reindexing, the engage
   gate, workspace and speed limits, the link watchdog;
7. the command (or a HOLD) leaves on the robot link.

A humanoid robot (``robot`` a packaged humanoid or a robot YAML, ``mocapkit robot list``)
replaces steps 4-7: the body's joint angles go through
:class:`~mocapkit.retarget.live.LiveRetargeter` (the offline retargeting's targets and QP,
one step per frame, self-collisions guarded) and
:class:`~mocapkit.teleop.humanoid_session.HumanoidSession` turns the target into a JOINTS
command (base pose and joint positions) on the same link, with the same watchdogs.

``pipeline_ms`` is the host-side time from the oldest contributing sample's arrival (the
receiver's ``t_arrival_ns``, taken when the datagram was read) to the command's send.

The chest frame (the robot's command frame, x forward, y left, z up): the body's heading
at calibration when the tree's root hangs from the ground (``right_arm_2``), or the
torso segment when the tree has one (``right_arm_torso_3``: the section-6 root sensor, so
the operator may turn).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.calibration import (
    BodyCalibration,
    HeadingFixed,
    HeadingFromSensor,
    calibrate_pose,
)
from mocapkit.body.kinematics import BodyStream
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError, MocapkitError
from mocapkit.geometry import quat_to_matrix
from mocapkit.imu.filter_bank import FilterBank
from mocapkit.imu.filters import make_filter
from mocapkit.robot.model import ArmModel
from mocapkit.robot.registry import available_robots, robot_arm
from mocapkit.series import OrientationSeries
from mocapkit.suit.protocol import Kind
from mocapkit.teleop import _kernels
from mocapkit.teleop.heading import HingeHeading
from mocapkit.teleop.humanoid_session import HumanoidSession, JointsTarget
from mocapkit.teleop.link import RobotLink
from mocapkit.teleop.retarget_setup import CHEST_IN_SEGMENT, setup_retarget
from mocapkit.teleop.session import State, TeleopSession, TickOutput

if TYPE_CHECKING:
    from mocapkit.retarget.live import LiveRetargeter

NEUTRAL_ROOT = ("pelvis_tilt", "pelvis_list", "pelvis_rotation")

#: [s] a sensor clock that steps back further than this was reset (a reboot); shorter
#: steps back are late or repeated samples, ignored as not fresh.
CLOCK_RESET_S = 0.5

log = logging.getLogger("mocapkit.teleop.pipeline")

_LATENCY_CAPACITY = 1 << 17
_NO_MAG = np.full(3, np.nan)  # a RAW sample without a magnetometer: a gap


@dataclass(frozen=True)
class PipelineConfig:
    """What the pipeline runs (SI units).

    Attributes:
        preset: body sensor tree (``right_arm_2``: the paper; ``right_arm_torso_3``).
        sensor_ids: ``(sensor name, suit ID)`` pairs; default: the tree's sensors in order,
            IDs 1, 2, ... (the paper: 1 upper arm, 2 forearm).
        robot: robot arm (``mocapkit.robot.available_robots()``), also the intermediate model;
            or a humanoid (``mocapkit robot list``, or a robot YAML): joint commands.
        retarget: ``"segments"`` (eq. 16 along the robot's axes; Robonaut 2) or ``"map"``
            (the robot's packaged YAML joint map on the human joint angles).
        fusion: ``"node"`` (orientations fused on the nodes) or ``"host"`` (RAW samples
            fused here).
        filter_name, rate_hz, use_mag: host-side fusion (registry name, sample rate, 9D).
        still_start_s: host-side fusion: the first seconds of each sensor are a still start
            (gyroscope bias and orientation, :mod:`mocapkit.imu.still_start`); 0: off.
        stale_after_s: a sensor without a valid sample this long holds the session.
        max_sensor_rate_rad_s: a sensor's orientation turning faster than this between two
            of its samples (by their sensor time) is a glitch, not a limb (a gyroscope's
            range, 2000 deg/s, is above any human motion): the session holds and
            re-engages only after reindexing, so the robot never chases the jump.
        pose: the calibration pose (``npose``: the paper's initialisation posture).
        heading_axis: the root sensor's axis that points forward in the pose (the body's
            heading at calibration), or None to use ``heading_rad``.
        heading_rad: the body's heading [rad from world x] when ``heading_axis`` is None.
        heading_refine: refine the heading from the first elbow flexion after the
            calibration (:mod:`mocapkit.teleop.heading`; needs ``humerus`` and ``radius``
            segments and ``heading_axis``), then recalibrate and reindex.
    """

    preset: str = "right_arm_2"
    sensor_ids: tuple[tuple[str, int], ...] | None = None
    robot: str = "robonaut2-right"
    retarget: Literal["segments", "map"] = "segments"
    fusion: Literal["node", "host"] = "node"
    filter_name: str = "miller"
    rate_hz: float = 100.0
    use_mag: bool = True
    still_start_s: float = 0.8
    stale_after_s: float = 0.1
    max_sensor_rate_rad_s: float = math.radians(2000.0)
    pose: str = "npose"
    heading_axis: str | None = "x"
    heading_rad: float = 0.0
    heading_refine: bool = True

    def __post_init__(self) -> None:
        if self.retarget not in ("segments", "map"):
            raise ConfigError(f"retarget: expected 'segments' or 'map', got {self.retarget!r}")
        if self.fusion not in ("node", "host"):
            raise ConfigError(f"fusion: expected 'node' or 'host', got {self.fusion!r}")
        for name in ("rate_hz", "stale_after_s"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a positive number, got {getattr(self, name)}")


@dataclass(slots=True)
class Frame:
    """What one processed batch did (kept for evaluation and recording).

    Attributes:
        t: session time (``time.monotonic()``) [s].
        t_sensor: the newest contributing sample's sensor time [s].
        state: the session state after the tick.
        command: the pose sent (4, 4) or None.
        T_model: the intermediate model's end effector (4, 4) or None.
        q_robot: the retargeted robot joints (n,) [rad] or None.
        angles: the human joint angles (K,) [rad] or None.
        latency_ns: arrival of the oldest contributing sample -> command sent, or None.
        notes: limit notes and faults.
        q_sensor, t_sample: with ``keep_frames``: (S, 4) each sensor's latest orientation
            and (S,) its sample's sensor time [s] (tree order), else None.
        q_segment: with ``keep_frames``: (S, 4) the body model's ``q_world_segment``.
    """

    t: float
    t_sensor: float
    state: State
    command: FloatArray | None
    T_model: FloatArray | None
    q_robot: FloatArray | None
    angles: FloatArray | None
    latency_ns: int | None
    notes: list[str] = field(default_factory=list)
    q_sensor: FloatArray | None = None
    t_sample: FloatArray | None = None
    q_segment: FloatArray | None = None


@dataclass
class _Calibration:
    t0: float
    t1: float
    times: list[list[float]]
    quats: list[list[FloatArray]]
    done: Callable[[BodyCalibration | None, str | None], None] | None = None


class TeleopPipeline:
    """See the module docstring.

    Args:
        config: :class:`PipelineConfig`.
        session: the session state machine.
        link: the robot link (None: compute only, e.g. a benchmark of the host side).
    """

    def __init__(
        self, config: PipelineConfig, session: TeleopSession, link: RobotLink | None = None
    ) -> None:
        self.config = c = config
        self.session = session
        self.link = link
        self.tree = tree = SensorTree.preset(c.preset)
        names = tree.sensor_names
        ids = (
            dict(c.sensor_ids)
            if c.sensor_ids is not None
            else {n: i + 1 for i, n in enumerate(names)}
        )
        unknown = sorted(set(ids) - set(names))
        missing = [n for n in names if n not in ids]
        if unknown or missing:
            raise ConfigError(
                f"sensor_ids: tree {tree.name!r} has sensors {', '.join(names)}; "
                f"unknown {unknown or 'none'}, without an ID {missing or 'none'}"
            )
        self.sensor_ids = ids
        self._slot_of_id = {ids[n]: i for i, n in enumerate(names)}
        self._label = [f"sensor {n} (id {ids[n]})" for n in names]
        n_s = len(names)
        self.q_sensor = np.full((n_s, 4), np.nan)
        """(S, 4) latest valid ``q_world_sensor`` per sensor (tree order)."""
        self.t_valid = np.full(n_s, -np.inf)
        self.t_sample = np.full(n_s, np.nan)
        """(S,) sensor time of each sensor's latest valid sample [s]."""
        self.bad: dict[int, str] = {}
        self._clock_note: dict[int, str] = {}  # slot -> its clock stood still or went back
        self.sensor_jumps = 0  # samples held as a jump faster than any limb
        make_filter(c.filter_name, c.rate_hz)  # fail early on a bad name
        self.fusion: FilterBank | None = (
            FilterBank(c.filter_name, c.rate_hz, n_s, c.still_start_s, c.use_mag, self._label)
            if c.fusion == "host"
            else None
        )
        self.humanoid: LiveRetargeter | None = None
        self.arm: ArmModel | None = None
        if c.robot in available_robots():
            self.arm = robot_arm(c.robot)
            rs = setup_retarget(tree, self.arm, c.robot, c.retarget, c.pose)
            self.retargeter = rs.retargeter
            self.compiled_map = rs.compiled_map
            self._rt_segments, self._rt_index = rs.segments, rs.index
            self._chest_index, self._map_extra = rs.chest_index, rs.map_extra
        else:  # a humanoid (packaged name or YAML): whole-body joints, one QP per frame
            if not isinstance(session, HumanoidSession):
                raise ConfigError(
                    f"robot {c.robot!r} is a humanoid (joint commands): its session must be "
                    "a HumanoidSession (LiveSession picks it by the robot's name)"
                )
            from mocapkit.retarget.live import LiveRetargeter

            self.humanoid = LiveRetargeter(c.robot, rate_hz=c.rate_hz)
            r = self.humanoid.robot
            session.v_max = r.v_max[r.iv]
            self.retargeter = None
            self.compiled_map = None
            self._rt_segments, self._rt_index = (), np.zeros(0, dtype=np.int64)
            self._chest_index, self._map_extra = 0, []
        self._target: JointsTarget | None = None
        self.body: BodyStream | None = None
        self.calibration: BodyCalibration | None = None
        self._calib: _Calibration | None = None
        self._calib_data: tuple[dict[str, OrientationSeries], tuple[float, float]] | None = None
        self._hinge: HingeHeading | None = None
        self.heading_correction_rad: float | None = None
        self._R_world_chest = np.eye(3)
        self._R_seg = np.empty((len(self._rt_segments), 3, 3))
        self._angles_ext = np.zeros(len(tree.coordinate_names) + len(self._map_extra))
        self.q_robot: FloatArray | None = None
        self.angles: FloatArray | None = None
        self.T_model: FloatArray | None = None
        self.clipped: tuple[str, ...] = ()
        self.latencies_ns = np.zeros(_LATENCY_CAPACITY, dtype=np.int64)
        self.n_latencies = 0
        self.frames: list[Frame] = []
        self.keep_frames = False
        self.on_frame: Callable[[Frame], None] | None = None
        self.last_fault: str | None = "not calibrated"
        self._t_sensor = math.nan
        _warm_up()
        if self.retargeter is not None:  # compile/load its kernel now
            self.retargeter.solve(np.tile(np.eye(3), (len(self._rt_segments), 1, 1)))
            self.retargeter.reset()
        if self.fusion is not None and not self.fusion.batched:  # compile the filter's kernel
            make_filter(c.filter_name, c.rate_hz).update([0.0, 0.0, 0.0], [0.0, 0.0, 9.81])

    # -- calibration ------------------------------------------------------------------------
    def start_calibration(
        self,
        now: float,
        duration_s: float,
        done: Callable[[BodyCalibration | None, str | None], None] | None = None,
    ) -> None:
        """Collect ``duration_s`` of orientations from ``now`` (the operator holds the pose),
        then calibrate the body model; ``done(calibration, error)`` is called at the end.
        The session holds meanwhile (no model pose)."""
        n = len(self.tree.sensor_names)
        self._calib = _Calibration(
            now, now + duration_s, [[] for _ in range(n)], [[] for _ in range(n)], done
        )
        log.info("calibration: hold the %s pose for %.1f s", self.config.pose, duration_s)

    @property
    def calibrating(self) -> bool:
        return self._calib is not None

    def _finish_calibration(self) -> None:
        cal = self._calib
        assert cal is not None
        self._calib = None
        series = {}
        error = None
        calib = None
        try:
            for i, name in enumerate(self.tree.sensor_names):
                t = np.array(cal.times[i])
                if len(t) < 2:
                    raise MocapkitError(
                        f"calibration: {self._label[i]} sent {len(t)} samples in "
                        f"{cal.t1 - cal.t0:.1f} s; is it on and streaming?"
                    )
                keep = np.concatenate([[True], np.diff(t) > 0])
                series[name] = OrientationSeries(t[keep], np.array(cal.quats[i])[keep], name=name)
            c = self.config
            root_sensor = self.tree.segments[0].sensor
            heading: HeadingFixed | HeadingFromSensor = (
                HeadingFixed(c.heading_rad)
                if c.heading_axis is None
                else HeadingFromSensor(root_sensor, c.heading_axis)
            )
            calib = calibrate_pose(
                self.tree, series, (cal.t0, cal.t1), pose=c.pose, heading=heading
            )
        except MocapkitError as exc:
            error = str(exc)
            log.warning("calibration failed: %s", error)
        if calib is not None:
            self.set_calibration(calib)
            self._calib_data = (series, (cal.t0, cal.t1))
            c = self.config
            segs = self.tree.segment_names
            if c.heading_refine and c.heading_axis is not None:
                for sfx in ("_r", "_l"):
                    if f"humerus{sfx}" in segs and f"radius{sfx}" in segs:
                        self._hinge = HingeHeading(self.tree, f"humerus{sfx}", f"radius{sfx}")
                        break
        if cal.done is not None:
            cal.done(calib, error)

    def _refine_heading(self, correction: float, now: float) -> None:
        """Recalibrate from the same pose window with the corrected heading; reindex."""
        assert self.calibration is not None
        assert self._calib_data is not None
        series, window = self._calib_data
        psi = self.calibration.heading_rad + correction
        try:
            calib = calibrate_pose(
                self.tree, series, window, pose=self.config.pose, heading=HeadingFixed(psi)
            )
        except MocapkitError as exc:  # the same data calibrated before: not expected
            log.warning("heading refinement failed: %s", exc)
            return
        self.heading_correction_rad = correction
        log.info("heading refined from the elbow flexion by %.1f deg", math.degrees(correction))
        self.set_calibration(calib)
        self.session.reindex(now)

    def set_calibration(self, calib: BodyCalibration) -> None:
        """Use a body calibration (from :meth:`start_calibration`, or a saved one)."""
        self._hinge = None
        self.calibration = calib
        self.body = BodyStream(self.tree, calib, dropout="hold", max_hold_s=0.5)
        self.body.update_array(np.tile([1.0, 0.0, 0.0, 0.0], (len(self.tree.segments), 1)), 0.0)
        self.body.reset()  # (that frame compiled or loaded the kernel)
        self._R_world_chest = quat_to_matrix(calib.q_world_ground) @ CHEST_IN_SEGMENT
        if self.retargeter is not None:
            self.retargeter.reset()
        log.info("calibrated: heading %.1f deg", math.degrees(calib.heading_rad))

    # -- per batch ------------------------------------------------------------------------------
    def _fuse(self, samples: Sequence[Any]) -> dict[int, Any]:
        """Host-side fusion of the batch's RAW samples, all sensors in one bank call:
        sample index -> ``q_world_sensor`` (4,), or the reason it failed (str)."""
        assert self.fusion is not None
        idx, slots, gyr, acc, mag = [], [], [], [], []
        use_mag = self.config.use_mag
        for i, s in enumerate(samples):
            if s.kind is not Kind.RAW or s.gyr is None or s.acc is None:
                continue
            slot = self._slot_of_id.get(s.sensor_id)
            if slot is None:
                continue
            idx.append(i)
            slots.append(slot)
            gyr.append(s.gyr)
            acc.append(s.acc)
            mag.append(s.mag if use_mag and s.mag is not None else _NO_MAG)
        if not idx:
            return {}
        m = np.array(mag) if use_mag else None
        q, errors = self.fusion.update(slots, np.array(gyr), np.array(acc), m)
        out: dict[int, Any] = {i: q[k] for k, i in enumerate(idx)}
        for k, why in errors.items():
            out[idx[k]] = why
        return out

    def ingest(self, samples: Sequence[Any], now: float) -> int | None:
        """Take a batch's samples in; returns the oldest contributing arrival [ns] or None."""
        oldest: int | None = None
        cal = self._calib
        fused = self._fuse(samples) if self.fusion is not None else None
        for i, s in enumerate(samples):
            slot = self._slot_of_id.get(s.sensor_id)
            if slot is None:
                continue
            if s.kind is Kind.RAW:
                q = None if fused is None else fused.get(i)
                if isinstance(q, str):
                    self.bad[slot] = f"{self._label[slot]}: host fusion failed ({q})"
                    continue
            else:
                q = s.quat
            if q is None:
                continue
            previous = self.t_sample[slot]
            if previous == previous and not s.t_sensor_s > previous:  # NaN: no sample yet
                if s.t_sensor_s < previous - CLOCK_RESET_S:
                    # ran far backwards (a reset): hold now (the session reindexes before
                    # it follows again) and follow the new clock from here
                    self.t_sample[slot] = s.t_sensor_s
                    self.bad[slot] = (
                        f"{self._label[slot]}: sensor clock ran backwards ({previous:.3f} -> "
                        f"{s.t_sensor_s:.3f} s)"
                    )
                else:  # a late or repeated sample: not fresh; if the clock stays stuck,
                    # the watchdog holds after stale_after_s and says so
                    self._clock_note[slot] = (
                        f"{self._label[slot]}: sensor clock stands still or runs backwards "
                        f"(at {s.t_sensor_s:.3f} s after {previous:.3f} s)"
                    )
                continue
            self._clock_note.pop(slot, None)
            w, x, y, z = float(q[0]), float(q[1]), float(q[2]), float(q[3])
            n2 = w * w + x * x + y * y + z * z
            if not (abs(n2 - 1.0) < 0.01):  # also False for NaN; the wire gives 1 +- 1e-4
                self.bad[slot] = (
                    f"{self._label[slot]}: invalid orientation [{w:.3g}, {x:.3g}, {y:.3g}, {z:.3g}]"
                )
                continue
            if slot in self.bad:
                del self.bad[slot]
            qs = self.q_sensor[slot]
            if previous == previous:  # a glitch: faster than any limb since the last sample
                dot = abs(w * qs[0] + x * qs[1] + y * qs[2] + z * qs[3]) / math.sqrt(n2)
                turn = 2.0 * math.acos(min(1.0, dot))
                step = max(s.t_sensor_s - previous, 1e-3)
                if turn > self.config.max_sensor_rate_rad_s * step:
                    self.bad[slot] = (
                        f"{self._label[slot]}: turned {math.degrees(turn):.0f} deg in "
                        f"{step * 1e3:.0f} ms (over "
                        f"{math.degrees(self.config.max_sensor_rate_rad_s):.0f} deg/s): a "
                        "glitch? held; re-engages after reindexing"
                    )
                    self.sensor_jumps += 1
            qs[0], qs[1], qs[2], qs[3] = w, x, y, z
            self.t_valid[slot] = now
            self.t_sample[slot] = s.t_sensor_s
            if not s.t_sensor_s <= self._t_sensor:
                self._t_sensor = s.t_sensor_s
            if oldest is None or s.t_arrival_ns < oldest:
                oldest = s.t_arrival_ns
            if cal is not None and cal.t0 <= now:
                cal.times[slot].append(now)
                cal.quats[slot].append(qs.copy())
        if cal is not None and now >= cal.t1:
            self._finish_calibration()
        return oldest

    def sensor_fault(self, now: float) -> str | None:
        """Why the sensor data cannot be used now, or None."""
        if self.bad:
            return next(iter(self.bad.values()))
        stale = now - self.t_valid
        worst = int(np.argmax(stale))
        if stale[worst] > self.config.stale_after_s:
            if not np.isfinite(stale[worst]):
                return f"{self._label[worst]}: no data yet"
            if worst in self._clock_note:
                return f"{self._clock_note[worst]}: no fresh sample for {stale[worst]:.2f} s"
            return f"{self._label[worst]}: no data for {stale[worst]:.2f} s (dropout?)"
        return None

    def model_pose(self, now: float) -> tuple[FloatArray | None, str | None]:
        """The intermediate model's ``T_chest_ee`` from the latest orientations, or a fault."""
        if self.body is None:
            return None, "calibrating" if self._calib is not None else "not calibrated"
        fault = self.sensor_fault(now)
        if fault is not None:
            return None, fault
        body = self.body
        angles = body.update_array(self.q_sensor, now)
        self.angles = angles
        if self._hinge is not None:
            correction = self._hinge.update(body.q_world_segment)
            if correction is not None:
                self._refine_heading(correction, now)
        if self.humanoid is not None:
            return None, self._humanoid_target(angles, now)
        assert self.arm is not None
        if self.retargeter is not None:
            R_seg = self._R_seg
            ok = _kernels.segments_in_chest(
                body.q_world_segment, self._rt_index, self._chest_index,
                self._R_world_chest, CHEST_IN_SEGMENT, R_seg,
            )  # fmt: skip
            if not ok:
                return None, "body model: a segment's orientation is unknown"
            q = self.retargeter.solve(R_seg)
            clipped = self.retargeter.clipped
        else:
            assert self.compiled_map is not None
            ext = self._angles_ext
            ext[: len(angles)] = angles
            if not np.isfinite(angles).all():
                return None, f"body model: {', '.join(body.invalid_coordinates())} unknown"
            q, clipped = self.compiled_map.apply(ext)
        self.q_robot = q
        self.clipped = (
            tuple(self.arm.joint_names[i] for i in np.flatnonzero(clipped)) if clipped.any() else ()
        )
        T = self.arm.fk(q)
        self.T_model = T
        return T, None

    @property
    def robot_joint_names(self) -> tuple[str, ...]:
        """The robot's joints as ``q_robot`` lists them."""
        if self.humanoid is not None:
            return self.humanoid.robot.iq_names
        assert self.arm is not None
        return tuple(self.arm.joint_names)

    def _humanoid_target(self, angles: FloatArray, now: float) -> str | None:
        """The humanoid's joints for the body's joint angles (``self._target``), or the
        reason there are none."""
        assert self.humanoid is not None
        assert self.body is not None
        if not np.isfinite(angles).all():
            self._target = None
            return f"body model: {', '.join(self.body.invalid_coordinates())} unknown"
        # the suit's tree may be part of a body (an arm): the rest stands in the neutral pose
        coords = dict.fromkeys(NEUTRAL_ROOT, 0.0)
        coords.update(zip(self.tree.coordinate_names, angles.tolist(), strict=True))
        try:
            q = self.humanoid.update(coords, now)
        except MocapkitError as exc:  # a fault to hold on, never a dead receiver thread
            self._target = None
            return f"retargeting: {exc}"
        if not np.isfinite(q).all():
            self._target = None
            return "retargeting: a joint came out non-finite"
        r = self.humanoid.robot
        joints = q[r.iq]
        self.q_robot = joints
        if r.spec.floating_base:
            pos, quat = q[:3].copy(), np.array([q[6], q[3], q[4], q[5]])
        else:
            pos, quat = np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
        self._target = JointsTarget(pos, quat, joints.copy())
        return None

    def _tick_humanoid(self, now: float, model: bool) -> TickOutput:
        link = self.link
        robot_q = gate = reason = None
        age = math.inf
        if link is not None and link.latest is not None:
            robot_q, gate, reason = link.latest.q, link.latest.gate, link.latest.reason
            age = link.report_age(now)
        if model:
            _, fault = self.model_pose(now)
        elif self.body is None:
            fault = "calibrating" if self._calib is not None else "not calibrated"
        else:
            fault = self.sensor_fault(now)
        self.last_fault = fault
        target = self._target if fault is None else None
        assert isinstance(self.session, HumanoidSession)
        return self.session.tick_joints(now, target, robot_q, age, fault, gate, reason)

    def _tick(self, now: float, model: bool) -> TickOutput:
        """Run the session with the model pose (``model``) or without (a watchdog tick)."""
        if self.humanoid is not None:
            return self._tick_humanoid(now, model)
        link = self.link
        robot_pose = gate = reason = None
        age = math.inf
        if link is not None:
            robot_pose = link.robot_pose()
            age = link.report_age(now)
            if link.latest is not None:
                gate, reason = link.latest.gate, link.latest.reason
        T: FloatArray | None = None
        fault: str | None
        if model:
            T, fault = self.model_pose(now)
        elif self.body is None:
            fault = "calibrating" if self._calib is not None else "not calibrated"
        else:
            fault = self.sensor_fault(now)
            T = self.T_model if fault is None else None
        self.last_fault = fault
        return self.session.tick(now, T, robot_pose, age, fault, gate, reason)

    def process(
        self, samples: Sequence[Any], now_ns: int | None = None, now: float | None = None
    ) -> Frame | None:
        """One drained batch (possibly empty: a watchdog tick); see the module docstring.
        ``now`` is the session clock [s] (default ``time.monotonic()``; tests set it)."""
        now = time.monotonic() if now is None else now
        if self.link is not None:
            self.link.poll()  # reports (and keep the socket drained) on every tick
            self.link.keepalive()  # a restarted server learns where to report
        oldest = self.ingest(samples, now) if samples else None
        if oldest is None:
            # no new data: only the watchdogs, so a dropout holds the robot at once
            session = self.session
            if not session.hold_pending:
                if session.state in (State.DISABLED, State.HELD):
                    return None
                if self.body is not None and self.sensor_fault(now) is None:
                    return None
            out = self._tick(now, model=False)
            out.command = out.joints = None  # nothing new: never resend
        else:
            out = self._tick(now, model=True)
        latency = None
        sent = out.command is not None or out.joints is not None
        if self.link is not None:
            if out.command is not None:
                self.link.send_command(out.command)
            elif out.joints is not None:
                self.link.send_joints(*out.joints)
            elif out.hold:
                self.link.send_hold()
        if oldest is not None and sent:
            latency = time.perf_counter_ns() - oldest
            self.latencies_ns[self.n_latencies % _LATENCY_CAPACITY] = latency
            self.n_latencies += 1
        if oldest is not None and self.clipped:
            out.notes.append(f"joint limit: {', '.join(self.clipped)} clipped")
        if oldest is None and not sent and not out.hold and not out.notes:
            return None
        frame = Frame(
            now,
            self._t_sensor,
            out.state,
            out.command,
            None if oldest is None else self.T_model,
            None if (oldest is None or self.q_robot is None) else self.q_robot.copy(),
            None if (oldest is None or self.angles is None) else self.angles.copy(),
            latency,
            out.notes,
        )
        if self.keep_frames:
            frame.q_sensor = self.q_sensor.copy()
            frame.t_sample = self.t_sample.copy()
            if self.body is not None:
                frame.q_segment = self.body.q_world_segment.copy()
            self.frames.append(frame)
        if self.on_frame is not None:
            self.on_frame(frame)
        return frame

    def latency_ms(self) -> FloatArray:
        """Recorded pipeline times [ms] (the last 131072 commands at most)."""
        n = min(self.n_latencies, _LATENCY_CAPACITY)
        return self.latencies_ns[:n] / 1e6


_WARM = False


def _warm_up() -> None:
    """Compile (or load from cache) every numba kernel of the per-packet path now, not on
    the first packet after engaging (a first compile takes seconds)."""
    global _WARM
    if _WARM:
        return

    T = np.eye(4)
    out = np.empty((4, 4))
    _kernels.apply_offset(T, np.eye(3), np.zeros(3), out)
    _kernels.pose_error(T, out)
    _kernels.limit_command(out, T, -np.ones(3), np.ones(3), 0.1, 0.1, True)
    _kernels.mat_to_quat(T, np.empty(4))
    q = np.array([[1.0, 0.0, 0.0, 0.0]])
    _kernels.segments_in_chest(
        q, np.zeros(1, np.int64), 0, np.eye(3), np.eye(3), np.empty((1, 3, 3))
    )
    _kernels.relative_rotvec(q[0], q[0], q[0], np.empty(4), np.empty(3))
    _kernels.pose_from_parts(np.zeros(3), q[0], np.empty((4, 4)))
    _WARM = True
