"""The view's GUI panel: which session to watch, and demo controls.

viser runs GUI callbacks on its own threads; anything that touches sessions is sent
to the service's event loop with ``asyncio.run_coroutine_threadsafe``.

The panel knows the view only through :class:`ViewHost` and starts simulated walks
only through the :class:`StartWalk` it is given (the application passes
:func:`app.demo.new_walk`), so the view imports neither this module's user nor the
demo.
"""

from __future__ import annotations

import asyncio
import contextlib
from concurrent.futures import Future
from typing import Any, Protocol

import viser

from app.service.sessions import SessionManager

NONE = "(none)"
FOVS = ("360", "270", "180")


class Walk(Protocol):
    """A running simulated walk, as the panel drives it."""

    session_id: str | None

    def kidnap(self) -> None: ...

    async def stop(self) -> None: ...


class StartWalk(Protocol):
    """Create a walk with the panel's settings and start it (on the event loop)."""

    def __call__(
        self, *, map_name: str, fov_deg: float, occlusion: bool, missing: bool, particles: int
    ) -> Walk: ...


class ViewHost(Protocol):
    """What the panel needs of the view that holds it."""

    server: viser.ViserServer | None
    manager: SessionManager
    loop: asyncio.AbstractEventLoop | None
    watched: str | None

    def watch(self, session_id: str | None) -> None: ...


class ViewControls:
    """GUI handles and what they do; the demo folder only when walks can be started."""

    def __init__(self, view: ViewHost, start_walk: StartWalk | None = None) -> None:
        self.view = view
        self.new_walk = start_walk
        server = view.server
        assert server is not None
        gui = server.gui
        self.walks: dict[str, Walk] = {}
        self._known: tuple[str, ...] = ()
        self.session = gui.add_dropdown("Watch session", (NONE,), initial_value=NONE)
        self.session.on_update(
            lambda _: view.watch(None if self.session.value == NONE else self.session.value)
        )
        self.status = gui.add_markdown("No session yet.")
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
        self.start_button.on_click(lambda _: self._run(self.start_walk()))
        self.kidnap_button.on_click(lambda _: self.kidnap())
        self.reset_button.on_click(lambda _: self._run(self.reset_walk()))

    def _run(self, coro: Any) -> None:
        """Start ``coro`` on the event loop from a GUI callback (which must return None)."""
        self._submit(coro)

    def _submit(self, coro: Any) -> Future[Any] | None:
        loop = self.view.loop
        if loop is None or loop.is_closed():
            coro.close()
            return None
        return asyncio.run_coroutine_threadsafe(coro, loop)

    async def start_walk(self) -> str:
        """Start a simulated walk with the panel's settings and watch it."""
        assert self.new_walk is not None, "this view was given no way to start walks"
        walk = self.new_walk(
            map_name=self.map.value,
            fov_deg=float(self.fov.value),
            occlusion=bool(self.occlusion.value),
            missing=bool(self.missing.value),
            particles=int(self.particles.value),
        )
        for _ in range(200):  # the session exists once the walk created it
            if walk.session_id is not None:
                break
            await asyncio.sleep(0.01)
        assert walk.session_id is not None
        self.walks[walk.session_id] = walk
        self.view.watch(walk.session_id)
        return walk.session_id

    def kidnap(self) -> None:
        walk = self.walks.get(self.view.watched or "")
        if walk is not None:
            walk.kidnap()

    async def reset_walk(self) -> str:
        walk = self.walks.pop(self.view.watched or "", None)
        if walk is not None:
            await walk.stop()
        return await self.start_walk()

    def sync_sessions(self) -> None:
        """Keep the session dropdown in step with the live sessions (view thread)."""
        ids = tuple(s.id for s in self.view.manager.sessions())
        if ids != self._known:
            self._known = ids
            self.session.options = (NONE, *ids) if ids else (NONE,)
            if self.view.watched not in ids:
                self.view.watch(ids[-1] if ids else None)
        watched = self.view.watched
        value = watched if watched in ids else NONE
        if self.session.value != value:
            # viser types the dropdown's value as read-only; it has a setter at run time.
            self.session.value = value  # type: ignore[misc]
        if watched is not None:
            with contextlib.suppress(Exception):
                s = self.view.manager.get(watched)
                r = s.last_outcome
                state = "converged" if r is not None and r.estimate.converged else "searching"
                text = f"**{s.map.name}**, {s.frames} frames, {state}"
                if r is not None and r.feedback.text:
                    text += f"\n\n_{r.feedback.text}_"
                if self.status.content != text:  # only send what changed
                    self.status.content = text

    def shutdown(self) -> None:
        for walk in list(self.walks.values()):
            self._submit(walk.stop())
        self.walks.clear()
