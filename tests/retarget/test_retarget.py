"""Whole-body retargeting (``mocapkit.retarget``) on short synthetic motions with exact
answers: the robot YAML checks, standing still, limits, contacts, heading, collisions."""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("proxsuite", reason="the robots extra (pip install 'mocapkit[robots]')")
pytest.importorskip("pinocchio", reason="the robots extra")

from mocapkit.body.sensor_tree import SensorTree
from mocapkit.body.simulate import gait_coordinates
from mocapkit.errors import ConfigError
from mocapkit.retarget.human import from_coordinates
from mocapkit.retarget.metrics import evaluate
from mocapkit.retarget.robot_model import build_humanoid
from mocapkit.retarget.robot_spec import load_robot_spec, packaged_robots
from mocapkit.retarget.solver import solve
from mocapkit.retarget.targets import RetargetWarning, make_targets

SEGMENTS = ("pelvis", "thorax", "head", "upper_arm_r", "forearm_r", "hand_r", "upper_arm_l",
            "forearm_l", "hand_l", "thigh_r", "shank_r", "foot_r", "thigh_l", "shank_l",
            "foot_l")  # fmt: skip


@pytest.fixture(scope="module")
def g1():
    return build_humanoid(load_robot_spec("g1"))


def _walk(duration_s=6.0, speed=1.2, heading_deg=0.0, start=(0.0, 0.0)):
    tree = SensorTree.preset("full_body_15")
    t, coords, walk = gait_coordinates(tree, duration_s=duration_s, still_s=1.0)
    moving = np.clip(t - walk, 0.0, None)
    h = np.radians(heading_deg)
    # OpenSim ground: x forward, y up, z right; walking along the heading
    coords = dict(coords)
    coords["pelvis_tx"] = start[0] + speed * moving * np.cos(h)
    coords["pelvis_tz"] = -(start[1] + speed * moving * np.sin(h))
    coords["pelvis_ty"] = np.zeros_like(t)
    coords["pelvis_rotation"] = coords["pelvis_rotation"] + h
    return from_coordinates(t, coords, SEGMENTS)


def _standing(n=50):
    tree = SensorTree.preset("full_body_15")
    t = np.arange(n) / 100.0
    coords = {c: np.zeros(n) for c in tree.coordinate_names}
    return from_coordinates(t, coords, SEGMENTS)


def test_packaged_robots_load():
    assert {"g1", "talos", "romeo", "icub"} <= set(packaged_robots())
    for name in ("g1", "talos", "romeo", "icub"):
        robot = build_humanoid(load_robot_spec(name))
        assert robot.model.nq > 7
        assert np.all(robot.q_ref[robot.iq] >= robot.q_min[robot.iq])
        assert np.all(robot.q_ref[robot.iq] <= robot.q_max[robot.iq])


def _yaml(tmp_path: Path, edit) -> Path:
    src = packaged_robots()["g1"].read_text()
    p = tmp_path / "robot.yaml"
    p.write_text(edit(src))
    return p


def test_wrong_frame_is_named(tmp_path):
    p = _yaml(tmp_path, lambda s: s.replace("frame: right_wrist_yaw_link", "frame: right_palm"))
    with pytest.raises(ConfigError, match="no frame 'right_palm'.*right_wrist_yaw_link"):
        build_humanoid(load_robot_spec(p))


def test_undriven_limb_end_is_refused(tmp_path):
    def drop_hand(s):
        return "\n".join(line for line in s.splitlines() if not line.strip().startswith("hand_r:"))

    with pytest.raises(ConfigError, match="right arm.*hand_r"):
        load_robot_spec(_yaml(tmp_path, drop_hand))


def test_unknown_human_segment_is_refused(tmp_path):
    p = _yaml(tmp_path, lambda s: s.replace("  thorax: {", "  chest: {"))
    with pytest.raises(ConfigError, match="keypoints.chest: not a human segment"):
        load_robot_spec(p)


