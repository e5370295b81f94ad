"""The per-packet pipeline, driven sample by sample with a controlled clock (no sockets):
truth in -> truth out, heading refinement, faults, joint limits, calibration errors,
host-side fusion."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mocapkit.body.calibration import q_world_ground
from mocapkit.body.joint_angles import compose_pose
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_exp, quat_from_axis_angle, quat_mul
from mocapkit.suit.protocol import Kind
from mocapkit.suit.samples import SuitSample
from mocapkit.teleop.evaluate import truth_model
from mocapkit.teleop.operator import operator_motion
from mocapkit.teleop.pipeline import PipelineConfig, TeleopPipeline
from mocapkit.teleop.session import State, TeleopSession

TREE = SensorTree.preset("right_arm_2")
NPOSE = {"pro_sup_r": np.pi / 2}


def _samples(q: np.ndarray, t: float, ids=(1, 2)) -> list[SuitSample]:
    return [SuitSample(i, 0, t, 0, Kind.ORIENTATION, q[k]) for k, i in enumerate(ids)]


def _calibrated(config: PipelineConfig | None = None, heading: float = 0.4):
    """A pipeline calibrated in the N-pose (sensors mounted as the segments), at t = 0-1."""
    pipe = TeleopPipeline(config or PipelineConfig(), TeleopSession(), None)
    q = quat_mul(q_world_ground(heading), compose_pose(TREE, NPOSE))
    errors = []
    pipe.start_calibration(0.0, 0.5, lambda c, e: errors.append(e))
    for k in range(60):
        pipe.ingest(_samples(q, k * 0.01), k * 0.01)
    assert errors == [None]
    return pipe, q


def test_truth_in_truth_out_and_the_heading_is_refined_from_the_elbow():
    """Sensors mounted 5 deg off (so the heading from the upper arm's x axis is wrong):
    after the first elbow flexion the heading is corrected, and from then on the pipeline
    reproduces the truth model exactly."""
    motion = operator_motion("circle", TREE, shape_s=2.0, heading_rad=1.1)
    rng = np.random.default_rng(3)
    mount = quat_exp(0.5 * np.radians(5.0) * rng.normal(size=(2, 3)))
    cfg = PipelineConfig()
    pipe = TeleopPipeline(cfg, TeleopSession(), None)
    _q_truth, T_truth, _angles_truth = truth_model(motion, cfg)
    w0, w1 = motion.calib_window
    T = np.full((len(motion.time), 4, 4), np.nan)
    for k, t in enumerate(motion.time):
        if abs(t - w0) < 1e-9:
            pipe.start_calibration(float(t), w1 - w0)
        pipe.ingest(_samples(quat_mul(motion.q_world_segment[k], mount), float(t)), float(t))
        Tk, _ = pipe.model_pose(float(t))
        if Tk is not None:
            T[k] = Tk
    assert pipe.calibration is not None
    assert pipe.heading_correction_rad is not None
    # exact sensors: the elbow axis gives the heading to rounding (1e-6 rad)
    assert pipe.calibration.heading_rad == pytest.approx(motion.heading_rad, abs=1e-6)
    sel = motion.time >= motion.engage_t
    np.testing.assert_allclose(T[sel], T_truth[sel], atol=1e-6)  # [m] and rotation entries
    assert pipe.session.transitions == []  # the reindex request waits for engage()


def test_dropout_nan_and_recovery_with_reasons():
    pipe, q = _calibrated(PipelineConfig(stale_after_s=0.1))
    session = pipe.session
    robot = pipe.arm.fk(pipe.arm.q_ref)
    pipe.link = _FakeLink(robot)
    session.engage(1.0)
    f = pipe.process(_samples(q, 1.0), now=1.0)
    assert f is not None
    assert session.state == State.ENGAGED
    np.testing.assert_allclose(f.command, robot, atol=1e-9)  # reindexed: no jump
    # sensor 2 drops out: the next idle tick after 0.1 s holds and says which
    pipe.process(_samples(q[:1], 1.05, ids=(1,)), now=1.05)
    f = pipe.process([], now=1.16)
    assert session.state == State.HELD
    assert f is not None
    assert f.notes == ["sensor forearm_r (id 2): no data for 0.16 s (dropout?)"]
    assert pipe.link.holds == 1
    # it comes back: aligning -> engaged again, no jump
    f = pipe.process(_samples(q, 1.2), now=1.2)
    assert session.state == State.ENGAGED
    np.testing.assert_allclose(f.command, robot, atol=1e-9)
    # a NaN orientation
    bad = q.copy()
    bad[0] = np.nan
    pipe.process(_samples(bad, 1.3), now=1.3)
    assert session.state == State.HELD
    assert session.transitions[-1].reason == (
        "sensor upper_arm_r (id 1): invalid orientation [nan, nan, nan, nan]"
    )
    pipe.process(_samples(q, 1.4), now=1.4)
    assert session.state == State.ENGAGED
    assert [tr.target for tr in session.transitions].count(State.HELD) == 2


def test_joint_limits_are_clipped_reported_and_recover():
    pipe, q = _calibrated()
    session = pipe.session
    pipe.link = _FakeLink(pipe.arm.fk(pipe.arm.q_ref))
    session.engage(1.0)
    pipe.process(_samples(q, 1.0), now=1.0)
    # the forearm hyperextended 30 deg about the elbow (R2's joint3 stops at 0)
    elbow = quat_from_axis_angle(TREE.segment("radius_r").joint.axes[0], np.radians(-30.0))
    over = q.copy()
    over[1] = quat_mul(q[1], elbow)
    f = pipe.process(_samples(over, 1.1), now=1.1)
    assert f is not None
    assert "joint limit: r2/right_arm/joint3 clipped" in f.notes
    assert pipe.arm.within_limits(f.q_robot).all()
    assert f.command is not None  # degraded (clipped), still commanding
    f = pipe.process(_samples(q, 1.2), now=1.2)
    assert not any("joint limit" in n for n in f.notes)


def test_calibration_failures_say_why():
    pipe = TeleopPipeline(PipelineConfig(), TeleopSession(), None)
    q = quat_mul(q_world_ground(0.0), compose_pose(TREE, NPOSE))
    errors: list[str | None] = []
    pipe.start_calibration(0.0, 0.5, lambda c, e: errors.append(e))
    for k in range(60):  # only sensor 1 streams
        pipe.ingest(_samples(q[:1], k * 0.01, ids=(1,)), k * 0.01)
    assert errors == [
        "calibration: sensor forearm_r (id 2) sent 0 samples in 0.5 s; is it on and streaming?"
    ]
    errors.clear()
    pipe.start_calibration(1.0, 0.5, lambda c, e: errors.append(e))
    for k in range(60):  # the forearm turns during the pose
        turn = quat_from_axis_angle([0.0, 0.0, 1.0], 0.01 * k)
        moving = np.stack([q[0], quat_mul(turn, q[1])])
        pipe.ingest(_samples(moving, 1.0 + k * 0.01), 1.0 + k * 0.01)
    assert errors[0] is not None
    assert "sensor 'forearm_r' moved during the calibration pose" in errors[0]
    assert pipe.body is None
    f = pipe.process(_samples(q, 2.0), now=2.0)
    assert pipe.last_fault == "not calibrated"
    assert f is not None
    assert f.command is None


def test_map_retargeting_and_config_errors():
    pipe, _q = _calibrated(PipelineConfig(retarget="map"))
    T, fault = pipe.model_pose(0.55)
    assert fault is None
    assert T is not None
    # in the N-pose the map gives R2's initialisation posture (the wrist, unmeasured: 0)
    from mocapkit.robot.segment_retarget import robonaut2_init_posture

    np.testing.assert_allclose(pipe.q_robot, robonaut2_init_posture("right"), atol=1e-6)
    with pytest.raises(ConfigError, match="retarget 'segments'"):
        TeleopPipeline(PipelineConfig(robot="talos-right"), TeleopSession(), None)
    with pytest.raises(ConfigError, match="sensor_ids: tree 'right_arm_2' has sensors"):
        TeleopPipeline(
            PipelineConfig(sensor_ids=(("upper_arm_r", 1), ("hand", 2))), TeleopSession(), None
        )
    with pytest.raises(ConfigError, match="fusion: expected 'node' or 'host'"):
        replace(PipelineConfig(), fusion="cloud")  # type: ignore[arg-type]


def test_host_fusion_turns_raw_samples_into_orientations():
    """RAW samples of a sensor at rest: the still start, then a level orientation."""
    pipe = TeleopPipeline(PipelineConfig(fusion="host", still_start_s=0.2), TeleopSession(), None)
    acc = np.array([0.0, 0.0, 9.81])
    mag = np.array([0.0, 20.0, -40.0])
    for k in range(40):
        s = [SuitSample(i, k, k * 0.01, 0, Kind.RAW, None, np.zeros(3), acc, mag) for i in (1, 2)]
        assert pipe.ingest(s, k * 0.01) == 0  # every sample contributed (arrival 0 ns)
    bank = pipe.fusion
    assert bank is not None
    assert bank.batched  # miller: both sensors advanced in one numba call per batch
    assert bank.in_bank.all()  # the still start is done: the state moved into the bank
    np.testing.assert_array_equal(bank.bias, 0.0)  # a bias-free gyroscope at rest
    np.testing.assert_allclose(pipe.q_sensor[0], [1.0, 0.0, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(pipe.t_sample, 0.39)  # the samples' own sensor times
    # a non-finite gyroscope sample: the sensor is faulted with the reason, not fused
    bad = [SuitSample(1, 40, 0.4, 0, Kind.RAW, None, np.full(3, np.nan), acc, mag)]
    pipe.ingest(bad, 0.4)
    assert pipe.sensor_fault(0.4) == (
        "sensor upper_arm_r (id 1): host fusion failed (gyr: non-finite value)"
    )
    good = [SuitSample(1, 41, 0.41, 0, Kind.RAW, None, np.zeros(3), acc, mag)]
    pipe.ingest(good, 0.41)
    assert pipe.sensor_fault(0.41) is None  # recovers with the next good sample


class _FakeLink:
    """The robot link's interface without a socket: a robot standing at ``pose``."""

    def __init__(self, pose: np.ndarray) -> None:
        self.pose = pose
        self.latest = None
        self.commands: list[np.ndarray] = []
        self.holds = 0

    def poll(self) -> int:
        return 0

    def robot_pose(self) -> np.ndarray:
        return self.pose

    def report_age(self, now: float) -> float:
        return 0.0

    def keepalive(self, now: float | None = None) -> bool:
        return False

    def send_command(self, T: np.ndarray) -> int:
        self.commands.append(T)
        return len(self.commands)

    def send_hold(self) -> None:
        self.holds += 1
