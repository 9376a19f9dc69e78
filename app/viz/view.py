"""LiveView: a viser server in the service's process, showing one session at a time.

It listens on loopback unless told otherwise (``--viser-host``) and shows only the
sessions shared with it and its own demo walks (:mod:`app.viz.gui`).

The view never touches the filter directly: a background thread wakes at most
``max_rate_hz`` times a second, takes a snapshot of the watched session (copies made
under the session's lock) and redraws only when the session's version changed. So
drawing can lag, but it never slows or blocks frame processing.
"""

from __future__ import annotations

import asyncio
import logging
import threading

import numpy as np
import viser

from app.service.errors import SessionNotFound
from app.service.session import SessionSnapshot
from app.service.sessions import SessionManager
from app.viz.gui import FOLLOW, StartWalk, ViewControls
from app.viz.particles import detection_rays, pose_arrow, sample_particles
from app.viz.scene import MapScene, build_map_scene

log = logging.getLogger("bearings.viz")

NONE = "(none)"


class LiveView:
    """The viser view of live sessions, with demo controls."""

    def __init__(
        self,
        manager: SessionManager,
        *,
        port: int = 8080,
        host: str = "127.0.0.1",
        max_rate_hz: float = 10.0,
        start_walk: StartWalk | None = None,
    ) -> None:
        """``start_walk``: how the panel's demo button starts a simulated walk (none:
        no demo controls)."""
        self.manager = manager
        self.start_walk = start_walk
        self.port = port
        self.host = host
        self.period_s = 1.0 / max_rate_hz
        self.server: viser.ViserServer | None = None
        self.map_scene: MapScene | None = None
        self.controls: ViewControls | None = None
        self.watched: str | None = None
        self.frames_drawn = 0
        #: The drawn path to the destination (hidden without one).
        self.route: viser.LineSegmentsHandle | None = None
        self._last_version = -1
        self._stop = threading.Event()
        self._draw_lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._rng = np.random.default_rng(0)
        self.loop: asyncio.AbstractEventLoop | None = None
        #: On a map with levels, which one to show: FOLLOW or a level's name.
        self.level_choice = FOLLOW

    # ------------------------------------------------------------ lifecycle
    def start(self) -> None:
        """Start the viser server and the redraw thread (call from the event loop)."""
        try:
            self.loop = asyncio.get_running_loop()
        except RuntimeError:
            self.loop = None
        self.server = viser.ViserServer(
            host=self.host, port=self.port, label="Bearings", verbose=False
        )
        self.port = self.server.get_port()
        self.server.scene.set_up_direction("+z")
        default_map = (
            "paper_office" if "paper_office" in self.manager.maps else next(iter(self.manager.maps))
        )
        self.show_map(default_map)
        self.controls = ViewControls(self, self.start_walk)
        if self.map_scene is not None:
            shown = self.manager.maps[self.map_scene.map_name]
            self.controls.set_levels(tuple(lv.name for lv in shown.layout.levels))
        self._thread = threading.Thread(target=self._run, name="bearings-view", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self.controls is not None:
            self.controls.shutdown()
        if self.server is not None:
            self.server.stop()

    # -------------------------------------------------------------- drawing
    def show_map(self, map_name: str) -> None:
        """Draw ``map_name`` (replacing the current map) and frame it."""
        assert self.server is not None
        if self.map_scene is not None and self.map_scene.map_name == map_name:
            return
        if self.map_scene is not None:
            self.map_scene.remove()
        semantic_map = self.manager.maps[map_name]
        self.map_scene = build_map_scene(self.server, semantic_map)
        self.level_choice = FOLLOW
        if self.controls is not None:
            self.controls.set_levels(tuple(lv.name for lv in semantic_map.layout.levels))

    def choose_level(self, choice: str) -> None:
        """Show the level named ``choice``, or (FOLLOW) the watched person's."""
        self.level_choice = choice
        self._last_version = -1  # redraw at the next refresh
        scene = self.map_scene
        if scene is None or self.server is None:
            return
        names = [lv.name for lv in self.manager.maps[scene.map_name].layout.levels]
        if choice in names:
            scene.show_level(self.server, names.index(choice))

    def level_to_show(self, snap: SessionSnapshot) -> int | None:
        """The level the view shows for ``snap``: the one chosen, else the estimate's
        (None on a map without levels)."""
        layout = self.manager.maps[snap.map_name].layout
        if not layout.has_levels:
            return None
        names = [lv.name for lv in layout.levels]
        if self.level_choice in names:
            return names.index(self.level_choice)
        if snap.estimate is None:
            return None if self.map_scene is None else self.map_scene.level_shown
        return layout.level_of(snap.estimate.x)

    def watch(self, session_id: str | None) -> None:
        self.watched = session_id
        self._last_version = -1

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            try:
                self.refresh()
            except Exception:  # the view must never take the service down
                log.exception("view refresh failed")

    def refresh(self) -> bool:
        """Redraw from the latest snapshot if it changed; True when something was drawn."""
        with self._draw_lock:
            return self._refresh()

    def _refresh(self) -> bool:
        if self.controls is not None:
            self.controls.sync_sessions()
        sid = self.watched
        if sid is None:
            return False
        if self.controls is not None and sid not in self.controls.visible_ids:
            self.watch(None)  # never draw a session the view may not show
            return False
        try:
            snap = self.manager.get(sid).snapshot()
        except SessionNotFound:
            self.watch(None)
            return False
        if snap.version == self._last_version:
            return False
        self._last_version = snap.version
        self.draw(snap)
        return True

    def draw(self, snap: SessionSnapshot) -> None:
        """Particles, estimate, hypotheses, detection rays and the ground truth."""
        assert self.server is not None
        self.show_map(snap.map_name)
        level = self.level_to_show(snap)
        if level is not None and self.map_scene is not None:
            self.map_scene.show_level(self.server, level)
        scene = self.server.scene
        pts, colours, ticks = sample_particles(snap, self._rng)
        with self.server.atomic():
            scene.add_point_cloud(
                "/session/particles", pts, colours, point_size=0.06, precision="float32"
            )
            tick_colours = np.repeat(colours[:, None, :], 2, axis=1)
            scene.add_line_segments("/session/headings", ticks, tick_colours, thickness=0.015)
            est = snap.estimate
            if est is not None:
                colour = (0, 170, 0) if est.converged else (230, 140, 0)
                scene.add_arrows(
                    "/session/estimate",
                    pose_arrow(est.x, est.y, est.theta_rad),
                    colour,
                    shaft_radius=0.05,
                    head_radius=0.12,
                    head_length=0.2,
                )
                hyp = np.array([[h.x, h.y, 0.1] for h in est.hypotheses], dtype=np.float32)
                if hyp.size:
                    scene.add_point_cloud(
                        "/session/hypotheses",
                        hyp,
                        (255, 0, 255),
                        point_size=0.25,
                        point_shape="diamond",
                        precision="float32",
                    )
                rays = detection_rays(snap)
                scene.add_line_segments(
                    "/session/rays",
                    rays if rays.size else np.zeros((1, 2, 3), np.float32),
                    (250, 200, 0),
                    thickness=0.02,
                    visible=bool(rays.size),
                )
            # The way to the destination, when one is set and the person is located.
            route = snap.route
            legs = np.zeros((1, 2, 3), np.float32)
            if route is not None and len(route) >= 2:
                legs = np.zeros((len(route) - 1, 2, 3), np.float32)
                legs[:, 0, :2], legs[:, 1, :2] = route[:-1], route[1:]
                legs[:, :, 2] = 0.08
            self.route = scene.add_line_segments(
                "/session/route", legs, (0, 120, 255), thickness=0.05, visible=route is not None
            )
            if snap.truth is not None:
                t = snap.truth
                scene.add_arrows(
                    "/session/truth",
                    pose_arrow(t.x, t.y, t.theta_rad),
                    (20, 20, 20),
                    shaft_radius=0.03,
                    head_radius=0.08,
                    head_length=0.15,
                )
        self.frames_drawn += 1
