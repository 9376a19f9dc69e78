"""Run the service (and the viser view) with uvicorn."""

from __future__ import annotations

import logging
import sys

import uvicorn

from app.config import Settings
from app.main import create_app


def run(settings: Settings, *, demo: bool = False) -> int:
    """Serve until interrupted; print where to look first."""
    logging.basicConfig(
        level=settings.log_level.upper(), format="%(levelname)s %(name)s %(message)s"
    )
    if settings.store != "memory":
        from app.service.store import StoreUnavailable, open_store, redacted

        try:  # say at once when the store cannot be reached, before serving anything
            open_store(settings.store).close()
        except StoreUnavailable as exc:
            print(f"bearings: {exc}", file=sys.stderr)
            return 2
        print(f"Sessions are shared through {redacted(settings.store)}")
    app = create_app(settings, demo=demo)
    shown = "localhost" if settings.host in ("0.0.0.0", "::") else settings.host
    print(f"Bearings API and demo page: http://{shown}:{settings.port}/  (docs: /docs)")
    if settings.viser:
        print(f"Bearings live view (viser): http://{shown}:{settings.viser_port}/")
    if demo:
        print(
            "Demo: a simulated walk in the paper office is running; watch the particles converge."
        )
    uvicorn.run(app, host=settings.host, port=settings.port, log_level=settings.log_level.lower())
    return 0
