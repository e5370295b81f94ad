"""The body model on real recordings: plausible joint angles, continuity, and agreement
with OpenSim's IMU inverse kinematics on the OpenSense example."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.body.calibration import HeadingFromSensor
from mocapkit.body.pipeline import BodyResult, run_body
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.io.joint_angles_mot import read_joint_angles_mot
from mocapkit.io.opensense import read_orientations_sto
from mocapkit.io.qmt_mat import read_qmt_mat
from tests.conftest import TEST_DATA

# Time markers of the qmt full-body recording (qmt's full_body_tracking example):
# standing 40-44 s, sitting 52-79 s, walking 95-115 s, a turn, walking 116-138.5 s.
# Its own orientation filter converges during the first 0.2 s, so we start at 40.3 s.
WALK = [(96.0, 114.0), (117.0, 138.0)]
SIT = (56.0, 76.0)


def _deg(res: BodyResult, name: str, window: tuple[float, float] | None = None) -> np.ndarray:
    a = res.body.angles
    v = np.rad2deg(a.column(name))
    if window is None:
        return v
    return v[(a.time >= window[0]) & (a.time <= window[1])]


@pytest.fixture(scope="module")
def full_body() -> BodyResult:
    from tests.conftest import SHARED_DATA

    if SHARED_DATA is None:
        pytest.skip("../shared/data is not present (set MOCAPKIT_SHARED_DATA to its path)")
    rec = read_qmt_mat(SHARED_DATA / "full-body-15-imu" / "full_body_example_data.mat")
    return run_body(SensorTree.preset("full_body_15"), rec.orientation, start=40.3)


def test_full_body_every_mounting_and_the_heading_estimated(full_body: BodyResult) -> None:
    cal = full_body.calibration
    assert cal.method == "functional"
    # the legs' functional axes all agree on the body heading within ~15 deg
    assert cal.diagnostics["heading_spread_deg"] < 20.0
    legs = {f"{s}_{side}" for s in ("femur", "tibia", "calcn") for side in "rl"}
    assert legs <= set(cal.diagnostics["functional_segments"])
    # knees flex positive: the forward/backward choice is clear
    assert (
        cal.diagnostics["forward_score_deg"] > 10.0 > -10.0 > cal.diagnostics["backward_score_deg"]
    )
    assert not full_body.body.missing


@pytest.mark.parametrize("side", ["r", "l"])
def test_full_body_knee_and_hip_in_gait(full_body: BodyResult, side: str) -> None:
    for w in WALK:
        knee = _deg(full_body, f"knee_angle_{side}", w)
        hip = _deg(full_body, f"hip_flexion_{side}", w)
        # normal gait: knee 0-70 deg (sensor wobble on the thigh adds ~10 deg at peaks),
        # hip about -20 to +40 deg
        assert -10.0 < np.percentile(knee, 2) < 10.0
        assert 50.0 < np.percentile(knee, 98) < 95.0
        assert -30.0 < np.percentile(hip, 2) < 0.0
        assert 20.0 < np.percentile(hip, 98) < 55.0
        ankle = _deg(full_body, f"ankle_angle_{side}", w)
        assert np.percentile(ankle, 2) > -30.0
        assert np.percentile(ankle, 98) < 35.0


def test_full_body_sitting(full_body: BodyResult) -> None:
    for side in "rl":
        assert 60.0 < np.median(_deg(full_body, f"knee_angle_{side}", SIT)) < 110.0
        assert 40.0 < np.median(_deg(full_body, f"hip_flexion_{side}", SIT)) < 100.0


def test_full_body_continuous_without_wrap_arounds(full_body: BodyResult) -> None:
    a = full_body.body.angles
    steps = np.abs(np.diff(np.rad2deg(a.values), axis=0))
    # 100 Hz: 20 deg per sample is 2000 deg/s, far above any joint's speed; a wrap-around
    # would be ~360
    worst = a.names[int(np.argmax(steps.max(axis=0)))]
    assert steps.max() < 20.0, worst
    # the turn at 115 s: the pelvis turns about half a turn, continuously
    before = np.median(_deg(full_body, "pelvis_rotation", (111.0, 114.0)))
    after = np.median(_deg(full_body, "pelvis_rotation", (118.0, 121.0)))
    assert 150.0 < abs(after - before) < 210.0


@pytest.fixture(scope="module")
def opensense() -> BodyResult:
    from tests.conftest import SHARED_DATA

    if SHARED_DATA is None:
        pytest.skip("../shared/data is not present (set MOCAPKIT_SHARED_DATA to its path)")
    d = SHARED_DATA / "opensense"
    return run_body(
        SensorTree.preset("opensense"),
        read_orientations_sto(d / "walking_orientations.sto"),
        calibration="anatomical",
        placement=read_orientations_sto(d / "placement_orientations.sto"),
        heading=HeadingFromSensor("torso_imu", "z"),
        root_reference="world",
    )


def test_opensense_against_opensim_imu_ik(opensense: BodyResult) -> None:
    """OpenSim's IMU IK (stored reference) and ours on the same frames. Bounds are the
    measured differences plus margin (docs/benchmarks.md); the knee and ankle agree best
    because both models have nearly the same axes there, the hips and pelvis least
    (OpenSim's pelvis also fits the torso IMU through the locked lumbar joint)."""
    ref = read_joint_angles_mot(TEST_DATA / "opensense_imu_ik_reference.mot")
    ours = opensense.body.angles
    bounds = {"knee_angle": 4.0, "ankle_angle": 3.0, "hip_flexion": 8.0, "hip_adduction": 8.0,
              "hip_rotation": 10.0, "pelvis_tilt": 8.0, "pelvis_list": 5.0}  # fmt: skip
    for name in ref.names:
        r = np.rad2deg(ref.column(name))
        o = np.rad2deg(np.interp(ref.time, ours.time, ours.column(name)))
        d = o - r
        if name == "pelvis_rotation":
            d = (d + 180.0) % 360.0 - 180.0
        rms = float(np.sqrt(np.mean(d**2)))
        bound = next((b for k, b in bounds.items() if name.startswith(k)), 6.0)
        assert rms < bound, (name, rms)


def test_opensense_knee_flexion_in_gait(opensense: BodyResult) -> None:
    for side in "rl":
        knee = _deg(opensense, f"knee_angle_{side}")
        assert knee.min() > -10.0
        assert 50.0 < knee.max() < 80.0
    steps = np.abs(np.diff(np.rad2deg(opensense.body.angles.values), axis=0))
    assert steps.max() < 20.0


def test_reference_file_is_present() -> None:
    assert (TEST_DATA / "opensense_imu_ik_reference.mot").is_file()
    assert Path(TEST_DATA / "opensense_imu_ik_reference.SOURCE.md").is_file()


@pytest.fixture(scope="module")
def ximu3() -> BodyResult:
    from mocapkit.io.imu_files import read_device_orientations
    from tests.conftest import SHARED_DATA

    if SHARED_DATA is None:
        pytest.skip("../shared/data is not present (set MOCAPKIT_SHARED_DATA to its path)")
    orientations = read_device_orientations(SHARED_DATA / "ximu3-lower-body")
    return run_body(SensorTree.preset("lower_body"), orientations)


def test_ximu3_lower_body_automatic(ximu3: BodyResult) -> None:
    """x-IMU3 lower body, 7 sensors at 50 Hz with their own clocks (resampled), the
    devices' own fusion, mountings unknown: standing, steps, a high knee raise on each
    side, a turn and back."""
    cal = ximu3.calibration
    assert len(cal.diagnostics["functional_segments"]) == 6
    assert cal.diagnostics["heading_spread_deg"] < 20.0
    t = ximu3.body.angles.time - ximu3.body.angles.time[0]
    for side, (t0, t1) in (("r", (4.0, 6.0)), ("l", (5.5, 7.5))):
        knee = _deg(ximu3, f"knee_angle_{side}")
        hip = _deg(ximu3, f"hip_flexion_{side}")
        raise_ = (t >= t0) & (t <= t1)
        # the knee raise: knee about 110-130 deg, hip 70-90 deg
        assert 95.0 < knee[raise_].max() < 140.0
        assert 55.0 < hip[raise_].max() < 100.0
        assert knee.min() > -10.0  # no hyperextension beyond soft-tissue noise
    rot = _deg(ximu3, "pelvis_rotation")
    assert 160.0 < abs(np.median(rot[(t > 10.0) & (t < 12.0)]) - rot[0]) < 200.0  # the turn
    steps = np.abs(np.diff(np.rad2deg(ximu3.body.angles.values), axis=0))
    assert steps.max() < 20.0  # 50 Hz: 1000 deg/s


def test_ximu3_with_our_own_filter_agrees_with_the_devices(ximu3: BodyResult) -> None:
    """Raw samples -> mocapkit's miller filter (9D) -> body model, against the body model
    on the devices' own fusion: the knees agree within a few degrees."""
    from mocapkit.imu.filters.base import make_filter
    from mocapkit.io.imu_files import read_imu_recordings
    from tests.conftest import SHARED_DATA

    assert SHARED_DATA is not None
    recs = read_imu_recordings(SHARED_DATA / "ximu3-lower-body")
    ori = {k: make_filter("miller", r.rate_hz).run_recording(r) for k, r in recs.items()}
    ours = run_body(SensorTree.preset("lower_body"), ori)
    a, b = ours.body.angles, ximu3.body.angles
    for name in ("knee_angle_r", "knee_angle_l", "hip_flexion_r", "hip_flexion_l"):
        x = np.rad2deg(a.column(name))
        y = np.rad2deg(np.interp(a.time, b.time, b.column(name)))
        # measured 0.9-2.4 deg; two different fusions of the same sensors
        assert np.sqrt(np.mean((x - y) ** 2)) < 4.0, name


def test_body_angles_6d_aligns_headings_from_the_pose(shared_data):
    """With a 6D filter each sensor has its own heading: the CLI's automatic calibration
    aligns them from the pose, and keeps them aligned through the joints ("joints"),
    unless told otherwise (the shared option is wrong there); 9D aligns them at the pose
    after comparing the hinges across the joints ("hinges")."""
    import json
    import subprocess
    import sys

    rec = shared_data / "ximu3-lower-body"
    base = [sys.executable, "-m", "mocapkit", "body", "angles", str(rec), "--preset",
            "lower_body", "--filter", "polaris-body", "--json"]  # fmt: skip
    for mode, expected in (("6d", "joints"), ("9d", "hinges")):
        p = subprocess.run([*base, "--mode", mode], capture_output=True, text=True, check=False)
        assert p.returncode == 0, p.stderr
        assert json.loads(p.stdout)["calibration"]["heading_alignment"] == expected
