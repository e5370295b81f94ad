"""``mocapkit body`` in-process through main(argv)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mocapkit.cli.main import main
from mocapkit.io.bvh import read_bvh
from mocapkit.io.joint_angles_mot import read_joint_angles_mot


def test_presets_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["body", "presets", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["full_body_15"]["sensors"] == 15
    assert out["right_arm_2"]["coordinates"][3] == "elbow_flex_r"
    assert main(["body", "presets"]) == 0
    assert "right_arm_2" in capsys.readouterr().out


def test_angles_on_the_opensense_recording(shared_data: Path, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:  # fmt: skip
    d = shared_data / "opensense"
    argv = [
        "body", "angles", str(d / "walking_orientations.sto"), "--preset", "opensense",
        "--placement", str(d / "placement_orientations.sto"), "--calibration", "anatomical",
        "--heading-sensor", "torso_imu", "--heading-axis", "z", "--root-reference", "world",
        "-o", str(tmp_path / "a.mot"), "--bvh", str(tmp_path / "a.bvh"),
        "--bone", "pelvis=Hips", "--segments", str(tmp_path / "s.sto"),
        "--calibration-out", str(tmp_path / "cal.json"), "--json",
    ]  # fmt: skip
    assert main(argv) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["n_frames"] == 2432
    assert report["tree"] == "opensense"
    assert 50.0 < report["coordinates"]["knee_angle_r"]["max_deg"] < 80.0
    angles = read_joint_angles_mot(tmp_path / "a.mot")
    assert "knee_angle_l" in angles.names
    assert angles.n_samples == 2432
    assert read_bvh(tmp_path / "a.bvh").joints[0].name == "Hips"
    # the saved calibration gives the same angles again
    again = [*argv[:3], "--preset", "opensense", "--calibration-in", str(tmp_path / "cal.json"),
             "-o", str(tmp_path / "b.mot")]  # fmt: skip
    assert main(again) == 0
    np.testing.assert_allclose(
        read_joint_angles_mot(tmp_path / "b.mot").values, angles.values, atol=1e-9
    )


def test_angles_automatic_on_the_full_body_recording(
    shared_data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The recording cut to its first 20 s (standing, then sitting down: no walking) is
    still calibrated, but the left shank's axis disagrees with the others by 31 deg,
    which is said, with the segment and sensor, in a warning and in the JSON."""
    from mocapkit.body.calibration_checks import CalibrationWarning

    path = shared_data / "full-body-15-imu" / "full_body_example_data.mat"
    with pytest.warns(CalibrationWarning, match=r"segment tibia_l \(sensor lower_leg_left\)"):
        rc = main(["body", "angles", str(path), "--start", "40.3", "--stop", "60", "--json"])
    assert rc == 0
    report = json.loads(capsys.readouterr().out)
    assert report["calibration"]["method"] == "functional"
    assert report["tree"] == "full_body_15"
    checks = report["calibration_checks"]
    assert [(c["kind"], c["segment"]) for c in checks] == [("turned", "tibia_l")]
    # the whole recording (walks included) agrees with itself
    assert main(["body", "angles", str(path), "--start", "40.3", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["calibration_checks"] == []


def test_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["body", "angles", str(tmp_path / "none.sto")]) == 1
    assert "no such file" in capsys.readouterr().err
    (tmp_path / "x.csv").write_text("t\n")
    assert main(["body", "angles", str(tmp_path / "x.csv")]) == 1
    assert "give --format" in capsys.readouterr().err
    (tmp_path / "x.sto").write_text("x\nendheader\ntime\ta\n0\t1,0,0,0\n1\t1,0,0,0\n")
    assert main(["body", "angles", str(tmp_path / "x.sto"), "--preset", "nope"]) == 1
    assert "unknown body preset 'nope'" in capsys.readouterr().err
    assert main(["body", "angles", str(tmp_path / "x.sto"), "--preset", "right_arm_2",
                 "--map", "femur=a"]) == 1  # fmt: skip
    assert "unknown segment(s) 'femur'" in capsys.readouterr().err
    assert main(["body", "angles", str(tmp_path / "x.sto"), "--preset", "right_arm_2"]) == 1
    assert "no data for sensor(s) humerus_r <- 'upper_arm_r'" in capsys.readouterr().err
    assert main(["body", "angles", str(tmp_path / "x.sto"), "--map", "nonsense"]) == 1
    assert "expected SEGMENT=SENSOR" in capsys.readouterr().err


def test_angles_on_the_ximu3_directory_with_a_filter(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    d = shared_data / "ximu3-lower-body"
    argv = ["body", "angles", str(d), "--preset", "lower_body", "--json"]
    assert main(argv) == 0
    device = json.loads(capsys.readouterr().out)
    from mocapkit.body.calibration_checks import CalibrationWarning

    # 6D worlds aligned at the pose only: the pelvis, with no functional axis, is named
    with pytest.warns(CalibrationWarning, match=r"pelvis \(sensor Pelvis\) has no functional"):
        assert main([*argv, "--filter", "bachmann", "--mode", "6d", "--heading-alignment",
                     "pose"]) == 0  # fmt: skip
    filt = json.loads(capsys.readouterr().out)
    assert [c["kind"] for c in filt["calibration_checks"]] == ["unaligned"]
    assert filt["calibration_checks"][0]["value_deg"] is None  # strict JSON: no NaN
    for report in (device, filt):
        assert 95.0 < report["coordinates"]["knee_angle_r"]["max_deg"] < 140.0
    assert main(["body", "angles", str(shared_data / "opensense" / "walking_orientations.sto"),
                 "--preset", "opensense", "--filter", "miller"]) == 1  # fmt: skip
    assert "has no raw samples to filter" in capsys.readouterr().err


@pytest.mark.shared_data
def test_raw_samples_through_a_6d_filter_report_what_no_human_does(
    shared_data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The 15-IMU recording's raw samples through polaris 6D, calibrated as if the
    sensors shared one heading (the wrong option for 6D, given explicitly): joints come
    out no human reaches (a knee bent 94 deg backwards), and each such coordinate is named
    with its sensor. With the default for 6D (headings aligned at the pose and kept
    aligned by the joints) the same recording gives no implausible joint."""
    import warnings

    from mocapkit.body.plausibility import ImplausibleAnglesWarning

    rec = shared_data / "full-body-15-imu" / "full_body_example_data.mat"
    argv = ["body", "angles", str(rec), "--filter", "polaris", "--mode", "6d"]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert main([*argv, "--start", "40.3", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["implausible"] == []
    assert not [w for w in caught if w.category is ImplausibleAnglesWarning]
    # the default in 6D: headings kept aligned by the joints, each pair reported
    pairs = {p["child"]: p for p in report["joint_headings"]["pairs"]}
    assert len(pairs) == 14
    assert pairs["lower_leg_right"]["windows_used"] > 20
    argv += ["--heading-alignment", "shared"]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert main([*argv, "--start", "40.3", "--json"]) == 0
    said = [str(w.message) for w in caught if w.category is ImplausibleAnglesWarning]
    assert any(m.startswith("knee_angle_r (segment tibia_r, sensor lower_leg_right)") for m in said)
    found = {f["coordinate"] for f in json.loads(capsys.readouterr().out)["implausible"]}
    assert "knee_angle_r" in found
    assert len(said) == len(found)  # one warning per coordinate, each in the JSON too
