"""Builders shared by the tests: small maps, service settings, real servers and processes.

Fixtures stay in the ``conftest.py`` files; anything a test module imports lives here.
"""

from __future__ import annotations

import functools
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import httpx
import numpy as np
from fastapi import FastAPI

from app.config import Settings
from app.localization.config import FilterConfig
from app.localization.filter import ParticleFilter
from app.localization.types import Detection, Estimate, InitialPose, Odometry, Pose
from app.maps.check import load_map, load_map_dir
from app.maps.model import SemanticMap, parse_map
from app.maps.prepare import ensure_prepared
from app.resources import bundled_maps_dir
from app.server import BearingsServer, uvicorn_config
from app.service.metrics import Metrics
from app.service.sessions import SessionManager
from app.simulation.camera import CameraModel, visible_objects


# ---------------------------------------------------------------------------- maps
@functools.cache
def _bundled_maps() -> tuple[tuple[str, SemanticMap], ...]:
    return tuple(load_map_dir(bundled_maps_dir()).items())


def bundled_maps() -> dict[str, SemanticMap]:
    """The bundled maps as ``load_map_dir`` gives them, checked and prepared once per
    test process (0.8 s each time on a 2-core machine; a service shares its maps between
    sessions, so managers may too). A new dict each call: adding a map to it changes no
    other test's."""
    return dict(_bundled_maps())


def room(objects: list[dict], walls: list[dict] | None = None, name: str = "room") -> SemanticMap:
    """A 6 m x 4 m walled room with the given objects (and extra walls), prepared."""
    outline = [
        {"x1": 0, "y1": 0, "x2": 6, "y2": 0},
        {"x1": 6, "y1": 0, "x2": 6, "y2": 4},
        {"x1": 6, "y1": 4, "x2": 0, "y2": 4},
        {"x1": 0, "y1": 4, "x2": 0, "y2": 0},
    ]
    return ensure_prepared(
        parse_map({"name": name, "walls": outline + (walls or []), "objects": objects})
    )


def seen_from(m: SemanticMap, pose: Pose, camera: CameraModel | None = None) -> list[Detection]:
    """What ``camera`` (default: 360 degrees, 15 m) sees from plane pose ``pose`` on
    ``m``: every visible object at its exact bearing, score 1."""
    idx, bearing = visible_objects(m, pose, camera or CameraModel(360.0, 15.0))
    return [Detection(m.class_of(int(j)), float(b), 1.0) for j, b in zip(idx, bearing, strict=True)]


def told_at(
    m: SemanticMap, pose: Pose, fov_deg: float = 66.0, frames: int = 10
) -> tuple[ParticleFilter, list[Detection], Estimate]:
    """A filter (2,000 particles, a ``fov_deg`` camera) started at ``pose`` (0.1 m,
    0.05 rad) and standing there ``frames`` frames seeing what it sees exactly; the
    filter, those detections and the last estimate."""
    pf = ParticleFilter(
        m,
        FilterConfig(particles=2000, fov_deg=fov_deg),
        rng=np.random.default_rng(3),
        initial_pose=InitialPose(pose.x, pose.y, pose.theta_rad, 0.1, 0.05),
    )
    seen = seen_from(m, pose, CameraModel(fov_deg, 15.0))
    est = None
    for _ in range(frames):
        est = pf.step(Odometry(0.0, 0.0, 0.0), seen)
    assert est is not None
    return pf, seen, est


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


def make_manager(**overrides: object) -> SessionManager:
    """A session manager over the bundled maps (:func:`bundled_maps`), in memory, with
    :func:`make_settings` and ``overrides``."""
    return SessionManager(bundled_maps(), make_settings(**overrides), Metrics())


# ------------------------------------------------------------------------- servers
ROOT = Path(__file__).resolve().parents[1]