def test_standing_human_gives_the_reference_posture(g1):
    targets = make_targets(_standing(), g1)
    sol = solve(g1, targets)
    figures = evaluate(g1, targets, sol)
    assert figures["keypoint_rmse_mm"]["mean"] < 2.0
    assert figures["limit_violations"] == {"position": 0, "velocity": 0}
    np.testing.assert_allclose(sol.q[-1][g1.iq], g1.q_ref[g1.iq], atol=0.02)


def test_walk_respects_limits_keeps_feet_still_and_above_ground(g1):
    motion = _walk()
    targets = make_targets(motion, g1)
    assert not targets.belt.any()  # overground: no treadmill
    assert all(c.sum() > 50 for c in targets.contact.values())
    sol = solve(g1, targets)
    f = evaluate(g1, targets, sol)
    assert f["limit_violations"] == {"position": 0, "velocity": 0}
    assert f["ground_penetration"]["frames"] == 0
    assert f["foot_skate_mm"] < 2.0
    assert f["held_frames"] == 0
    assert np.isfinite(sol.q).all()
    # the robot walked forward too (pelvis), at the leg-length ratio of the human's speed
    travel = sol.q[-1, 0] - sol.q[0, 0]
    assert 0.5 * 1.2 * 5.0 * targets.scale["pelvis"] < travel


def test_any_starting_heading_and_position_gives_the_same_robot_motion(g1):
    a = solve(g1, make_targets(_walk(heading_deg=0.0), g1))
    b = solve(g1, make_targets(_walk(heading_deg=135.0, start=(3.0, -2.0)), g1))
    diff = np.abs(a.q[:, g1.iq] - b.q[:, g1.iq])
    assert diff.mean() < 5e-3  # the QP's tolerance moves a few joints by up to ~2 deg
    assert diff.max() < 0.05


def test_treadmill_is_detected_and_warned(g1):
    """Feet that glide back at 1 m/s on the ground and swing forward in the air while the
    body stays: a treadmill."""
    from mocapkit.retarget.human import HumanMotion

    still = _standing(n=400)
    t = still.time
    pos = dict(still.pos)
    for foot, phase in (("foot_r", 0.0), ("foot_l", 0.5)):
        cyc = ((t / 1.0) + phase) % 1.0  # 1 s stride: 0.6 s stance, 0.4 s swing
        x = np.where(cyc < 0.6, 0.3 - 1.0 * cyc, -0.3 + 1.5 * (cyc - 0.6))
        z = np.where(cyc < 0.6, 0.0, 0.1 * np.sin(np.pi * (cyc - 0.6) / 0.4))
        pos[foot] = still.pos[foot] + np.column_stack([x, np.zeros_like(t), z])
    tread = HumanMotion(t, pos, still.quat, still.neutral_pos, still.neutral_quat, "test")
    with pytest.warns(RetargetWarning, match="treadmill"):
        targets = make_targets(tread, g1)
    assert targets.belt[0] == pytest.approx(-1.0, abs=0.05)
    assert targets.belt[1] == pytest.approx(0.0, abs=0.05)


def test_self_collision_is_counted(g1):
    from mocapkit.retarget.collisions import SelfCollision

    sc = SelfCollision(g1)
    assert sc.available
    assert sc.colliding(g1.q_ref) == []
    q = g1.q_ref.copy()
    jid = g1.model.getJointId("left_shoulder_roll_joint")
    q[g1.model.joints[jid].idx_q] = g1.q_min[g1.model.joints[jid].idx_q]  # arm into the body
    jid = g1.model.getJointId("left_elbow_joint")
    q[g1.model.joints[jid].idx_q] = 0.0
    hits = sc.colliding(q)
    assert hits, "the left arm pressed into the torso must collide"
    assert any("left" in a or "left" in b for a, b in hits)


def _hand_in_torso(g1, n=120):
    targets = make_targets(_standing(n=n), g1)
    inside = targets.pos["thorax"][0] if "thorax" in targets.pos else targets.pos["pelvis"][0]
    targets.pos["hand_l"][:] = inside + np.array([0.05, 0.0, 0.15])
    return targets


