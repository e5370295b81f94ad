"""The robot link to a ROS 2 robot over Zenoh (rmw_zenoh's format): a fake ros2_control
robot in the test (a Zenoh peer that publishes /joint_states and takes
Float64MultiArray commands) and the live chain driving G1 through it."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

pytest.importorskip("zenoh", reason="ROS 2 over Zenoh needs eclipse-zenoh ('mocapkit[ros]')")
pytest.importorskip("rosbags")

from mocapkit.errors import ConfigError
from mocapkit.io.ros2_zenoh import Ros2ZenohPublisher
from mocapkit.teleop import protocol as proto
from mocapkit.teleop.ros2_link import Ros2RobotLink
from tests.io.test_ros2_zenoh import listening_peer
from tests.teleop.test_live import _wait

pytestmark = pytest.mark.realtime

JOINTS = ["hip", "knee", "ankle"]


class FakeRobot:
    """A ROS 2 robot as rmw_zenoh shows it: listens on a Zenoh endpoint, publishes its
    joint states (in its own joint order), keeps the commands it receives; it moves its
    joints towards the last command at ``speed`` [rad/s]."""

    def __init__(self, names: list[str], q0: np.ndarray, speed: float = 2.0) -> None:
        self.session, self.endpoint = listening_peer()  # the ROS machine's router role
        self.names = list(names)
        self.q = np.asarray(q0, dtype=float).copy()
        self.speed = speed
        self.commands: list[np.ndarray] = []
        self.order = list(names)  # the controller's joints
        self.node = Ros2ZenohPublisher(connect=[self.endpoint], domain_id=0)
        self.node.subscribe("/forward_position_controller/commands",
                            "std_msgs/msg/Float64MultiArray", self._on_command)  # fmt: skip
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def _on_command(self, msg) -> None:  # type: ignore[no-untyped-def]
        if msg is not None:
            self.commands.append(np.asarray(msg.data, dtype=float))

    def _loop(self) -> None:
        while not self._stop.is_set():
            if self.commands:
                target = np.empty_like(self.q)
                for i, n in enumerate(self.order):
                    target[self.names.index(n)] = self.commands[-1][i]
                step = np.clip(target - self.q, -self.speed * 0.02, self.speed * 0.02)
                self.q = self.q + step
            self.node.joint_state("/joint_states", self.names, self.q)
            time.sleep(0.02)

    def __enter__(self) -> FakeRobot:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.node.close()
        self.session.close()


def test_reports_in_the_models_order_and_targets_in_the_controllers() -> None:
    # the robot names its joints in another order than the model
    with FakeRobot(["knee", "ankle", "hip"], np.array([0.5, -0.2, 0.1])) as robot:
        robot.order = ["ankle", "hip", "knee"]
        with Ros2RobotLink(JOINTS, [robot.endpoint], domain_id=0,
                           controller_joints=robot.order) as link:  # fmt: skip
            assert _wait(lambda: link.poll() > 0, 5.0)
            rep = link.latest
            assert rep is not None
            assert rep.gate == proto.Gate.SYNCED
            np.testing.assert_allclose(rep.q, [0.1, 0.5, -0.2])  # hip, knee, ankle
            link.send_joints(np.zeros(3), np.array([1.0, 0, 0, 0]), [0.3, 0.6, -0.1])
            assert _wait(lambda: bool(robot.commands), 5.0)
            np.testing.assert_allclose(robot.commands[-1], [-0.1, 0.3, 0.6])  # ankle, hip, knee
            link.send_hold()  # nothing sent: the controller keeps its last target
            time.sleep(0.2)
            assert len(robot.commands) == 1
            assert link.report_age() < 1.0


def test_bad_joint_states_are_counted_not_reports() -> None:
    with (
        FakeRobot(["hip", "knee"], np.zeros(2)) as robot,  # no 'ankle'
        Ros2RobotLink(JOINTS, [robot.endpoint], domain_id=0) as link,
    ):
        assert _wait(lambda: link.malformed > 0, 5.0)
        assert link.poll() == 0
        assert link.latest is None
        # garbage on the state topic's key: counted, nothing breaks
        key = "0/joint_states/sensor_msgs::msg::dds_::JointState_/RIHS01_garbage"
        robot.session.put(key, b"\x00\x01garbage")
        n = link.malformed
        assert _wait(lambda: link.malformed > n, 5.0)


def test_controller_joints_must_be_the_models() -> None:
    with pytest.raises(ConfigError, match="controller joints elbow are not joints"):
        Ros2RobotLink(JOINTS, ["tcp/127.0.0.1:1"], controller_joints=["hip", "elbow"])
    link = Ros2RobotLink(JOINTS, ["tcp/127.0.0.1:1"])
    with link, pytest.raises(ConfigError, match="takes joint targets; give it a pose topic"):
        link.send_command(np.eye(4))


def _vertical_stroke():  # type: ignore[no-untyped-def]
    """The operator's vertical shape (the paper's two arm sensors, IDs 1 and 2) and the
    simulated suit's datagrams for it."""
    from mocapkit.body.sensor_tree import SensorTree
    from mocapkit.teleop.operator import operator_motion
    from mocapkit.teleop.operator_suit import SuitSetup, suit_timeline

    motion = operator_motion(
        "vertical", SensorTree.preset("right_arm_2"), calib_s=2.0, reach_s=1.2,
        settle_s=0.6, shape_s=5.0, hold_s=0.5, heading_rad=0.7,
    )  # fmt: skip
    items, _ = suit_timeline(motion, SuitSetup(), {"upper_arm_r": 1, "forearm_r": 2},
                             np.random.default_rng(0))  # fmt: skip
    return motion, items


