"""The viewer without a browser: what it shows for a snapshot, what its buttons call."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from mocapkit.errors import DataError, MissingDependencyError
from mocapkit.robot.robonaut2 import robonaut2_arm
from mocapkit.viz.geometry import arm_points, polyline_segments
from mocapkit.viz.live_api import LiveSession, LiveSnapshot, SegmentPose, SensorPose
from tests.viz.browser import free_port

# runs live processes and sockets against the clock: run serially (see Makefile)
pytestmark = pytest.mark.realtime

viser = pytest.importorskip("viser", reason="the viewer needs the viz extra")

from mocapkit.viz.viewer import TeleopViewer, import_viser  # noqa: E402


class RecordedSession:
    """A session replaying fixed snapshots: the viewer's own logic under test (the live
    chain is tested in test_viewer_browser.py and tests/demo)."""

    def __init__(self, snap: LiveSnapshot) -> None:
        self.snap = snap
        self.calls: list[str] = []

    def calibrate(self) -> str:
        self.calls.append("calibrate")
        raise DataError("sensor 'forearm_r' moved during the calibration pose")

    def engage(self) -> str:
        self.calls.append("engage")
        return "engage: aligning"

    def disengage(self) -> str:
        self.calls.append("disengage")
        return "disengage: disabled"

    def reindex(self) -> str:
        self.calls.append("reindex")
        return "reindex: engaged"

    def snapshot(self) -> LiveSnapshot:
        return self.snap


def _snapshot() -> LiveSnapshot:
    arm = robonaut2_arm("right")
    T = arm.fk(arm.q_ref)
    seg = SegmentPose(
        "torso", np.array([0, 0, 1.0]), np.array([0, 0, 1.45]), np.array([1.0, 0, 0, 0])
    )
    sensor = SensorPose("torso", np.array([0, 0, 1.2]), np.array([0.0, 1.0, 0.0, 0.0]))
    return LiveSnapshot(
        t_s=3.0, state="engaged", safety="robot gate synced (ok)", calibrated=True,
        latency_ms_p50=1.25, latency_ms_p99=4.5, packet_loss=0.012, packets=1234,
        segments=(seg,), sensors=(sensor,), robot_q=arm.q_ref.copy(), ee_command=T,
        ee_actual=T, message="calibrated",
    )  # fmt: skip


def test_update_shows_the_snapshot() -> None:
    session = RecordedSession(_snapshot())
    assert isinstance(session, LiveSession)
    with TeleopViewer(session, port=free_port()) as v:
        v.update()
        assert v.state.value == "engaged"
        assert v.safety.value == "robot gate synced (ok)"
        assert v.latency_p50.value == pytest.approx(1.25)
        assert v.latency_p99.value == pytest.approx(4.5)
        assert v.latency_bar.value == pytest.approx(100 * 4.5 / 20.0)
        assert v.loss.value == pytest.approx(1.2)
        assert v.packets.value == 1234
        arm = robonaut2_arm("right")
        expected = polyline_segments(arm_points(arm, arm.q_ref))
        np.testing.assert_allclose(v.robot_links.points, expected, atol=1e-6)  # float32
        np.testing.assert_allclose(v.bones.points[0], [[0, 0, 1.0], [0, 0, 1.45]], atol=1e-6)
        np.testing.assert_allclose(v.ee_command.position, arm.fk(arm.q_ref)[:3, 3], atol=1e-9)
        assert v._sensor_handles["torso"].wxyz == pytest.approx((0.0, 1.0, 0.0, 0.0))


def test_buttons_call_the_session_and_show_failures() -> None:
    session = RecordedSession(_snapshot())
    with TeleopViewer(session, port=free_port()) as v:
        assert v.command("engage") == "engage: aligning"
        msg = v.command("calibrate")
        assert msg.startswith("calibrate failed: sensor 'forearm_r' moved")
        assert v.message.value == msg
        assert session.calls == ["engage", "calibrate"]
        assert set(v.buttons) == {"calibrate", "engage", "disengage", "reindex"}


def test_missing_viser_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "viser", None)
    with pytest.raises(MissingDependencyError, match=r"pip install 'mocapkit\[viz\]'"):
        import_viser()


def test_a_status_mapping_becomes_a_snapshot() -> None:
    # the layout the teleoperation package's live session publishes (JSON-ready values)
    arm = robonaut2_arm("right")
    d = {
        "t": 12.5,
        "state": "held",
        "calibration": "done",
        "fault": "sensor 2: stale for 0.31 s (dropout?)",
        "transitions": [{"t": 12.0, "from": "engaged", "to": "held", "reason": "sensor 2 stale"}],
        "latency_ms": {"p50": 0.8, "p99": None, "n": 10},
        "safety": {"robot_gate": "HOLDING", "robot_reason": "HOLD_REQUESTED",
                   "session_fault": "sensor 2: stale"},
        "robot_joints_deg": dict(zip(arm.joint_names, np.degrees(arm.q_ref), strict=True)),
        "ee_commanded": None,
        "ee_actual": {"pos": [0.6, -0.3, -0.1], "quat": [1.0, 0.0, 0.0, 0.0]},
        "packet_loss": 0.25,
        "sensors": {
            "forearm_r": {"delivered": 30, "segment": "radius_r", "quat": [0.0, 1.0, 0.0, 0.0]},
            "upper_arm_r": {"delivered": 40, "segment": "humerus_r", "quat": None},
        },
        "segments": [{"name": "radius_r", "start": [0.0, -0.2, 1.1], "end": [0.0, -0.2, 0.9],
                      "quat": [1.0, 0.0, 0.0, 0.0]}],
    }  # fmt: skip
    s = LiveSnapshot.from_mapping(d)
    assert s.state == "held"
    assert s.calibrated
    assert s.safety == "sensor 2: stale; robot gate holding (hold_requested)"
    assert s.latency_ms_p50 == pytest.approx(0.8)
    assert np.isnan(s.latency_ms_p99)
    assert s.packets == 70
    assert s.robot_q is not None
    np.testing.assert_allclose(s.robot_q, arm.q_ref, atol=1e-12)
    assert s.ee_command is None
    assert s.ee_actual is not None
    np.testing.assert_allclose(s.ee_actual[:3, 3], [0.6, -0.3, -0.1])
    assert s.transitions == ("engaged -> held: sensor 2 stale",)
    assert [seg.name for seg in s.segments] == ["radius_r"]
    # a sensor with an orientation is drawn in the middle of its (drawn) segment; one
    # without (lost) is not
    assert [sp.name for sp in s.sensors] == ["forearm_r"]
    np.testing.assert_allclose(s.sensors[0].position, [0.0, -0.2, 1.0])
    np.testing.assert_allclose(s.sensors[0].q_world_sensor, [0.0, 1.0, 0.0, 0.0])
    assert s.message.startswith("sensor 2: stale for 0.31 s")

    class MappingSession(RecordedSession):
        def snapshot(self) -> dict:  # type: ignore[override]
            return d

        def engage(self) -> None:  # type: ignore[override]
            self.calls.append("engage")

    with TeleopViewer(MappingSession(_snapshot()), port=free_port()) as v:
        assert v.update().state == "held"
        assert v.command("engage") == "engage: done"


@pytest.mark.slow
def test_viewer_cli_serves_a_live_session_and_prints_its_figures(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``mocapkit viewer --seconds`` in-process: the simulated session streams, calibrates
    itself in the N-pose, nobody engages; the summary says so."""
    import json

    from mocapkit.cli.main import main

    port = free_port()
    argv = ["viewer", "--seconds", "3", "--port", str(port), "--shapes", "circle", "--json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["url"] == f"http://127.0.0.1:{port}/"
    assert out["filter"] == "bachmann"
    assert out["state"] == "disabled"  # the viewer's operator engages with the button
    assert out["packets"] > 3 * 100  # three sensors at 100 Hz for about 3 s
    assert out["packet_loss"] == 0.0  # loopback
    assert out["commands"] == []
    assert out["latency_ms_p50"] is None  # no command sent: no pipeline time
    assert 2.5 < out["seconds"] < 10.0