def test_guard_keeps_a_hand_out_of_the_torso(g1):
    """A hand target inside the torso: without the guard the arm is in the torso in every
    frame; with it in none (checked on the meshes), the limits held, the hand as near
    its target as the torso allows."""
    from mocapkit.retarget.collisions import SelfCollision

    targets = _hand_in_torso(g1)
    sc = SelfCollision(g1)
    plain = evaluate(g1, targets, solve(g1, targets), sc)
    sol = solve(g1, targets, guard=sc)
    guarded = evaluate(g1, targets, sol, sc)
    assert plain["collisions"]["frames"] == 120
    assert guarded["collisions"]["frames"] == 0
    assert all(sc.colliding(q) == [] for q in sol.q)
    assert guarded["limit_violations"] == {"position": 0, "velocity": 0}
    assert sol.kept_apart or sol.stopped  # the guard acted, and says so
    gap = np.linalg.norm(sol.keypoint_pos["hand_l"] - targets.pos["hand_l"], axis=1)
    assert float(np.median(gap)) < 0.25  # pressed against the torso, not thrown away


def test_hull_rows_keep_a_hand_out_of_the_torso(g1):
    """The avoidance rows alone (convex hulls, soft): in at most 10 % of the frames the
    meshes still touch (linearised rows; the guard removes the rest)."""
    from mocapkit.retarget.collisions import HullAvoidance, SelfCollision

    targets = _hand_in_torso(g1)
    sc = SelfCollision(g1)
    avoided = evaluate(g1, targets, solve(g1, targets, HullAvoidance(sc)), sc)
    assert avoided["collisions"]["frames"] <= 12
    assert avoided["limit_violations"] == {"position": 0, "velocity": 0}


def test_hull_distance_never_exceeds_the_mesh_distance(g1):
    """The rows rely on a hull containing its mesh: on random postures the hulls' distance
    is never larger than the meshes' (within coal's tolerance)."""
    import pinocchio as pin

    from mocapkit.retarget.collisions import SelfCollision

    sc = SelfCollision(g1)
    rng = np.random.default_rng(3)
    hd = sc.hm.createData()
    checked = 0
    for _ in range(15):
        q = g1.q_ref.copy()
        q[g1.iq] = np.clip(q[g1.iq] + rng.normal(0, 0.3, g1.iq.size), g1.q_min[g1.iq],
                           g1.q_max[g1.iq])  # fmt: skip
        pin.forwardKinematics(g1.model, sc.data, q)
        cand = sc._candidates(0.03)[:4]
        pin.updateGeometryPlacements(g1.model, sc.data, sc.hm, hd)
        for k in cand:
            d_hull = pin.computeDistance(sc.hm, hd, int(k)).min_distance
            d_mesh = pin.computeDistance(sc.gm, sc.gd, int(k)).min_distance
            assert d_hull <= d_mesh + 1e-4
            checked += 1
    assert checked > 10


