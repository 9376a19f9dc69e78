"""Helpers shared by tests that run real servers."""

from __future__ import annotations

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
from fastapi import FastAPI

from app.config import Settings
from app.server import BearingsServer, uvicorn_config

ROOT = Path(__file__).resolve().parents[1]


def free_port() -> int:
    """A TCP port on the loopback interface that nothing listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def serving(
    app: FastAPI, port: int, *, timeout_s: float = 60.0, log_level: str = "warning"
) -> Iterator[str]:
    """Run ``app`` with a real uvicorn server on ``port`` in a thread; yield host:port.

    The server is configured as ``bearings serve`` configures it (size limits, log
    redaction, draining at shutdown), from the app's own settings.
    """
    settings: Settings = app.state.settings
    config = uvicorn_config(app, settings, host="127.0.0.1", port=port, log_level=log_level)
    server = BearingsServer(config, app)
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
