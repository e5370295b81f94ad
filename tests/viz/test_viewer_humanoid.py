"""The live viewer with a humanoid: the simulated operator drives Unitree G1 through the
live session, and the viewer draws G1 from its meshes at the reported joints."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tests.viz.browser import free_port

pytest.importorskip("viser", reason="the viewer needs the viz extra (pip install -e '.[viz]')")
pytest.importorskip("pinocchio")

from mocapkit.teleop.simulated import SimulatedConfig, SimulatedSession
from mocapkit.viz.viewer import TeleopViewer

pytestmark = pytest.mark.realtime


def test_live_viewer_draws_the_humanoid_following_the_operator() -> None:
    cfg = SimulatedConfig(shapes=("circle",), robot="g1", auto_engage=True, duration_s=30.0)
    with SimulatedSession(cfg) as sim, TeleopViewer(sim, port=free_port()) as viewer:
        end = time.monotonic() + 40.0
        while sim.snapshot()["state"] != "engaged" and time.monotonic() < end:
            time.sleep(0.1)
        assert sim.snapshot()["state"] == "engaged", sim.snapshot().get("message")
        viewer.update()
        meshes = viewer._humanoid
        assert meshes is not None
        assert len(meshes.handles) > 20  # G1's links
        assert not viewer.robot_links.visible  # the arm's drawing is hidden
        elbow = next(h for g, h in meshes.handles
                     if "right_elbow" in meshes.gm.geometryObjects[g].name)  # fmt: skip
        p0 = np.array(elbow.position)
        moved = 0.0
        for _ in range(30):
            time.sleep(0.1)
            viewer.update()
            moved = max(moved, float(np.linalg.norm(np.array(elbow.position) - p0)))
        assert moved > 0.02, "G1's right elbow did not follow the operator's circle"
