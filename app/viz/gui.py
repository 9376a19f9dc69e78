"""The view's GUI panel: which session to watch, and demo controls.

The view is private: its list holds only the sessions their creators shared
(``share_view``) and the view's own demo walks, each under a short label ("walk 1",
or the map's name and a tag that cannot be traced back to the id), never an id. A demo
walk started here belongs to the viewer who started it: it ends when that viewer's
browser disconnects, or after ``demo_walk_max_s`` (10 minutes by default).

viser runs GUI callbacks on its own threads; anything that touches sessions is sent
to the service's event loop with ``asyncio.run_coroutine_threadsafe``.

The panel knows the view only through :class:`ViewHost` and starts simulated walks
only through the :class:`StartWalk` it is given (the application passes
:func:`app.demo.new_walk`), so viz imports neither the demo nor itself in a circle.
"""

from __future__ import annotations

import asyncio
import contextlib
from concurrent.futures import Future
from typing import TYPE_CHECKING, Any, Protocol

import viser

from app.service.sessions import SessionManager

if TYPE_CHECKING:
    from app.service.session import Session

NONE = "(none)"
FOVS = ("360", "270", "180")
#: The level selector's first choice (as app.viz.view names it).
FOLLOW = "(the person's level)"


class Walk(Protocol):
    """A running simulated walk, as the panel drives it."""

    session_id: str | None
    finished: bool

    def kidnap(self) -> None: ...

    async def stop(self) -> None: ...


class StartWalk(Protocol):
    """Create a walk with the panel's settings and start it (on the event loop)."""

    def __call__(
        self,
        *,
        map_name: str,
        fov_deg: float,
        occlusion: bool,
        missing: bool,
        particles: int,
        max_duration_s: float | None,
    ) -> Walk: ...


class ViewHost(Protocol):
    """What the panel needs of the view that holds it."""

    server: viser.ViserServer | None
    manager: SessionManager
    loop: asyncio.AbstractEventLoop | None
    watched: str | None

    def watch(self, session_id: str | None) -> None: ...

    def choose_level(self, choice: str) -> None: ...