def free_port() -> int:
    """A TCP port on the loopback interface that nothing listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def serving(
    app: FastAPI,
    port: int,
    *,
    timeout_s: float = 60.0,
    log_level: str = "warning",
    freeze_start_up: bool = False,
) -> Iterator[str]:
    """Run ``app`` with a real uvicorn server on ``port`` in a thread; yield host:port.

    The server is configured as ``bearings serve`` configures it (size limits, log
    redaction, draining at shutdown), from the app's own settings.
    """
    settings: Settings = app.state.settings
    # log_config=None: records go to pytest's capture, not to handlers bound to a stream
    # that one test's capture closes (the redaction filters sit on the loggers as well).
    config = uvicorn_config(
        app, settings, host="127.0.0.1", port=port, log_level=log_level, log_config=None
    )
    server = BearingsServer(config, app, freeze_start_up=freeze_start_up)
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


@dataclass
class ServerProcess:
    """A running `bearings serve`: where it listens, the process, and its log file."""

    url: str
    proc: subprocess.Popen[bytes]
    log: Path

    def output(self) -> str:
        """Everything the server wrote so far (stdout and stderr: every log line)."""
        return self.log.read_text(errors="replace")


@contextmanager
def server_process(
    *args: str, env: dict[str, str] | None = None, timeout_s: float = 120.0
) -> Iterator[ServerProcess]:
    """`bearings serve --no-viser` in its own process on a free port.

    Its stdout and stderr go to a file (never a pipe that could fill and block it).
    The process is killed at the end if it still runs.
    """
    port = free_port()
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "server.log"
        with log.open("wb") as sink:
            proc = subprocess.Popen(
                [sys.executable, "-m", "app.cli", "serve", "--port", str(port), "--no-viser",
                 *args],
                cwd=ROOT,
                env={**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})},
                stdout=sink,
                stderr=subprocess.STDOUT,
            )  # fmt: skip
        served = ServerProcess(f"127.0.0.1:{port}", proc, log)
        deadline = time.time() + timeout_s
        try:
            while True:
                if proc.poll() is not None:
                    raise RuntimeError(f"the server exited: {served.output()}")
                try:
                    if httpx.get(f"http://{served.url}/healthz", timeout=1).status_code == 200:
                        break
                except httpx.HTTPError:
                    pass
                if time.time() > deadline:
                    raise RuntimeError("the server did not start")
                time.sleep(0.2)
            yield served
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(timeout=30)


def rss_kib(pid: int) -> int:
    """Resident memory of a process, KiB (Linux /proc)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise RuntimeError(f"no VmRSS for process {pid}")


def need_binary(name: str) -> str:
    """The path of a program the test needs: skipped here when missing, a failure in CI."""
    import os
    import shutil

    import pytest

    path = shutil.which(name) or next(
        (p for p in (f"/usr/sbin/{name}", f"/usr/bin/{name}") if os.path.exists(p)), None
    )
    if path is None:
        message = f"{name} is not installed (Debian package: see .ci/run)"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"{message}; CI must run this test")
        pytest.skip(message)
    return path


def wait_for_port(port: int, timeout_s: float = 20.0) -> None:
    """Until something accepts connections on 127.0.0.1:port."""
    deadline = time.time() + timeout_s
    while time.time() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise RuntimeError(f"nothing listens on port {port} after {timeout_s} s")


@contextmanager
def redis_server(*config: str) -> Iterator[str]:
    """A private redis-server on a free port, in memory only; yields its redis:// URL.

    ``config``: more of its settings, as command-line arguments (``"--requirepass", "pw"``).
    """
    import subprocess

    binary = need_binary("redis-server")
    port = free_port()
    proc = subprocess.Popen(
        [binary, "--port", str(port), "--bind", "127.0.0.1", "--save", "", "--appendonly", "no",
         *config],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        wait_for_port(port)
        yield f"redis://127.0.0.1:{port}/0"
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def venue_frame_json(vf: object) -> dict[str, object]:
    """A simulated venue frame (app.simulation.venue_walk.VenueFrame) as a service frame:
    its contract form without the truth (which is in the filter's plane), with the
    barometer's altitude."""
    out = vf.frame.to_contract()  # type: ignore[attr-defined]
    out.pop("truth")
    alt = vf.altitude  # type: ignore[attr-defined]
    out["altitude"] = {"relative_m": round(alt.relative_m, 3), "std_m": alt.std_m}
    return out


def symmetric_venue_spec(first_floor_extra: list[dict] | None = None) -> dict[str, object]:
    """Two floors, each a 12 x 8 m room that a half turn about (6, 4) carries onto itself
    (the symmetric room's windows and tables on the Ground Floor, its windows and two
    plants on the First Floor: the floors differ), joined by two stairs whose landings
    are each other's images: a venue with twins (app.maps.symmetry). Extra objects on
    the First Floor with ``first_floor_extra``."""
    from app.experiments.hard_maps import hard_map

    room = hard_map("symmetric_room").map.to_json()
    walls = room["walls"]
    objects = room["objects"]
    windows = [o for o in objects if o["class"] == "window"]
    plants = [{"class": "plant", "x": 2.5, "y": 4.5}, {"class": "plant", "x": 9.5, "y": 3.5}]
    upstairs = windows + plants + list(first_floor_extra or [])

    def landing(x: float, y: float, level: str) -> dict[str, object]:
        square = [[x - 0.5, y - 0.5], [x + 0.5, y - 0.5], [x + 0.5, y + 0.5], [x - 0.5, y + 0.5]]
        return {"level": level, "polygon": square}

    return {
        "name": "symmetric_venue",
        "levels": [
            {"id": "L0", "name": "Ground Floor", "ordinal": 0},
            {"id": "L1", "name": "First Floor", "ordinal": 1},
        ],
        "walls": [{**w, "level": lv} for lv in ("L0", "L1") for w in walls],
        "objects": [{**o, "level": "L0"} for o in objects]
        + [{**o, "level": "L1"} for o in upstairs],
        "connectors": [
            {
                "id": f"stairs-{n}",
                "kind": "stairs",
                "stops": [landing(x, y, "L0"), landing(x, y, "L1")],
            }
            for n, (x, y) in (("west", (1.5, 1.5)), ("east", (10.5, 6.5)))
        ],
    }
