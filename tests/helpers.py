"""Builders shared by the tests: small maps, service settings, real servers.

Fixtures stay in the ``conftest.py`` files; anything a test module imports lives here.
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import uvicorn
from fastapi import FastAPI

from app.config import Settings
from app.maps.check import load_map
from app.maps.model import SemanticMap, parse_map
from app.resources import bundled_maps_dir


# ---------------------------------------------------------------------------- maps
def room(objects: list[dict], walls: list[dict] | None = None, name: str = "room") -> SemanticMap:
    """A 6 m x 4 m walled room with the given objects (and extra walls)."""
    outline = [
        {"x1": 0, "y1": 0, "x2": 6, "y2": 0},
        {"x1": 6, "y1": 0, "x2": 6, "y2": 4},
        {"x1": 6, "y1": 4, "x2": 0, "y2": 4},
        {"x1": 0, "y1": 4, "x2": 0, "y2": 0},
    ]
    return parse_map({"name": name, "walls": outline + (walls or []), "objects": objects})


def paper_office() -> SemanticMap:
    """The bundled 10 m x 7 m office of the paper's experiments."""
    return load_map(bundled_maps_dir() / "paper_office.json")


# ------------------------------------------------------------------------- service
def make_settings(**overrides: object) -> Settings:
    """Service settings for tests: no viser, small limits so they are easy to hit."""
    base = {
        "viser": False,
        "max_sessions": 5,
        "max_particles": 20_000,
        "default_particles": 1000,
        "max_detections": 20,
        "max_message_bytes": 8192,
    }
    return Settings(**{**base, **overrides})


# ------------------------------------------------------------------------- servers
def free_port() -> int:
    """A TCP port on the loopback interface that nothing listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def serving(app: FastAPI, port: int, *, timeout_s: float = 60.0) -> Iterator[str]:
    """Run ``app`` with a real uvicorn server on ``port`` in a thread; yield host:port."""
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.time() + timeout_s
    while not server.started:
        if time.time() > deadline or not thread.is_alive():
            raise RuntimeError("the server did not start")
        time.sleep(0.05)
    try:
        yield f"127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(timeout=10)
