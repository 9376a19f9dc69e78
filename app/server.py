"""Run the service (and the viser view) with uvicorn.

:func:`uvicorn_config` is the one place a server is configured from the settings (the
tests start theirs through it too): WebSocket messages larger than the limit are
refused by the protocol before they are buffered, and every log handler redacts
session ids and keys. :class:`BearingsServer` drains the service before uvicorn closes
its connections, so a SIGTERM answers every frame accepted and closes WebSockets with
1012 and a reason (app.main.drain).
"""

from __future__ import annotations

import copy
import gc
import logging
import socket
import sys

import uvicorn
from fastapi import FastAPI
from uvicorn.config import LOGGING_CONFIG

from app.api.access import StartupRefused
from app.config import Settings
from app.main import create_app, drain

log = logging.getLogger("bearings")

#: A WebSocket message up to this many times the message limit gets a readable error
#: (the connection stays open); a larger one is refused by the protocol (close 1009)
#: before it is read into memory.
WS_FRAME_SLACK = 2
#: How long a thread may keep the GIL while another waits for it (Python's default is
#: 5 ms). Chosen when filter steps ran on threads (a 10 Hz client's p95 under a flood:
#: 40-75 ms with 1 ms against 80-120 ms with 5 ms, benchmarks/README.md). Steps now run
#: on the event loop; the other threads (the shared store's lease renewals, loads and
#: releases, the live view) get in within 1 ms. With Redis at 120 sessions, 1 ms and 5 ms served
#: 607/664 and 640/672 frames/s in alternating runs: no difference this VM can show.
GIL_SWITCH_INTERVAL_S = 0.001


def log_config(level: str) -> dict[str, object]:
    """uvicorn's logging configuration, plus redaction on every handler and a root logger."""
    config = copy.deepcopy(LOGGING_CONFIG)
    config["filters"] = {"redact": {"()": "app.api.redact.RedactFilter"}}
    for handler in config["handlers"].values():
        handler["filters"] = ["redact"]
    config["loggers"]["bearings"] = {"handlers": ["default"], "level": level.upper()}
    return config


def uvicorn_config(app: FastAPI, settings: Settings, **overrides: object) -> uvicorn.Config:
    """The uvicorn configuration for ``app`` under ``settings`` (size limits, logging)."""
    options: dict[str, object] = {
        "host": settings.host,
        "port": settings.port,
        "log_level": settings.log_level.lower(),
        "log_config": log_config(settings.log_level),
        "ws_max_size": WS_FRAME_SLACK * settings.max_message_bytes,
        "ws_per_message_deflate": False,  # a small compressed message must not inflate to MBs
        "h11_max_incomplete_event_size": max(16_384, settings.max_message_bytes),
        "timeout_graceful_shutdown": 30,
    }
    options.update(overrides)
    return uvicorn.Config(app, **options)  # type: ignore[arg-type]


#: Garbage-collector thresholds while serving (see :class:`BearingsServer`): young,
#: middle and old generations, Python's defaults being (700, 10, 10).
SERVING_GC_THRESHOLDS = (100_000, 50, 100)


class BearingsServer(uvicorn.Server):
    """uvicorn's server, draining the service first when asked to stop.

    With ``freeze_start_up`` (the ``bearings serve`` process, whose command line turned
    garbage collection off for the start-up), once the service has started, every object
    made so far is moved out of the collector's reach (:func:`gc.freeze`) and collection
    resumes: the first collections then do not walk the few hundred thousand start-up
    objects (about 0.1 s each, on the first requests), nor does any full collection later.
    What start-up left in unreachable cycles stays (measured: under 1 MB, no arrays).
    Serving, the youngest generation is collected every ``SERVING_GC_THRESHOLDS[0]``
    allocations instead of 700: a frame allocates a few hundred objects (messages,
    models, small arrays), nearly all freed by reference counting at once, so the
    default collected several times a frame for next to nothing (120 sessions at
    saturation: 1-5 % more frames in three alternating pairs).
    """

    def __init__(
        self, config: uvicorn.Config, app: FastAPI, *, freeze_start_up: bool = False
    ) -> None:
        super().__init__(config)
        self.app = app
        self.freeze_start_up = freeze_start_up

    async def startup(self, sockets: list[socket.socket] | None = None) -> None:
        try:
            await super().startup(sockets)
        finally:
            if self.freeze_start_up:
                gc.freeze()
                gc.set_threshold(*SERVING_GC_THRESHOLDS)
                gc.enable()

    async def shutdown(self, sockets: list[socket.socket] | None = None) -> None:
        for server in self.servers:  # no new connections while draining
            server.close()
        try:
            await drain(self.app)
        except Exception:  # the server must still stop
            log.exception("draining the service failed")
        await super().shutdown(sockets)


def run(settings: Settings, *, demo: bool = False) -> int:
    """Serve until interrupted; print where to look first."""
    try:
        app = create_app(settings, demo=demo)
    except StartupRefused as exc:
        print(f"bearings: {exc}", file=sys.stderr)
        return 2
    if settings.store != "memory":
        from app.service.store import StoreUnavailable, open_store, redacted

        try:  # say at once when the store cannot be reached, before serving anything
            open_store(settings.store).close()
        except StoreUnavailable as exc:
            print(f"bearings: {exc}", file=sys.stderr)
            return 2
        print(f"Sessions are shared through {redacted(settings.store)}")
    shown = "localhost" if settings.host in ("0.0.0.0", "::") else settings.host
    print(f"Bearings API and demo page: http://{shown}:{settings.port}/  (docs: /docs)")
    if settings.viser:
        print(f"Bearings live view (viser): http://{settings.viser_host}:{settings.viser_port}/")
    if demo:
        print(
            "Demo: a simulated walk in the paper office is running; watch the particles converge."
        )
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
    server = BearingsServer(uvicorn_config(app, settings), app, freeze_start_up=True)
    server.run()
    return 0
