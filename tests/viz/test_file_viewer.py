"""``mocapkit view``: files as tracks on a timeline; in a real headless Chromium, the body
and the robot drawn side by side and moving when played."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from tests.viz.browser import chromium, color_pixels, free_port, png_rgb, save_artifact
from tests.viz.test_viewer_browser import _FIND_BUTTON, _wait

pytest.importorskip("viser", reason="the viewer needs the viz extra (pip install -e '.[viz]')")
pytest.importorskip("pinocchio")

from mocapkit.viz.file_viewer import FileViewer
from mocapkit.viz.tracks import HumanTrack, RobotTrack, frame_at, load_track
from mocapkit.viz.viewer import ROBOT_RGB, SKELETON_RGB

__all__ = ["chromium"]


@pytest.fixture(scope="module")
def walk_files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A synthetic walk as a .mot and its G1 retargeting as an .npz."""
    from mocapkit.retarget.run import retarget, write_trajectory
    from tests.body.synth import write_walk_mot

    d = tmp_path_factory.mktemp("view")
    mot = write_walk_mot(d / "walk.mot", duration_s=4.0, still_s=1.0)
    npz = write_trajectory(d / "walk_g1.npz", retarget(mot, "g1"))
    return Path(mot), Path(npz)


def test_tracks_from_a_mot_and_a_robot_trajectory(walk_files, tmp_path):
    mot, npz = walk_files
    human = load_track(mot)
    robot = load_track(npz)
    assert isinstance(human, HumanTrack)
    assert isinstance(robot, RobotTrack)
    assert len(human.bones()) == 14
    assert robot.q.shape == (human.time.size, robot.robot.model.nq)
    assert frame_at(human.time, -1.0) == 0
    assert frame_at(human.time, 1e9) == human.time.size - 1
    assert frame_at(human.time, float(human.time[10]) + 1e-9) == 10
    csv = tmp_path / "g1.csv"
    csv.write_text("time,base_x\n0,0\n")
    with pytest.raises(ConfigError, match="give --robot"):
        load_track(csv)


def test_a_file_it_cannot_read_is_named_and_the_others_shown(walk_files, tmp_path):
    mot, _ = walk_files
    bad = tmp_path / "bad.bvh"
    bad.write_text("not a bvh")
    with FileViewer(port=free_port()) as v:
        v.load([bad, mot, tmp_path / "missing.mot"])
        assert [tr.name for tr in v.tracks] == ["walk.mot"]
        assert [Path(p).name for p, _ in v.failed] == ["bad.bvh", "missing.mot"]
        assert "HIERARCHY" in v.failed[0][1]
        n = v.frames_drawn
        v.draw(2.0)
        assert v.frames_drawn == n + 1
    with FileViewer(port=free_port()) as v, pytest.raises(ConfigError, match="nothing to show"):
        v.load([bad])


@pytest.mark.realtime
@pytest.mark.slow
def test_view_in_chromium_plays_the_body_beside_the_robot(walk_files, chromium: Any) -> None:
    from selenium.webdriver.common.action_chains import ActionChains

    mot, npz = walk_files
    with FileViewer(port=free_port()) as v:
        v.load([mot, npz])
        v.start()
        v.draw(1.5)
        chromium.get(v.url)
        play = _wait(lambda: chromium.execute_script(_FIND_BUTTON, "Play"), 60, "Play")
        time.sleep(3.0)
        first = png_rgb(chromium.get_screenshot_as_png())
        t_before = v.t
        ActionChains(chromium).move_to_element(play).click().perform()
        _wait(lambda: v.playing, 20, "the Play click to reach the viewer")
        _wait(lambda: v.t > t_before + 1.0, 20, "the timeline to move")
        time.sleep(1.0)
        png = chromium.get_screenshot_as_png()
    path = save_artifact("view_chromium.png", png)
    second = png_rgb(png)
    h, w, _ = second.shape
    canvas = second[int(0.25 * h) :, : int(0.6 * w)]
    assert canvas.std() > 5.0, f"the canvas looks blank; see {path}"
    assert color_pixels(canvas, SKELETON_RGB, tol=70) > 150, f"no body drawn; see {path}"
    assert color_pixels(canvas, ROBOT_RGB, tol=70) > 150, f"no robot drawn; see {path}"
    before = first[int(0.25 * h) :, : int(0.6 * w)].astype(int)
    changed = np.abs(before - canvas.astype(int)).sum(axis=2) > 60
    assert changed.sum() > 500, f"nothing moved while playing; see {path}"


def test_cli_view_json_names_what_it_showed(walk_files, tmp_path, capsys):
    import json

    from mocapkit.cli.main import main

    mot, npz = walk_files
    bad = tmp_path / "bad.trc"
    bad.write_text("nonsense")
    code = main(["view", str(mot), str(npz), str(bad), "--port", str(free_port()),
                 "--seconds", "0.3", "--json"])  # fmt: skip
    assert code == 0
    out = json.loads(capsys.readouterr().out)  # stdout is the JSON alone
    assert [(s["file"], s["kind"]) for s in out["shown"]] == [
        ("walk.mot", "human"),
        ("walk_g1.npz", "robot"),
    ]
    assert out["failed"][0]["file"].endswith("bad.trc")