def test_g1_follows_the_operator_through_a_ros2_robot(tmp_path) -> None:
    """The live chain (simulated suit process, body model, retargeting, HumanoidSession)
    with the ROS 2 link: the session aligns from the robot's /joint_states (all zeros)
    and then follows; while engaged the robot's right shoulder moves with the operator's
    arm, its left arm does not."""
    pytest.importorskip("pinocchio")
    from mocapkit.teleop.live import LiveConfig, LiveSession
    from mocapkit.teleop.pipeline import PipelineConfig
    from mocapkit.teleop.sender import TimelineSender
    from tests.teleop.test_live import _sleep_until

    motion, items = _vertical_stroke()
    robots: list[FakeRobot] = []

    def make_link(pipeline) -> Ros2RobotLink:  # type: ignore[no-untyped-def]
        joints = pipeline.robot_joint_names
        robot = FakeRobot(list(joints), np.zeros(len(joints)), speed=3.0).__enter__()
        robots.append(robot)
        return Ros2RobotLink(joints, [robot.endpoint], domain_id=0)

    cfg = LiveConfig(pipeline=PipelineConfig(robot="g1"))
    live = LiveSession(cfg, None, make_link=make_link)
    try:
        with live, TimelineSender(items, "127.0.0.1", live.suit_port) as sender:
            assert _wait(lambda: live.link.latest is not None, 20.0)
            names = live.pipeline.robot_joint_names
            t_go = sender.go()
            _sleep_until(t_go + motion.calib_window[0])
            assert live.calibrate(motion.calib_window[1] - motion.calib_window[0]) is not None
            _sleep_until(t_go + motion.engage_t)
            live.engage()
            assert _wait(lambda: live.snapshot()["state"] == "engaged", 8.0)
            robot = robots[0]
            q_engaged = robot.q.copy()  # aligned from zeros onto the operator's posture
            time.sleep(1.5)  # the shape goes on (5 s): alignment from zeros took ~2 s
            assert len(robot.commands) > 20
            moved = np.abs(robot.q - q_engaged)
            right = max(moved[i] for i, n in enumerate(names) if n.startswith("right_shoulder"))
            left = max(moved[i] for i, n in enumerate(names) if n.startswith("left_"))
            assert right > 0.1  # the vertical shape, 1.5 s of it
            assert left < 0.05
            live.disengage()
            sender.wait(20.0)
    finally:
        for r in robots:
            r.__exit__()


def test_an_arm_gets_end_effector_poses_for_its_own_ik() -> None:
    """The paper's Robonaut route: end-effector targets (PoseStamped in the arm's base
    frame) to the robot's IK, its current end-effector pose back as the reports."""
    router, endpoint = listening_peer()
    targets: list = []
    with router, Ros2ZenohPublisher(connect=[endpoint], domain_id=0) as arm:
        arm.subscribe("/target_pose", "geometry_msgs/msg/PoseStamped", targets.append)
        ends = [endpoint]
        frame = "r2/right_base"
        link = Ros2RobotLink((), ends, domain_id=0, pose_topic="/target_pose", frame_id=frame)
        with link:
            assert link.robot_pose() is None
            for _ in range(50):  # the arm reports where its hand is
                arm.pose_stamped("/current_pose", "r2/right_base", [0.4, -0.2, 0.1],
                                 [np.cos(0.25), 0.0, 0.0, np.sin(0.25)])  # fmt: skip
                if link.poll():
                    break
                time.sleep(0.02)
            T = link.robot_pose()
            assert T is not None
            np.testing.assert_allclose(T[:3, 3], [0.4, -0.2, 0.1])
            c, si = np.cos(0.5), np.sin(0.5)
            np.testing.assert_allclose(T[:2, :2], [[c, -si], [si, c]], atol=1e-12)
            assert link.latest.q.shape == (0,)
            goal = np.eye(4)
            goal[:3, 3] = [0.5, -0.1, 0.2]
            link.send_command(goal)
            assert _wait(lambda: any(m is not None for m in targets), 5.0)
            msg = next(m for m in targets if m is not None)
            assert msg.header.frame_id == "r2/right_base"
            p = msg.pose.position
            assert (p.x, p.y, p.z) == (0.5, -0.1, 0.2)
            assert msg.pose.orientation.w == 1.0