class ViewControls:
    """GUI handles and what they do; the demo folder only when walks can be started."""

    def __init__(self, view: ViewHost, start_walk: StartWalk | None = None) -> None:
        self.view = view
        self.new_walk = start_walk
        server = view.server
        assert server is not None
        gui = server.gui
        self.walks: dict[str, Walk] = {}
        self._walk_viewer: dict[str, int | None] = {}  # session id -> viser client id
        self._walk_labels: dict[str, str] = {}
        self._walks_started = 0
        self._labels: dict[str, str] = {}  # label shown -> session id
        self._known: tuple[str, ...] = ()
        self.session = gui.add_dropdown("Watch session", (NONE,), initial_value=NONE)
        self.session.on_update(lambda _: view.watch(self._labels.get(self.session.value)))
        self.status = gui.add_markdown("No session yet.")
        # A venue's levels: the view shows one at a time (the person's, or one chosen).
        self.level = gui.add_dropdown("Level", (FOLLOW,), initial_value=FOLLOW, disabled=True)
        self.level.on_update(lambda _: view.choose_level(self.level.value))
        server.on_client_disconnect(lambda client: self.viewer_left(client.client_id))
        if start_walk is None:
            return
        with gui.add_folder("Demo: simulated walk"):
            maps = tuple(sorted(view.manager.maps))
            self.map = gui.add_dropdown(
                "Map", maps, initial_value="paper_office" if "paper_office" in maps else maps[0]
            )
            self.fov = gui.add_dropdown("Field of view (deg)", FOVS, initial_value="360")
            self.occlusion = gui.add_checkbox("Occlusion (face a corner)", False)
            self.missing = gui.add_checkbox("Missing detections", False)
            self.particles = gui.add_slider(
                "Particles", min=500, max=20_000, step=500, initial_value=10_000
            )
            self.start_button = gui.add_button("Start walk")
            self.kidnap_button = gui.add_button("Kidnap now")
            self.reset_button = gui.add_button("Reset walk")
        self.start_button.on_click(lambda e: self._run(self.start_walk(e.client_id)))
        self.kidnap_button.on_click(lambda _: self.kidnap())
        self.reset_button.on_click(lambda e: self._run(self.reset_walk(e.client_id)))

    def set_levels(self, names: tuple[str, ...]) -> None:
        """The level selector's choices for the map shown (none: disabled)."""
        self.level.options = (FOLLOW, *names)
        self.level.value = FOLLOW  # type: ignore[misc]
        self.level.disabled = not names

    def _run(self, coro: Any) -> None:
        """Start ``coro`` on the event loop from a GUI callback (which must return None)."""
        self._submit(coro)

    def _submit(self, coro: Any) -> Future[Any] | None:
        loop = self.view.loop
        if loop is None or loop.is_closed():
            coro.close()
            return None
        return asyncio.run_coroutine_threadsafe(coro, loop)

    async def start_walk(self, viewer: int | None = None) -> str:
        """Start a simulated walk with the panel's settings, for ``viewer``, and watch it."""
        assert self.new_walk is not None, "this view was given no way to start walks"
        map_name = self.map.value
        walk = self.new_walk(
            map_name=map_name,
            fov_deg=float(self.fov.value),
            occlusion=bool(self.occlusion.value),
            missing=bool(self.missing.value),
            particles=int(self.particles.value),
            max_duration_s=self.view.manager.settings.demo_walk_max_s,
        )
        for _ in range(200):  # the session exists once the walk created it
            if walk.session_id is not None or walk.finished:
                break
            await asyncio.sleep(0.01)
        assert walk.session_id is not None, "the demo walk could not create its session"
        self._walks_started += 1
        self.walks[walk.session_id] = walk
        self._walk_viewer[walk.session_id] = viewer
        self._walk_labels[walk.session_id] = f"walk {self._walks_started} ({map_name})"
        self.view.watch(walk.session_id)
        return walk.session_id

    def kidnap(self) -> None:
        walk = self.walks.get(self.view.watched or "")
        if walk is not None:
            walk.kidnap()

    async def stop_walk(self, session_id: str) -> None:
        walk = self.walks.pop(session_id, None)
        self._walk_viewer.pop(session_id, None)
        self._walk_labels.pop(session_id, None)
        if walk is not None:
            await walk.stop()

    async def reset_walk(self, viewer: int | None = None) -> str:
        await self.stop_walk(self.view.watched or "")
        return await self.start_walk(viewer)

    def viewer_left(self, client_id: int) -> None:
        """The viewer's browser disconnected: end the walks it started."""
        for sid, viewer in list(self._walk_viewer.items()):
            if viewer == client_id:
                self._submit(self.stop_walk(sid))

    def label(self, session: Session) -> str:
        """What the list shows for a session: never its id."""
        own = self._walk_labels.get(session.id)
        return own if own is not None else f"{session.map.name} · {session.tag}"

    def visible(self) -> list[Session]:
        """The sessions this view may show: shared ones and its own demo walks."""
        for sid in [sid for sid, walk in self.walks.items() if walk.finished]:
            self._submit(self.stop_walk(sid))  # ended by its time limit
        return [s for s in self.view.manager.sessions() if s.shared or s.id in self._walk_labels]

    @property
    def visible_ids(self) -> tuple[str, ...]:
        """Ids of the sessions listed at the last :meth:`sync_sessions`."""
        return self._known

    def sync_sessions(self) -> None:
        """Keep the session dropdown in step with the visible sessions (view thread)."""
        sessions = self.visible()
        ids = tuple(s.id for s in sessions)
        if ids != self._known:
            self._known = ids
            self._labels = {self.label(s): s.id for s in sessions}
            self.session.options = (NONE, *self._labels) if ids else (NONE,)
            if self.view.watched not in ids:
                self.view.watch(ids[-1] if ids else None)
        watched = self.view.watched
        shown = {sid: label for label, sid in self._labels.items()}
        value = shown.get(watched, NONE) if watched is not None else NONE
        if self.session.value != value:
            # viser types the dropdown's value as read-only; it has a setter at run time.
            self.session.value = value  # type: ignore[misc]
        if watched is not None:
            with contextlib.suppress(Exception):
                s = self.view.manager.get(watched)
                r = s.last_outcome
                state = "converged" if r is not None and r.estimate.converged else "searching"
                text = f"**{s.map.name}**, {s.frames} frames, {state}"
                if r is not None and r.level is not None:
                    text = f"**{s.map.name}**, {r.level.name}, {s.frames} frames, {state}"
                if r is not None and r.feedback.text:
                    text += f"\n\n_{r.feedback.text}_"
                if self.status.content != text:  # only send what changed
                    self.status.content = text

    def shutdown(self) -> None:
        for walk in list(self.walks.values()):
            self._submit(walk.stop())
        self.walks.clear()
        self._walk_viewer.clear()
        self._walk_labels.clear()
