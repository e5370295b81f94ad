"""Sensor placement from the motion (``mocapkit.body.identify``): synthetic suits with
shuffled labels (exact answers), the failure reasons, and the real recordings."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mocapkit.body.identify import IdentifyError, dispersion_matrix, identify
from mocapkit.body.joint_centres import fit_pair, kinematics
from mocapkit.body.sensor_tree import SensorTree
from mocapkit.body.simulate import (
    gait_coordinates,
    gait_root_path,
    segment_poses,
    virtual_suit,
)
from mocapkit.geometry import quat_conj, quat_exp, quat_mul, quat_normalize, quat_rotate
from mocapkit.imu.filters import make_filter
from mocapkit.imu.simulate import ImuErrorModel
from mocapkit.series import OrientationSeries


def _suit(preset: str, seed: int, *, duration_s: float = 15.0, coords_edit=None, ideal=False,
          glide=False):  # fmt: skip
    """A walk with the pelvis bouncing and swaying as people's does (``glide``: at
    constant speed instead)."""
    tree = SensorTree.preset(preset)
    t, coords, walk = gait_coordinates(tree, duration_s=duration_s)
    if coords_edit:
        coords_edit(coords)
    root = None if glide else gait_root_path(t, walk)
    poses = segment_poses(tree, t, coords, heading_rad=0.7, walk_start_s=walk, root_path=root)
    rng = np.random.default_rng(seed)
    errors = ImuErrorModel() if ideal else None
    recs, _ = virtual_suit(tree, poses, rng, errors=errors)
    return tree, recs, rng


def _shuffled(tree, oris, recs, rng):
    """Labels replaced by shuffled names; returns (orientations, recordings, truth)."""
    names = list(oris)
    perm = rng.permutation(len(names))
    label = {n: f"imu{perm[i]:02d}" for i, n in enumerate(names)}
    o = {label[n]: oris[n] for n in names}
    r = None if recs is None else {label[n]: recs[n] for n in names}
    truth = {s.name: label[s.sensor] for s in tree.segments}
    return o, r, truth


def _filtered(recs, mode):
    return {
        k: make_filter("polaris-body", r.rate_hz).run_recording(r, use_mag=mode == "9d")
        for k, r in recs.items()
    }


@pytest.mark.parametrize(
    ("preset", "mode", "seed"),
    [("lower_body", "9d", 0), ("full_body_15", "9d", 1), ("lower_body", "6d", 1),
     ("full_body_15", "6d", 2), ("opensense", "6d", 0)],
)  # fmt: skip
def test_shuffled_suit_is_identified(preset, mode, seed):
    """Every sensor right, 9D and 6D (60 of 60 suits in benchmarks/body_identify.py)."""
    tree, recs, rng = _suit(preset, seed)
    o, r, truth = _shuffled(tree, _filtered(recs, mode), recs, rng)
    result = identify(tree, o, r, headings="shared" if mode == "9d" else "independent")
    assert all(0.0 <= a.confidence <= 1.0 for a in result.assignments)
    assert result.decided, result.undecided
    assert result.mapping == truth
    assert all("joint centres" in a.evidence for a in result.assignments
               if a.segment.startswith("femur"))  # fmt: skip


@pytest.mark.parametrize("seed", [1, 2])
def test_6d_gliding_pelvis_sides_are_not_taken_from_the_joint_centres(seed):
    """A pelvis gliding at constant speed shows its sensor's world heading to no joint:
    in 6D its hip centres came out 3-10 cm off and the side wrong (seed 1: 0.91 of the
    separation, against the gait). The side is then the gait's, or undecided with the
    reason: never the joint centres' guess."""
    tree, recs, rng = _suit("lower_body", seed, glide=True)
    o, r, truth = _shuffled(tree, _filtered(recs, "6d"), recs, rng)
    result = identify(tree, o, r, headings="independent")
    femurs = [a for a in result.assignments if a.segment.startswith("femur")]
    assert all("joint centres" not in a.evidence for a in femurs)
    if result.decided:
        assert result.mapping == truth
        assert all("gait" in a.evidence for a in femurs)
        return
    assert all("--known" in u for u in result.undecided)
    open_segments = {s for u in result.undecided for s in u.split(":")[0].split(" / ")}
    assert open_segments <= {"femur_r", "femur_l", "humerus_r", "humerus_l"}
    found = result.mapping
    # only whole mirror branches may be exchanged
    for seg, sensor in truth.items():
        mirror = seg[:-1] + ("l" if seg.endswith("r") else "r") if seg[-2:] in ("_r", "_l") else seg
        assert found[seg] in (sensor, truth[mirror])