def test_cli_retarget_writes_a_trajectory_and_reports(tmp_path):
    from mocapkit.io.joint_angles_mot import read_joint_angles_mot
    from tests.body.synth import write_walk_mot

    mot = write_walk_mot(tmp_path / "walk.mot", duration_s=3.0, still_s=1.0)
    t = read_joint_angles_mot(mot).time
    out = tmp_path / "g1.csv"
    p = subprocess.run(
        [sys.executable, "-m", "mocapkit", "retarget", str(mot), "--robot", "g1", "-o", str(out),
         "--json"],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert p.returncode == 0, p.stderr
    report = json.loads(p.stdout)
    for key in ("robot", "frames", "fps", "keypoint_rmse_mm", "foot_skate_mm",
                "limit_violations", "collisions"):  # fmt: skip
        assert key in report
    assert report["frames"] == t.size
    header = out.read_text().splitlines()[0].split(",")
    assert header[:8] == ["time", "base_x", "base_y", "base_z", "base_qw", "base_qx", "base_qy",
                          "base_qz"]  # fmt: skip
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert data.shape == (t.size, 1 + 7 + 29)
    assert np.isfinite(data).all()
    p = subprocess.run([sys.executable, "-m", "mocapkit", "robot", "list", "--json"],
                       capture_output=True, text=True, check=True)  # fmt: skip
    assert json.loads(p.stdout)["g1"]["available"]


def test_cli_refuses_an_unknown_output_format(tmp_path):
    p = subprocess.run(
        [sys.executable, "-m", "mocapkit", "retarget", "x.mot", "--robot", "g1", "-o",
         str(tmp_path / "x.bvh")],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert p.returncode == 1
    assert ".csv" in p.stderr


def test_warnings_as_errors_do_not_leak():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_robot_spec("talos")


def test_fixed_base_robonaut2_from_the_shared_urdf(shared_data, monkeypatch):
    """Robonaut 2's upper body on its fixed waist (URDF from ../shared, not shipped): the
    human is seen from its pelvis; standing gives the reference posture, a walk keeps the
    limits."""
    monkeypatch.setenv("MOCAPKIT_SHARED_DATA", str(shared_data))
    r2 = build_humanoid(load_robot_spec("robonaut2"))
    assert not r2.spec.floating_base
    still = make_targets(_standing(), r2)
    sol = solve(r2, still)
    assert evaluate(r2, still, sol)["keypoint_rmse_mm"]["mean"] < 2.0
    walk = make_targets(_walk(), r2)
    f = evaluate(r2, walk, solve(r2, walk))
    assert f["limit_violations"] == {"position": 0, "velocity": 0}
    assert f["keypoint_rmse_mm"]["mean"] < 80.0


def test_fixed_base_needs_its_root_frame(tmp_path):
    p = tmp_path / "r.yaml"
    p.write_text(
        "name: x\nurdf: example-robot-data:robots/g1_description/urdf/g1_29dof_rev_1_0.urdf\n"
        "floating_base: false\nkeypoints:\n  hand_r: {frame: right_wrist_yaw_link}\n"
        "  forearm_r: {frame: right_elbow_link}\n"
    )
    with pytest.raises(ConfigError, match="root_frame"):
        load_robot_spec(p)


def test_mcap_output_reads_back_with_the_mcap_library(tmp_path):
    """The .mcap output, read by the mcap package: joint positions equal the solution, and
    the frame tree composed from world down to a link gives that link's pose."""
    import pinocchio as pin

    from mocapkit.geometry import quat_to_matrix
    from mocapkit.io.foxglove_mcap import read_foxglove_mcap
    from mocapkit.io.joint_angles_mot import write_joint_angles_mot
    from mocapkit.retarget.run import retarget, write_trajectory
    from mocapkit.series import JointAngleSeries

    tree = SensorTree.preset("full_body_15")
    t, coords, _ = gait_coordinates(tree, duration_s=2.0, still_s=0.5)
    coords = dict(coords)
    coords.update(pelvis_tx=np.clip(t - 0.5, 0, None), pelvis_ty=np.full_like(t, 0.93),
                  pelvis_tz=np.zeros_like(t))  # fmt: skip
    names = tuple(coords)
    mot = write_joint_angles_mot(
        tmp_path / "w.mot", JointAngleSeries(t, names, np.column_stack([coords[n] for n in names]))
    )
    res = retarget(mot, "g1", check_collisions=False)
    out = write_trajectory(tmp_path / "g1.mcap", res)
    msgs = read_foxglove_mcap(out)
    joints = msgs["/robot/joints"]
    assert len(joints) == t.size
    k = 10
    np.testing.assert_allclose(joints[k][2]["position"], res.solution.q[k, 7:], atol=1e-9)
    tf = {m["child_frame_id"]: m for m in msgs["/robot/tf"][k][2]["transforms"]}
    link = "right_elbow_joint"
    chain = []
    while link in tf:
        chain.append(tf[link])
        link = tf[link]["parent_frame_id"]
    assert link == "world"
    pose = pin.SE3.Identity()
    for m in reversed(chain):
        r, p = m["rotation"], m["translation"]
        rot = quat_to_matrix(np.array([r["w"], r["x"], r["y"], r["z"]]))
        pose = pose * pin.SE3(rot, np.array([p["x"], p["y"], p["z"]]))
    model = res.robot.model
    data = model.createData()
    pin.forwardKinematics(model, data, res.solution.q[k])
    expected = data.oMi[model.getJointId("right_elbow_joint")]
    np.testing.assert_allclose(pose.translation, expected.translation, atol=1e-6)
    assert joints[0][0] > 1_600_000_000 * 10**9  # wall-clock timestamps, not 1970


def test_bvh_input_gives_the_segments_it_was_written_from(tmp_path):
    """A BVH written by mocapkit from known segment orientations reads back (through the
    y-up -> z-up turn and the BVH's own rest pose) with the same relative rotations, and
    retargets like the joint angles it came from."""
    from mocapkit.body.calibration import q_world_ground
    from mocapkit.body.simulate import segment_poses
    from mocapkit.body.skeleton import bvh_from_segments
    from mocapkit.geometry import quat_angle, quat_conj, quat_mul
    from mocapkit.io.bvh import write_bvh
    from mocapkit.retarget.human import TREE_TO_HUMAN, from_bvh
    from mocapkit.series import OrientationSeries

    tree = SensorTree.preset("full_body_15")
    t, coords, _ = gait_coordinates(tree, duration_s=2.0, still_s=0.5)
    poses = segment_poses(tree, t, coords, speed=0.0)
    segs = {k: OrientationSeries(t, p.quat) for k, p in poses.items()}
    bvh = write_bvh(tmp_path / "walk.bvh", bvh_from_segments(tree, segs, q_world_ground(0.0)))
    motion, notes = from_bvh(bvh, SEGMENTS)
    assert any("cm" in n for n in notes)
    for tree_seg, human_seg in TREE_TO_HUMAN.items():
        # the knee's rotation relative to the thigh is what the BVH must keep
        if human_seg != "shank_r":
            continue
        parent = "femur_r"
        rel_src = quat_mul(quat_conj(poses[parent].quat), poses[tree_seg].quat)
        rel_bvh = quat_mul(quat_conj(motion.quat["thigh_r"]), motion.quat["shank_r"])
        rel0_src = quat_mul(quat_conj(rel_src[0]), rel_src)
        rel0_bvh = quat_mul(quat_conj(rel_bvh[0]), rel_bvh)
        assert np.degrees(quat_angle(quat_mul(quat_conj(rel0_src), rel0_bvh))).max() < 0.01
    g1 = build_humanoid(load_robot_spec("g1"))
    sol = solve(g1, make_targets(motion, g1))
    f = evaluate(g1, make_targets(motion, g1), sol)
    assert f["limit_violations"] == {"position": 0, "velocity": 0}
    assert f["keypoint_rmse_mm"]["mean"] < 40.0


def test_live_retargeting_frame_by_frame_keeps_the_limits():
    """The live path (one frame of joint angles in, one configuration out) on a walk:
    every configuration finite, within the position limits, steps within the velocity
    limits; the heading alignment of the first frame is kept."""
    import pinocchio as pin

    from mocapkit.retarget.live import LiveRetargeter

    tree = SensorTree.preset("full_body_15")
    t, coords, _ = gait_coordinates(tree, duration_s=3.0, still_s=0.5)
    live = LiveRetargeter("g1")
    qs = np.array([live.update({c: v[k] for c, v in coords.items()}, float(t[k]))
                   for k in range(t.size)])  # fmt: skip
    robot = live.robot
    assert np.isfinite(qs).all()
    iq, iv = robot.iq, robot.iv
    assert (qs[:, iq] >= robot.q_min[iq] - 1e-9).all()
    assert (qs[:, iq] <= robot.q_max[iq] + 1e-9).all()
    v = np.array([pin.difference(robot.model, a, b) for a, b in itertools.pairwise(qs)])
    assert (np.abs(v[1:, iv]) / np.diff(t)[1:, None] <= robot.v_max[iv] * 1.001).all()
    start = live.start
    live.update({c: v[0] for c, v in coords.items()}, float(t[-1] + 0.01))
    assert live.start is start
