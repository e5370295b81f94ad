"""Live web viewer for teleoperation (viser): skeleton, robot arm, sensor frames, controls.

``TeleopViewer(session).serve()`` opens a web page (``viewer.url``) showing

- the operator's skeleton (segments from the body model's orientations, blue) and the
  sensor frames (small axes, the fused ``q_world_sensor`` drawn on each segment);
- the robot arm beside it (its reported joints through ``mocapkit.robot`` forward
  kinematics: links as an orange polyline, joints as spheres) with two end-effector
  frames, commanded (large) and reported (small), in the robot's chest frame;
- buttons Calibrate, Engage, Disengage, Reindex, which call the session's methods;
- gauges: state, safety, pipeline latency p50/p99 (numbers and a bar against a 20 ms
  budget), packet loss (number and bar), packets, and the latest message.

The session is anything that satisfies :class:`mocapkit.viz.live_api.LiveSession`.
viser is the ``viz`` extra and is imported only here, when a viewer is made.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from mocapkit.errors import MissingDependencyError, MocapkitError
from mocapkit.geometry import quat_from_matrix
from mocapkit.robot.model import ArmModel
from mocapkit.viz.geometry import arm_frames, arm_points, polyline_segments
from mocapkit.viz.live_api import LiveSession, LiveSnapshot
from mocapkit.viz.robot_meshes import ROBOT_RGB, RobotMeshes, full_configuration

log = logging.getLogger("mocapkit.viz.viewer")

SKELETON_RGB = (40, 90, 220)
LATENCY_BUDGET_MS = 20.0
_MAX_SEGMENTS = 32


def import_viser() -> Any:
    """The viser module, or a :class:`MissingDependencyError` with the install hint."""
    try:
        import viser
    except ImportError as exc:
        raise MissingDependencyError(
            "the live viewer needs viser: pip install 'mocapkit[viz]'"
        ) from exc
    return viser


class TeleopViewer:
    """See the module docstring.

    Args:
        session: the live session to show and drive.
        host, port: where the web server listens (port busy: viser takes the next one).
        robot_origin: where the robot's chest frame is drawn in the viewer's world [m].
        update_hz: how often the scene follows the session.
    """

    def __init__(
        self,
        session: LiveSession,
        host: str = "127.0.0.1",
        port: int = 8080,
        robot_origin: tuple[float, float, float] = (0.0, -1.2, 1.35),
        update_hz: float = 20.0,
    ) -> None:
        viser = import_viser()
        self.session = session
        # viser prints its address banner on stdout whatever ``verbose`` says: keep stdout
        # for the command's own output (``--json``)
        with contextlib.redirect_stdout(sys.stderr):
            self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.url = f"http://{host}:{self.server.get_port()}/"
        self.robot_origin = np.asarray(robot_origin, dtype=float)
        self.update_hz = update_hz
        self.commands: list[tuple[str, str]] = []
        """(command, message) for every button press, oldest first."""
        self.updates = 0
        self._arm: ArmModel | None = None
        self._humanoid: RobotMeshes | None = None
        self._arm_frames: tuple[str, ...] = ()
        self._sensor_handles: dict[str, Any] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._build_gui()
        self._build_scene()

    # -- construction ---------------------------------------------------------------------
    def _build_gui(self) -> None:
        gui = self.server.gui
        gui.configure_theme(control_width="large")
        with gui.add_folder("Session"):
            buttons: list[tuple[str, str, str]] = [
                ("Calibrate", "calibrate", "take the body calibration (hold the N-pose)"),
                ("Engage", "engage", "start sending commands (relative control)"),
                ("Disengage", "disengage", "stop sending commands"),
                ("Reindex", "reindex", "take a new offset between hand and robot"),
            ]
            self.buttons = {}
            for label, method, hint in buttons:
                btn = gui.add_button(label, hint=hint)
                btn.on_click(self._on_click(method))
                self.buttons[method] = btn
        with gui.add_folder("Status"):
            self.state = gui.add_text("State", "starting", disabled=True)
            self.safety = gui.add_text("Safety", "", disabled=True)
            self.latency_p50 = gui.add_number("Latency p50 [ms]", 0.0, step=0.001, disabled=True)
            self.latency_p99 = gui.add_number("Latency p99 [ms]", 0.0, step=0.001, disabled=True)
            self.latency_bar = gui.add_progress_bar(0.0, color="teal")
            self.loss = gui.add_number("Packet loss [%]", 0.0, step=0.001, disabled=True)
            self.loss_bar = gui.add_progress_bar(0.0, color="red")
            self.packets = gui.add_number("Packets", 0, disabled=True)
            self.message = gui.add_text("Message", "", multiline=True, disabled=True)

    def _build_scene(self) -> None:
        scene = self.server.scene
        scene.set_up_direction("+z")
        # in front of the operator (who faces +x), a little above, both figures in view
        self.server.initial_camera.position = (3.2, -0.3, 2.0)
        self.server.initial_camera.look_at = (0.0, -0.6, 1.1)
        scene.add_grid("/ground", width=4.0, height=4.0, cell_size=0.25, position=(0.0, -0.6, 0.0))
        empty = np.zeros((_MAX_SEGMENTS, 2, 3), dtype=np.float32)
        self.bones = scene.add_line_segments("/human/bones", empty, SKELETON_RGB, thickness=0.035)
        self.robot_base = scene.add_frame(
            "/robot", axes_length=0.15, axes_radius=0.008, position=tuple(self.robot_origin)
        )
        self.robot_links = scene.add_line_segments(
            "/robot/links", np.zeros((1, 2, 3), dtype=np.float32), ROBOT_RGB, thickness=0.04
        )
        self.robot_joints: list[Any] = []
        self.ee_command = scene.add_frame(
            "/robot/ee_command", axes_length=0.12, axes_radius=0.008, visible=False
        )
        self.ee_actual = scene.add_frame("/robot/ee_actual", axes_length=0.07, axes_radius=0.005)
        scene.add_label("/robot/label", "robot chest frame", position=(0.0, 0.0, 0.25))
        scene.add_label("/human/label", "operator", position=(0.0, 0.0, 2.0))

    def _on_click(self, method: str) -> Callable[[Any], None]:
        def handler(_event: Any) -> None:
            self.command(method)

        return handler

    # -- commands and updates ---------------------------------------------------------------
    def command(self, method: str) -> str:
        """Call a session method (what the buttons do) and show its message."""
        try:
            result = getattr(self.session, method)()
            msg = result if isinstance(result, str) else f"{method}: done"
        except MocapkitError as exc:
            msg = f"{method} failed: {exc}"
        except TimeoutError:
            msg = f"{method}: the session did not answer"
        log.info("viewer command %s: %s", method, msg)
        self.commands.append((method, msg))
        self.message.value = msg
        return msg

    def _arm_for(self, name: str) -> ArmModel:
        if self._arm is None or self._arm.name != name:
            from mocapkit.robot.registry import robot_arm

            self._arm = robot_arm(name)
            self._arm_frames = arm_frames(self._arm)
            for h in self.robot_joints:
                h.remove()
            self.robot_joints = [
                self.server.scene.add_icosphere(
                    f"/robot/joint_{k}", radius=0.035, color=ROBOT_RGB, subdivisions=2
                )
                for k in range(len(self._arm_frames))
            ]
        return self._arm

    def update(self) -> LiveSnapshot:
        """Pull one snapshot from the session and show it."""
        raw = self.session.snapshot()
        snap = raw if isinstance(raw, LiveSnapshot) else LiveSnapshot.from_mapping(raw)
        with self.server.atomic():
            self._show_gauges(snap)
            self._show_human(snap)
            self._show_robot(snap)
        self.updates += 1
        return snap

    def _show_gauges(self, s: LiveSnapshot) -> None:
        self.state.value = s.state
        self.safety.value = s.safety
        p50 = 0.0 if not np.isfinite(s.latency_ms_p50) else round(s.latency_ms_p50, 3)
        p99 = 0.0 if not np.isfinite(s.latency_ms_p99) else round(s.latency_ms_p99, 3)
        self.latency_p50.value = p50
        self.latency_p99.value = p99
        self.latency_bar.value = float(min(100.0, 100.0 * p99 / LATENCY_BUDGET_MS))
        self.loss.value = round(100.0 * s.packet_loss, 3)
        self.loss_bar.value = float(min(100.0, 100.0 * s.packet_loss))
        self.packets.value = int(s.packets)
        if s.message and not self.commands:
            self.message.value = s.message

    def _show_human(self, s: LiveSnapshot) -> None:
        pts = np.zeros((_MAX_SEGMENTS, 2, 3), dtype=np.float32)
        for k, seg in enumerate(s.segments[:_MAX_SEGMENTS]):
            pts[k, 0], pts[k, 1] = seg.start, seg.end
        self.bones.points = pts
        for sensor in s.sensors:
            h = self._sensor_handles.get(sensor.name)
            if h is None:
                h = self._sensor_handles[sensor.name] = self.server.scene.add_frame(
                    f"/human/sensors/{sensor.name}", axes_length=0.1, axes_radius=0.006
                )
            if np.isfinite(sensor.q_world_sensor).all():
                h.wxyz = tuple(sensor.q_world_sensor)
                h.position = tuple(sensor.position)

    def _show_robot(self, s: LiveSnapshot) -> None:
        if s.robot_q is None:
            return
        from mocapkit.robot.registry import available_robots

        if s.robot_name not in available_robots():
            self._show_humanoid(s)
            return
        arm = self._arm_for(s.robot_name)
        pts = arm_points(arm, s.robot_q, self._arm_frames)
        self.robot_links.points = polyline_segments(pts).astype(np.float32)
        for h, p in zip(self.robot_joints, pts, strict=True):
            h.position = tuple(p)
        for handle, T in ((self.ee_command, s.ee_command), (self.ee_actual, s.ee_actual)):
            if T is None:
                handle.visible = False
                continue
            handle.visible = True
            handle.position = tuple(np.asarray(T)[:3, 3])
            handle.wxyz = tuple(quat_from_matrix(np.asarray(T)[:3, :3]))

    def _show_humanoid(self, s: LiveSnapshot) -> None:
        """A humanoid from its meshes at its reported base pose and joints, standing on the
        ground beside the operator (the arm's lines and frames hidden)."""
        if self._humanoid is None or self._humanoid.robot.spec.name != s.robot_name:
            from mocapkit.retarget.robot_model import build_humanoid
            from mocapkit.retarget.robot_spec import load_robot_spec

            robot = build_humanoid(load_robot_spec(s.robot_name))
            self._humanoid = RobotMeshes(self.server.scene, "/humanoid", robot)
            for h in (self.robot_base, self.robot_links, self.ee_command, self.ee_actual):
                h.visible = False
        robot = self._humanoid.robot
        if s.robot_q is None or s.robot_q.shape != robot.iq.shape:
            return
        T = s.ee_actual  # a humanoid's report carries its base pose
        base = np.eye(4) if T is None else np.asarray(T)
        q = full_configuration(robot, base[:3, 3], quat_from_matrix(base[:3, :3]), s.robot_q)
        offset = np.array([self.robot_origin[0], self.robot_origin[1], 0.0])
        offset[:2] -= q[:2] if robot.spec.floating_base else 0.0  # beside the operator
        self._humanoid.place(q, offset)

    # -- running ----------------------------------------------------------------------------
    def _loop(self, seconds: float | None) -> None:
        period = 1.0 / self.update_hz
        end = None if seconds is None else time.monotonic() + seconds
        while not self._stop.is_set() and (end is None or time.monotonic() < end):
            t = time.monotonic()
            try:
                self.update()
            except MocapkitError as exc:
                self.message.value = f"session error: {exc}"
                log.error("viewer: %s", exc)
                return
            self._stop.wait(max(0.0, period - (time.monotonic() - t)))

    def start(self) -> TeleopViewer:
        """Follow the session in a background thread."""
        self._thread = threading.Thread(target=self._loop, args=(None,), daemon=True)
        self._thread.start()
        return self

    def serve(self, seconds: float | None = None) -> None:
        """Follow the session in this thread (until Ctrl-C or ``seconds``)."""
        self._loop(seconds)

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
        with contextlib.redirect_stdout(sys.stderr):  # ("Server stopped", on stdout)
            self.server.stop()

    def __enter__(self) -> TeleopViewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
