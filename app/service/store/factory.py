"""The store a ``--store`` value names."""

from __future__ import annotations

from urllib.parse import urlsplit

from app.service.store.group_commit import JOURNAL_GAP_S
from app.service.store.memory import MemoryStore
from app.service.store.protocol import SessionStore
from app.service.store.redis_store import RedisStore
from app.service.store.urls import redacted


def open_store(url: str, *, journal_gap_s: float = JOURNAL_GAP_S) -> SessionStore:
    """The store a ``--store`` value names: ``memory`` or ``redis://HOST:PORT/DB``
    (``journal_gap_s``: see :data:`~app.service.store.group_commit.JOURNAL_GAP_S`)."""
    if url == "memory":
        return MemoryStore()
    scheme = urlsplit(url).scheme
    if scheme in ("redis", "rediss", "unix"):
        return RedisStore(url, journal_gap_s=journal_gap_s)
    raise ValueError(
        f"store: {redacted(url)!r} is neither 'memory' nor a redis:// (rediss://, unix://) URL"
    )
