"""Streaming and batch body kinematics: fast == reference, frame by frame == batch, split
runs, dropouts and bad frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.body.calibration import (
    HeadingFixed,
    HeadingFromSensor,
    calibrate_pose,
    pose_coordinates,
)
from mocapkit.body.kinematics import BodyStream, body_angles
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.errors import ConfigError, ShapeError
from mocapkit.io.opensense import read_orientations_sto
from mocapkit.series import OrientationSeries
from tests.body.synth import gait_like, random_mountings, sensor_orientations

# fast (numba, scalar) and reference (numpy) paths do the same arithmetic in another
# order: they agree to rounding, 1e-9 rad is the project's equivalence bound
AGREE = 1e-9


@pytest.fixture(scope="module")
def synthetic() -> tuple:
    tree = SensorTree.preset("full_body_15")
    t = np.arange(400) / 100.0
    coords = gait_like(tree, t, 1.0, pose_coordinates(tree, "npose"), seed=7)
    coords["arm_rot_r"] = coords["arm_rot_r"] + 2.8 * np.maximum(t - 1.0, 0.0)  # wraps twice
    mounts = random_mountings(tree, np.random.default_rng(7))
    ori = sensor_orientations(tree, t, coords, mounts, heading_rad=-0.4)
    cal = calibrate_pose(tree, ori, (0.0, 0.9), heading=HeadingFixed(-0.4))
    return tree, t, coords, ori, cal


def test_fast_equals_reference_and_truth(synthetic: tuple) -> None:
    tree, _t, coords, ori, cal = synthetic
    fast, seg_f = body_angles(tree, cal, ori, backend="fast")
    ref, seg_r = body_angles(tree, cal, ori, backend="reference")
    np.testing.assert_allclose(fast.angles.values, ref.angles.values, atol=AGREE)
    for name in tree.segment_names:
        np.testing.assert_allclose(seg_f[name].quat, seg_r[name].quat, atol=AGREE)
    for c in tree.coordinate_names:
        np.testing.assert_allclose(fast.angles.column(c), coords[c], atol=AGREE, err_msg=c)


def test_stream_frame_by_frame_equals_batch(synthetic: tuple) -> None:
    tree, t, _coords, ori, cal = synthetic
    batch, _ = body_angles(tree, cal, ori)
    stream = BodyStream(tree, cal)
    out = np.empty_like(batch.angles.values)
    for n in range(len(t)):
        frame = {s: ori[s].quat[n] for s in tree.sensor_names}
        out[n] = stream.update(frame, t[n])
    np.testing.assert_allclose(out, batch.angles.values, atol=AGREE)
    assert stream.q_world_segment.shape == (15, 4)
    assert not stream.stale.any()
    assert stream.invalid_coordinates() == []


def test_split_run_equals_single_run(synthetic: tuple) -> None:
    tree, t, _coords, ori, cal = synthetic
    q = np.stack([ori[s].quat for s in tree.sensor_names], axis=1)
    whole = BodyStream(tree, cal).run(t, q)[0]
    stream = BodyStream(tree, cal)
    first = stream.run(t[:150], q[:150])[0]
    state = stream.get_state()
    second = stream.run(t[150:], q[150:])[0]
    np.testing.assert_allclose(np.vstack([first, second]), whole, atol=0)
    stream.set_state(state)  # checkpoint: the second half again from the saved state
    np.testing.assert_allclose(stream.run(t[150:], q[150:])[0], second, atol=0)


def test_stream_dropout_hold_then_nan(synthetic: tuple) -> None:
    tree, t, _coords, ori, cal = synthetic
    stream = BodyStream(tree, cal, dropout="hold", max_hold_s=0.05)
    k = tree.sensor_names.index("forearm_right")
    last = None
    for n in range(200):
        frame = {s: ori[s].quat[n] for s in tree.sensor_names}
        if n >= 150:
            del frame["forearm_right"]  # the sensor stops answering
        if n == 170:
            frame["hand_right"] = np.full(4, np.nan)  # a NaN sample
        out = stream.update(frame, t[n])
        if n == 149:
            last = stream.q_world_segment[k].copy()
        if 150 <= n <= 154:  # held 0.05 s after the last sample: joints still known
            assert stream.stale[k]
            assert np.isfinite(out).all()
            np.testing.assert_array_equal(stream.q_world_segment[k], last)
        if n >= 155:  # then the forearm and every joint touching it are unknown
            bad = stream.invalid_coordinates()
            assert {"elbow_flex_r", "pro_sup_r", "wrist_flex_r", "wrist_dev_r"} <= set(bad)
            assert "arm_flex_r" not in bad
            assert "knee_angle_r" not in bad
    # back again: everything recovers
    frame = {s: ori[s].quat[200] for s in tree.sensor_names}
    stream.update(frame, t[200])
    assert stream.invalid_coordinates() == []


def test_batch_dropout_policies(synthetic: tuple) -> None:
    tree, t, _coords, ori, cal = synthetic
    gap = dict(ori)
    q = ori["lower_leg_left"].quat.copy()
    q[100:140] = np.nan  # 0.4 s
    gap["lower_leg_left"] = OrientationSeries(t, q, name="lower_leg_left")
    nan_res, _ = body_angles(tree, cal, gap, dropout="nan")
    assert nan_res.missing == {"knee_angle_l": 40, "ankle_angle_l": 40, "subtalar_angle_l": 40}
    hold, _ = body_angles(tree, cal, gap, dropout="hold", max_hold_s=0.2)
    assert hold.held == {"lower_leg_left": 20}
    assert hold.missing["knee_angle_l"] == 20
    # held samples repeat the last orientation: the knee follows the thigh only
    assert np.isfinite(hold.angles.column("knee_angle_l")[100:120]).all()
    ref, _ = body_angles(tree, cal, gap, dropout="hold", max_hold_s=0.2, backend="reference")
    np.testing.assert_allclose(hold.angles.values, ref.angles.values, atol=AGREE)


def test_bad_frames_and_configuration(synthetic: tuple) -> None:
    tree, _t, _coords, ori, cal = synthetic
    stream = BodyStream(tree, cal)
    frame = {s: ori[s].quat[0] for s in tree.sensor_names}
    frame["imu99"] = np.array([1.0, 0.0, 0.0, 0.0])
    with pytest.raises(ConfigError, match="unknown sensor name\\(s\\) 'imu99' in the frame"):
        stream.update(frame, 0.0)
    del frame["imu99"]
    frame["head"] = np.zeros(3)
    with pytest.raises(ShapeError, match="sensor 'head': expected a quaternion"):
        stream.update(frame, 0.0)
    with pytest.raises(ConfigError, match="q_world_sensor: expected shape \\(15, 4\\)"):
        stream.update_array(np.zeros((14, 4)), 0.0)
    with pytest.raises(ConfigError, match="dropout: expected 'nan' or 'hold'"):
        BodyStream(tree, cal, dropout="zero")
    with pytest.raises(ConfigError, match="backend: expected 'fast' or 'reference'"):
        body_angles(tree, cal, ori, backend="gpu")
    with pytest.raises(ConfigError, match="dropout: expected one of"):
        body_angles(tree, cal, ori, dropout="zero")


def test_fast_equals_reference_on_the_opensense_recording(shared_data: Path) -> None:
    d = shared_data / "opensense"
    walk = read_orientations_sto(d / "walking_orientations.sto")
    place = read_orientations_sto(d / "placement_orientations.sto")
    tree = SensorTree.preset("opensense")
    cal = calibrate_pose(tree, place, (0.0, 0.0), pose="anatomical",
                         heading=HeadingFromSensor("torso_imu", "z"))  # fmt: skip
    fast, _ = body_angles(tree, cal, walk)
    ref, _ = body_angles(tree, cal, walk, backend="reference")
    np.testing.assert_allclose(fast.angles.values, ref.angles.values, atol=AGREE)
    stream = BodyStream(tree, cal)
    q = np.stack([walk[s].quat for s in tree.sensor_names], axis=1)
    rows = [stream.update_array(q[n], walk["pelvis_imu"].time[n]).copy() for n in range(len(q))]
    np.testing.assert_allclose(np.array(rows), fast.angles.values, atol=AGREE)


def test_live_calibration_from_frames(synthetic: tuple) -> None:
    """A live session: collect the first second of frames, calibrate, then stream."""
    from mocapkit.body.timebase import orientations_from_frames

    tree, t, coords, ori, _ = synthetic
    frames = [{s: ori[s].quat[n] for s in tree.sensor_names} for n in range(90)]
    del frames[10]["head"]  # a lost packet during calibration is tolerated
    cal = calibrate_pose(tree, orientations_from_frames(frames, t[:90]), (0.0, 0.89),
                         heading=HeadingFixed(-0.4))  # fmt: skip
    stream = BodyStream(tree, cal)
    out = np.array([stream.update({s: ori[s].quat[n] for s in tree.sensor_names}, t[n]).copy()
                    for n in range(len(t))])  # fmt: skip
    for k, c in enumerate(tree.coordinate_names):
        np.testing.assert_allclose(out[:, k], coords[c], atol=AGREE, err_msg=c)