def test_without_accelerometers_walking_decides_by_gait():
    tree, recs, rng = _suit("lower_body", 3)
    o, _, truth = _shuffled(tree, _filtered(recs, "9d"), None, rng)
    result = identify(tree, o)
    assert result.decided, result.undecided
    assert result.mapping == truth
    assert any("gait" in a.evidence for a in result.assignments)


def test_no_accelerometers_no_pelvis_turn_is_undecided_with_reason():
    def still_pelvis(coords):
        coords["pelvis_rotation"][:] = 0.0

    tree, recs, rng = _suit("lower_body", 4, coords_edit=still_pelvis)
    o, _, truth = _shuffled(tree, _filtered(recs, "9d"), None, rng)
    result = identify(tree, o)
    assert not result.decided
    assert "femur_r / femur_l" in result.undecided[0]
    assert "--known" in result.undecided[0]
    # the chains themselves are still right, only their side is open
    found = result.mapping
    assert {found["femur_r"], found["femur_l"]} == {truth["femur_r"], truth["femur_l"]}
    # pinning one sensor decides the side
    pinned = identify(tree, o, known={"femur_r": truth["femur_r"]})
    assert pinned.decided
    assert pinned.mapping == truth


def test_look_alike_segments_are_reported():
    tree, recs, rng = _suit("upper_body", 5)
    o, r, _ = _shuffled(tree, _filtered(recs, "9d"), recs, rng)
    result = identify(tree, o, r)
    assert any("pelvis / head" in u for u in result.undecided)


def test_dispersion_does_not_depend_on_the_mountings():
    rng = np.random.default_rng(0)
    q = quat_normalize(rng.normal(size=(200, 3, 4)))
    mounts = quat_normalize(rng.normal(size=(3, 4)))
    mounted = quat_mul(q, np.broadcast_to(mounts, q.shape))
    np.testing.assert_allclose(dispersion_matrix(q), dispersion_matrix(mounted), atol=1e-12)


def test_joint_centres_from_ideal_sensors_are_exact():
    """Perfect sensors and true orientations: the hip centre in both sensors' frames to a
    millimetre (the equation's two sides filtered alike; filtering the rates alone left
    3-9 cm and a 0.13 m/s^2 residual)."""
    tree = SensorTree.preset("lower_body")
    t, coords, walk = gait_coordinates(tree, duration_s=15.0)
    poses = segment_poses(tree, t, coords, heading_rad=0.7, walk_start_s=walk,
                          root_path=gait_root_path(t, walk))  # fmt: skip
    recs, mounts = virtual_suit(tree, poses, np.random.default_rng(0), errors=ImuErrorModel())
    pelvis, femur = tree.segment("pelvis"), tree.segment("femur_l")
    q = np.stack([quat_mul(poses[s.name].quat, mounts[s.name]) for s in (pelvis, femur)], 1)
    acc = np.stack([recs[s.sensor].acc for s in (pelvis, femur)], axis=1)
    fit = fit_pair(kinematics(q, acc, 100.0), 0, 1)
    # the sensors sit at their segments' middles, turned by their mountings
    hip_in_pelvis = np.asarray(femur.offset) - 0.5 * np.asarray(pelvis.end)
    hip_in_femur = -0.5 * np.asarray(femur.end)
    np.testing.assert_allclose(fit.o_i, quat_rotate(quat_conj(mounts["pelvis"]), hip_in_pelvis),
                               atol=0.002)  # fmt: skip
    np.testing.assert_allclose(fit.o_j, quat_rotate(quat_conj(mounts["femur_l"]), hip_in_femur),
                               atol=0.002)  # fmt: skip
    assert fit.residual < 0.01


def test_joint_centre_of_an_ideal_pair_is_exact():
    tree, recs, _ = _suit("lower_body", 6, ideal=True)
    oris = _filtered(recs, "9d")
    # truth orientations would be exact; the filter's are within a degree: centre to ~1 cm
    names = ["Pelvis", "Right Upper Leg"]
    q = np.stack([oris[n].quat for n in names], axis=1)
    acc = np.stack([recs[n].acc for n in names], axis=1)
    fit = fit_pair(kinematics(q, acc, 100.0), 0, 1)
    seg = tree.segment("femur_r")
    # hip centre in the thigh sensor frame: the sensor sits at the segment's middle
    expected_len = float(np.linalg.norm(0.5 * np.asarray(seg.end)))
    assert abs(float(np.linalg.norm(fit.o_j)) - expected_len) < 0.02
    assert fit.residual < 0.3


