"""The live viewer in a real headless Chromium: open the page, click, check a screenshot.

The session is the live teleoperation session (``mocapkit.teleop.live``) fed by a simulated
suit (a sender process over UDP, receiver, host-side filters, body model, retargeting,
robot-server process); the browser is Debian's Chromium through chromedriver.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import pytest

from mocapkit.teleop.simulated import SimulatedConfig, SimulatedSession
from mocapkit.viz.live_api import LiveSnapshot
from tests.viz.browser import chromium, color_pixels, free_port, png_rgb, save_artifact

pytest.importorskip("viser", reason="the viewer needs the viz extra (pip install -e '.[viz]')")

from mocapkit.viz.viewer import ROBOT_RGB, SKELETON_RGB, TeleopViewer

# runs live processes and sockets against the clock: run serially (see Makefile)
pytestmark = pytest.mark.realtime

__all__ = ["chromium"]  # the fixture, imported for pytest


def _wait(cond: Callable[[], Any], timeout_s: float, what: str) -> Any:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        value = cond()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")


_FIND_BUTTON = """
return Array.from(document.querySelectorAll('button'))
    .find(b => b.innerText.trim() === arguments[0] && b.offsetParent !== null) || null;
"""


def _click(driver: Any, element: Any) -> None:
    """A real pointer click (move, press, release) on the element. (WebElement.click()
    first waits for the page to settle, which a live 3-D page never does: ~10 s.)"""
    from selenium.webdriver.common.action_chains import ActionChains

    ActionChains(driver).move_to_element(element).click().perform()


def _button(driver: Any, label: str) -> Any:
    """The visible button with this label, or None (one script call: the page is busy
    rendering in software WebGL, so element-by-element queries are slow)."""
    return driver.execute_script(_FIND_BUTTON, label)


@pytest.mark.slow
def test_viewer_page_buttons_drive_the_session_and_the_scene_renders(chromium: Any) -> None:
    sim = SimulatedSession(SimulatedConfig(shapes=("circle",)))

    def snap() -> LiveSnapshot:
        return LiveSnapshot.from_mapping(sim.snapshot())

    with sim, TeleopViewer(sim, port=free_port()) as viewer:
        viewer.start()
        chromium.get(viewer.url)
        engage = _wait(lambda: _button(chromium, "Engage"), 60, "the Engage button")
        _wait(
            lambda: snap().calibrated or "failed" in snap().message,
            30,
            "the automatic body calibration",
        )
        assert snap().calibrated, snap().message
        assert snap().state == "disabled"
        # the operator is still in the N-pose: wait for the hand at the working point
        span = sim.cycle.spans[0]
        _wait(lambda: sim.motion_time >= span.engage_t, 30, "the working point")
        _click(chromium, engage)
        # the click travels browser -> websocket -> viewer -> session (receiver thread)
        _wait(lambda: viewer.commands, 20, "the click to reach the viewer")
        assert viewer.commands[0] == ("engage", "engage: aligning")
        assert sim.live is not None
        transitions = sim.live.session.transitions
        _wait(
            lambda: any(t.reason == "operator engaged" for t in transitions),
            10,
            "the session to engage",
        )
        _wait(lambda: snap().state == "engaged", 10, "the robot to be aligned")
        _click(chromium, _button(chromium, "Reindex"))
        _wait(lambda: len(viewer.commands) >= 2, 20, "the Reindex click")
        assert viewer.commands[1][0] == "reindex"
        assert viewer.commands[1][1].startswith("reindex: ")  # the session answered
        # the robot has reported and the page has had time to draw the latest scene
        _wait(lambda: snap().robot_q is not None, 10, "a robot report")
        assert {s.name for s in snap().segments} == {"torso", "humerus_r", "radius_r"}
        assert len(snap().sensors) == 3
        n = viewer.updates
        _wait(lambda: viewer.updates > n + 20, 20, "viewer updates")
        time.sleep(1.5)
        page_text = chromium.execute_script("return document.body.innerText")
        png = chromium.get_screenshot_as_png()
    path = save_artifact("viewer_chromium.png", png)
    rgb = png_rgb(png)
    h, w, _ = rgb.shape
    assert (h, w) == (800, 1280) or (h > 400 and w > 600), f"screenshot {w}x{h}, saved to {path}"
    # the 3-D canvas: the left 60 % of the page below the notification area (the GUI
    # panel is on the right); a blank or failed WebGL canvas is uniformly white
    canvas = rgb[int(0.25 * h) :, : int(0.6 * w)]
    assert canvas.std() > 5.0, f"the canvas looks blank (std {canvas.std():.1f}); see {path}"
    # both figures are drawn in their colours (lines are unlit: the colour survives)
    robot = color_pixels(canvas, ROBOT_RGB)
    skeleton = color_pixels(canvas, SKELETON_RGB)
    assert robot > 150, f"robot arm not visible: {robot} orange pixels; see {path}"
    assert skeleton > 150, f"skeleton not visible: {skeleton} blue pixels; see {path}"
    # the GUI panel shows the controls and the gauges
    for label in ("Calibrate", "Engage", "Disengage", "Reindex", "Packet loss", "Latency p99"):
        assert label in page_text, f"{label!r} not on the page; see {path}"
