"""What the service refuses, and how it logs session events.

Apart from :mod:`app.service.sessions` so that the modules the session manager uses
(sharing, store) can raise and log the same way without importing it back.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import logging
import secrets
import time

log = logging.getLogger("bearings.sessions")

#: When this process started: a session id unknown to it may have ended with a restart.
STARTED_AT = time.monotonic()
#: Per-process secret of :func:`session_tag` (so a tag cannot be traced back to an id).
_TAG_KEY = secrets.token_bytes(16)


def session_tag(session_id: str) -> str:
    """A short handle for logs and the view: a keyed hash, not a piece of the id."""
    return hmac.new(_TAG_KEY, session_id.encode(), hashlib.sha256).hexdigest()[:8]


class SessionNotFound(KeyError):
    """No live session has that id for this caller (another key's session counts as none)."""

    def __init__(self, session_id: str) -> None:
        super().__init__(session_id)
        up = time.monotonic() - STARTED_AT
        self.message = (
            f"no session {session_id!r}: it never existed, was deleted, expired, or ended "
            f"when the service restarted (this server started {up:.0f} s ago); "
            "create a new session"
        )

    def __str__(self) -> str:
        return self.message


class LimitReached(RuntimeError):
    """A service limit was hit; ``code`` names the limit in a machine-readable word.

    ``retry_after_s`` says when trying again may succeed (None: it never will as asked).
    """

    def __init__(
        self, message: str, code: str = "limit", retry_after_s: float | None = None
    ) -> None:
        super().__init__(message)
        self.code = code
        self.retry_after_s = retry_after_s


class CapacityReached(LimitReached):
    """The whole service is full now (sessions, waiting filter steps, or it is restarting)."""


class QuotaReached(LimitReached):
    """One client's own quota (sessions, particles, frames per second) is used up now."""


class RequestTooLarge(LimitReached):
    """One request asks for more than the service ever allows (particles, detections)."""


class SessionUnavailable(LimitReached):
    """The session exists but cannot be served here right now (another worker still
    holds it, or this worker is stopping); retrying soon, or reconnecting, serves it."""


class InvalidSessionSpec(ValueError):
    """A session cannot be built as asked (e.g. a start pose outside the free space)."""


class UnknownMap(LookupError):
    def __init__(self, name: str, known: list[str]) -> None:
        super().__init__(f"no map {name!r}; known maps: {', '.join(known) or 'none'}")


def log_event(event: str, **fields: object) -> None:
    """One structured (JSON) log line per session event."""
    log.info(json.dumps({"event": event, **fields}, default=str))
