"""``mocapkit view FILE...``: recordings and results in the browser, side by side, on a
timeline (viser).

Every file is a track (:mod:`mocapkit.viz.tracks`): a human as a body of capsules between
its joints (blue; a marker trial's tracked markers as points), a robot from its URDF's
visual meshes (orange), each placed beside the previous one (``SPACING_M`` apart, each
started at the origin of the floor). The GUI: Play / Pause, a time slider (scrub), the
speed, a loop switch, and the list of files with what could not be read.

A file the viewer cannot read is named with the reason in the page and on stderr; the
others are shown. viser is the ``viz`` extra, imported only here.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.errors import ConfigError, MocapkitError
from mocapkit.viz.robot_meshes import RobotMeshes
from mocapkit.viz.tracks import ENDS, HumanTrack, RobotTrack, Track, frame_at, load_track
from mocapkit.viz.viewer import SKELETON_RGB, import_viser

log = logging.getLogger("mocapkit.viz.file_viewer")

SPACING_M = 1.6  # between tracks, along the viewer's -y
BONE_RADIUS_M = 0.045
MARKER_RGB = (230, 30, 30)
SPEEDS = ("0.25", "0.5", "1", "2", "4")


def _z_to(d: np.ndarray) -> np.ndarray:
    """[w, x, y, z] of the rotation taking +z onto the unit vector ``d``."""
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(z, d)
    c = float(z @ d)
    if c < -1.0 + 1e-9:
        return np.array([0.0, 1.0, 0.0, 0.0])
    q = np.array([1.0 + c, *v])
    return q / np.linalg.norm(q)


class FileViewer:
    """See the module docstring. ``load()`` the files, ``start()`` the playback thread."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8080, update_hz: float = 30.0) -> None:
        viser = import_viser()
        with contextlib.redirect_stdout(sys.stderr):  # viser's banner: keep stdout clean
            self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.url = f"http://{host}:{self.server.get_port()}/"
        self.update_hz = update_hz
        self.tracks: list[Track] = []
        self.failed: list[tuple[str, str]] = []
        self.t = 0.0
        self.t0 = 0.0
        self.t1 = 0.0
        self.playing = False
        self.frames_drawn = 0
        # per track: a human's (handle, (kind, from, to)) list, or a robot's meshes
        self._scenes: list[list[tuple[Any, tuple[str, str, str]]] | RobotMeshes] = []
        self._offsets: list[np.ndarray] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self.server.scene.add_grid("/grid", width=12.0, height=12.0, plane="xy")

    # -- files --------------------------------------------------------------------------------
    def load(self, paths: Sequence[str | Path], **options: Any) -> None:
        """Read every file (a failure is kept with its reason, the rest go on)."""
        for path in paths:
            try:
                track = load_track(path, **options)
            except (MocapkitError, OSError, ValueError, KeyError) as exc:
                self.failed.append((str(path), str(exc)))
                log.warning("view: %s not shown: %s", path, exc)
                continue
            self._add(track)
        if not self.tracks:
            why = "; ".join(f"{p}: {e}" for p, e in self.failed)
            raise ConfigError(f"view: nothing to show ({why})")
        self.t0 = min(float(tr.time[0]) for tr in self.tracks)
        self.t1 = max(float(tr.time[-1]) for tr in self.tracks)
        self.t = self.t0
        self._build_gui()
        self.draw(self.t)

    def _add(self, track: Track) -> None:
        k = len(self.tracks)
        self.tracks.append(track)
        self._offsets.append(np.array([0.0, -SPACING_M * k, 0.0]) - track.origin())
        root = f"/track{k}"
        self.server.scene.add_label(
            f"{root}/label", track.name, position=(0.0, -SPACING_M * k, 2.1)
        )
        if isinstance(track, HumanTrack):
            self._scenes.append(self._human_scene(root, track))
        else:
            meshes = RobotMeshes(self.server.scene, root, track.robot)
            track.notes.extend(meshes.notes)
            self._scenes.append(meshes)

    def _human_scene(self, root: str, track: HumanTrack) -> list[tuple[Any, tuple[str, str, str]]]:
        import trimesh

        m = track.motion
        out: list[tuple[Any, tuple[str, str, str]]] = []
        for a, b in track.bones():
            length = float(np.nanmedian(np.linalg.norm(m.pos[b] - m.pos[a], axis=1)))
            mesh = trimesh.creation.capsule(height=max(length, 1e-3), radius=BONE_RADIUS_M)
            mesh.visual = trimesh.visual.ColorVisuals(mesh, face_colors=(*SKELETON_RGB, 255))
            h = self.server.scene.add_mesh_trimesh(f"{root}/{a}-{b}", mesh)
            out.append((h, ("bone", a, b)))
        for s in ENDS:
            if s in m.pos:
                h = self.server.scene.add_icosphere(f"{root}/{s}", radius=0.07, color=SKELETON_RGB)
                out.append((h, ("end", s, s)))
        if track.markers is not None:
            pts = np.nan_to_num(track.markers[0])
            h = self.server.scene.add_point_cloud(
                f"{root}/markers", points=pts, colors=MARKER_RGB, point_size=0.025
            )
            out.append((h, ("markers", "", "")))
        return out

    # -- GUI and playback -----------------------------------------------------------------------
    def _build_gui(self) -> None:
        gui = self.server.gui
        with gui.add_folder("Timeline"):
            self.play_button = gui.add_button("Play")
            self.pause_button = gui.add_button("Pause")
            self.slider = gui.add_slider(
                "Time [s]", min=self.t0, max=max(self.t1, self.t0 + 1e-3), step=0.01,
                initial_value=self.t0,
            )  # fmt: skip
            self.speed = gui.add_dropdown("Speed", SPEEDS, initial_value="1")
            self.loop = gui.add_checkbox("Loop", True)
        with gui.add_folder("Files"):
            for tr in self.tracks:
                kind = "robot" if isinstance(tr, RobotTrack) else "human"
                gui.add_markdown(f"**{tr.name}** ({kind}, {tr.time.size} frames)")
            for path, why in self.failed:
                gui.add_markdown(f"**{Path(path).name}**: not shown: {why}")
        self.play_button.on_click(lambda _: self.play())
        self.pause_button.on_click(lambda _: self.pause())

        @self.slider.on_update
        def _(_: Any) -> None:
            if not self.playing:  # the user scrubs
                self.draw(float(self.slider.value))

    def play(self) -> None:
        self.playing = True

    def pause(self) -> None:
        self.playing = False

    def draw(self, t: float) -> None:
        """Put every track's scene at time ``t`` [s]."""
        with self._lock:
            self.t = t
            for k, tr in enumerate(self.tracks):
                self._draw_track(k, tr, t)
            self.frames_drawn += 1

    def _draw_track(self, k: int, tr: Track, t: float) -> None:
        off = self._offsets[k]
        i = frame_at(tr.time, t)
        if isinstance(tr, HumanTrack):
            m = tr.motion
            scene = self._scenes[k]
            assert isinstance(scene, list)
            for h, (kind, a, b) in scene:
                if kind == "bone":
                    pa, pb = m.pos[a][i], m.pos[b][i]
                    d = pb - pa
                    n = float(np.linalg.norm(d))
                    if not (np.isfinite(n) and n > 1e-6):
                        h.visible = False
                        continue
                    h.visible = True
                    h.position = tuple(0.5 * (pa + pb) + off)
                    h.wxyz = tuple(_z_to(d / n))
                elif kind == "end":
                    p = m.pos[a][i]
                    h.visible = bool(np.isfinite(p).all())
                    if h.visible:
                        h.position = tuple(p + off)
                elif kind == "markers" and tr.markers is not None:
                    h.points = np.nan_to_num(tr.markers[i] + off, nan=-100.0)
            return
        meshes = self._scenes[k]
        assert isinstance(meshes, RobotMeshes)
        meshes.place(tr.q[i], off)

    def start(self) -> FileViewer:
        self._thread = threading.Thread(target=self._loop, name="mocapkit-view", daemon=True)
        self._thread.start()
        return self

    def _loop(self) -> None:
        period = 1.0 / self.update_hz
        last = time.monotonic()
        while not self._stop.wait(period):
            now = time.monotonic()
            dt, last = now - last, now
            if not self.playing:
                continue
            t = self.t + dt * float(self.speed.value)
            if t > self.t1:
                if self.loop.value:
                    t = self.t0
                else:
                    t, self.playing = self.t1, False
            self.draw(t)
            self.slider.value = round(t, 2)

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        with contextlib.redirect_stdout(sys.stderr):  # viser says "Server stopped" on stdout
            self.server.stop()

    def __enter__(self) -> FileViewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
