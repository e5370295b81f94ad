"""The simulated operator and suit: exact truth, shapes that loop, the frames on the wire,
dropouts, the magnetometer calibration, and input errors."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.body.joint_angles import joint_angles_reference
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_angle_between
from mocapkit.series import OrientationSeries
from mocapkit.suit.protocol import Kind, decode
from mocapkit.teleop.operator import SHAPES, operator_motion, shape_path
from mocapkit.teleop.operator_suit import Dropout, SuitSetup, sensor_recording, suit_timeline
from mocapkit.teleop.run import parse_commands

TREE = SensorTree.preset("right_arm_2")


def _short(shape: str = "box"):
    return operator_motion(
        shape, TREE, calib_s=1.0, reach_s=0.5, settle_s=0.3, shape_s=1.0, hold_s=0.2
    )


@pytest.mark.parametrize("shape", SHAPES)
def test_every_shape_starts_and_ends_at_its_centre(shape):
    s = np.linspace(0.0, 1.0, 201)
    p = shape_path(shape, s, 0.1)
    np.testing.assert_allclose(p[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(p[-1], 0.0, atol=1e-12)
    # [m] 10 cm shapes: the circle hangs from its start at the top (20 cm diameter)
    assert 0.05 < np.abs(p).max() <= 0.2 + 1e-12
    np.testing.assert_array_equal(p[:, 0], 0.0)  # in the frontal plane


def test_the_truth_is_the_body_models_own():
    """The segment orientations decompose (body.joint_angles) into the truth coordinates,
    and the hand traces the shape around the working point."""
    m = _short("circle")
    segs = {
        s.name: OrientationSeries(m.time, m.q_world_segment[:, i], name=s.name)
        for i, s in enumerate(TREE.segments)
    }
    from mocapkit.body.calibration import q_world_ground

    res = joint_angles_reference(TREE, segs, q_world_ground(m.heading_rad))
    np.testing.assert_allclose(res.angles.values, m.coordinates.values, atol=1e-9)
    sel = (m.time >= m.shape_start) & (m.time <= m.shape_end)
    centre = m.hand[round(m.shape_start * 100)]
    d = m.hand[sel] - centre
    # the IK is position-exact (1e-7 m) and the circle has a 10 cm radius: 20 cm tall
    assert np.ptp(d[:, 2]) == pytest.approx(0.2, abs=1e-5)
    np.testing.assert_allclose(m.hand[-1], centre, atol=1e-6)  # loops
    still = m.time <= m.calib_window[1]
    assert np.ptp(m.coordinates.values[still], axis=0).max() == 0.0  # a still N-pose


def test_operator_errors_name_the_fix():
    with pytest.raises(ConfigError, match="shape: expected one of vertical"):
        shape_path("spiral", np.zeros(3))
    with pytest.raises(ConfigError, match="has no segment 'humerus_r'; use a right-arm"):
        operator_motion("box", SensorTree.preset("lower_body"))


def test_frames_on_the_wire_ideal_chain_and_a_dropout():
    m = _short()
    ids = {"upper_arm_r": 1, "forearm_r": 2}
    setup = SuitSetup(chain="ideal")
    items, poses = suit_timeline(
        m, setup, ids, np.random.default_rng(0), (Dropout("forearm_r", 1.2, 1.4),)
    )
    assert len(items) == len(m.time)  # one bundle per hub round
    for t, data in items:
        pkt = decode(data)
        assert pkt.kind is Kind.BUNDLE
        sids = [sid for sid, _ in pkt.entries]
        assert sids == ([1] if 1.2 <= t < 1.4 else [1, 2])
        k = round(t * 100)
        for sid, q in pkt.entries:
            name = "upper_arm_r" if sid == 1 else "forearm_r"
            # smallest-three with 15 bits per component: 1e-4 rad
            assert float(quat_angle_between(q, poses[name].quat[k])) < 1e-4
    with pytest.raises(ConfigError, match="dropout: unknown sensor 'hand'"):
        suit_timeline(m, setup, ids, np.random.default_rng(0), (Dropout("hand", 0, 1),))
    with pytest.raises(ConfigError, match="sensor_ids: no suit ID for forearm_r"):
        suit_timeline(m, setup, {"upper_arm_r": 1}, np.random.default_rng(0))
    with pytest.raises(ConfigError, match="chain: expected 'real' or 'ideal'"):
        SuitSetup(chain="perfect")  # type: ignore[arg-type]


def test_real_chain_nodes_send_filtered_orientations_and_host_mode_raw():
    m = _short()
    ids = {"upper_arm_r": 1, "forearm_r": 2}
    items, poses = suit_timeline(m, SuitSetup(), ids, np.random.default_rng(1))
    last = decode(items[-1][1])
    for sid, q in last.entries:  # on-node miller with consumer-grade errors, calibrated mag
        name = "upper_arm_r" if sid == 1 else "forearm_r"
        assert np.degrees(float(quat_angle_between(q, poses[name].quat[-1]))) < 5.0
    raw, _ = suit_timeline(m, SuitSetup(fusion="host"), ids, np.random.default_rng(1))
    kinds = {decode(d).kind for _, d in raw}
    assert kinds == {Kind.RAW}
    assert len(raw) == 2 * len(m.time)


def test_the_magnetometer_dance_calibrates_hard_and_soft_iron():
    m = _short()
    rng = np.random.default_rng(2)
    from mocapkit.teleop.operator_suit import sensor_poses

    pose = sensor_poses(m, rng)["forearm_r"]
    calibrated = sensor_recording(pose, SuitSetup(), np.random.default_rng(3))
    raw = sensor_recording(pose, SuitSetup(mag_calibration=False), np.random.default_rng(3))
    assert calibrated.mag is not None
    assert raw.mag is not None
    # the field's norm is constant once calibrated (noise 0.3 uT); 1 uT offsets and 1 %
    # scale errors make it vary with the orientation
    assert np.std(np.linalg.norm(calibrated.mag, axis=1)) < 0.5
    assert np.std(np.linalg.norm(raw.mag, axis=1)) > np.std(np.linalg.norm(calibrated.mag, axis=1))
    six = sensor_recording(pose, SuitSetup(use_mag=False), np.random.default_rng(3))
    assert six.mag is None


def test_scheduled_commands_parse_or_say_how():
    assert parse_commands("3.5:engage, 1:calibrate") == ((1.0, "calibrate"), (3.5, "engage"))
    assert parse_commands("") == ()
    with pytest.raises(ConfigError, match="expected 'seconds:command' items"):
        parse_commands("soon:engage")


def test_server_start_posture_option():
    import argparse

    from mocapkit.teleop.server import config_args, config_from_args

    p = argparse.ArgumentParser()
    config_args(p)
    cfg = config_from_args(p.parse_args(["--q-start-deg", "10,-80,90,-60,-90,0,0"]))
    assert cfg.q_start is not None
    assert cfg.q_start[0] == pytest.approx(np.radians(10.0))
    with pytest.raises(ConfigError, match="--q-start-deg: expected comma-separated degrees"):
        config_from_args(p.parse_args(["--q-start-deg", "ten"]))


def test_the_cycle_chains_shapes_without_a_jump_and_loops():
    """Shapes one after the other, each back to the N-pose: the coordinates never jump,
    not even from the cycle's last frame to its first (it repeats)."""
    from mocapkit.teleop.operator import npose_coordinates
    from mocapkit.teleop.operator_cycle import operator_cycle

    tree = SensorTree.preset("right_arm_torso_3")
    c = operator_cycle(("vertical", "circle"), tree, shape_s=1.0, return_s=1.0)
    m = c.motion
    values = m.coordinates.values
    assert [s.shape for s in c.spans] == ["vertical", "circle"]
    assert c.period_s == pytest.approx(len(m.time) / 100.0)
    # 10 ms steps: the fastest coordinate (the elbow in the reach) moves < 2 deg per step;
    # a jump between shapes or at the seam would be tens of degrees
    steps = np.abs(np.diff(np.vstack([values, values[:1]]), axis=0))
    assert np.degrees(steps.max()) < 2.0
    np.testing.assert_allclose(values[0], npose_coordinates(tree), atol=1e-12)
    np.testing.assert_allclose(values[-1], npose_coordinates(tree), atol=1e-12)
    for s in c.spans:  # the calibration windows are still, the shapes are not
        w = (m.time >= s.calib_window[0]) & (m.time <= s.calib_window[1])
        assert np.ptp(values[w], axis=0).max() == 0.0
        sh = (m.time >= s.t_start) & (m.time <= s.t_end)
        assert np.ptp(m.hand[sh], axis=0).max() > 0.05  # [m] a 10 cm shape
        assert s.calib_window[1] < s.engage_t < s.t_start < s.t_end
    assert c.span_at(c.spans[1].t_start + 0.1 + c.period_s) == c.spans[1]  # any cycle
    assert c.span_at(0.0) is None  # in the N-pose
    with pytest.raises(ConfigError, match="shapes: expected some of vertical"):
        operator_cycle(("spiral",))
    with pytest.raises(ConfigError, match="rate_hz, shape_s and return_s: expected positive"):
        operator_cycle(("box",), return_s=0.0)
