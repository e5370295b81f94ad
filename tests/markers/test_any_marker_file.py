"""Marker files no preset knows, stature without a head, static trials that are not: the
paths a new user meets (issue 10, "Any marker file" and "Silent bad results")."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from mocapkit.body.markerset_auto import auto_markerset, classify_label
from mocapkit.errors import ConfigError, DataError
from mocapkit.io.c3d import write_c3d
from mocapkit.io.trc import read_trc, write_trc
from mocapkit.markers.reconstruct import ReconstructionOptions, run
from mocapkit.markers.trajectories import MarkerTrajectories
from tests.conftest import TEST_DATA
from tests.markers import synthetic

RAJAGOPAL = TEST_DATA / "trc" / "markers_walk_excerpt.trc"  # OpenSim's Rajagopal example


@pytest.mark.parametrize(
    ("label", "segment"),
    [("R.ASIS", "pelvis"), ("LASI", "pelvis"), ("S2", "pelvis"), ("L.TH3", "thigh_l"),
     ("RKNE", "thigh_r"), ("R.MKnee", "thigh_r"), ("L.SH2", "shank_l"), ("RTIB", "shank_r"),
     ("L.MAnkle", "shank_l"), ("RHEE", "foot_r"), ("L.MT5", "foot_l"), ("Sternum", "thorax"),
     ("C7", "thorax"), ("RBAK", "thorax"), ("LFHD", "head"), ("R.Shoulder", "clavicle_r"),
     ("L.Elbow", "upper_arm_l"), ("RWRB", "forearm_r"), ("rASIS", "pelvis"),
     ("Left_Knee", "thigh_l"), ("MidASIS", None), ("L.HeelGround", None)],
)  # fmt: skip
def test_labels_name_segments(label: str, segment: str | None) -> None:
    assert classify_label(label).segment == segment


def test_rigid_clusters_place_unknown_labels_and_fix_wrong_ones() -> None:
    human, ms = synthetic.subject(1.8)
    names = [n for n in ms.names if n.startswith(("R.", "L.", "V.", "Top", "Stern"))]
    Q = synthetic.motion(human, n=60, amplitude=0.6)
    X = synthetic.markers(human, names, Q)
    labels = list(names)
    labels[labels.index("R.Thigh.Front")] = "Marker17"  # a label that names nothing
    labels[labels.index("L.Heel")] = "L.Knee.Extra"  # a label that names the wrong segment
    auto, report = auto_markerset(labels, X)
    seg = {m.name: m.segment for m in auto.markers}
    assert seg["Marker17"] == "thigh_r"  # moves rigidly with the right thigh's markers
    assert seg["L.Knee.Extra"] == "foot_l"  # "Knee" says thigh, the motion says foot
    assert set(report.clusters) == {"Marker17", "L.Knee.Extra"}
    assert (seg["R.ASIS"], seg["L.Shank.Rear"]) == ("pelvis", "shank_l")


def test_unknown_set_is_assigned_and_reported(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING):
        result, subject, _ = run(
            RAJAGOPAL, None, None, 1.8, 75.0, ReconstructionOptions(method="ik")
        )
    assert "no preset knows these labels" in caplog.text
    assert "pelvis: R.ASIS, L.ASIS, R.PSIS, S2, L.PSIS" in caplog.text
    assert subject.markerset.name == "auto"
    for c in ("hip_flexion_r", "knee_angle_l", "ankle_angle_r"):
        assert np.isfinite(result.column(c)).all(), c
    # 20 frames of a walk, lengths from the motion alone: a fit of a few millimetres
    assert result.metrics()["marker_rms_mm"] < 15.0


def test_no_lower_limbs_is_an_error_with_the_yaml_to_write(tmp_path: Path) -> None:
    traj = read_trc(RAJAGOPAL)
    keep = [n for n in traj.names if not n.startswith(("L.SH", "L.Ankle", "L.Heel", "L.Toe",
                                                       "L.MT"))]  # fmt: skip
    p = write_trc(tmp_path / "no_left_shank.trc", traj.select(keep))
    with pytest.raises(DataError) as err:
        run(p, None, None, 1.8, 75.0, ReconstructionOptions(method="ik"))
    msg = str(err.value)
    assert "no marker of the trial could be placed on shank_l, foot_l" in msg
    assert "R.ASIS: {segment: pelvis" in msg  # the YAML, segments found so far
    assert "pass --markerset FILE" in msg


def test_stature_without_head_markers(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """The Rajagopal set has no head markers: the stature comes from the shoulders, said
    loudly; without shoulders either, it is refused."""
    with caplog.at_level(logging.WARNING):
        run(RAJAGOPAL, None, None, None, None, ReconstructionOptions(method="ik"))
    assert "NO HEAD MARKERS: the stature" in caplog.text
    traj = read_trc(RAJAGOPAL)
    keep = [n for n in traj.names if "Shoulder" not in n and "Clavicle" not in n]
    p = write_trc(tmp_path / "no_top.trc", traj.select(keep))
    with pytest.raises(DataError, match="no head or shoulder markers .* pass --height-m"):
        run(p, None, None, None, None, ReconstructionOptions(method="ik"))


def test_static_trials_that_are_not(shared_data: Path, tmp_path: Path) -> None:
    gait = shared_data / "opensim" / "gait2392"
    walk = gait / "subject01_walk1.trc"
    opts = ReconstructionOptions(method="ik", end_s=0.3)
    with pytest.raises(ConfigError, match="is the trial itself"):
        run(walk, walk, "gait2392", 1.8, 72.6, opts)
    copy = tmp_path / "walk_copy.trc"
    copy.write_bytes(walk.read_bytes())
    with pytest.raises(DataError, match="not a static trial: its stillest 0.5 s still moves"):
        run(walk, copy, "gait2392", 1.8, 72.6, opts)


def test_static_a_little_off_is_used_with_a_warning(
    shared_data: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """OpenSim uses a static trial whose marker distances differ by 17 mm; so do we, and
    say so (refused above 40 mm, another subject or swapped labels)."""
    gait = shared_data / "opensim" / "gait2392"
    static = read_trc(gait / "subject01_static.trc")
    pos = static.positions.copy()
    a, b = static.index("R.Thigh.Rear"), static.index("R.Thigh.Upper")
    away = pos[:, a] - pos[:, b]
    pos[:, a] += 0.02 * away / np.linalg.norm(away, axis=1, keepdims=True)  # 20 mm further
    p = write_trc(tmp_path / "s.trc", MarkerTrajectories(static.time, pos, static.names,
                                                         meta={"rate_hz": 60.0}))  # fmt: skip
    with caplog.at_level(logging.WARNING):
        run(gait / "subject01_walk1.trc", p, "gait2392", 1.8, 72.6,
            ReconstructionOptions(method="ik", end_s=0.3))  # fmt: skip
    assert "the static trial and the trial differ: markers" in caplog.text


def test_plugin_gait_is_recognised_and_exact(tmp_path: Path) -> None:
    """A Plug-in Gait C3D (exact synthetic markers, z-up, mm, Vicon's subject prefix) is
    read with the plugin_gait preset and its joint angles come back."""
    from mocapkit.body.human_model import build_human_model
    from mocapkit.body.markersets import load_markerset

    ms = load_markerset("plugin_gait")
    human = build_human_model(1.75, 70.0).with_markers(ms.placements(1.75, {}))
    names = [n for n in ms.names if n not in ("SACR",)]
    Q = synthetic.motion(human, n=90, rate=100.0, amplitude=0.3)
    X = synthetic.markers(human, names, Q)
    traj = MarkerTrajectories(np.arange(90) / 100.0, X, tuple(f"Sub01:{n}" for n in names),
                              meta={"rate_hz": 100.0})  # fmt: skip
    p = write_c3d(tmp_path / "pig.c3d", traj)
    result, subject, _ = run(p, None, None, 1.75, 70.0, ReconstructionOptions(method="ik"))
    assert subject.markerset.name == "plugin_gait"
    knee = np.degrees(result.column("knee_angle_r"))
    truth = np.degrees(Q[:, human.dof_index("knee_angle_r") + 1])
    # lengths and offsets estimated from 0.9 s of exact markers: within a couple of degrees
    assert np.sqrt(np.mean((knee - truth) ** 2)) < 3.0