class FakeArm:
    """An arm with its own IK as rmw_zenoh shows it (the paper's Robonaut route): takes
    ``PoseStamped`` targets on /target_pose, reports where its hand is on /current_pose,
    the hand moving towards the last target at ``speed`` [m/s] (orientation at once)."""

    def __init__(self, frame: str, pos0: list[float], speed: float = 1.0) -> None:
        self.session, self.endpoint = listening_peer()
        self.frame = frame
        self.pos = np.asarray(pos0, dtype=float)
        self.quat = np.array([1.0, 0.0, 0.0, 0.0])
        self.speed = speed
        self.targets: list = []
        self.path: list[np.ndarray] = []
        self.node = Ros2ZenohPublisher(connect=[self.endpoint], domain_id=0)
        self.node.subscribe("/target_pose", "geometry_msgs/msg/PoseStamped", self._on_target)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def _on_target(self, msg) -> None:  # type: ignore[no-untyped-def]
        if msg is not None:
            self.targets.append(msg)

    def _loop(self) -> None:
        while not self._stop.is_set():
            if self.targets:
                m = self.targets[-1].pose
                goal = np.array([m.position.x, m.position.y, m.position.z])
                step = goal - self.pos
                n = float(np.linalg.norm(step))
                self.pos = self.pos + (
                    step if n <= self.speed * 0.02 else step * self.speed * 0.02 / n
                )
                o = m.orientation
                self.quat = np.array([o.w, o.x, o.y, o.z])
            self.path.append(self.pos.copy())
            self.node.pose_stamped("/current_pose", self.frame, self.pos, self.quat)
            time.sleep(0.02)

    def __enter__(self) -> FakeArm:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.node.close()
        self.session.close()


def test_the_arm_follows_the_operator_through_its_own_ik() -> None:
    """The paper's chain over ROS 2: simulated suit process, body model, Robonaut 2's
    right arm in the session, end-effector poses to an arm that does its own IK; while
    engaged the arm's hand traces the operator's vertical shape from where it was (up and
    down by more than 10 cm), every target in the arm's base frame."""
    pytest.importorskip("pinocchio")
    from mocapkit.teleop.live import LiveConfig, LiveSession
    from mocapkit.teleop.pipeline import PipelineConfig
    from mocapkit.teleop.sender import TimelineSender
    from tests.teleop.test_live import _sleep_until

    motion, items = _vertical_stroke()
    frame = "r2/right_base"
    arms: list[FakeArm] = []

    def make_link(pipeline) -> Ros2RobotLink:  # type: ignore[no-untyped-def]
        arm = FakeArm(frame, [0.3, -0.3, -0.2]).__enter__()
        arms.append(arm)
        return Ros2RobotLink((), [arm.endpoint], domain_id=0, pose_topic="/target_pose",
                             frame_id=frame)  # fmt: skip

    cfg = LiveConfig(pipeline=PipelineConfig(robot="robonaut2-right"))
    live = LiveSession(cfg, None, make_link=make_link)
    try:
        with live, TimelineSender(items, "127.0.0.1", live.suit_port) as sender:
            assert _wait(lambda: live.link.robot_pose() is not None, 20.0)
            t_go = sender.go()
            _sleep_until(t_go + motion.calib_window[0])
            assert live.calibrate(motion.calib_window[1] - motion.calib_window[0]) is not None
            _sleep_until(t_go + motion.engage_t)
            live.engage()
            assert _wait(lambda: live.snapshot()["state"] == "engaged", 8.0)
            arm = arms[0]
            n0 = len(arm.path)
            time.sleep(3.0)  # the vertical shape goes on (5 s)
            assert len(arm.targets) > 50
            assert all(m.header.frame_id == frame for m in arm.targets)
            z = np.array(arm.path[n0:])[:, 2]
            # relative control: the hand starts where it was, goes up with the operator's
            # hand and comes down again (the shape's vertical stroke, ~0.17 m)
            assert abs(z[0] - (-0.2)) < 0.01
            top = int(np.argmax(z))
            assert z[top] - z[0] > 0.10
            assert z[top] - z[top:].min() > 0.10
            live.disengage()
            sender.wait(20.0)
    finally:
        for a in arms:
            a.__exit__()
