"""A private redis-server that a test can kill, stop, and start again on the same port.

tests/helpers.py's ``redis_server`` runs one for a whole test; the store-outage tests
need to do to it what happens to a real one: ``kill -9``, a restart without
persistence (empty) or with its append-only file (what was written comes back), and
SIGSTOP (a Redis that stops answering but keeps its connections).
"""

from __future__ import annotations

import signal
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from tests.helpers import free_port, need_binary, wait_for_port


class RedisProcess:
    """redis-server on a fixed port, in ``data_dir``; ``aof``: every write is appended
    to a file and fsynced before Redis answers (``appendfsync always``)."""

    def __init__(self, data_dir: Path, *, aof: bool = False) -> None:
        self.binary = need_binary("redis-server")
        self.port = free_port()
        self.data_dir = data_dir
        self.aof = aof
        self.proc: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"redis://127.0.0.1:{self.port}/0"

    def start(self) -> None:
        persistence = ["--appendonly", "yes", "--appendfsync", "always"] if self.aof else [
            "--appendonly", "no"]  # fmt: skip
        self.proc = subprocess.Popen(
            [self.binary, "--port", str(self.port), "--bind", "127.0.0.1", "--save", "",
             "--dir", str(self.data_dir), *persistence],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )  # fmt: skip
        wait_for_port(self.port)
        if self.aof:  # the append-only file is loaded before Redis answers commands
            import redis

            deadline = time.monotonic() + 20
            while True:
                try:
                    redis.Redis(port=self.port).ping()
                    break
                except redis.BusyLoadingError:
                    if time.monotonic() > deadline:
                        raise
                    time.sleep(0.05)

    def kill(self) -> None:
        """``kill -9``: gone at once, connections reset, nothing flushed."""
        assert self.proc is not None
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=10)

    def pause(self) -> None:
        """SIGSTOP: connections stay open and unanswered."""
        assert self.proc is not None
        self.proc.send_signal(signal.SIGSTOP)

    def resume(self) -> None:
        assert self.proc is not None
        self.proc.send_signal(signal.SIGCONT)

    def close(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGCONT)
            self.proc.kill()
            self.proc.wait(timeout=10)


@contextmanager
def redis_process(data_dir: Path, *, aof: bool = False) -> Iterator[RedisProcess]:
    """A started :class:`RedisProcess`, killed at the end."""
    process = RedisProcess(data_dir, aof=aof)
    process.start()
    try:
        yield process
    finally:
        process.close()
