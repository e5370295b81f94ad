"""OpenSim IK setup files: read the tutorial's, use it from the CLI, refuse bad ones."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from mocapkit.cli.main import main
from mocapkit.errors import FileFormatError
from mocapkit.io.opensim_ik_setup import read_ik_setup


@pytest.fixture
def gait(shared_data: Path) -> Path:
    return shared_data / "opensim" / "gait2392"


def test_reads_the_tutorial_setup(gait: Path) -> None:
    setup = read_ik_setup(gait / "subject01_Setup_IK.xml")
    assert len(setup.marker_weights) == 31  # the tutorial's 31 IKMarkerTasks
    assert setup.marker_weights["R.ASIS"] == 10.0
    assert setup.marker_weights["Top.Head"] == 0.1
    assert setup.coordinate_tasks["subtalar_angle_r"] == (0.0, 1000.0)
    assert setup.coordinate_tasks["mtp_angle_l"] == (0.0, 1000.0)
    assert setup.time_range == (0.5, 2.5)
    assert setup.marker_file == gait / "subject01_walk1.trc"
    assert "accuracy" in setup.ignored
    assert "constraint_weight" in setup.ignored


def test_cli_uses_its_weights_and_time_range(
    gait: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "walk.mot"
    code = main([
        "markers", "reconstruct", str(gait / "subject01_walk1.trc"),
        "--static", str(gait / "subject01_static.trc"), "--height-m", "1.8034",
        "--mass-kg", "72.6", "--method", "ik", "--ik-setup", str(gait / "subject01_Setup_IK.xml"),
        "-o", str(out), "--json",
    ])  # fmt: skip
    assert code == 0
    m = json.loads(capsys.readouterr().out)
    assert m["frames"] == 121  # 0.5-2.5 s at 60 Hz, the setup's time range
    lines = out.read_text().splitlines()
    first = lines[lines.index("endheader") + 2].split()
    assert float(first[0]) == pytest.approx(0.5, abs=1e-6)


def _write(tmp_path: Path, body: str) -> Path:
    p = tmp_path / "setup.xml"
    p.write_text(f'<?xml version="1.0"?><OpenSimDocument Version="30000">{body}</OpenSimDocument>')
    return p


def test_bad_setups_are_refused(gait: Path, tmp_path: Path) -> None:
    with pytest.raises(FileFormatError, match="no <InverseKinematicsTool> element"):
        read_ik_setup(gait / "subject01_Setup_Scale.xml")
    task = "<IKTaskSet><objects>{}</objects></IKTaskSet>"
    cases = [
        (
            '<IKMarkerTask name="A"><apply>true</apply><weight>-1</weight></IKMarkerTask>',
            "IKMarkerTask 'A' <weight>: must be >= 0",
        ),
        (
            '<IKMarkerTask name="A"><apply>yes</apply><weight>1</weight></IKMarkerTask>',
            "<apply> must be true or false",
        ),
        (
            '<IKCoordinateTask name="knee"><apply>true</apply><value_type>from_file'
            "</value_type></IKCoordinateTask>",
            "IKCoordinateTask 'knee' <value_type>: from_file is not supported",
        ),
        (
            '<IKMarkerTask name="A"><weight>heavy</weight></IKMarkerTask>',
            "IKMarkerTask 'A' <weight>: expected a number, got 'heavy'",
        ),
    ]
    for body, message in cases:
        p = _write(tmp_path, f"<InverseKinematicsTool>{task.format(body)}</InverseKinematicsTool>")
        with pytest.raises(FileFormatError, match=message):
            read_ik_setup(p)
    p = _write(
        tmp_path, "<InverseKinematicsTool><time_range>2 1</time_range></InverseKinematicsTool>"
    )
    with pytest.raises(FileFormatError, match="<time_range> must end after it starts"):
        read_ik_setup(p)
    p = tmp_path / "broken.xml"
    p.write_text("<InverseKinematicsTool>")
    with pytest.raises(FileFormatError, match="not an XML file"):
        read_ik_setup(p)


def test_unassigned_weights_are_set_apart(tmp_path: Path) -> None:
    p = _write(
        tmp_path,
        "<InverseKinematicsTool><IKTaskSet><objects>"
        '<IKMarkerTask name="A"><apply>false</apply><weight>5</weight></IKMarkerTask>'
        '<IKCoordinateTask name="k"><apply>true</apply><value_type>manual_value</value_type>'
        "<value>0.25</value><weight>3</weight></IKCoordinateTask>"
        '<IKCoordinateTask name="off"><apply>false</apply></IKCoordinateTask>'
        "</objects></IKTaskSet><model_file>Unassigned</model_file></InverseKinematicsTool>",
    )
    setup = read_ik_setup(p)
    assert setup.marker_weights == {"A": 0.0}  # apply false: not fitted
    assert setup.coordinate_tasks == {"k": (0.25, 3.0)}
    assert setup.time_range is None
    assert setup.model_file is None
