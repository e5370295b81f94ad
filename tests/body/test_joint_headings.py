"""Heading through the joints (body.joint_headings): a simulated walk whose sensors' headings
drift by known amounts, with exact answers."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from mocapkit.body.joint_headings import align_headings_by_joints
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.body.simulate import gait_coordinates, segment_poses, virtual_suit
from mocapkit.errors import ConfigError
from mocapkit.geometry import quat_mul
from mocapkit.imu.simulate import ImuErrorModel
from mocapkit.series import OrientationSeries


def _rz(yaw):
    return np.stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)], axis=-1)


def _walk(duration_s=40.0, still_s=2.0):
    tree = SensorTree.preset("lower_body")
    t, coords, _ = gait_coordinates(tree, duration_s=duration_s, still_s=still_s)
    # the pelvis bounces (2 cm) and sways (2 cm) with the stride, as people's do
    phase = 2 * np.pi * np.clip(t - still_s, 0, None) / 1.1
    root = np.column_stack(
        [0.01 * np.sin(2 * phase), 0.02 * np.sin(2 * phase), 0.02 * np.sin(phase)]
    )
    poses = segment_poses(tree, t, coords, speed=1.2, walk_start_s=still_s, root_path=root)
    recs, mounts = virtual_suit(tree, poses, np.random.default_rng(1), errors=ImuErrorModel())
    truth = {
        seg.sensor: OrientationSeries(t, quat_mul(poses[seg.name].quat, mounts[seg.name]))
        for seg in tree.segments
    }
    return tree, t, recs, truth


def test_known_drifts_are_taken_out():
    """Each sensor's heading drifts by its own known amount (6D-like worlds); after the
    joints, every sensor's heading differs from the pelvis sensor's by its true drift's
    difference, its change over time within a degree. (The constant is what the pose
    alignment sets; through the hips it is found only to ~7 deg here, as the pelvis
    turns little.)"""
    tree, t, recs, truth = _walk()
    rng = np.random.default_rng(2)
    drift = {}
    drifted = {}
    for seg in tree.segments:
        d = np.radians(rng.uniform(-30, 30) + rng.uniform(-15, 15) * t / t[-1])
        drift[seg.sensor] = d
        drifted[seg.sensor] = OrientationSeries(t, quat_mul(_rz(-d), truth[seg.sensor].quat))
    turned, info = align_headings_by_joints(tree, drifted, recs)
    assert not info.notes
    root = tree.segments[0].sensor
    moving = t > 4.0
    for seg in tree.segments[1:]:
        # the correction puts the child in the root's (drifted) world: d_child - d_root
        want = drift[seg.sensor] - drift[root]
        err = np.degrees(np.angle(np.exp(1j * (info.correction[seg.sensor] - want))))
        e = err[moving]
        assert np.abs(e - e.mean()).max() < 1.0, (seg.name, np.abs(e - e.mean()).max())
    # the orientations are turned by exactly the corrections reported
    k = tree.segments[2].sensor
    q = quat_mul(_rz(info.correction[k]), drifted[k].quat)
    assert np.allclose(np.abs(np.sum(q * turned[k].quat, axis=1)), 1.0)


def test_standing_still_follows_nothing_and_says_so():
    """No motion: no joint shows its centre; every pair is left as it was, noted."""
    tree, _t, recs, truth = _walk(duration_s=12.0, still_s=20.0)
    turned, info = align_headings_by_joints(tree, truth, recs)
    assert len(info.notes) == len(tree.segments) - 1
    assert "not followed" in info.notes[0]
    for k, v in info.correction.items():
        assert np.allclose(v, 0.0), k
    assert np.allclose(turned[tree.segments[2].sensor].quat, truth[tree.segments[2].sensor].quat)


def test_a_missing_accelerometer_is_refused_naming_the_sensor():
    tree, _t, recs, truth = _walk(duration_s=8.0)
    gone = tree.segments[2].sensor
    recs = {k: v for k, v in recs.items() if k != gone}
    with pytest.raises(ConfigError, match=gone):
        align_headings_by_joints(tree, truth, recs)


def test_cli_joints_without_raw_samples_names_the_fix(tmp_path):
    """``--heading-alignment joints`` on orientations alone (no accelerometers) is refused
    with the options that make it work."""
    from mocapkit.cli.main import main
    from mocapkit.io.opensense import write_orientations_sto

    _tree, _t, _recs, truth = _walk(duration_s=6.0)
    sto = write_orientations_sto(tmp_path / "o.sto", truth)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        code = main(["body", "angles", str(sto), "--preset", "lower_body",
                     "--heading-alignment", "joints"])  # fmt: skip
    assert code != 0


def test_a_gap_in_one_sensor_neither_crashes_nor_spreads():
    """Half a second of a shank's orientations missing (NaN, as a dropout leaves them):
    the other samples are used, the corrections stay finite, the gap stays a gap."""
    tree, t, recs, truth = _walk(duration_s=30.0)
    k = tree.segments[2].sensor
    q = truth[k].quat.copy()
    gap = (t > 12.0) & (t < 12.5)
    q[gap] = np.nan
    truth = dict(truth)
    truth[k] = OrientationSeries(t, q)
    turned, info = align_headings_by_joints(tree, truth, recs)
    assert all(np.isfinite(v).all() for v in info.correction.values())
    assert np.isnan(turned[k].quat[gap]).all()
    assert np.isfinite(turned[k].quat[~gap]).all()