@pytest.mark.parametrize(
    ("case", "match"),
    [("still", "hardly turn"), ("short", "at least 5 s"), ("count", "15 segments")],
)
def test_recordings_that_cannot_identify_are_refused(case, match):
    tree = SensorTree.preset("full_body_15" if case == "count" else "lower_body")
    t = np.arange(0.0, 2.0 if case == "short" else 20.0, 0.01)
    rng = np.random.default_rng(0)
    n = 7 if case != "count" else 14
    oris = {}
    for k in range(n):
        q0 = quat_normalize(rng.normal(size=4))
        wobble = quat_exp(np.outer(np.sin(t), [0.0, 0.0, 0.002 * k]))
        if case != "still":
            wobble = quat_exp(np.outer(np.sin((k + 1) * t), [0.3, 0.1 * k, 0.2]))
        oris[f"s{k}"] = OrientationSeries(t, quat_mul(wobble, q0))
    with pytest.raises(IdentifyError, match=match):
        identify(tree, oris)


def test_a_sensor_that_stops_is_named():
    tree, recs, _ = _suit("lower_body", 7)
    oris = _filtered(recs, "9d")
    s = oris["Right Foot"]
    q = s.quat.copy()
    q[len(q) // 3 :] = np.nan
    oris["Right Foot"] = OrientationSeries(s.time, q)
    with pytest.raises(IdentifyError, match="'Right Foot'.*stopped"):
        identify(tree, oris)


# -- the real recordings, labels removed -------------------------------------------------
def _real(shared: Path, case: str) -> tuple[SensorTree, Path]:
    if case == "ximu3":
        return SensorTree.preset("lower_body"), shared / "ximu3-lower-body"
    if case == "opensense-xsens":
        return SensorTree.preset("opensense"), shared / "opensense" / "xsens" / "IMUData"
    return SensorTree.preset("full_body_16"), (
        shared / "full-body-15-imu" / "full_body_example_data.mat"
    )


@pytest.mark.parametrize("case", ["ximu3", "opensense-xsens", "qmt"])
def test_real_recordings_with_labels_removed(shared_data, case):
    import xml.etree.ElementTree as ET

    from mocapkit.body.recordings import load_for_identify

    tree, path = _real(shared_data, case)
    oris, raw, headings, _ = load_for_identify(path, "auto", "polaris-body", None)
    if case == "opensense-xsens":  # the Xsens ids -> the tree's sensor names (the mapping)
        setup = path.parent / "myIMUMappings.xml"
        ids = {
            e.get("name", "").lstrip("_"): e.findtext("name_in_model", "")
            for e in ET.parse(setup).iter("ExperimentalSensor")
        }
        truth_sensor = {s.sensor.removesuffix("_imu"): s.sensor for s in tree.segments}
        rename = {k: truth_sensor[v.removesuffix("_imu")] for k, v in ids.items()}
        oris = {rename[k]: v for k, v in oris.items()}
        raw = {rename[k]: v for k, v in raw.items()}
    rng = np.random.default_rng(0)
    o, r, truth = _shuffled(tree, oris, raw, rng)
    result = identify(tree, o, r, headings=headings)
    assert result.decided, result.undecided
    assert result.mapping == truth


def test_cli_identify_then_angles_with_the_map(shared_data, tmp_path):
    rec = shared_data / "ximu3-lower-body"
    out = tmp_path / "placement.json"
    run = [sys.executable, "-m", "mocapkit", "body"]
    p = subprocess.run(
        [*run, "identify", str(rec), "--preset", "lower_body", "-o", str(out), "--json"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert p.returncode == 0, p.stderr
    report = json.loads(p.stdout)
    assert report["decided"]
    assert report["mapping"]["femur_r"] == "Right Upper Leg"
    assert json.loads(out.read_text()) == report["mapping"]
    mot = tmp_path / "angles.mot"
    p = subprocess.run(
        [*run, "angles", str(rec), "--format", "device", "--preset", "lower_body",
         "--map-file", str(out), "-o", str(mot), "--json"],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert p.returncode == 0, p.stderr
    assert mot.exists()
    residuals = json.loads(p.stdout)["calibration"]["segments"]
    assert set(residuals) == {"pelvis", "femur_r", "tibia_r", "calcn_r", "femur_l", "tibia_l",
                              "calcn_l"}  # fmt: skip
    assert all("still_deviation_deg" in r for r in residuals.values())
    assert residuals["tibia_r"]["functional_share"] > 0.6
