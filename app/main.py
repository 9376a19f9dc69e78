"""Build the FastAPI application (thin: wiring only)."""

from __future__ import annotations

import asyncio
import contextlib
import functools
import importlib.util
import logging
from collections.abc import AsyncIterator

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from fastapi.staticfiles import StaticFiles

from app.api.access import OPEN_PATHS, AccessControl, startup_keys
from app.api.errors import document_key_errors, install_error_handlers
from app.api.limits import BodySizeLimit
from app.api.methods import AllowedMethods
from app.api.redact import install_redaction
from app.api.routes import health, maps, metrics, sessions, speech
from app.api.streams import StreamRegistry
from app.config import Settings, get_settings
from app.maps.check import load_map_dirs
from app.maps.model import SemanticMap
from app.resources import bundled_maps_dir, static_dir
from app.service.metrics import Metrics
from app.service.sessions import SessionManager
from app.service.store import open_store

log = logging.getLogger("bearings")


def load_maps(settings: Settings) -> dict[str, SemanticMap]:
    """Bundled maps plus every ``--maps`` directory (later directories win on a name clash).

    Each map is checked and prepared (grids built or read from the cache) here, at
    start-up, never inside a request; a file with errors is skipped and logged.
    """
    maps, _ = load_map_dirs([bundled_maps_dir(), *settings.maps], cache_dir=settings.cache_dir)
    return maps


async def drain(app: FastAPI, timeout_s: float = 30.0) -> None:
    """Before the server closes its connections: take no new frames, answer every frame
    accepted (waiting at most ``timeout_s``), then close each WebSocket with 1012 and a
    reason to reconnect."""
    streams: StreamRegistry = app.state.streams
    streams.stop_reading()
    manager = getattr(app.state, "manager", None)
    if manager is not None:
        try:
            await asyncio.wait_for(manager.shutdown(), timeout_s)
        except TimeoutError:
            log.error("frames still unanswered after %.0f s of shutdown; closing anyway", timeout_s)
        if manager.sharing is not None:  # checkpoint every session, release it
            await manager.sharing.shutdown()
    await streams.close_all()


def create_app(settings: Settings | None = None, *, demo: bool = False) -> FastAPI:
    """The service: REST + WebSocket API, metrics, the demo page and (optionally) the view.

    Raises :class:`~app.api.access.StartupRefused` when the access settings are unsafe
    or the key file is bad (docs/SECURITY.md).
    """
    settings = settings or get_settings()
    keys = startup_keys(settings)
    install_redaction()
    metrics_ = Metrics()

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        from app.feedback.narrator import warm_up as warm_up_narrator
        from app.guidance.planner import warm_up as warm_up_guidance
        from app.localization.filter import warm_up

        def warm_up_all() -> None:
            warm_up()
            warm_up_narrator()
            warm_up_guidance()

        # Kernels compile (or load from numba's cache) while the maps are checked and
        # prepared: both release the GIL for most of their work.
        _, maps_ = await asyncio.gather(
            asyncio.to_thread(warm_up_all), asyncio.to_thread(load_maps, settings)
        )
        store = await asyncio.to_thread(
            functools.partial(open_store, settings.store, journal_gap_s=settings.journal_gap_s)
        )
        manager = SessionManager(maps_, settings, metrics_, store)
        app.state.manager = manager
        tasks = [asyncio.create_task(manager.run_sweeper())]
        if manager.sharing is not None:
            tasks.append(asyncio.create_task(manager.sharing.run_keeper()))
        view = None
        if settings.viser:
            from app.demo import new_walk
            from app.viz import LiveView

            view = LiveView(
                manager,
                port=settings.viser_port,
                host=settings.viser_host,
                start_walk=functools.partial(new_walk, manager),
            )
            view.start()
            app.state.view = view
        if demo:
            from app.demo import run_demo_walk

            tasks.append(asyncio.create_task(run_demo_walk(manager, share_view=True)))
        try:
            yield
        finally:
            for task in tasks:
                task.cancel()
            for task in tasks:
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await task
            if view is not None:
                view.stop()
            if manager.sharing is not None:  # (already done when drained)
                await manager.sharing.shutdown()
            manager.close()

    app = FastAPI(
        title="Bearings",
        version="0.1.0",
        summary="Bearing-only semantic self-localization for blind and visually impaired people.",
        lifespan=lifespan,
    )
    app.state.settings = settings
    app.state.metrics = metrics_
    app.state.view = None
    app.state.keys = keys
    app.state.streams = StreamRegistry()
    app.add_middleware(BodySizeLimit, max_bytes=settings.max_message_bytes)
    routers = [module.router for module in (health, metrics, maps, sessions, speech)]
    if importlib.util.find_spec("app.api.routes.demo") is not None:
        from app.api.routes import demo as demo_routes

        routers.append(demo_routes.router)
    app.add_middleware(AllowedMethods, routers=routers)
    app.add_middleware(AccessControl, keys=keys, allowed_origins=settings.allowed_origins)
    if settings.allowed_origins:  # outermost: answers CORS preflights without a key
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.allowed_origins,
            allow_methods=["GET", "POST", "PUT", "DELETE"],
            allow_headers=["authorization", "content-type"],
            expose_headers=["retry-after"],
            max_age=600,
        )
    install_error_handlers(app)
    document_key_errors(app, OPEN_PATHS)
    for router in routers:
        app.include_router(router)
    app.mount("/", StaticFiles(directory=static_dir(), html=True), name="static")
    return app
